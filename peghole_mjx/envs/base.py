"""The peg extraction task in MJX: shared by RectExtract and DualExtract (thesis Ch 4).

API (MuJoCo Playground / Brax style): ``reset(rng) -> State``, ``step(state, action) -> State``,
``State(data, obs, reward, done, metrics, info)``, all pure and jit/vmap-able.

Frames and signs. The hole frame has its origin at the hole mouth, +z up = the extraction
direction. Depth ``h`` is how far the peg tip is below the mouth (h > 0 inside the hole). The
progress of a step is ``dz = h_t - h_{t-1}`` (mm), negative when the peg comes out, so the
thesis's reward term ``-w_d dz`` (eq 4.4) rewards pulling out.

Control. An action moves the commanded tip pose and feed-forward force; the impedance law
(:mod:`peghole_mjx.control`) runs at every physics substep and tracks the commanded pose with
its compliance centre ``L_C`` above the tip. See :class:`PegHoleEnv` for the tables.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from ml_collections import config_dict

from peghole_mjx._mjx import WARP_AVAILABLE, mjx
from peghole_mjx.control import GAINS, LIMITS, ImpedanceController, Target, make_params
from peghole_mjx.control.impedance import rotvec_from_mat
from peghole_mjx.errors import UserInputError
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT, SimOptions, build_scene
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import MM, PegHoleSpec, get_preset

#: Table 4.1 reward weights (one source of truth; configs copy them into reward_config)
REWARD_WEIGHTS = {"w_d": 1.0, "w_f": 1.0, "w_stf": 0.1, "r_success": 1.0, "r_failure": -1.0}


@struct.dataclass
class State:
    """Environment state (MuJoCo Playground layout)."""

    data: mjx.Data
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    metrics: dict[str, jax.Array]
    info: dict[str, Any]


def base_config(preset: str) -> config_dict.ConfigDict:
    """Defaults shared by both tasks (see each task's ``default_config``)."""
    spec = get_preset(preset)
    return config_dict.create(
        preset=preset,
        impl="jax",  # "jax" (CPU, GPU) or "warp" (CUDA GPU)
        # collision representation of the parts (geometry/parts.py); None: the preset's default
        # (dual "capsule", GPU-scale; rect "edges", edge-capsule contacts); also dual "mesh"
        # (exact 16-gon parts) or "cylinder" (warp only), rect "box". env.representation is
        # the one in effect
        representation=None,
        contact_cap=None,  # MJX max_contact_points; None: the measured cap (mjcf.CONTACT_CAPS)
        ctrl_dt=0.02,  # s, one env step (50 Hz)
        sim_dt=SimOptions().timestep,  # s, physics step (from the one place it is set)
        episode_length=600,  # env steps (12 s at 50 Hz)
        # contact settings (docs/contact.md; peghole experiment contact-check, variant "envs"):
        # a 10 ms contact time constant (0: 2 x sim_dt, MuJoCo's stiffest) and frictional rows
        # relaxed over 1 s (0: as stiff as the normal row)
        contact=config_dict.create(timeconst_s=0.01, friction_timeconst_s=1.0),
        # warp: contact buffer per world (x num worlds) and constraint rows per world; the most
        # active contacts measured (benchmarks/results/contact_caps.json) are rect 20, dual
        # capsule 22, dual mesh 47; 3 rows per elliptic condim-3 contact + joint limits
        naconmax=64,
        njmax=256,
        action=config_dict.create(
            max_step_offset_mm=LIMITS.max_step_offset_m / MM,  # |dx|, |dy| per step (Sec 4.3.1)
            max_speed_m_s=LIMITS.max_speed_m_s,  # |dz| per step = this x ctrl_dt
            max_force_step_N=2.0,  # |dF| per step
            # bound of the accumulated lateral feed-forward |F_x|, |F_y| (the force limit of
            # E11 by default; DualExtract's training profiles lower it: docs/training.md,
            # "Lateral feed-forward bound")
            max_ff_xy_N=LIMITS.max_force_N[0],
        ),
        compliance_strategy=False,  # when on, the action also sets k_xy (and K_theta, L_C)
        # with compliance_strategy: the action also sets the rotational stiffness K_theta (the
        # stiffness that the angular error loads; see docs/training.md, "Compliance strategy")
        compliance_rotation=True,
        learn_compliance_centre=False,  # with compliance_strategy: the action also sets L_C
        stiffness=config_dict.create(
            k_xy_N_m=GAINS.lateral_stiffness_N_m,  # fixed lateral stiffness (CS off)
            k_xy_min_N_m=50.0,  # CS bounds (Table 4.2's 50 N/m to 1 N/mm)
            k_xy_max_N_m=1000.0,
            # CS bounds of K_theta: the KUKA iiwa's Cartesian impedance mode allows 0-300 N m/rad;
            # the fixed value (below) is the top of the range
            k_rot_min_Nm_rad=10.0,
            k_rot_max_Nm_rad=GAINS.rotational_stiffness_Nm_rad,
            k_z_N_m=GAINS.axial_stiffness_N_m,
            k_rot_Nm_rad=GAINS.rotational_stiffness_Nm_rad,
            damping_ratio=GAINS.damping_ratio,
            compliance_centre_mm=0.0,  # L_C above the tip (the thesis's best: at the tip)
        ),
        reward_config=config_dict.create(
            **REWARD_WEIGHTS,
            force_scale_N=LIMITS.max_force_N[0],  # |f_xy| is measured in units of this
            stiffness_scale_N_m=1000.0,  # ||k_xy|| is measured in N/mm
            # not in eq (4.4): the stiffness term extended to K_theta, for the K_theta compliance
            # strategy (our extension). 0 = the thesis's reward; DualExtract's training profiles
            # set it (train/configs/DualExtract.json; docs/training.md, "Rotational stiffness term")
            w_stf_rot=0.0,
            rot_stiffness_scale_Nm_rad=GAINS.rotational_stiffness_Nm_rad,
            # not in eq (4.4) either: a penalty on the extraction force |f_z| itself, the
            # quantity of R3 (eq 4.4 only penalises |f_xy|). 0 = the thesis's reward
            w_fz=0.0,
            fz_scale_N=1.0,
        ),
        success_margin_mm=5.0,  # success when the tip is this far above the mouth
        # jamming: the lateral contact force at the controller's threshold (20 N, E11; 90 %
        # of it, since the law saturates there and the reading oscillates about it) ...
        jam_force_N=0.9 * LIMITS.max_force_N[0],
        jam_time_s=0.3,  # ... when it lasts this long
        obs=config_dict.create(
            torques=False,
            stiffness=False,
            prev_action=False,
            force_scale_N=LIMITS.max_force_N[0],
            torque_scale_Nm=LIMITS.max_torque_Nm[0],
        ),
        randomization=config_dict.create(
            lateral_error_mm=1.0,  # commanded tip offset from the hole axis, uniform in a disc
            angular_error_deg=0.5,  # commanded tilt about x and y, uniform (E3: |theta0| <= 0.9)
            hole_xy_mm=5.0,  # hole position, uniform in a square
            hole_yaw_deg=5.0,  # hole rotation about its axis
            friction_scale=(0.8, 1.2),  # x preset's mu
            stiffness_N_m=(0.0, 0.0),  # CS off: if max > 0, k_xy ~ U(range) per episode
        ),
        peg_length_mm=spec.length_mm,
    )


def sim_options(config: config_dict.ConfigDict) -> SimOptions:
    """The simulator options of an env config (its step and ``contact`` group)."""
    c = config.contact
    for name in ("timeconst_s", "friction_timeconst_s"):
        v = float(c[name])
        if not (math.isfinite(v) and v >= 0):
            raise UserInputError(f"contact.{name} must be a finite number >= 0, got {v}")
    return SimOptions(
        timestep=config.sim_dt,
        contact_timeconst=float(c.timeconst_s) or None,
        friction_timeconst=float(c.friction_timeconst_s) or None,
    )


#: MuJoCo Warp's ``OverflowType`` bits that mean dropped contacts or constraint rows: NEFC,
#: NJMAX_NNZ, BROADPHASE, NARROWPHASE, CCD (mujoco_warp/_src/types.py). Its ``overflow``
#: bitmask is per world and sticky until the world's data is reset.
WARP_CONTACT_OVERFLOW_BITS = 0b11111


def contact_overflow(data) -> jax.Array:
    """1.0 if MuJoCo Warp overflowed a contact or constraint buffer in this world, else 0.0.

    Warp drops what does not fit in ``naconmax`` / ``njmax`` and only prints a warning; the env
    ends such an episode as a failure and counts it (``metrics["overflow"]``). MJX-JAX sizes
    its buffers statically and never overflows: always 0.0 there.
    """
    flags = getattr(getattr(data, "_impl", None), "overflow", None)
    if flags is None:
        return jnp.zeros((), jnp.float32)
    hit = (jnp.asarray(flags).astype(jnp.int32) & WARP_CONTACT_OVERFLOW_BITS) != 0
    return jnp.any(hit).astype(jnp.float32)


def reward_terms(
    dz_mm, fxy_N, k_xy_N_m, success, failure, rc, k_rot_Nm_rad=0.0, fz_N=0.0
) -> dict[str, jax.Array]:
    """The named reward terms of eq (4.4) (Table 4.1 weights in ``rc``).

    ``dz_mm``: change of tip depth this step (negative when the peg comes out);
    ``fxy_N``: lateral contact force; ``k_xy_N_m``: lateral stiffness (both axes equal, so
    ``||k_xy|| = sqrt(2) k``); ``success``/``failure``: 0 or 1. Two terms are not in
    eq (4.4) and are zero at their default weights: ``rot_stiffness``
    ``-w_stf_rot K_theta / 300 N m/rad`` and ``extraction_force`` ``-w_fz |f_z| / fz_scale_N``.
    """
    return {
        "progress": -rc.w_d * dz_mm,
        "force": -rc.w_f * fxy_N / rc.force_scale_N,
        "stiffness": -rc.w_stf * jnp.sqrt(2.0) * jnp.abs(k_xy_N_m) / rc.stiffness_scale_N_m,
        "rot_stiffness": -rc.w_stf_rot * jnp.abs(k_rot_Nm_rad) / rc.rot_stiffness_scale_Nm_rad,
        "extraction_force": -rc.w_fz * jnp.abs(fz_N) / rc.fz_scale_N,
        "end": rc.r_success * success + rc.r_failure * failure,
    }


def _clean_action(action: jax.Array) -> jax.Array:
    """The action clipped to [-1, 1], NaN entries set to 0 (the step also flags the world)."""
    return jnp.clip(jnp.where(jnp.isnan(action), 0.0, action), -1.0, 1.0)


def _rotz(a):
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_from_rotvec(v):
    """Rodrigues' formula (small-angle safe)."""
    th = jnp.linalg.norm(v)
    k = v / jnp.maximum(th, 1e-12)
    K = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return jnp.eye(3) + jnp.sin(th) * K + (1 - jnp.cos(th)) * K @ K


def _check_override_keys(config: config_dict.ConfigDict, overrides: dict) -> None:
    """Every flat ``a.b.c`` key of ``overrides`` names an existing config entry (no typos)."""
    for key in overrides:
        node, path = config, []
        for part in key.split("."):
            if not isinstance(node, config_dict.ConfigDict) or part not in node:
                where = ".".join(path) or "the env config"
                have = sorted(node.keys()) if isinstance(node, config_dict.ConfigDict) else []
                raise UserInputError(
                    f"unknown env config key {key!r}: {where} has no {part!r}"
                    + (f" (it has: {', '.join(have)})" if have else "")
                )
            node, path = node[part], [*path, part]


def _check_config_values(config: config_dict.ConfigDict) -> None:
    """Every number of the env config is finite, and the ones a user sets are in range."""
    from peghole_mjx.validation import RANGES, check_finite_tree

    check_finite_tree(config.to_dict(), "env config")

    def need(cond: bool, what: str) -> None:
        if not cond:
            raise UserInputError(f"env config: {what}")

    need(config.ctrl_dt > 0 and config.sim_dt > 0, "ctrl_dt and sim_dt must be > 0")
    need(
        isinstance(config.episode_length, int) and config.episode_length >= 1,
        f"episode_length must be an integer >= 1, got {config.episode_length!r}",
    )
    r = config.randomization
    for key in ("lateral_error_mm", "angular_error_deg", "hole_xy_mm", "hole_yaw_deg"):
        need(r[key] >= 0, f"randomization.{key} must be >= 0, got {r[key]!r}")
    for key in ("friction_scale", "stiffness_N_m"):
        pair = tuple(r[key])
        need(
            len(pair) == 2 and 0 <= pair[0] <= pair[1],
            f"randomization.{key} must be a range (lo, hi) with 0 <= lo <= hi, got {pair!r}",
        )
    mu = get_preset(config.preset).friction * r.friction_scale[1]
    fr = RANGES["friction"]
    need(
        fr.problem(mu) is None,
        f"randomization.friction_scale gives friction {mu:g}, outside [0, {fr.hi:g}]",
    )
    a = config.action
    for key in ("max_step_offset_mm", "max_speed_m_s", "max_force_step_N", "max_ff_xy_N"):
        need(a[key] >= 0, f"action.{key} must be >= 0, got {a[key]!r}")
    s = config.stiffness
    need(
        0 < s.k_xy_min_N_m <= s.k_xy_max_N_m and 0 < s.k_rot_min_Nm_rad <= s.k_rot_max_Nm_rad,
        "stiffness bounds must satisfy 0 < min <= max",
    )


class PegHoleEnv:
    """Pull a peg out of its hole with the iiwa's impedance layer (thesis Ch 4).

    Observation (eq 4.2, hole frame, scaled to order one):

    | index | quantity | unit / scale |
    |---|---|---|
    | 0-1 | flange x, y offset from the hole axis | mm |
    | 2 | flange height above its start, / peg length | 0 inserted, 1 out |
    | 3-5 | F/T sensor force Fx, Fy, Fz (peg weight removed) | / 20 N |
    | 6-8 | flange tilt theta, phi, psi (rotation vector vs. straight down) | deg |
    | + | optional: torques (/3 N m), k_xy (/1000 N/m), K_theta (/300 N m/rad), L_C (/L), | |
    |   | previous action | |

    Action (eq 4.3), each in [-1, 1]:

    | index | quantity | mapping |
    |---|---|---|
    | 0-1 | dx, dy: commanded tip offset | x 0.1 mm per step |
    | 2 | dz: commanded pull (+ = out) | x 0.1 m/s x ctrl_dt |
    | 3-5 | dFx, dFy, dFz: feed-forward change | x 2 N per step, total within 20/20/60 N [1] |
    | 6 | k_xy (compliance_strategy) | [50, 1000] N/m |
    | 7 | K_theta (compliance_strategy and compliance_rotation) | [10, 300] N m/rad |
    | last | L_C (learn_compliance_centre) | [0, L] |

    [1] the lateral total within ``action.max_ff_xy_N`` (20 N by default).

    Reward (eq 4.4, Table 4.1), named terms logged as ``metrics["reward/<term>"]``:

    | term | value |
    |---|---|
    | progress | ``-w_d dz`` with dz = change of tip depth in mm (pulling out is positive) |
    | force | ``-w_f ||f_xy|| / 20 N`` |
    | stiffness | ``-w_stf ||k_xy|| / (1000 N/m)`` (k_xy in N/mm) |
    | rot_stiffness | ``-w_stf_rot K_theta / (300 N m/rad)``: not in eq 4.4, 0 by default |
    | extraction_force | ``-w_fz |f_z| / 1 N``: not in eq 4.4, 0 by default |
    | end | ``+1`` on success, ``-1`` on failure (jamming, NaN, time limit) |
    """

    def __init__(self, config: config_dict.ConfigDict, config_overrides: dict | None = None):
        config = config_dict.ConfigDict(config)
        if config_overrides:
            _check_override_keys(config, config_overrides)
            try:
                config.update_from_flattened_dict(config_overrides)
            except (TypeError, ValueError) as exc:
                raise UserInputError(f"bad env config override: {exc}") from None
        _check_config_values(config)
        self._config = config
        config.lock()
        if config.impl not in ("jax", "warp"):
            raise UserInputError(f"impl must be 'jax' or 'warp', got {config.impl!r}")
        if config.impl == "warp" and not WARP_AVAILABLE:
            raise UserInputError(
                "impl='warp' needs warp-lang and a CUDA GPU: pip install 'peghole_mjx[warp]'"
            )
        n_sub = config.ctrl_dt / config.sim_dt
        if abs(n_sub - round(n_sub)) > 1e-6 or n_sub < 1:
            raise UserInputError("ctrl_dt must be a whole multiple of sim_dt")
        self._n_substeps = round(n_sub)
        self.spec: PegHoleSpec = get_preset(config.preset)
        sim = sim_options(config)
        self.representation = resolve_representation(
            self.spec, config.representation, impl=config.impl
        )
        self._mj_model = build_scene(
            self.spec, sim=sim, representation=self.representation, contact_cap=config.contact_cap
        ).compile()
        m = self._mj_model
        if config.impl == "warp":
            # MuJoCo Warp collides box-box (rect) and capsule-box with its primitive routines
            # only with nativeccd off; the cylinder representation's cylinder-box pairs go
            # through GJK/EPA either way
            m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_NATIVECCD
        self._mjx_model = mjx.put_model(m, impl=config.impl)
        self._ctrl = ImpedanceController.from_model(m)
        # ids, looked up by name
        self._peg_body = m.body("peg").id
        self._hole_body = m.body("hole").id
        self._hole_mocap = int(m.body_mocapid[self._hole_body])
        self._tip_site = m.site("peg_tip").id
        self._mouth_site = m.site("hole_mouth").id
        self._flange_site = m.site("flange").id
        self._ft_site = m.site("ft_site").id
        self._force_adr = int(m.sensor_adr[m.sensor("ft_force").id])
        self._torque_adr = int(m.sensor_adr[m.sensor("ft_torque").id])
        self._qadr = self._ctrl.qadr
        # start pose: the "inserted" keyframe (nominal hole pose)
        key = m.key("inserted")
        self._q_inserted = np.array(key.qpos)
        d = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d, key.id)
        mujoco.mj_forward(m, d)
        self._hole_pos0 = d.xpos[self._hole_body].copy()
        self._tip_local = self._ctrl.tip_local
        self._peg_mass = float(m.body_subtreemass[self._peg_body])
        self._gravity = np.array(m.opt.gravity)
        self._flange_z0 = float(d.site_xpos[self._flange_site][2] - self._hole_pos0[2])
        self._pair_friction0 = np.array(m.pair_friction)
        self._depth0_mm = float(self._hole_pos0[2] - d.site_xpos[self._tip_site][2]) / MM
        self._init_q = jnp.asarray(self._q_inserted)

    # ------------------------------------------------------------------ properties
    @property
    def config(self) -> config_dict.ConfigDict:
        return self._config

    @property
    def mj_model(self) -> mujoco.MjModel:
        return self._mj_model

    @property
    def mjx_model(self) -> mjx.Model:
        return self._mjx_model

    @property
    def dt(self) -> float:
        return self._config.ctrl_dt

    @property
    def n_substeps(self) -> int:
        return self._n_substeps

    @property
    def compliance_actions(self) -> dict[str, tuple[int, float, float]]:
        """Each compliance-strategy action present: name (``k_xy``, ``k_rot``, ``L_C``) ->
        (action index, value at -1, value at +1), in N/m, N m/rad and m."""
        c, s = self._config, self._config.stiffness
        ranges = {}
        if c.compliance_strategy:
            ranges["k_xy"] = (s.k_xy_min_N_m, s.k_xy_max_N_m)
            if c.compliance_rotation:
                ranges["k_rot"] = (s.k_rot_min_Nm_rad, s.k_rot_max_Nm_rad)
            if c.learn_compliance_centre:
                ranges["L_C"] = (0.0, self.spec.length_mm * MM)
        return {name: (6 + i, *r) for i, (name, r) in enumerate(ranges.items())}

    @property
    def fixed_compliance(self) -> dict[str, float]:
        """k_xy, K_theta and L_C of the fixed-compliance method (CS off; the baseline)."""
        s = self._config.stiffness
        return {"k_xy": s.k_xy_N_m, "k_rot": s.k_rot_Nm_rad, "L_C": s.compliance_centre_mm * MM}

    @property
    def action_size(self) -> int:
        return 6 + len(self.compliance_actions)

    @functools.cached_property
    def observation_size(self) -> int:
        out = jax.eval_shape(self.reset, jax.random.PRNGKey(0))
        return int(out.obs.shape[-1])

    @property
    def unwrapped(self) -> PegHoleEnv:
        return self

    # ------------------------------------------------------------------ reset
    def _solve_start(self, hole_pos, hole_mat):
        """Joint angles with the peg inserted in a moved hole: Newton steps from the keyframe."""
        m = self._mjx_model
        tip_target = hole_pos + hole_mat @ jnp.array([0.0, 0.0, -(self._depth0_mm * MM)])
        mat_target = hole_mat @ jnp.asarray(TOOL_DOWN_MAT)
        d0 = self._make_data()

        def newton(q, _):
            d = d0.replace(qpos=d0.qpos.at[self._qadr].set(q))
            d = d.replace(mocap_pos=d.mocap_pos.at[self._hole_mocap].set(hole_pos))
            d = mjx.kinematics(m, d)
            d = mjx.com_pos(m, d)
            R = d.xmat[self._peg_body]
            tip = d.xpos[self._peg_body] + R @ jnp.asarray(self._tip_local)
            jacp, jacr = mjx_jac(m, d, tip, self._peg_body)
            J = jnp.concatenate([jacp.T, jacr.T])[:, self._ctrl.dadr]
            err = jnp.concatenate([tip_target - tip, rotvec_from_mat(mat_target @ R.T)])
            dq = jnp.linalg.lstsq(J, err)[0]
            return q + dq, None

        q, _ = jax.lax.scan(newton, self._init_q[self._qadr], None, length=4)
        return q

    def _make_data(self):
        c = self._config
        if c.impl == "warp":
            return mjx.make_data(self._mjx_model, impl="warp", naconmax=c.naconmax, njmax=c.njmax)
        return mjx.make_data(self._mjx_model, impl="jax")

    def reset(self, rng: jax.Array) -> State:
        """A fully re-randomised episode start (never a cached first state)."""
        r = self._config.randomization
        keys = jax.random.split(rng, 8)
        # hole pose
        hole_xy = jax.random.uniform(keys[0], (2,), minval=-1.0, maxval=1.0) * r.hole_xy_mm * MM
        hole_pos = jnp.asarray(self._hole_pos0) + jnp.concatenate([hole_xy, jnp.zeros(1)])
        yaw = jax.random.uniform(keys[1], (), minval=-1.0, maxval=1.0) * jnp.deg2rad(r.hole_yaw_deg)
        hole_mat = _rotz(yaw)
        q = self._solve_start(hole_pos, hole_mat)
        data = self._make_data()
        data = data.replace(
            qpos=data.qpos.at[self._qadr].set(q),
            mocap_pos=data.mocap_pos.at[self._hole_mocap].set(hole_pos),
            mocap_quat=data.mocap_quat.at[self._hole_mocap].set(
                jnp.array([jnp.cos(yaw / 2), 0.0, 0.0, jnp.sin(yaw / 2)])
            ),
        )
        data = mjx.forward(self._mjx_model, data)
        # commanded pose errors (hole frame): lateral offset in a disc, tilt about x and y
        rad = r.lateral_error_mm * MM * jnp.sqrt(jax.random.uniform(keys[2]))
        ang = jax.random.uniform(keys[3], (), maxval=2 * jnp.pi)
        lat = jnp.array([rad * jnp.cos(ang), rad * jnp.sin(ang), 0.0])
        tilt = jax.random.uniform(keys[4], (2,), minval=-1.0, maxval=1.0) * jnp.deg2rad(
            r.angular_error_deg
        )
        R_tilt = _rot_from_rotvec(jnp.array([tilt[0], tilt[1], 0.0]))
        tip = self._tip_world(data)
        cmd_tip = tip + hole_mat @ lat
        cmd_mat = hole_mat @ R_tilt @ jnp.asarray(TOOL_DOWN_MAT)
        fric = jax.random.uniform(
            keys[5], (), minval=r.friction_scale[0], maxval=r.friction_scale[1]
        )
        lo, hi = r.stiffness_N_m
        fixed = self.fixed_compliance
        k_xy_draw = jax.random.uniform(keys[6], (), minval=lo, maxval=hi)
        k_xy = jnp.where(hi > 0, k_xy_draw, fixed["k_xy"])
        info = {
            "rng": keys[7],
            "cmd_tip": cmd_tip,
            "cmd_mat": cmd_mat,
            "hole_pos": hole_pos,
            "hole_mat": hole_mat,
            "wrench_ff": jnp.zeros(3),
            "k_xy": jnp.asarray(k_xy, jnp.float32),
            "k_rot": jnp.asarray(fixed["k_rot"], jnp.float32),
            "L_C": jnp.asarray(fixed["L_C"], jnp.float32),
            "friction_scale": fric,
            "depth_mm": self._depth_mm(data, hole_pos, hole_mat),
            "jam_time": jnp.zeros(()),
            "prev_action": jnp.zeros(self.action_size),
            "step": jnp.zeros((), jnp.int32),
            "success": jnp.zeros(()),
            "failure": jnp.zeros(()),
            "sum_fz": jnp.zeros(()),
            "sum_fxy": jnp.zeros(()),
            "peak_fz": jnp.zeros(()),
            "nan": jnp.zeros(()),
            # the F/T sensor is zeroed at the start (no contact there; the arm is not yet
            # under control, so the raw reading would hold its free-fall transient)
            "wrench": jnp.zeros(6),
        }
        obs = self._obs(data, info)
        metrics = self._zero_metrics()
        return State(data, obs, jnp.zeros(()), jnp.zeros(()), metrics, info)

    def _zero_metrics(self) -> dict[str, jax.Array]:
        names = [
            "reward/progress",
            "reward/force",
            "reward/stiffness",
            "reward/rot_stiffness",
            "reward/extraction_force",
            "reward/end",
            "success",
            "failure",
            "jammed",
            "nan",
            "overflow",
            "extraction_time_s",
            "mean_fz_N",
            "peak_fz_N",
            "mean_fxy_N",
            "fz_N",
            "fxy_N",
            "depth_mm",
            "k_xy_N_m",
            "k_rot_Nm_rad",
        ]
        return {n: jnp.zeros(()) for n in names}

    # ------------------------------------------------------------------ physics helpers
    def _tip_world(self, d):
        R = d.xmat[self._peg_body]
        return d.xpos[self._peg_body] + R @ jnp.asarray(self._tip_local)

    def _depth_mm(self, d, hole_pos, hole_mat):
        rel = hole_mat.T @ (self._tip_world(d) - hole_pos)
        return -rel[2] / MM

    def contact_wrench(self, d, hole_mat):
        """F/T sensor force and torque in the hole frame with the peg's weight removed (N, N m).

        The sensor reads the wrench that the flange side applies to the tool side; the static
        part of it is the peg's weight. The remainder is (minus) the contact load on the peg.
        """
        R_s = d.site_xmat[self._ft_site]
        f_world = R_s @ d.sensordata[self._force_adr : self._force_adr + 3]
        t_world = R_s @ d.sensordata[self._torque_adr : self._torque_adr + 3]
        f_world = f_world + self._peg_mass * jnp.asarray(self._gravity)  # remove holding force
        return hole_mat.T @ f_world, hole_mat.T @ t_world

    def _flange_pose(self, d, info):
        rel = info["hole_mat"].T @ (d.site_xpos[self._flange_site] - info["hole_pos"])
        R = info["hole_mat"].T @ d.site_xmat[self._flange_site] @ jnp.asarray(TOOL_DOWN_MAT).T
        return rel, rotvec_from_mat(R)

    def _obs(self, d, info) -> jax.Array:
        c = self._config
        pos, rot = self._flange_pose(d, info)
        f, t = info["wrench"][:3], info["wrench"][3:]
        parts = [
            pos[:2] / MM,
            ((pos[2] - self._flange_z0) / (self.spec.length_mm * MM))[None],
            f / c.obs.force_scale_N,
            jnp.rad2deg(rot),
        ]
        if c.obs.torques:
            parts.append(t / c.obs.torque_scale_Nm)
        if c.obs.stiffness:
            parts.append(
                jnp.stack(
                    [
                        info["k_xy"] / 1000.0,
                        info["k_rot"] / GAINS.rotational_stiffness_Nm_rad,
                        info["L_C"] / (self.spec.length_mm * MM),
                    ]
                )
            )
        if c.obs.prev_action:
            parts.append(info["prev_action"])
        obs = jnp.concatenate(parts)
        return jnp.where(jnp.isfinite(obs), obs, 0.0)

    # ------------------------------------------------------------------ step
    def _decode_action(self, action, info):
        """Commanded tip pose, feed-forward force, k_xy, K_theta and L_C after this action."""
        c, a = self._config, _clean_action(action)
        H = info["hole_mat"]
        dxy = a[:2] * c.action.max_step_offset_mm * MM
        dz = a[2] * c.action.max_speed_m_s * c.ctrl_dt
        cmd_tip = info["cmd_tip"] + H @ jnp.array([dxy[0], dxy[1], dz])
        fx, fy, fz = LIMITS.max_force_N  # E11; the lateral ones lowered to max_ff_xy_N
        ff_xy = c.action.max_ff_xy_N
        cap = jnp.asarray((min(fx, ff_xy), min(fy, ff_xy), fz), jnp.float32)
        wrench_ff = jnp.clip(info["wrench_ff"] + a[3:6] * c.action.max_force_step_N, -cap, cap)
        gains = {k: info[k] for k in ("k_xy", "k_rot", "L_C")}
        for name, (i, lo, hi) in self.compliance_actions.items():  # [-1, 1] -> [lo, hi]
            gains[name] = lo + 0.5 * (a[i] + 1.0) * (hi - lo)
        return cmd_tip, wrench_ff, gains["k_xy"], gains["k_rot"], gains["L_C"]

    def _physics(self, data, info, cmd_tip_prev, cmd_tip, wrench_ff, k_xy, k_rot, L_C):
        """Run the substeps with the impedance law tracking a linearly moving target."""
        c, s = self._config, self._config.stiffness
        m = self._mjx_model.replace(
            pair_friction=jnp.asarray(self._pair_friction0) * info["friction_scale"]
        )
        cmd_mat = info["cmd_mat"]
        axis = cmd_mat[:, 2]  # peg axis (towards the tip) of the commanded pose
        vel = (cmd_tip - cmd_tip_prev) / c.ctrl_dt
        # force feed-forward: hole frame -> compliance (commanded) frame
        ff = cmd_mat.T @ (info["hole_mat"] @ wrench_ff)
        params = make_params(
            L_C,
            self._init_q[self._qadr],
            stiffness=jnp.stack([k_xy, k_xy, s.k_z_N_m, k_rot, k_rot, k_rot]).astype(jnp.float32),
            damping_ratio=s.damping_ratio,
            wrench_ff=jnp.concatenate([ff, jnp.zeros(3)]),
        )

        def substep(d, i):
            frac = (i + 1.0) / self._n_substeps
            tip = cmd_tip_prev + frac * (cmd_tip - cmd_tip_prev)
            target = Target(pos=tip - L_C * axis, mat=cmd_mat, vel=vel)
            d, _ = self._ctrl.apply(m, d, target, params)
            d = mjx.step(m, d)
            f, t = self.contact_wrench(d, info["hole_mat"])
            return d, jnp.concatenate([f, t])

        data, wrenches = jax.lax.scan(
            substep, data, jnp.arange(self._n_substeps, dtype=jnp.float32)
        )
        # the F/T reading averaged over the control period (a sensor's anti-aliasing filter):
        # single-substep contact impulses do not reach the observation or the force metrics
        wrench = jnp.mean(jnp.where(jnp.isfinite(wrenches), wrenches, 0.0), axis=0)
        return data, wrench

    def step(self, state: State, action: jax.Array) -> State:
        c, rc = self._config, self._config.reward_config
        info = dict(state.info)
        cmd_tip, wrench_ff, k_xy, k_rot, L_C = self._decode_action(action, info)
        data, wrench = self._physics(
            state.data, info, info["cmd_tip"], cmd_tip, wrench_ff, k_xy, k_rot, L_C
        )
        finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
        # a NaN action (NaN policy parameters) is applied as 0 and ends the episode like a NaN
        # world (counted in nan_worlds)
        finite = finite & jnp.all(jnp.isfinite(action))
        # a NaN world keeps its last finite state and ends its episode; the batch goes on
        data = jax.tree.map(lambda new, old: jnp.where(finite, new, old), data, state.data)
        nan = 1.0 - finite.astype(jnp.float32)
        overflow = contact_overflow(data)  # warp only: contacts were dropped, end the episode

        wrench = jnp.where(finite, wrench, 0.0)
        f = wrench[:3]
        fxy = jnp.linalg.norm(f[:2])
        fz = jnp.abs(f[2])
        depth = self._depth_mm(data, info["hole_pos"], info["hole_mat"])
        dz = depth - info["depth_mm"]
        jam_time = jnp.where(fxy > c.jam_force_N, info["jam_time"] + c.ctrl_dt, 0.0)
        jammed = (jam_time >= c.jam_time_s).astype(jnp.float32)
        success = (depth < -c.success_margin_mm).astype(jnp.float32) * (1.0 - nan)
        step = info["step"] + 1
        timeout = (step >= c.episode_length).astype(jnp.float32)
        failure = jnp.maximum(jnp.maximum(jammed, nan), jnp.maximum(timeout, overflow))
        failure = failure * (1.0 - success)
        done = jnp.maximum(success, failure)

        terms = reward_terms(dz, fxy, k_xy, success, failure, rc, k_rot, fz)
        terms["progress"] = jnp.where(finite, terms["progress"], 0.0)
        reward = sum(terms.values())

        sum_fz = info["sum_fz"] + fz
        sum_fxy = info["sum_fxy"] + fxy
        peak_fz = jnp.maximum(info["peak_fz"], fz)
        info.update(
            cmd_tip=cmd_tip,
            wrench_ff=wrench_ff,
            k_xy=jnp.asarray(k_xy, jnp.float32),
            k_rot=jnp.asarray(k_rot, jnp.float32),
            L_C=jnp.asarray(L_C, jnp.float32),
            depth_mm=depth,
            jam_time=jam_time,
            prev_action=_clean_action(action),
            step=step,
            success=success,
            failure=failure,
            sum_fz=sum_fz,
            sum_fxy=sum_fxy,
            peak_fz=peak_fz,
            nan=nan,
            wrench=wrench,
        )
        metrics = {f"reward/{k}": v for k, v in terms.items()}
        n = step.astype(jnp.float32)
        metrics.update(
            success=success,
            failure=failure,
            jammed=jammed * (1.0 - success),
            nan=nan,
            overflow=overflow,
            extraction_time_s=jnp.where(success > 0, n * c.ctrl_dt, 0.0),
            mean_fz_N=sum_fz / n,
            peak_fz_N=peak_fz,
            mean_fxy_N=sum_fxy / n,
            fz_N=fz,
            fxy_N=fxy,
            depth_mm=depth,
            k_xy_N_m=jnp.asarray(k_xy, jnp.float32),
            k_rot_Nm_rad=jnp.asarray(k_rot, jnp.float32),
        )
        obs = self._obs(data, info)
        return State(data, obs, reward, done, metrics, info)


@functools.cache
def _jac_fn():
    from mujoco.mjx._src import support

    return support.jac


def mjx_jac(m, d, point, body_id):
    """(nv, 3) translational and rotational Jacobians of a point on a body (MJX)."""
    return _jac_fn()(m, d, point, body_id)
