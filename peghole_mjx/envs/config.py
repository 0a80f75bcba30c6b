"""The env config: the defaults shared by the tasks, and how overrides are checked.

Every number the env's reset and step use is an entry of this config (or is derived from it
when the env is built: the compiled scene of ``preset``, the peg length, the substep count).
The defaults are copied from their one source: the robot's limits and gains
(:mod:`peghole_mjx.control.limits`), the reward weights (:data:`~peghole_mjx.envs.reward.
REWARD_WEIGHTS`), the simulator step (:class:`~peghole_mjx.geometry.mjcf.SimOptions`).
"""

from __future__ import annotations

import dataclasses
import json
import math

from ml_collections import config_dict

from peghole_mjx.control import GAINS, LIMITS
from peghole_mjx.envs.reward import REWARD_WEIGHTS
from peghole_mjx.errors import InfeasibleGeometryError, UserInputError
from peghole_mjx.geometry.mjcf import SimOptions
from peghole_mjx.geometry.specs import MM, PegHoleSpec, get_preset, with_changes


def base_config(preset: str) -> config_dict.ConfigDict:
    """Defaults shared by both tasks (see each task's ``default_config``)."""
    get_preset(preset)  # an unknown preset fails here
    return config_dict.create(
        preset=preset,
        # a peg-hole other than the preset's (held-out geometries): a JSON object of the
        # preset spec's fields to change, in mm, e.g. '{"peg_w_mm": 49.9, "hole_w_mm": 50.1}'
        # (geometry/specs.py RectSpec, DualSpec; checked by specs.validate). "": the preset's
        geometry="",
        # the physics engine (envs/engines.py): "mjx" (MuJoCo MJX, CPU or GPU) or "mujoco"
        # (MuJoCo C through mujoco.batch on a CPU thread pool, envs/engine_mujoco.py)
        engine="mjx",
        impl="jax",  # engine mjx: MJX's implementation, "jax" (CPU, GPU) or "warp" (CUDA GPU)
        mujoco_threads=0,  # engine mujoco: threads of its pool; 0 = every CPU of the process
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
        # active contacts measured (benchmarks/results/contact_caps.json, 2026-11-30) are rect
        # 20 (edges and box), dual capsule 26, dual mesh 37; 3 rows per elliptic condim-3
        # contact + joint limits
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
        # the impedance layer's caps of the commanded Cartesian wrench, compliance frame
        # (control/limits.py, E11): force x, y, z (N) and torque about x, y, z (N m). The
        # accumulated feed-forward force is also held within max_force_N (its lateral part
        # within action.max_ff_xy_N as well)
        limits=config_dict.create(
            max_force_N=LIMITS.max_force_N,
            max_torque_Nm=LIMITS.max_torque_Nm,
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
            # null-space posture spring and damper of the impedance law
            null_stiffness_Nm_rad=GAINS.null_stiffness_Nm_rad,
            null_damping_Nms_rad=GAINS.null_damping_Nms_rad,
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
            # the accumulated feed-forward force and the commanded tip minus the tip (6
            # entries): the integrators of actions 0-5, which eq (4.2)'s state leaves hidden
            # (docs/training.md, "Self-inflicted failures")
            commands=False,
            force_scale_N=LIMITS.max_force_N[0],
            torque_scale_Nm=LIMITS.max_torque_Nm[0],
            # with stiffness: k_xy and K_theta in units of these (L_C in units of the peg
            # length, from the preset)
            k_xy_scale_N_m=1000.0,
            k_rot_scale_Nm_rad=GAINS.rotational_stiffness_Nm_rad,
        ),
        randomization=config_dict.create(
            lateral_error_mm=1.0,  # commanded tip offset from the hole axis, uniform in a disc
            angular_error_deg=0.5,  # commanded tilt about x and y, uniform (E3: |theta0| <= 0.9)
            hole_xy_mm=5.0,  # hole position, uniform in a square
            hole_yaw_deg=5.0,  # hole rotation about its axis
            friction_scale=(0.8, 1.2),  # x preset's mu
            stiffness_N_m=(0.0, 0.0),  # CS off: if max > 0, k_xy ~ U(range) per episode
        ),
    )


def env_spec(config: config_dict.ConfigDict) -> PegHoleSpec:
    """The peg-hole of an env config: the preset's spec with ``geometry``'s changes."""
    spec = get_preset(config.preset)
    text = config.get("geometry", "")
    if not text:
        return spec
    try:
        changes = json.loads(text)
    except ValueError:
        changes = None
    if not isinstance(changes, dict) or not changes:
        raise UserInputError(
            f"env config geometry must be a JSON object of spec fields, got {text!r}"
        )
    fields = {f.name for f in dataclasses.fields(spec) if f.init}
    unknown = sorted(set(changes) - fields)
    if unknown:
        raise UserInputError(
            f"env config geometry: {', '.join(unknown)} not fields of {type(spec).__name__} "
            f"(it has: {', '.join(sorted(fields))})"
        )
    changes = {k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()}
    try:
        return with_changes(spec, **changes)
    except (InfeasibleGeometryError, TypeError) as exc:
        raise UserInputError(f"env config geometry {text}: {exc}") from None


def geometry_text(changes: dict | str) -> str:
    """The ``geometry`` config entry for spec ``changes`` (a canonical JSON object)."""
    if isinstance(changes, str):
        return changes
    return json.dumps(
        {k: list(v) if isinstance(v, tuple) else v for k, v in changes.items()},
        sort_keys=True,
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


def apply_overrides(
    config: config_dict.ConfigDict, overrides: dict | None
) -> config_dict.ConfigDict:
    """A checked, locked copy of ``config`` with flat ``a.b.c`` ``overrides`` applied."""
    config = config_dict.ConfigDict(config)
    if overrides:
        check_override_keys(config, overrides)
        if isinstance(overrides.get("geometry"), dict):  # --set env.geometry={...} parses to a dict
            overrides = {**overrides, "geometry": geometry_text(overrides["geometry"])}
        try:
            config.update_from_flattened_dict(overrides)
        except (TypeError, ValueError) as exc:
            raise UserInputError(f"bad env config override: {exc}") from None
    check_config_values(config)
    config.lock()
    return config


def check_override_keys(config: config_dict.ConfigDict, overrides: dict) -> None:
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


def check_config_values(config: config_dict.ConfigDict) -> None:
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
    mu = env_spec(config).friction * r.friction_scale[1]
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
    lim = config.limits
    for key in ("max_force_N", "max_torque_Nm"):
        caps = tuple(lim[key])
        need(
            len(caps) == 3 and all(v >= 0 for v in caps),
            f"limits.{key} must be three numbers >= 0, got {caps!r}",
        )
