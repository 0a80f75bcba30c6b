"""The thesis's extraction experiment with an active compliance centre, in MJX (Sec 2.5, 3.4).

Per world: the peg starts fully inserted (keyframe ``inserted``, centred, aligned, no contact).
The impedance law (:mod:`peghole_mjx.control`) holds the compliance centre ``C`` (``L_C`` above
the tip) with a lateral stiffness ``k_lat`` and a rotational stiffness ``k_rot``. Its commanded
pose is the start pose of ``C`` displaced to the spring rest pose of the quasi-static model
(:func:`peghole_mjx.analysis.common.rest_pose`): a lateral error ``delta0`` along world x plus
``-L_C sin(theta0)``, and a rotation by ``beta0 + theta0`` about ``C`` (about world y). Both
errors are ramped in over the settling time; then the commanded point moves straight up at a
constant speed until the tip is clear of the mouth. Angles use the thesis's (the model's) sign:
a positive angle tilts the peg top towards -x (a rotation of ``-(beta0 + theta0)`` about world y).

Logged per 20 ms sample (the mean over its physics steps, like an anti-aliased F/T reading):
the tip depth, the tared F/T force, and per lateral wall side (contact normals along +x and -x)
the mean and the peak per-step normal contact force, the fraction of steps with both sides
loaded, and the number of wall-contact switches. Two-point contact is judged on the per-side
mean force of each sample (:func:`two_point_windows`), not on same-step coincidence.

Batching: all worlds of a (preset, friction) run through ``jax.vmap`` inside one jitted,
time-chunked ``lax.scan`` (tqdm shows the chunks); :meth:`Extraction.run` takes any table of
per-world parameters, so a sweep batches every cell of a preset into the same compiled call.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx
from scipy.signal import savgol_filter

from peghole_mjx import progress as prog
from peghole_mjx.analysis import dual as an_dual
from peghole_mjx.analysis import oracle
from peghole_mjx.analysis import rect as an_rect
from peghole_mjx.control import GAINS, ImpedanceController, Target, make_params, rot_y
from peghole_mjx.errors import UserInputError
from peghole_mjx.geometry.mjcf import SimOptions, compile_scene
from peghole_mjx.geometry.specs import MM, PRESETS
from peghole_mjx.mjx_fixes import cone_hessian_fix

#: thesis values to compare with (Sec 3.5, R1): reductions of the mean peak extraction force
THESIS = {
    "reduction_tip_vs_top_pct": 77.1,
    "reduction_tip_vs_centre_pct": 55.6,
    "source": "thesis Sec 3.5 (rectangular peg, real KUKA LBR iiwa); dual: Fig 2.20 ordering only",
}

GEOMETRIES = ("rect", "dual")


@dataclass(frozen=True)
class GeometrySetup:
    """What the experiment sets per geometry (an :class:`ExperimentConfig` field per geometry,
    ``ExperimentConfig.rect`` and ``.dual``, with its defaults).

    * ``lc_mm``: the compliance centre's positions, mm above the peg tip: tip, centre, top.
    * ``timestep_s``, ``contact_timeconst_s``: the physics step and the contact time constant,
      s (evidence: ``peghole experiment contact-check``, benchmarks/results/evals/contact_check.json
      and the table in docs/research/contact.md). In float32 a 1 um penetration is within a few ulps
      of the world coordinates (~0.6 m), so MuJoCo's stiffest contact (time constant 2 steps)
      turns rounding noise into force noise; a 10 ms time constant keeps the tilted rect pegs
      in two-point contact with a few um of penetration. The dual presets' clearances are 2-4x
      larger.
    * ``representation``: the collision representation. Dual: the exact 16-gon meshes, not
      the envs' capsules: in a jammed two-point configuration MJX-JAX's capsule-box contact
      keeps the mouth normal horizontal and reads F_z 33-97 % above the quasi-static oracle,
      the mesh scene within 3 % (benchmarks/results/studies/capsule_fidelity.json).

    Decided 2026-12-02: these were module tables (``LC_MM``, ``TIMESTEP_S``,
    ``CONTACT_TIMECONST_S``, ``REPRESENTATION``) beside the config; as config fields a run
    states and records them with its other settings (:func:`config_dict`), values unchanged.
    """

    lc_mm: tuple[float, ...]
    timestep_s: float
    contact_timeconst_s: float
    representation: str


#: a 20 ms sample is a two-point window when both wall sides carry at least this mean normal
#: force (N): well below the lateral spring's 0.3-0.6 N and above the solver's noise floor
TWO_POINT_MIN_N = 0.05
#: a physics step counts a side as loaded above this normal force, N
LOADED_N = 1e-3
#: the part of the pull left out of the "late" peaks (the start transient), mm
EARLY_MM = {"rect": 5.0, "dual": 2.0}

#: per-sample record columns (means over the sample's steps unless the name says otherwise)
REC = (
    "depth",
    "fx",
    "fy",
    "fz",
    "f_plus",
    "f_minus",
    "f_plus_max",
    "f_minus_max",
    "both_frac",
    "switches",
    "any_frac",
    "wrench_ratio",
    "pen_max",
)
_R = {k: i for i, k in enumerate(REC)}
_MEAN = ("depth", "fx", "fy", "fz", "f_plus", "f_minus", "both_frac", "any_frac")
_MAX = ("f_plus_max", "f_minus_max", "wrench_ratio", "pen_max")
WORLD_KEYS = ("L_C", "delta0", "beta0", "theta0", "k_lat", "k_rot")


@dataclass(frozen=True)
class ExperimentConfig:
    """Parameters of the simulated extraction experiment (SI unless the name says mm/deg)."""

    geometry: str = "rect"
    presets: tuple[str, ...] = ()
    repeats: int = 6
    seed: int = 0
    lateral_stiffness_N_m: float = GAINS.lateral_stiffness_N_m
    axial_stiffness_N_m: float = GAINS.axial_stiffness_N_m
    rotational_stiffness_Nm_rad: float = GAINS.rotational_stiffness_Nm_rad
    #: lateral error of the commanded C (thesis analyses: delta0 = 2 mm), uniform range, mm
    delta0_mm: tuple[float, float] = (1.5, 2.5)
    #: angular error of the commanded frame about C, uniform range, deg (thesis sign; one sign
    #: per run, since the sign of the L_C effect follows it)
    beta0_deg: tuple[float, float] = (0.1, 0.3)
    #: commanded initial tilt theta0 (thesis Tables 2.2, 3.2, erratum E3: -0.9 deg), deg
    theta0_deg: float = 0.0
    speed_m_s: float = 0.02
    settle_s: float = 0.3
    clear_mm: float = 5.0  # pull until the tip is this far above the mouth
    #: F/T sample period, s: each logged sample is the mean over its physics steps
    record_every_s: float = 0.02
    #: physics steps per jitted call (a multiple of the steps per sample)
    chunk_steps: int = 400
    batch: str = "vmap"
    #: simulator options of the scene (None: ``SimOptions()`` at the geometry's
    #: ``timestep_s`` and ``contact_timeconst_s``, :meth:`sim_options`)
    sim: SimOptions | None = None
    #: collision representation (None: the geometry's ``representation``, :meth:`setup`)
    representation: str | None = None
    #: the law cancels the arm model's joint damping (``ImpedanceController``'s
    #: ``compensate_passive``): uncancelled, it tilts a 3 N m/rad spring by more than beta0
    #: (benchmarks/results/studies/low_stiffness_check.json; docs/research/pull_speed.md, "Soft
    #: rotational springs")
    compensate_joint_damping: bool = True
    #: trace the experiment with MJX's elliptic-cone Newton Hessian fixed
    #: (:mod:`peghole_mjx.mjx_fixes`): the shipped one turned 13 of 48 worlds to NaN at
    #: K_theta 3 N m/rad, the fixed one none
    fix_cone_hessian: bool = True
    #: rotational stiffness about the compliance frame's x and z axes (the axes other than the
    #: tilt axis y of the planar oracle), N m/rad; None: the world's K_theta on all three axes
    off_axis_rotational_stiffness_Nm_rad: float | None = None
    #: the law's damping ratio zeta (None: ``GAINS.damping_ratio``)
    damping_ratio: float | None = None
    #: the rect and dual presets' L_C positions, step, contact time constant and collision
    #: representation (:class:`GeometrySetup`)
    rect: GeometrySetup = GeometrySetup(
        lc_mm=(0.0, 75.0, 150.0), timestep_s=0.001, contact_timeconst_s=0.01, representation="edges"
    )
    dual: GeometrySetup = GeometrySetup(
        lc_mm=(0.0, 25.0, 50.0), timestep_s=0.002, contact_timeconst_s=0.01, representation="mesh"
    )

    def setup(self, kind: str | None = None) -> GeometrySetup:
        """The :class:`GeometrySetup` of geometry ``kind`` (None: this config's ``geometry``)."""
        kind = kind or self.geometry
        if kind not in GEOMETRIES:
            raise UserInputError(f"geometry must be rect or dual, not {kind!r}")
        return getattr(self, kind)

    def representation_of(self, kind: str) -> str:
        """The collision representation of a ``kind`` preset: ``representation``, else the
        geometry's."""
        return self.representation or self.setup(kind).representation

    def sim_options(self) -> SimOptions:
        """The simulator options in effect: ``sim``, else the project's default options at the
        geometry's experiment step and contact time constant (:meth:`setup`)."""
        if self.sim is not None:
            return self.sim
        setup = self.setup()
        return dataclasses.replace(
            SimOptions(),
            timestep=setup.timestep_s,
            contact_timeconst=setup.contact_timeconst_s,
        )

    @classmethod
    def quick(cls, geometry: str = "rect", seed: int = 0) -> ExperimentConfig:
        """The quick experiment (``--quick``, ``peghole demo``): one preset (rect-2 or
        dual-2), 2 repeats."""
        return cls(geometry=geometry, presets=(f"{geometry}-2",), repeats=2, seed=seed)

    def preset_names(self) -> tuple[str, ...]:
        if self.presets:
            return self.presets
        return tuple(n for n, s in PRESETS.items() if s.kind == self.geometry)


def world_table(cfg: ExperimentConfig, preset: str) -> dict[str, np.ndarray]:
    """Per-world parameters (SI; angles in rad, thesis sign): the three L_C x ``repeats``.

    The same error draws are used for each L_C (paired comparison).
    """
    rng = np.random.default_rng([cfg.seed, sorted(PRESETS).index(preset)])
    d0 = rng.uniform(*cfg.delta0_mm, cfg.repeats) * MM
    b0 = np.radians(rng.uniform(*cfg.beta0_deg, cfg.repeats))
    lc = np.array(cfg.setup(PRESETS[preset].kind).lc_mm) * MM
    n = len(lc) * cfg.repeats
    return {
        "L_C": np.repeat(lc, cfg.repeats),
        "delta0": np.tile(d0, len(lc)),
        "beta0": np.tile(b0, len(lc)),
        "theta0": np.full(n, math.radians(cfg.theta0_deg)),
        "k_lat": np.full(n, cfg.lateral_stiffness_N_m),
        "k_rot": np.full(n, cfg.rotational_stiffness_Nm_rad),
    }


class Extraction:
    """One preset's compiled scene (at friction ``mu``), controller and jitted chunk function."""

    def __init__(self, preset: str, cfg: ExperimentConfig, mu: float | None = None):
        if preset not in PRESETS:
            raise UserInputError(f"unknown preset {preset!r}; known: {', '.join(PRESETS)}")
        self.preset, self.cfg = preset, cfg
        self.spec = PRESETS[preset]
        if mu is not None:
            self.spec = dataclasses.replace(self.spec, friction=float(mu))
        self.mu = float(self.spec.friction)
        rep = cfg.representation_of(self.spec.kind)
        m = compile_scene(self.spec, sim=cfg.sim_options(), representation=rep)
        self.m = m
        self.ctl = ImpedanceController(m, compensate_passive=cfg.compensate_joint_damping)
        d = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
        mujoco.mj_forward(m, d)
        self.q0 = d.qpos.copy()
        # tare: static F/T reading (world frame) with the peg held by gravity compensation
        d.ctrl[self.ctl.act] = d.qfrc_bias[self.ctl.dadr]
        mujoco.mj_forward(m, d)
        ft = m.sensor("ft_force")
        R = d.site("ft_site").xmat.reshape(3, 3)
        self.tare_world = R @ d.sensordata[ft.adr[0] : ft.adr[0] + 3]
        self.ft_adr = int(ft.adr[0])
        self.ft_site = m.site("ft_site").id
        self.tip_site = m.site("peg_tip").id
        self._peg_geom = jnp.asarray(m.geom_bodyid == m.body("peg").id)
        self.mouth_z = float(d.site("hole_mouth").xpos[2])
        self.tip_z0 = float(d.site("peg_tip").xpos[2])
        self.dt = m.opt.timestep
        self.mx = mjx.put_model(m, impl="jax")
        dx0 = mjx.put_data(m, d, impl="jax")
        # with jax_enable_x64 a step returns some int32 fields as int64: start with its dtypes
        out = jax.eval_shape(mjx.step, self.mx, dx0)
        self.dx0 = jax.tree.map(lambda a, o: a.astype(o.dtype), dx0, out)
        depth = self.mouth_z - self.tip_z0
        pull = depth + cfg.clear_mm * MM
        self.n_settle = round(cfg.settle_s / self.dt)
        n = self.n_settle + math.ceil(pull / (cfg.speed_m_s * self.dt))
        self.record_every = round(cfg.record_every_s / self.dt)
        if self.record_every < 1 or abs(self.record_every * self.dt - cfg.record_every_s) > 1e-9:
            raise ValueError(
                f"record_every_s ({cfg.record_every_s}) must be a multiple of the step ({self.dt})"
            )
        if cfg.chunk_steps % self.record_every:
            raise ValueError(
                f"chunk_steps ({cfg.chunk_steps}) must be a multiple of the steps per sample "
                f"({self.record_every})"
            )
        self.n_chunks = math.ceil(n / cfg.chunk_steps)
        self.n_steps = self.n_chunks * cfg.chunk_steps
        self._chunk = jax.jit(self._chunk_fn)
        self._compiled = False  # the first chunk of the first run compiles _chunk

    # ---- one world -------------------------------------------------------------------
    def init_world(self, L_C, delta0, beta0, theta0, k_lat, k_rot):
        kz = self.cfg.axial_stiffness_N_m
        off = self.cfg.off_axis_rotational_stiffness_Nm_rad
        k_off = k_rot if off is None else jnp.full_like(k_rot, off)
        params = make_params(
            L_C,
            self.q0,
            stiffness=jnp.stack([k_lat, k_lat, jnp.full_like(k_lat, kz), k_off, k_rot, k_off]),
            damping_ratio=self.cfg.damping_ratio,
        )
        x_C, R = self.ctl.centre_pose(self.dx0, params.L_C)
        # spring rest pose of the quasi-static model (analysis.common.rest_pose), world frame:
        # lateral offset along +x, rotation about world y of -(beta0 + theta0) (thesis sign)
        dx = delta0 - L_C * jnp.sin(theta0)
        err = jnp.stack([dx, -(beta0 + theta0)])
        target = Target(x_C, R, jnp.zeros(3))
        # max penetration m, nan flag, depth and time at max penetration, last single side,
        # max penetration while the tip is below the mouth (where the clearance constrains it)
        stats = jnp.zeros(6)
        return (self.dx0, target, params, err, stats)

    def _side_forces(self, dx):
        """Normal contact force summed over the contacts facing +x and -x, N."""
        con = dx._impl.contact
        addr = con.efc_address
        fn = jnp.where(addr >= 0, dx._impl.efc_force[jnp.maximum(addr, 0)], 0.0)
        nx = con.frame[:, 0, 0] if con.frame.ndim == 3 else con.frame[:, 0]
        # the normal points from geom1 to geom2: make it point from the peg into the hole
        nx = jnp.where(self._peg_geom[con.geom1], nx, -nx)
        plus = jnp.sum(jnp.where(nx > 0.3, fn, 0.0))
        minus = jnp.sum(jnp.where(nx < -0.3, fn, 0.0))
        pen = jnp.max(jnp.where((addr >= 0) & jnp.isfinite(con.dist), -con.dist, 0.0), initial=0.0)
        return plus, minus, pen

    def step(self, carry, t):
        dx, target, params, err, stats = carry
        cfg = self.cfg
        moving = t >= self.n_settle
        vel = jnp.where(moving, cfg.speed_m_s, 0.0) * jnp.array([0.0, 0.0, 1.0])
        target = target._replace(pos=target.pos + vel * self.dt, vel=vel)
        # both errors are ramped in over the settling time (no impact at the start)
        a = jnp.clip(t / jnp.maximum(self.n_settle, 1), 0.0, 1.0)
        cmd = target._replace(
            pos=target.pos + a * err[0] * jnp.array([1.0, 0.0, 0.0]),
            mat=rot_y(a * err[1]) @ target.mat,
        )
        dx_c, out = self.ctl.apply(self.mx, dx, cmd, params)
        new = mjx.step(self.mx, dx_c)
        ok = jnp.all(jnp.isfinite(new.qpos)) & jnp.all(jnp.isfinite(new.qvel)) & (stats[1] == 0)
        dx = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, dx)
        plus, minus, pen = self._side_forces(dx)
        pen = jnp.where(ok, pen, 0.0)
        new_max = pen > stats[0]
        tip_depth = self.mouth_z - dx.site_xpos[self.tip_site, 2]
        # wall-contact switch: the one loaded side differs from the last one-sided step's
        lp, lm = plus > LOADED_N, minus > LOADED_N
        side = jnp.where(lp & ~lm, 1.0, jnp.where(lm & ~lp, -1.0, 0.0))
        switch = (side != 0) & (stats[4] != 0) & (side != stats[4])
        stats = (
            stats.at[2]
            .set(jnp.where(new_max, tip_depth, stats[2]))
            .at[3]
            .set(jnp.where(new_max, t * self.dt, stats[3]))
            .at[0]
            .max(pen)
            .at[1]
            .set(jnp.where(ok, 0.0, 1.0))
            .at[4]
            .set(jnp.where(side != 0, side, stats[4]))
            .at[5]
            .max(jnp.where(tip_depth > 0, pen, 0.0))
        )
        # F/T force on the peg, world frame, tared
        f = dx.site_xmat[self.ft_site] @ dx.sensordata[self.ft_adr : self.ft_adr + 3]
        f = f - self.tare_world
        ratio = jnp.max(jnp.abs(out.wrench) / jnp.asarray(self.ctl.limits.max_wrench))
        rec = jnp.stack(
            [
                tip_depth,
                f[0],
                f[1],
                f[2],
                plus,
                minus,
                plus,
                minus,
                (lp & lm).astype(f.dtype),
                switch.astype(f.dtype),
                (lp | lm).astype(f.dtype),
                ratio,
                pen,
            ]
        )
        return (dx, target, params, err, stats), rec

    def _world_chunk(self, carry, t0):
        ts = t0 + jnp.arange(self.cfg.chunk_steps)
        carry, rec = jax.lax.scan(self.step, carry, ts)
        k = self.record_every
        rec = rec.reshape(-1, k, rec.shape[-1])
        out = [None] * len(REC)
        for name in _MEAN:
            out[_R[name]] = rec[:, :, _R[name]].mean(1)
        for name in _MAX:
            out[_R[name]] = rec[:, :, _R[name]].max(1)
        out[_R["switches"]] = rec[:, :, _R["switches"]].sum(1)
        return carry, jnp.stack(out, axis=-1)

    def _chunk_fn(self, carries, t0):
        f = functools.partial(self._world_chunk, t0=t0)
        if self.cfg.batch == "vmap":
            return jax.vmap(f)(carries)
        return f(carries)  # batch="map": one world per call

    def run(
        self, progress: bool = True, table: dict[str, np.ndarray] | None = None
    ) -> dict[str, np.ndarray]:
        """Run every world of ``table`` (default :func:`world_table`) in one batch.

        Returns per world and sample the :data:`REC` columns (forces in N, ``depth_mm``), the
        table, ``two_point`` (:func:`two_point_windows`), per-world ``penetration_mm`` (the
        whole pull), ``penetration_in_hole_mm`` (while the tip is below the mouth; this still
        holds the exit, where the tip's rounded edges pass the mouth's within about two edge
        radii of the mouth), ``penetration_two_point_mm`` (inside the two-point windows, from
        the per-sample maxima ``pen_max_mm``; NaN without a window) and ``nan``, the sample
        times ``time_s`` and the start depth ``h0_mm``.
        """
        tab = world_table(self.cfg, self.preset) if table is None else table
        missing = [k for k in WORLD_KEYS if k not in tab]
        if missing:
            raise ValueError(f"world table lacks {missing}")
        carries = jax.vmap(self.init_world)(*(jnp.asarray(tab[k]) for k in WORLD_KEYS))
        nw = len(tab["L_C"])
        if self.cfg.batch == "vmap":
            groups = [carries]
        else:
            groups = [jax.tree.map(lambda a, i=i: a[i], carries) for i in range(nw)]
        bar = None  # started after the first chunk, so that its rate leaves the compile out
        recs, stats = [], []
        for g in groups:
            grec = []
            for c in range(self.n_chunks):
                what = f"the experiment's MJX step ({self.preset}, {nw} worlds)"
                with prog.compiling(what, enabled=progress and not self._compiled):
                    with cone_hessian_fix(self.cfg.fix_cone_hessian):
                        g, rec = self._chunk(g, jnp.asarray(c * self.cfg.chunk_steps))
                    grec.append(np.asarray(rec))
                self._compiled = True
                if bar is None:
                    bar = prog.bar(
                        self.n_chunks * len(groups),
                        f"{self.preset} pull",
                        unit="chunk",
                        enabled=progress,
                        initial=1,
                        leave=False,
                    )
                else:
                    bar.update()
            recs.append(
                np.concatenate(grec, axis=-2).reshape(-1, sum(r.shape[-2] for r in grec), len(REC))
            )
            stats.append(np.asarray(g[4]).reshape(-1, 6))
        if bar is not None:
            bar.close()
        rec = np.concatenate(recs, axis=0).astype(np.float64)  # (worlds, samples, REC)
        stats = np.concatenate(stats, axis=0)
        out = {k: np.asarray(v) for k, v in tab.items()}
        for name in REC:
            out[name] = rec[..., _R[name]]
        out["depth_mm"] = out.pop("depth") / MM
        out["pen_max_mm"] = out.pop("pen_max") / MM
        out["two_point"] = two_point_windows(out["f_plus"], out["f_minus"])
        out.update(
            penetration_two_point_mm=two_point_penetration(out["two_point"], out["pen_max_mm"]),
            penetration_mm=stats[:, 0] / MM,
            penetration_in_hole_mm=stats[:, 5] / MM,
            penetration_at_depth_mm=stats[:, 2] / MM,
            penetration_at_time_s=stats[:, 3],
            nan=stats[:, 1] > 0,
        )
        out["time_s"] = (np.arange(rec.shape[1]) + 1) * self.record_every * self.dt
        out["h0_mm"] = (self.mouth_z - self.tip_z0) / MM
        out["settle_s"] = self.n_settle * self.dt
        return out


def two_point_penetration(two_point: np.ndarray, pen_max: np.ndarray) -> np.ndarray:
    """Per world, the deepest contact inside its two-point windows (the scope of the contact
    bound), from per-sample maxima ``pen_max`` (worlds x samples); NaN for a world without a
    window. The whole-pull maxima also hold the exit, where the tip's rounded edges pass the
    mouth's within about two edge radii of the mouth with no wall force (rect-2, K_theta
    3 N m/rad, 2 mm/s: 144 um there, 2 um in the windows; 2026-11-29)."""
    two_point, pen_max = np.asarray(two_point, bool), np.asarray(pen_max, float)
    if two_point.shape != pen_max.shape:
        raise ValueError(f"two_point {two_point.shape} and pen_max {pen_max.shape} differ")
    deepest = np.where(two_point, pen_max, -np.inf).max(axis=-1)
    return np.where(np.isfinite(deepest), deepest, np.nan)


def two_point_windows(
    f_plus: np.ndarray, f_minus: np.ndarray, min_force_N: float = TWO_POINT_MIN_N
) -> np.ndarray:
    """Two-point contact per sample: both wall sides carry a mean normal force >=
    ``min_force_N`` over the sample (time-averaged, so a contact that alternates between the
    walls within the sample counts as loading both; see :func:`chatter_stats`)."""
    f_plus, f_minus = np.asarray(f_plus, float), np.asarray(f_minus, float)
    return (f_plus >= min_force_N) & (f_minus >= min_force_N)


def window_means(per_step: np.ndarray, steps_per_window: int) -> np.ndarray:
    """Mean of a per-step trace (..., steps) over consecutive windows (a short tail dropped)."""
    a = np.asarray(per_step, float)
    n = a.shape[-1] // steps_per_window * steps_per_window
    return a[..., :n].reshape(*a.shape[:-1], -1, steps_per_window).mean(-1)


def chatter_stats(res: dict[str, np.ndarray], world: int) -> dict[str, float | None]:
    """Contact quality inside one world's two-point windows: the fraction of physics steps
    with both sides loaded, and the peak per-step over the 20 ms mean side force (median,
    p95 and max over the windows); ``None`` where the world has no two-point window."""
    tp = res["two_point"][world]
    if not tp.any():
        return {
            "windows": 0,
            "both_frac": None,
            "peak_ratio_median": None,
            "peak_ratio_p95": None,
            "peak_ratio_max": None,
        }
    ratio = np.maximum(
        res["f_plus_max"][world] / np.maximum(res["f_plus"][world], 1e-12),
        res["f_minus_max"][world] / np.maximum(res["f_minus"][world], 1e-12),
    )[tp]
    return {
        "windows": int(tp.sum()),
        "both_frac": float(np.mean(res["both_frac"][world][tp])),
        "peak_ratio_median": float(np.median(ratio)),
        "peak_ratio_p95": float(np.percentile(ratio, 95)),
        "peak_ratio_max": float(np.max(ratio)),
    }


#: Savitzky-Golay filter of the logged forces (the thesis filters its measurements so too)
SG_WINDOW, SG_ORDER = 11, 2


def force_magnitude(res: dict[str, np.ndarray], filtered: bool = True) -> np.ndarray:
    """Tared F/T force magnitude per world and sample, N (Savitzky-Golay filtered)."""
    mag = np.sqrt(res["fx"] ** 2 + res["fy"] ** 2 + res["fz"] ** 2)
    if filtered and mag.shape[1] >= SG_WINDOW:
        mag = savgol_filter(mag, SG_WINDOW, SG_ORDER, axis=1)
    return mag


def peak_forces(res: dict[str, np.ndarray]) -> np.ndarray:
    """Per-world peak of the filtered, tared F/T force magnitude, N (NaN worlds: NaN)."""
    peak = np.max(force_magnitude(res), axis=1)
    return np.where(res["nan"], np.nan, peak)


def pulled_mm(res: dict[str, np.ndarray]) -> np.ndarray:
    """How far each world's tip has risen from its start depth, per sample, mm."""
    return res["h0_mm"] - res["depth_mm"]


def peaks(res: dict[str, np.ndarray], skip_mm: float = 0.0) -> dict[str, np.ndarray]:
    """Per-world peaks during the pull, N: ``fz`` (the extraction force, F/T z, filtered like
    the thesis's measurements) and ``mag`` (|F|), over the samples after the settling time whose
    tip has risen more than ``skip_mm`` (0: the whole pull). NaN worlds give NaN."""
    sel = (res["time_s"] > res.get("settle_s", 0.0))[None, :] & (pulled_mm(res) > skip_mm)
    fz = res["fz"]
    if fz.shape[1] >= SG_WINDOW:
        fz = savgol_filter(fz, SG_WINDOW, SG_ORDER, axis=1)
    out = {}
    for name, a in (("fz", fz), ("mag", force_magnitude(res))):
        pk = np.max(np.where(sel, a, -np.inf), axis=1)
        out[name] = np.where(res["nan"] | ~np.isfinite(pk), np.nan, pk)
    return out


def two_point_interval(res: dict[str, np.ndarray], world: int) -> list[float] | None:
    """[min, max] tip depth (mm) at which one world touched opposite walls (None if never)."""
    mask = res["two_point"][world] & (res["time_s"] > 0)
    if not mask.any():
        return None
    d = res["depth_mm"][world][mask]
    return [round(float(d.min()), 3), round(float(d.max()), 3)]


#: how the experiment's parameters are mapped onto the quasi-static model (recorded in the JSON)
ANALYTIC_MAPPING = (
    "Per world, the same L_C, K_lateral, K_rot, friction, delta0, beta0 and theta0 as the "
    "simulation (the simulation commands the model's spring rest pose, analysis.common."
    "rest_pose; angles in the thesis's sign) and h0 = the start depth of the tip. rect: the error "
    "lies in the world x-z plane, across the hole width w (60.1 mm), i.e. the model's case 1 "
    "(y-z plane, psi = 0; case 3 equals case 1 since there is no error across v); dual: the "
    "x-z plane through both peg axes, categories 5, 10, 9 (16-gon pegs and holes with vertices "
    "on x: the x-clearance equals R - r). The interval is the union over the worlds (and "
    "categories) of the refined (exact-statics) regions. Not modelled: robot dynamics, the "
    "axial spring (the model prescribes the vertical motion), contact softness, the settling-"
    "time ramp-in of the errors."
)


def analytic_two_point_hook(
    preset: str,
    L_C_mm: float,
    cfg: ExperimentConfig,
    delta0_mm: np.ndarray | None = None,
    beta0_rad: np.ndarray | None = None,
    h0_mm: float | None = None,
) -> dict:
    """Cross-check: the quasi-static two-point region (:mod:`peghole_mjx.analysis`) for the
    experiment's parameters (see :data:`ANALYTIC_MAPPING`).

    ``delta0_mm``, ``beta0_rad`` (thesis sign): the worlds' errors (default: the
    mean of the config's ranges). Returns ``interval_mm`` (union of the worlds' regions, tip
    depth below the mouth, or None), ``worlds_with_two_point``, ``per_category`` (each
    category's union) and ``per_world`` ([lo, hi] or None per world).
    """
    spec = PRESETS[preset]
    d0 = np.atleast_1d(
        np.asarray(float(np.mean(cfg.delta0_mm)) if delta0_mm is None else delta0_mm, float)
    )
    b0 = np.atleast_1d(np.asarray(0.0 if beta0_rad is None else beta0_rad, float))
    h0 = spec.hole_depth_mm if h0_mm is None else min(float(h0_mm), spec.length_mm)
    K = cfg.lateral_stiffness_N_m * MM  # N/mm
    Kr = cfg.rotational_stiffness_Nm_rad / MM  # N mm/rad
    regions = {}
    if spec.kind == "dual":
        for cat in an_dual.CATEGORIES:
            r = an_dual.two_point_region(
                spec,
                cat,
                L_C_mm,
                K_x_N_per_mm=K,
                K_theta_Nmm_per_rad=Kr,
                delta0_mm=d0,
                beta0_rad=b0,
                theta0_rad=math.radians(cfg.theta0_deg),
                h0_mm=h0,
                refine=True,
            )
            regions[cat] = (np.broadcast_to(r.h_lo, d0.shape), np.broadcast_to(r.h_hi, d0.shape))
    else:
        r = an_rect.two_contact_region(
            spec,
            1,
            L_C_mm,
            h0_mm=h0,
            refine=True,
            K_x_N_per_mm=K,
            K_y_N_per_mm=K,
            K_theta_Nmm_per_rad=Kr,
            K_phi_Nmm_per_rad=Kr,
            K_psi_Nmm_per_rad=Kr,
            delta_x_mm=0.0,
            delta_y_mm=d0,
            delta_theta_rad=b0,
            theta0_rad=math.radians(cfg.theta0_deg),
        )
        regions["case 1"] = (np.broadcast_to(r.h_lo, d0.shape), np.broadcast_to(r.h_hi, d0.shape))

    def union(lo, hi):
        ok = np.isfinite(lo) & np.isfinite(hi)
        if not ok.any():
            return None
        return [round(float(lo[ok].min()), 3), round(float(hi[ok].max()), 3)]

    los = np.stack([lo for lo, _ in regions.values()])
    his = np.stack([hi for _, hi in regions.values()])
    per_world = [union(los[:, w], his[:, w]) for w in range(d0.size)]
    return {
        "interval_mm": union(los.ravel(), his.ravel()),
        "worlds_with_two_point": sum(iv is not None for iv in per_world),
        "per_category": {c: union(lo, hi) for c, (lo, hi) in regions.items()},
        "per_world": per_world,
    }


class DivergedError(UserInputError):
    """Every world of a run went NaN: reported as a failure with its likely cause (exit 2),
    not written as a result."""


def nan_cause(cfg: ExperimentConfig, x64: bool = False, k_rot_min: float | None = None) -> str:
    """The likely cause of worlds that went NaN, from the settings that are known to do it."""
    k_rot = cfg.rotational_stiffness_Nm_rad if k_rot_min is None else k_rot_min
    if not cfg.fix_cone_hessian:
        return (
            "MJX's elliptic-cone Newton Hessian as shipped (run without --no-fix-cone-hessian; "
            "peghole_mjx/mjx_fixes.py)"
        )
    if not x64 and cfg.speed_m_s < 0.005:
        return f"float32 at a slow pull ({cfg.speed_m_s * 1e3:g} mm/s): run with --x64"
    if k_rot < 10.0:
        return (
            f"a soft rotational spring (K_theta {k_rot:g} N m/rad) with a physics step of "
            f"{cfg.sim_options().timestep * 1e3:g} ms: try --x64 or a stiffer K_theta"
        )
    return (
        f"the contact settings (step {cfg.sim_options().timestep * 1e3:g} ms, contact time "
        "constant too short for it) or float32 rounding: try --x64"
    )


def check_not_all_nan(nan: np.ndarray, what: str, cause: str) -> None:
    """Raise :class:`DivergedError` when every world of ``nan`` (one flag per world) is set."""
    nan = np.asarray(nan, bool)
    if nan.size and nan.all():
        raise DivergedError(
            f"{what}: every one of its {nan.size} worlds went NaN (the simulation diverged), so "
            f"there is no result; likely cause: {cause}"
        )


def config_dict(cfg: ExperimentConfig) -> dict:
    """The config as JSON-ready data; ``sim``: the effective simulator options. A geometry's
    :class:`GeometrySetup` is written only when it differs from the default, so that a
    config's record (and a sweep's resume key, ``sweep.SweepConfig.settings``) is what it was
    before the setups became fields."""
    default = ExperimentConfig()
    out = {
        k: _json_ready(v)
        for k, v in dataclasses.asdict(cfg).items()
        if k not in GEOMETRIES or getattr(cfg, k) != getattr(default, k)
    }
    sim = cfg.sim_options()
    out["sim"] = {k: _json_ready(v) for k, v in dataclasses.asdict(sim).items()}
    return out


def _json_ready(v):
    """Tuples as lists, in nested dicts too (a :class:`GeometrySetup` as ``asdict`` gives it)."""
    if isinstance(v, dict):
        return {k: _json_ready(x) for k, x in v.items()}
    return list(v) if isinstance(v, tuple) else v


def quasi_static(
    preset: str,
    mu: float,
    table: dict[str, np.ndarray],
    h0_mm: float,
    n_depths: int = 300,
) -> dict[str, np.ndarray]:
    """The quasi-static oracle (:mod:`peghole_mjx.analysis.oracle`) for each world of ``table``
    (see :data:`ANALYTIC_MAPPING`), at ``n_depths`` tip depths from ``h0_mm`` to the mouth.

    Returns ``depth_mm`` (n,), and per world and depth ``fz`` (the extraction force, N; NaN at
    isolated three-point depths), ``f_plus`` / ``f_minus`` (normal force on the +x / -x wall
    side, N) and ``two_point`` (contacts on both sides).
    """
    spec = PRESETS[preset]
    col = {k: np.asarray(table[k], float)[:, None] for k in WORLD_KEYS}
    h = np.linspace(min(h0_mm, spec.length_mm), 0.2, n_depths)[None, :]
    common = {"K_theta_Nmm_per_rad": col["k_rot"] / MM, "theta0_rad": col["theta0"], "mu": mu}
    if spec.kind == "dual":
        body, _ = an_dual.oracle_body(
            spec,
            None,
            col["L_C"] / MM,
            K_x_N_per_mm=col["k_lat"] * MM,
            delta0_mm=col["delta0"] / MM,
            beta0_rad=col["beta0"],
            **common,
        )
        side = np.array([1.0 if "R-" in c.name else -1.0 for c in body.contacts])
    else:
        kr = common.pop("K_theta_Nmm_per_rad")
        body, _ = an_rect.oracle_body(
            spec,
            1,
            col["L_C"] / MM,
            K_x_N_per_mm=col["k_lat"] * MM,
            K_y_N_per_mm=col["k_lat"] * MM,
            K_theta_Nmm_per_rad=kr,
            K_phi_Nmm_per_rad=kr,
            K_psi_Nmm_per_rad=kr,
            delta_y_mm=col["delta0"] / MM,
            delta_theta_rad=col["beta0"],
            **common,
        )
        side = np.sign([float(np.mean(c.X)) for c in body.contacts])
    sol = oracle.solve(body, h)
    lam = np.where(sol.active, sol.lam, 0.0)
    f_plus = np.sum(np.where(side > 0, lam, 0.0), axis=-1)
    f_minus = np.sum(np.where(side < 0, lam, 0.0), axis=-1)
    return {
        "depth_mm": h[0],
        "fz": np.where(sol.valid, sol.F_z, np.nan),
        "f_plus": f_plus,
        "f_minus": f_minus,
        "two_point": (f_plus > 0) & (f_minus > 0),
    }


def quasi_static_peaks(qs: dict[str, np.ndarray], h0_mm: float, skip_mm: float = 0.0):
    """Per-world peak of the oracle's extraction force over depths more than ``skip_mm`` above
    the start depth, N."""
    sel = (h0_mm - qs["depth_mm"]) > skip_mm
    return np.nanmax(np.where(sel[None, :], qs["fz"], np.nan), axis=1)
