"""The thesis's extraction experiment with an active compliance centre, in MJX (Sec 2.5, 3.4).

Per world: the peg starts fully inserted (keyframe ``inserted``, centred, aligned, no contact).
The impedance law (:mod:`peghole_mjx.control`) holds the compliance centre ``C`` (``L_C`` above
the tip) with K = 0.3 N/mm laterally; its commanded pose is the start pose of ``C`` with a
lateral error ``delta0`` (at ``C``, along world x) and an angular error ``beta0`` (about ``C``,
about world y), both drawn per world. After a short settling time the commanded point moves
straight up at a constant speed until the tip is clear of the mouth. The tared F/T-sensor force
is logged against the tip depth.

Batching: all worlds of a preset run through ``jax.vmap`` inside one jitted, time-chunked
``lax.scan`` (tqdm shows the chunks). With ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=false``
(set by :mod:`peghole_mjx` at import) the batched step is fast on the CPU too: about 4000
world-steps/s for a rect scene and 60-200 for the contact-rich dual scene (2-core CPU, 18
worlds, measured; see docs/control.md). ``batch="map"`` runs the worlds one after another
(each still a jitted scan); it gives the same numbers and only saves memory.
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
from tqdm import tqdm

from peghole_mjx.control import GAINS, ImpedanceController, Target, make_params
from peghole_mjx.geometry.mjcf import SimOptions, compile_scene
from peghole_mjx.geometry.specs import MM, PRESETS

#: thesis values to compare with (Sec 3.5, R1): reductions of the mean peak extraction force
THESIS = {
    "reduction_tip_vs_top_pct": 77.1,
    "reduction_tip_vs_centre_pct": 55.6,
    "source": "thesis Sec 3.5 (rectangular peg, real KUKA LBR iiwa); dual: Fig 2.20 ordering only",
}

LC_MM = {"rect": (0.0, 75.0, 150.0), "dual": (0.0, 25.0, 50.0)}


#: The experiment's physics step as a fraction of the project's (``SimOptions().timestep``).
#: The rect presets' radial clearances are 25-300 um and the experiment allows a penetration
#: of 25 % of it (6.25 um for rect-3). At the default 2 ms step (contact time constant 4 ms)
#: the pulled peg's contacts penetrate 11-30 um in rect-2 / rect-3, whatever the solimp
#: impedance (0.99-0.997 change nothing; 0.999 goes NaN in float32). Max over the rect-3
#: worlds (docs/control.md): 2 ms 11-14 um, 1 ms 8-9 um, 0.5 ms 7.5 um (2 of 18 worlds over),
#: 0.25 ms 3.9 um. So the rect experiment runs at an eighth of the default step; the dual
#: presets (at most 12 um of 50-400 um at 2 ms) keep it.
TIMESTEP_DIVISOR = {"rect": 8, "dual": 1}


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
    #: angular error of the commanded frame about C, uniform range, deg
    beta0_deg: tuple[float, float] = (-0.2, 0.2)
    speed_m_s: float = 0.02
    settle_s: float = 0.3
    clear_mm: float = 5.0  # pull until the tip is this far above the mouth
    #: F/T sample period, s: each logged sample is the mean over its physics steps
    record_every_s: float = 0.02
    #: physics steps per jitted call (a multiple of the steps per sample)
    chunk_steps: int = 400
    batch: str = "vmap"
    #: simulator options of the scene (None: ``SimOptions()``, the project default)
    sim: SimOptions | None = None

    def sim_options(self) -> SimOptions:
        """The simulator options in effect: ``sim``, else the project's default with the
        geometry's finer step (:data:`TIMESTEP_DIVISOR`)."""
        if self.sim is not None:
            return self.sim
        base = SimOptions()
        return dataclasses.replace(
            base, timestep=base.timestep / TIMESTEP_DIVISOR.get(self.geometry, 1)
        )

    def preset_names(self) -> tuple[str, ...]:
        if self.presets:
            return self.presets
        return tuple(n for n, s in PRESETS.items() if s.kind == self.geometry)


def world_table(cfg: ExperimentConfig, preset: str) -> dict[str, np.ndarray]:
    """Per-world L_C (m), delta0 (m), beta0 (rad): the three L_C x ``repeats`` draws.

    The same error draws are used for each L_C (paired comparison).
    """
    rng = np.random.default_rng([cfg.seed, sorted(PRESETS).index(preset)])
    d0 = rng.uniform(*cfg.delta0_mm, cfg.repeats) * MM
    b0 = np.radians(rng.uniform(*cfg.beta0_deg, cfg.repeats))
    lc = np.array(LC_MM[PRESETS[preset].kind]) * MM
    return {
        "L_C": np.repeat(lc, cfg.repeats),
        "delta0": np.tile(d0, len(lc)),
        "beta0": np.tile(b0, len(lc)),
    }


def _rot_y(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


class Extraction:
    """One preset's compiled scene, controller and jitted chunk function."""

    def __init__(self, preset: str, cfg: ExperimentConfig):
        self.preset, self.cfg = preset, cfg
        self.spec = PRESETS[preset]
        m = compile_scene(self.spec, sim=cfg.sim_options())
        self.m = m
        self.ctl = ImpedanceController(m)
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
        self.mouth_z = float(d.site("hole_mouth").xpos[2])
        self.tip_z0 = float(d.site("peg_tip").xpos[2])
        self.dt = m.opt.timestep
        self.mx = mjx.put_model(m, impl="jax")
        self.dx0 = mjx.put_data(m, d, impl="jax")
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

    # ---- one world -------------------------------------------------------------------
    def _init_world(self, L_C, delta0, beta0):
        cfg = self.cfg
        k, kz, kr = (
            cfg.lateral_stiffness_N_m,
            cfg.axial_stiffness_N_m,
            cfg.rotational_stiffness_Nm_rad,
        )
        params = make_params(L_C, self.q0, stiffness=jnp.array([k, k, kz, kr, kr, kr]))
        x_C, R = self.ctl.centre_pose(self.dx0, params.L_C)
        target = Target(x_C + jnp.array([1.0, 0.0, 0.0]) * delta0, _rot_y(beta0) @ R, jnp.zeros(3))
        # max penetration m, nan flag, tip depth m and time s at the max penetration
        stats = jnp.zeros(4)
        return (self.dx0, target, params, stats)

    def x_C0(self, params):
        return self.ctl.centre_pose(self.dx0, params.L_C)[0]

    def _step(self, carry, t):
        dx, target, params, stats = carry
        cfg = self.cfg
        moving = t >= self.n_settle
        vel = jnp.where(moving, cfg.speed_m_s, 0.0) * jnp.array([0.0, 0.0, 1.0])
        target = target._replace(pos=target.pos + vel * self.dt, vel=vel)
        # the errors are ramped in over the settling time (no impact at the start)
        a = jnp.clip(t / jnp.maximum(self.n_settle, 1), 0.0, 1.0)
        dp = target.pos - self.x_C0(params)
        cmd = target._replace(pos=target.pos - (1.0 - a) * dp.at[2].set(0.0))
        dx_c, out = self.ctl.apply(self.mx, dx, cmd, params)
        new = mjx.step(self.mx, dx_c)
        ok = jnp.all(jnp.isfinite(new.qpos)) & jnp.all(jnp.isfinite(new.qvel)) & (stats[1] == 0)
        dx = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, dx)
        con = dx._impl.contact
        pen = jnp.max(jnp.where(jnp.isfinite(con.dist), -con.dist, 0.0), initial=0.0)
        pen = jnp.where(ok, pen, 0.0)
        new_max = pen > stats[0]
        tip_depth = self.mouth_z - dx.site_xpos[self.tip_site, 2]
        stats = (
            stats.at[2]
            .set(jnp.where(new_max, tip_depth, stats[2]))
            .at[3]
            .set(jnp.where(new_max, t * self.dt, stats[3]))
            .at[0]
            .max(pen)
            .at[1]
            .set(jnp.where(ok, 0.0, 1.0))
        )
        # F/T force on the peg, world frame, tared
        f = dx.site_xmat[self.ft_site] @ dx.sensordata[self.ft_adr : self.ft_adr + 3]
        f = f - self.tare_world
        depth = self.mouth_z - dx.site_xpos[self.tip_site, 2]
        # two-point contact: active contacts with opposite lateral normals
        n = con.frame[:, 0, :] if con.frame.ndim == 3 else con.frame[:, :3]
        nxy = n[:, :2]
        side = (con.dist < 0) & (jnp.linalg.norm(nxy, axis=1) > 0.5)
        dots = nxy @ nxy.T
        two = jnp.any(side[:, None] & side[None, :] & (dots < -0.25))
        rec = jnp.stack(
            [
                depth,
                f[0],
                f[1],
                f[2],
                two.astype(f.dtype),
                jnp.max(jnp.abs(out.wrench) / jnp.asarray(self.ctl.limits.max_wrench)),
            ]
        )
        return (dx, target, params, stats), rec

    def _world_chunk(self, carry, t0):
        ts = t0 + jnp.arange(self.cfg.chunk_steps)
        carry, rec = jax.lax.scan(self._step, carry, ts)
        k = self.record_every
        rec = rec.reshape(-1, k, rec.shape[-1])
        # each sample: the mean over its k steps (a sensor's anti-alias average); contact
        # flag and wrench ratio: the max
        return carry, jnp.concatenate([rec[:, :, :4].mean(1), rec[:, :, 4:].max(1)], axis=-1)

    def _chunk_fn(self, carries, t0):
        f = functools.partial(self._world_chunk, t0=t0)
        if self.cfg.batch == "vmap":
            return jax.vmap(f)(carries)
        return f(carries)  # batch="map": one world per call

    def run(self, progress: bool = True) -> dict[str, np.ndarray]:
        tab = world_table(self.cfg, self.preset)
        carries = jax.vmap(self._init_world)(
            *(jnp.asarray(tab[k]) for k in ("L_C", "delta0", "beta0"))
        )
        nw = len(tab["L_C"])
        if self.cfg.batch == "vmap":
            groups = [carries]
        else:
            groups = [jax.tree.map(lambda a, i=i: a[i], carries) for i in range(nw)]
        bar = tqdm(
            total=self.n_chunks * len(groups), desc=self.preset, disable=not progress, leave=False
        )
        recs, stats = [], []
        for g in groups:
            grec = []
            for c in range(self.n_chunks):
                g, rec = self._chunk(g, jnp.asarray(c * self.cfg.chunk_steps))
                grec.append(np.asarray(rec))
                bar.update()
            recs.append(
                np.concatenate(grec, axis=-2).reshape(-1, sum(r.shape[-2] for r in grec), 6)
            )
            stats.append(np.asarray(g[3]).reshape(-1, 4))
        bar.close()
        rec = np.concatenate(recs, axis=0)  # (worlds, samples, 6)
        stats = np.concatenate(stats, axis=0)
        out = dict(tab)
        out.update(
            depth_mm=rec[..., 0] / MM,
            fx=rec[..., 1],
            fy=rec[..., 2],
            fz=rec[..., 3],
            two_point=rec[..., 4] > 0.5,
            wrench_ratio=rec[..., 5],
            penetration_mm=stats[:, 0] / MM,
            penetration_at_depth_mm=stats[:, 2] / MM,
            penetration_at_time_s=stats[:, 3],
            nan=stats[:, 1] > 0,
        )
        out["time_s"] = (np.arange(rec.shape[1]) + 1) * self.record_every * self.dt
        out["h0_mm"] = (self.mouth_z - self.tip_z0) / MM
        return out


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


def two_point_interval(res: dict[str, np.ndarray], world: int) -> list[float] | None:
    """[min, max] tip depth (mm) at which one world touched opposite walls (None if never)."""
    mask = res["two_point"][world] & (res["time_s"] > 0)
    if not mask.any():
        return None
    d = res["depth_mm"][world][mask]
    return [round(float(d.min()), 3), round(float(d.max()), 3)]


#: how the experiment's parameters are mapped onto the quasi-static model (recorded in the JSON)
ANALYTIC_MAPPING = (
    "Per world, the same L_C, K_lateral, K_rot, friction (spec), delta0 and beta0 as the "
    "simulation, theta0 = 0 (the simulated peg starts centred and aligned) and h0 = the start "
    "depth of the tip. Sign: a simulated rotation beta0 about world y tilts the peg top "
    "towards +x, the model's tilt is the opposite, so beta0_model = -beta0_sim. rect: the error "
    "lies in the world x-z plane, across the hole width w (60.1 mm), i.e. the model's case 1 "
    "(y-z plane, psi = 0; case 3 equals case 1 since there is no error across v); dual: the "
    "x-z plane through both peg axes, categories 5, 10, 9 (16-gon pegs and holes with vertices "
    "on x: the x-clearance equals R - r). The interval is the union over the worlds (and "
    "categories) of the refined (exact-statics) regions. Not modelled: robot dynamics, the "
    "axial spring (the model prescribes the vertical motion), contact softness, the 0.3 s "
    "ramp-in of the errors."
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

    ``delta0_mm``, ``beta0_rad`` (the simulation's sign): the worlds' errors (default: the
    mean of the config's ranges). Returns ``interval_mm`` (union of the worlds' regions, tip
    depth below the mouth, or None), ``worlds_with_two_point``, ``per_category`` (each
    category's union) and ``per_world`` ([lo, hi] or None per world).
    """
    from peghole_mjx.analysis import dual as an_dual
    from peghole_mjx.analysis import rect as an_rect

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
                beta0_rad=-b0,
                theta0_rad=0.0,
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
            delta_theta_rad=-b0,
            theta0_rad=0.0,
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


def config_dict(cfg: ExperimentConfig) -> dict:
    """The config as JSON-ready data; ``sim``: the effective simulator options."""
    out = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(cfg).items()}
    sim = cfg.sim_options()
    out["sim"] = {
        k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(sim).items()
    }
    return out
