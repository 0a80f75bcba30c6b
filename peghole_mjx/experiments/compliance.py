"""The thesis's extraction experiment with an active compliance centre (Sec 2.5, 3.4), on two
engines (:data:`ENGINES`).

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

Engines (:class:`Extraction`'s ``engine``, ``ExperimentConfig.engine``): both step on the sim
layer (:mod:`peghole_mjx.sim`), the only place the package steps physics. ``mjx`` runs all
worlds of a (preset, friction) through ``jax.vmap`` inside one jitted, time-chunked
``lax.scan`` (tqdm shows the chunks) of :meth:`peghole_mjx.sim.engines.MjxEngine.law_step`, so
a sweep batches every cell of a preset into the same compiled call; ``mujoco`` runs every world
of the table in one ``mujoco.batch`` (float64) of
:class:`peghole_mjx.sim.engine_mujoco.MujocoEngine` (:meth:`~MujocoEngine.law_step`, its
contacts per step :meth:`~MujocoEngine.contact_forces`), with the NumPy twin of the law, and also
gives a per-step trace (:meth:`Extraction.trace`, :data:`TRACE_COLUMNS`). The experiment is the
engines' scripted client: what it owns exists once here: the compiled scene (with optional
``mjOption`` fields), the keyframe start, the F/T tare, the step count, the command schedule
(:func:`rest_pose_errors`, :func:`command`), the wall-side contact rule
(:func:`contact_sides`), the loaded sides and wall switches (:func:`loaded_sides`,
:func:`wall_switch`), the per-step record (:func:`record_row`, :func:`update_stats`) and its
20 ms aggregation (:func:`aggregate_samples`). The records the experiment's earlier per-world
``MjData`` loop wrote reproduce on the batch within a rule fixed before the check, four of 228
worlds outside it (``benchmarks/studies/sim_reproduction.py``, docs/guide/experiments.md,
"Engines"); the ``mjx`` path does the same float operations as before (the law and the plain
``mjx.step``, called through the engine).

MuJoCo C's multi-point CCD (on by default in MuJoCo 4) is off in every compiled scene
(``geometry.mjcf._set_options``): MJX collides convex meshes with its own routine, and with
multi-point CCD on the ``mujoco`` engine does not reproduce it on the dual meshes (two dual-2
worlds, K_theta 3 N m/rad, beta0 -0.2 deg, L_C = top, 0.5 mm/s: late peaks 0.121 / 0.112 N
with it, 0.168 / 0.177 N without; MJX float64 0.167 / 0.176 N, the quasi-static oracle 0.167 /
0.176 N; 2026-11-29). The rect scenes (boxes, edge capsules) do not use CCD.
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

from peghole_mjx.analysis import dual as an_dual
from peghole_mjx.analysis import oracle
from peghole_mjx.analysis import rect as an_rect
from peghole_mjx.control import GAINS, ImpedanceController, Target, make_params, rot_y
from peghole_mjx.control.reference import tool_centre
from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.rotations import rot_from_rotvec
from peghole_mjx.geometry.mjcf import SimOptions, compile_scene
from peghole_mjx.geometry.specs import MM, PRESETS
from peghole_mjx.sim.engine_mujoco import MujocoEngine
from peghole_mjx.sim.engines import MjxEngine, SceneIds, default_engine
from peghole_mjx.sim.mjx_fixes import cone_hessian_fix

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

    They are config fields so that a run states and records them with its other settings
    (:func:`config_dict`).
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

#: the experiment's engines and what each is (the ``mujoco`` string is stored beside the
#: results of the studies that ran on it, so that a result of another engine is redone)
ENGINES = {
    "mjx": "MJX-JAX: all worlds vmapped in one jitted lax.scan, float32 unless jax_enable_x64",
    "mujoco": "MuJoCo C, float64, multi-point CCD off, NumPy impedance law",
}
#: per-step trace columns of the ``mujoco`` engine (:meth:`Extraction.trace`): tip depth m,
#: normal force on the +x / -x wall sides N, largest penetration m, tangential and normal
#: force sums N, extraction force = minus the contacts' vertical force on the peg N
TRACE_COLUMNS = ("depth", "f_plus", "f_minus", "penetration", "f_tangential", "f_normal", "fz")
#: a contact loads a wall side when its normal, pointing from the peg into the hole, has an x
#: component beyond this (+x side above, -x side below its negative)
SIDE_NX = 0.3


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
    #: (:mod:`peghole_mjx.sim.mjx_fixes`): the shipped one turned 13 of 48 worlds to NaN at
    #: K_theta 3 N m/rad, the fixed one none
    fix_cone_hessian: bool = True
    #: rotational stiffness about the compliance frame's x and z axes (the axes other than the
    #: tilt axis y of the planar oracle), N m/rad; None: the world's K_theta on all three axes
    off_axis_rotational_stiffness_Nm_rad: float | None = None
    #: the law's damping ratio zeta (None: ``GAINS.damping_ratio``)
    damping_ratio: float | None = None
    #: the engine (:data:`ENGINES`): ``mjx`` (MJX-JAX, batched) or ``mujoco`` (MuJoCo C,
    #: float64, all worlds in one ``mujoco.batch``), ``auto`` (:func:`auto_engine`, made concrete by
    #: :class:`Extraction`); recorded by :func:`config_dict` when not ``mjx``. The commands
    #: default to ``auto`` and pass the concrete engine; this field stays ``mjx``, the engine of
    #: the records written before the engine was a field (their resume keys stay as they were)
    engine: str = "mjx"
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


#: the experiments' ``--engine`` choices: :data:`ENGINES` and ``auto`` (:func:`auto_engine`)
ENGINE_CHOICES = ("auto", *ENGINES)


def auto_engine(x64: bool = False) -> str:
    """The engine ``auto`` stands for: the envs' rule
    (:func:`peghole_mjx.sim.engines.default_engine`, 2026-12-05), ``mujoco`` where JAX has no
    GPU, else ``mjx`` (the experiments have no MuJoCo Warp path). ``x64`` (MJX's float64 asked
    for): ``mjx``, so that the commands of the float64 results recorded before the default
    became ``auto`` still reproduce them."""
    return "mjx" if x64 or default_engine() != "mujoco" else "mujoco"


def check_engine(engine: str, x64: bool = False) -> str:
    """``engine`` if it is one of :data:`ENGINES` (``auto``: :func:`auto_engine`), else
    :class:`UserInputError` in one line."""
    if engine == "auto":
        return auto_engine(x64)
    if engine not in ENGINES:
        raise UserInputError(f"engine must be auto, {' or '.join(ENGINES)}, not {engine!r}")
    return engine


def set_options(m: mujoco.MjModel, opt: dict[str, float] | None) -> None:
    """Set the ``mjOption`` fields ``opt`` (e.g. ``noslip_iterations``, ``impratio``) on the
    compiled scene ``m``, for diagnoses of options the experiment does not set; an unknown
    field is refused in one line."""
    for k, v in (opt or {}).items():
        if not hasattr(m.opt, k):
            raise UserInputError(f"unknown mjOption field {k!r}")
        setattr(m.opt, k, v)


# ---- the per-step rules both engines share (xp: jax.numpy or numpy) -------------------------
def rest_pose_errors(xp, L_C, delta0, beta0, theta0):
    """The errors of the commanded pose of C: the spring rest pose of the quasi-static model
    (:func:`peghole_mjx.analysis.common.rest_pose`; thesis Sec 2.3, Tables 2.2 and 3.2), world
    frame: the lateral offset along +x, ``delta0 - L_C sin(theta0)`` (m), and the rotation about
    world y, ``-(beta0 + theta0)`` (rad; thesis sign: a positive angle tilts the peg top
    towards -x). ``xp``: ``jax.numpy``, ``numpy`` or ``math`` (floats)."""
    return delta0 - L_C * xp.sin(theta0), -(beta0 + theta0)


def command(xp, t, n_settle, speed_m_s: float, lateral_m, tilt_rad):
    """The command schedule at physics step ``t`` (thesis Sec 2.5.1, 3.4.1: a perturbed start,
    then a pull at constant speed): the commanded velocity of C (3,), m/s, zero during the
    ``n_settle`` settling steps and ``speed_m_s`` straight up after them; and the rest-pose
    errors (:func:`rest_pose_errors`) ramped in linearly over the settling steps (no impact at
    the start): the lateral offset of C (3,), m, and the rotation about world y, rad.

    Each engine integrates the velocity into its pulled point as it did before the engines
    were joined: ``mjx`` accumulates the commanded point, ``mujoco`` the pulled distance added
    to the start point (the same motion; the sums round differently in the last bit)."""
    vel = xp.where(t >= n_settle, speed_m_s, 0.0) * xp.asarray([0.0, 0.0, 1.0])
    a = xp.clip(t / xp.maximum(n_settle, 1), 0.0, 1.0)
    return vel, a * lateral_m * xp.asarray([1.0, 0.0, 0.0]), a * tilt_rad


def contact_sides(xp, normal_x, peg_is_geom1, normal_force, active, dist):
    """Per contact, the wall side it loads and how deep it is: (normal force on the +x side,
    on the -x side, N; penetration, m). A contact's normal points from geom1 to geom2; it is
    turned to point from the peg into the hole, and the contact loads the +x side when its x
    component exceeds :data:`SIDE_NX`, the -x side when it is below ``-SIDE_NX`` (the
    floor's and the y walls' contacts load neither). ``normal_force`` is 0 for a contact that
    carries none; ``active``: the contacts whose penetration counts (``mjx``: a constraint row
    and a finite distance; ``mujoco``: a positive normal force)."""
    nx = xp.where(peg_is_geom1, normal_x, -normal_x)
    plus = xp.where(nx > SIDE_NX, normal_force, 0.0)
    minus = xp.where(nx < -SIDE_NX, normal_force, 0.0)
    return plus, minus, xp.where(active, -dist, 0.0)


def loaded_sides(xp, plus, minus):
    """Which wall sides a physics step loads (normal force above :data:`LOADED_N`): (+x
    loaded, -x loaded, the one loaded side: +1 / -1, or 0 for none or both)."""
    lp, lm = plus > LOADED_N, minus > LOADED_N
    side = xp.where(lp & xp.logical_not(lm), 1.0, xp.where(lm & xp.logical_not(lp), -1.0, 0.0))
    return lp, lm, side


def wall_switch(side, last_side):
    """A wall-contact switch: the one loaded side (:func:`loaded_sides`) differs from
    ``last_side``, the last one-sided step's (0: none yet)."""
    return (side != 0) & (last_side != 0) & (side != last_side)


def update_stats(xp, stats, t_s, tip_depth, pen, ok, side):
    """A world's running statistics after one physics step (6,): [0] the deepest contact, m,
    [1] the NaN flag (1 once the state went non-finite), [2] the tip depth (m) and [3] the time
    (s) of that deepest contact, [4] the last one-loaded side (:func:`loaded_sides`), [5] the
    deepest contact while the tip is below the mouth, m."""
    new_max = pen > stats[0]
    return xp.stack(
        [
            xp.maximum(stats[0], pen),
            xp.where(ok, 0.0, 1.0),
            xp.where(new_max, tip_depth, stats[2]),
            xp.where(new_max, t_s, stats[3]),
            xp.where(side != 0, side, stats[4]),
            xp.maximum(stats[5], xp.where(tip_depth > 0, pen, 0.0)),
        ]
    ).astype(stats.dtype)


def record_row(xp, tip_depth, f, plus, minus, lp, lm, switch, ratio, pen):
    """One physics step's :data:`REC` values: tip depth (m), the tared F/T force ``f`` (world
    frame, N), the wall sides' normal forces (N, twice: for the means and the peaks), both /
    either side loaded, a wall switch, the commanded wrench over its caps, the penetration
    (m)."""
    return xp.stack(
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


def aggregate_samples(xp, rec, k: int):
    """Per-step records (steps, :data:`REC`) as 20 ms F/T samples of ``k`` steps each
    (samples, :data:`REC`): the mean over the sample of the ``_MEAN`` columns (an anti-aliased
    F/T reading), the maximum of the ``_MAX`` columns, the sum of the wall switches."""
    rec = rec.reshape(-1, k, rec.shape[-1])
    out = [None] * len(REC)
    for name in _MEAN:
        out[_R[name]] = rec[:, :, _R[name]].mean(1)
    for name in _MAX:
        out[_R[name]] = rec[:, :, _R[name]].max(1)
    out[_R["switches"]] = rec[:, :, _R["switches"]].sum(1)
    return xp.stack(out, axis=-1)


def _sum_in_order(a: np.ndarray) -> np.ndarray:
    """The sum over the last axis of ``a``, left to right from 0 (the ``mujoco`` engine's
    per-step sums keep the order of the per-contact loop they replaced; ``np.sum`` pairs the
    terms differently)."""
    s = np.zeros(a.shape[:-1])
    for j in range(a.shape[-1]):
        s = s + a[..., j]
    return s


class Extraction:
    """One preset's experiment (at friction ``mu``) on one engine: the compiled scene, the
    law, the F/T tare and the step count, shared; then per engine the jitted MJX chunk
    function (``mjx``) or the MuJoCo C loop (``mujoco``).

    ``engine`` (None: ``cfg.engine``): ``mjx`` or ``mujoco`` (:data:`ENGINES`); ``opt``:
    ``mjOption`` fields set on the compiled scene (:func:`set_options`)."""

    def __init__(
        self,
        preset: str,
        cfg: ExperimentConfig,
        mu: float | None = None,
        engine: str | None = None,
        opt: dict[str, float] | None = None,
    ):
        if preset not in PRESETS:
            raise UserInputError(f"unknown preset {preset!r}; known: {', '.join(PRESETS)}")
        if engine is not None:
            cfg = dataclasses.replace(cfg, engine=engine)
        self.engine = check_engine(cfg.engine)
        self.preset, self.cfg = preset, cfg
        self.spec = PRESETS[preset]
        if mu is not None:
            self.spec = dataclasses.replace(self.spec, friction=float(mu))
        self.mu = float(self.spec.friction)
        rep = cfg.representation_of(self.spec.kind)
        m = compile_scene(self.spec, sim=cfg.sim_options(), representation=rep)
        set_options(m, opt)
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
        self.mouth_z = float(d.site("hole_mouth").xpos[2])
        self.tip_z0 = float(d.site("peg_tip").xpos[2])
        self.dt = m.opt.timestep
        depth = self.mouth_z - self.tip_z0
        pull = depth + cfg.clear_mm * MM
        self.n_settle = round(cfg.settle_s / self.dt)
        #: steps until the tip is clear (a ``mujoco`` trace); ``run`` rounds up to whole chunks
        self.n_pull = self.n_settle + math.ceil(pull / (cfg.speed_m_s * self.dt))
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
        self.n_chunks = math.ceil(self.n_pull / cfg.chunk_steps)
        self.n_steps = self.n_chunks * cfg.chunk_steps
        ids = SceneIds.from_model(m, self.ctl.qadr)
        #: the sim layer's engine that steps this experiment's physics
        self.sim: MjxEngine | MujocoEngine
        if self.engine == "mjx":
            self._peg_geom = jnp.asarray(m.geom_bodyid == m.body("peg").id)
            mx = mjx.put_model(m, impl="jax")
            # the plain mjx.step in the chunk's graph, as the committed records were computed
            self.sim = MjxEngine(mx, self.ctl, ids, impl="jax", jit_calls=False)
            self.dx0 = self.sim.start_data(m, d)
            self._chunk = jax.jit(self._chunk_fn)
            self._compiled = False  # the first chunk of the first run compiles _chunk
        else:
            self.sim = MujocoEngine(m, self.ctl, ids, n_substeps=1, threads=0)

    # ---- engine mjx: one world ---------------------------------------------------------
    def init_world(self, L_C, delta0, beta0, theta0, k_lat, k_rot):
        """The scan carry of one world (``mjx``): start state, target, law parameters, the
        rest-pose errors (:func:`rest_pose_errors`) and the running statistics."""
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
        err = jnp.stack(rest_pose_errors(jnp, L_C, delta0, beta0, theta0))
        target = Target(x_C, R, jnp.zeros(3))
        # max penetration m, nan flag, depth and time at max penetration, last single side,
        # max penetration while the tip is below the mouth (where the clearance constrains it)
        stats = jnp.zeros(6)
        return (self.dx0, target, params, err, stats)

    def _side_forces(self, dx):
        """Normal contact force summed over the contacts facing +x and -x, N, and the deepest
        contact, m (:func:`contact_sides`)."""
        c = self.sim.contact_forces(dx, self._peg_geom)
        plus, minus, pen = contact_sides(
            jnp, c.normal_x, c.peg_is_geom1, c.normal_force, c.active, c.dist
        )
        return jnp.sum(plus), jnp.sum(minus), jnp.max(pen, initial=0.0)

    def step(self, carry, t):
        """One physics step of one world (``mjx``): command (:func:`command`), law, MJX step
        (a non-finite state keeps the last finite one and sets the NaN flag), readings."""
        dx, target, params, err, stats = carry
        cfg = self.cfg
        vel, offset, tilt = command(jnp, t, self.n_settle, cfg.speed_m_s, err[0], err[1])
        target = target._replace(pos=target.pos + vel * self.dt, vel=vel)
        cmd = target._replace(pos=target.pos + offset, mat=rot_y(tilt) @ target.mat)
        new, out = self.sim.law_step(dx, cmd, params)
        ok = jnp.all(jnp.isfinite(new.qpos)) & jnp.all(jnp.isfinite(new.qvel)) & (stats[1] == 0)
        dx = jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, dx)
        plus, minus, pen = self._side_forces(dx)
        pen = jnp.where(ok, pen, 0.0)
        tip_depth = self.mouth_z - dx.site_xpos[self.tip_site, 2]
        lp, lm, side = loaded_sides(jnp, plus, minus)
        switch = wall_switch(side, stats[4])
        stats = update_stats(jnp, stats, t * self.dt, tip_depth, pen, ok, side)
        # F/T force on the peg, world frame, tared
        f = dx.site_xmat[self.ft_site] @ dx.sensordata[self.ft_adr : self.ft_adr + 3]
        f = f - self.tare_world
        ratio = jnp.max(jnp.abs(out.wrench) / jnp.asarray(self.ctl.limits.max_wrench))
        rec = record_row(jnp, tip_depth, f, plus, minus, lp, lm, switch, ratio, pen)
        return (dx, target, params, err, stats), rec

    def _world_chunk(self, carry, t0):
        ts = t0 + jnp.arange(self.cfg.chunk_steps)
        carry, rec = jax.lax.scan(self.step, carry, ts)
        return carry, aggregate_samples(jnp, rec, self.record_every)

    def _chunk_fn(self, carries, t0):
        f = functools.partial(self._world_chunk, t0=t0)
        if self.cfg.batch == "vmap":
            return jax.vmap(f)(carries)
        return f(carries)  # batch="map": one world per call

    def _run_mjx(self, tab: dict[str, np.ndarray], progress: bool):
        """Every world of ``tab`` in MJX: (samples per world (worlds, samples, REC), stats)."""
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
        return np.concatenate(recs, axis=0), np.concatenate(stats, axis=0)

    # ---- engine mujoco: every world in one MuJoCo C batch -----------------------------------
    def law_params(self, tab: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The law's parameters of every world of ``tab`` as float64 arrays (worlds, ...) by
        ``ImpedanceParams`` field, the values :meth:`init_world` gives the MJX path."""
        cfg, n = self.cfg, len(tab["L_C"])
        kl, kr = np.asarray(tab["k_lat"], float), np.asarray(tab["k_rot"], float)
        off = cfg.off_axis_rotational_stiffness_Nm_rad
        ko = kr if off is None else np.full(n, float(off))
        kz = np.full(n, float(cfg.axial_stiffness_N_m))
        zeta = GAINS.damping_ratio if cfg.damping_ratio is None else cfg.damping_ratio
        null = (GAINS.null_stiffness_Nm_rad, GAINS.null_damping_Nms_rad)
        return {
            "stiffness": np.stack([kl, kl, kz, ko, kr, ko], axis=1),
            "damping_ratio": np.full(n, float(zeta)),
            "L_C": np.asarray(tab["L_C"], float),
            "wrench_ff": np.zeros((n, 6)),
            "q_null": np.tile(self.q0[self.ctl.qadr], (n, 1)),
            "null_gains": np.tile(np.asarray(null, float), (n, 1)),
        }

    def _pull(self, tab: dict[str, np.ndarray], n: int, record: bool = True, progress=False):
        """Every world of ``tab`` in MuJoCo C (float64) on the sim layer's engine
        (:meth:`peghole_mjx.sim.engine_mujoco.MujocoEngine.law_step`, all worlds in one batch),
        for ``n`` physics steps: per world its per-step trace (n, :data:`TRACE_COLUMNS`) and,
        with ``record``, its per-step record (n, :data:`REC`) and statistics (6,). A world
        that raises in MuJoCo or goes non-finite keeps its last finite state and has the NaN
        flag from that step on, as on ``mjx``."""
        sim, cfg, ctl = self.sim, self.cfg, self.ctl
        nw = len(tab["L_C"])
        p = sim.pool(np.tile(self.q0, (nw, 1)))
        prm = self.law_params(tab)
        peg, tip = ctl.body_id, self.tip_site
        R0 = np.array(p.xmat[:, peg]).reshape(nw, 3, 3)
        x0, _ = tool_centre(np.array(p.xpos[:, peg]), R0, ctl.tip_local, prm["L_C"])
        lateral, tilt0 = rest_pose_errors(
            np, prm["L_C"], tab["delta0"], tab["beta0"], tab["theta0"]
        )
        dt = self.dt
        data = mujoco.MjData(sim.model)
        depth, sums = np.zeros((nw, n)), np.zeros((nw, n, 3))  # tangential, normal, extraction
        contacts = [[] for _ in range(nw)]  # per step: normal force, normal x, own, dist
        ft_R, ft_s = np.zeros((nw, n, 9)), np.zeros((nw, n, 3))
        wrench, ok = np.zeros((nw, n, 6)), np.ones((nw, n), bool)
        ft = slice(self.ft_adr, self.ft_adr + 3)
        alive = np.ones(nw, bool)
        z = np.zeros(nw)
        bar = prog.bar(n, f"{self.preset} pull (MuJoCo C)", unit="step", enabled=progress)
        try:
            for t in range(n):
                vel, offset, tilt = command(
                    np, t, self.n_settle, cfg.speed_m_s, lateral[:, None], tilt0
                )
                vel = np.broadcast_to(vel, (nw, 3))
                z = z + vel[:, 2] * dt
                pos = x0 + z[:, None] * np.array([0.0, 0.0, 1.0]) + offset
                Rc = np.stack([rot_from_rotvec(np.array([0.0, a, 0.0])) for a in tilt]) @ R0
                step_ok, wrench[:, t] = sim.law_step(p, pos, Rc, vel, prm)
                alive &= step_ok
                ok[:, t] = alive
                for w in range(nw):
                    c = sim.contact_forces(p, w, data)
                    contacts[w].append((c.normal_force, c.normal_x, c.peg_is_geom1, c.dist))
                    sums[w, t] = (
                        _sum_in_order(c.tangential),
                        _sum_in_order(c.normal_force),
                        -_sum_in_order(c.peg_force_z),
                    )
                depth[:, t] = self.mouth_z - p.site_xpos[:, tip, 2]
                if record:
                    ft_R[:, t] = p.site_xmat[:, self.ft_site]
                    ft_s[:, t] = p.sensordata[:, ft]
                bar.update()
        finally:
            bar.close()
        out = []
        cap = np.asarray(ctl.limits.max_wrench, float)
        for w in range(nw):
            # the contact rule over every step's contacts (padded with contacts that carry
            # nothing)
            per = np.zeros((4, n, max((len(c[0]) for c in contacts[w]), default=0)))
            for t, c in enumerate(contacts[w]):
                per[:, t, : len(c[0])] = c
            fn, nx, own, dist = per[0], per[1], per[2] > 0, per[3]
            plus, minus, pens = contact_sides(np, nx, own, fn, fn > 0, dist)
            fp, fm = _sum_in_order(plus), _sum_in_order(minus)
            pen = np.max(pens, -1, initial=0.0)
            trace = np.column_stack([depth[w], fp, fm, pen, sums[w]])
            if not record:
                out.append((trace, None, None))
                continue
            # the experiment's record, as the mjx engine keeps it
            pen = np.where(ok[w], pen, 0.0)
            lp, lm, side = loaded_sides(np, fp, fm)
            stats, last = np.zeros(6), np.zeros(n)
            for t in range(n):
                last[t] = stats[4]
                stats = update_stats(np, stats, t * dt, depth[w, t], pen[t], ok[w, t], side[t])
            f = (ft_R[w].reshape(n, 3, 3) @ ft_s[w][:, :, None])[:, :, 0] - self.tare_world
            ratio = np.max(np.abs(wrench[w]) / cap, axis=1)
            switch = wall_switch(side, last)
            rec = record_row(np, depth[w], f.T, fp, fm, lp, lm, switch, ratio, pen).T
            out.append((trace, rec, stats))
        return out

    def _run_mujoco(self, tab: dict[str, np.ndarray], progress: bool):
        """Every world of ``tab`` in MuJoCo C, in one batch: (samples, stats)."""
        res = self._pull(tab, self.n_steps, progress=progress)
        recs = [aggregate_samples(np, rec, self.record_every) for _, rec, _ in res]
        return np.stack(recs), np.stack([st for _, _, st in res])

    def trace(self, world: dict[str, float]) -> tuple[np.ndarray, int, float]:
        """One world's per-step trace (``mujoco`` engine only), from the start until the tip
        is :attr:`ExperimentConfig.clear_mm` above the mouth: (trace (steps,
        :data:`TRACE_COLUMNS`), the settling steps, the physics step s). ``world`` holds the
        :data:`WORLD_KEYS` (SI, rad)."""
        if self.engine != "mujoco":
            raise UserInputError(
                "a per-step trace comes from the mujoco engine (MuJoCo C, float64); "
                f"this experiment runs on {self.engine}"
            )
        tab = {k: np.array([float(world[k])]) for k in WORLD_KEYS}
        ((trace, _, _),) = self._pull(tab, self.n_pull, record=False)
        return trace, self.n_settle, self.dt

    # ---- both engines ----------------------------------------------------------------------
    def run(
        self, progress: bool = True, table: dict[str, np.ndarray] | None = None
    ) -> dict[str, np.ndarray]:
        """Run every world of ``table`` (default :func:`world_table`) on this engine (``mjx``:
        in one batch; ``mujoco``: one after the other, the same steps and samples).

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
        if self.engine == "mujoco":
            rec, stats = self._run_mujoco(tab, progress)
        else:
            rec, stats = self._run_mjx(tab, progress)
        rec = rec.astype(np.float64)  # (worlds, samples, REC)
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
    if cfg.engine == "mujoco":
        return (
            f"MuJoCo C reset a diverged state (step {cfg.sim_options().timestep * 1e3:g} ms, "
            f"K_theta {k_rot:g} N m/rad): try a shorter step or a stiffer K_theta"
        )
    if not cfg.fix_cone_hessian:
        return (
            "MJX's elliptic-cone Newton Hessian as shipped (run without --no-fix-cone-hessian; "
            "peghole_mjx/sim/mjx_fixes.py)"
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
    :class:`GeometrySetup` and the ``engine`` are written only when they differ from the
    default, so that a config's record (and a sweep's resume key,
    ``sweep.SweepConfig.settings``) is what it was before they became fields."""
    default = ExperimentConfig()
    out = {
        k: _json_ready(v)
        for k, v in dataclasses.asdict(cfg).items()
        if k not in (*GEOMETRIES, "engine") or getattr(cfg, k) != getattr(default, k)
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
