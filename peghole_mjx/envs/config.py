"""The env config: the defaults shared by the tasks, and how overrides are checked.

Every number the env's reset and step use is an entry of this config (or is derived from it
when the env is built: the compiled scene of ``preset``, the peg length, the substep count).
The defaults are copied from their one source: the robot's limits and gains
(:mod:`peghole_mjx.control.limits`), the reward weights (:data:`~peghole_mjx.envs.reward.
REWARD_WEIGHTS`), the simulator step (:class:`~peghole_mjx.geometry.mjcf.SimOptions`).

Every config is checked when it is built (:func:`apply_overrides`), before any model is built
or compiled: each entry's type (switches, text, numbers), each number against its range in
:data:`peghole_mjx.core.validation.RANGES` (``"env." + key``, the one table of allowed ranges), and
the relations between entries (time steps, bounds, the contact cap). A refusal is one
:class:`~peghole_mjx.core.errors.UserInputError` line naming the entry.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math

from ml_collections import config_dict

from peghole_mjx.control import GAINS, LIMITS
from peghole_mjx.core.errors import InfeasibleGeometryError, UserInputError
from peghole_mjx.core.validation import CONTACT_CAP_FACTOR, RANGES, _num, check_finite_tree
from peghole_mjx.envs.reward import (
    OUTCOME_WEIGHTS,
    REWARD_KINDS,
    REWARD_WEIGHTS,
    TIME_LIMITS,
    outcome_ordering_problem,
)
from peghole_mjx.geometry.mjcf import SimOptions, contact_cap_entry, contact_cap_for
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import MM, PegHoleSpec, get_preset, with_changes
from peghole_mjx.geometry.task import TaskSpec, load_task


def base_config(preset: str) -> config_dict.ConfigDict:
    """Defaults shared by the tasks (see each task's ``default_config``); ``preset`` "" for a
    task whose peg-hole is not a preset (MeshExtract: a task folder, ``task``)."""
    if preset:
        get_preset(preset)  # an unknown preset fails here
    return config_dict.create(
        preset=preset,
        # a peg-hole other than the preset's (held-out geometries): a JSON object of the
        # preset spec's fields to change, in mm, e.g. '{"peg_w_mm": 49.9, "hole_w_mm": 50.1}'
        # (geometry/specs.py RectSpec, DualSpec; checked by specs.validate). "": the preset's
        geometry="",
        # the physics engine (sim/engines.py): "auto" (default_engine: MuJoCo C without a GPU,
        # MJX-Warp on a CUDA GPU with warp-lang, else MJX-JAX; the built env's config holds the
        # one chosen), "mjx" (MuJoCo MJX, CPU or GPU) or "mujoco" (MuJoCo C through
        # mujoco.batch on a CPU thread pool, sim/engine_mujoco.py). Provenance, not the task
        engine="auto",
        impl="jax",  # engine mjx: MJX's implementation, "jax" (CPU, GPU) or "warp" (CUDA, or CPU)
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
        # contact settings (docs/research/contact.md; peghole experiment contact-check, variant
        # "envs"):
        # a 10 ms contact time constant (0: 2 x sim_dt, MuJoCo's stiffest) and frictional rows
        # relaxed over 1 s (0: as stiff as the normal row)
        contact=config_dict.create(timeconst_s=0.01, friction_timeconst_s=1.0),
        # warp: contact buffer per world (x num worlds) and constraint rows per world; the most
        # active contacts measured (benchmarks/results/perf/contact_caps.json, 2026-11-30) are rect
        # 20 (edges and box), dual capsule 26, dual mesh 37; 3 rows per elliptic condim-3
        # contact + joint limits
        naconmax=64,
        njmax=256,
        action=config_dict.create(
            max_step_offset_mm=LIMITS.max_step_offset_m / MM,  # |dx|, |dy| per step (Sec 4.3.1)
            max_speed_m_s=LIMITS.max_speed_m_s,  # |dz| per step = this x ctrl_dt
            max_force_step_N=2.0,  # |dF| per step
            # bound of the accumulated lateral feed-forward |F_x|, |F_y| (the force limit of
            # E11 by default; DualExtract's training profiles lower it: docs/guide/training.md,
            # "Lateral feed-forward bound")
            max_ff_xy_N=LIMITS.max_force_N[0],
            # residual actions: the pull is the scripted 20 mm/s plus residual_scale x its
            # action, the gains are the action's, the lateral offset and feed-forward are held
            # at 0 (envs/extraction.py residual_affine; docs/research/residual.md)
            residual=False,
            residual_scale=0.25,
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
        # stiffness that the angular error loads; see docs/guide/training.md, "Compliance strategy")
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
            # "thesis": eq (4.4) as the thesis wrote it (the env's own default and the
            # reproduction studies'); "outcome": every extraction returns more than every
            # failure, less force and time more (opt-in: it did not learn RectExtract,
            # docs/research/learning.md; envs/reward.py says why and how)
            kind="thesis",
            # the outcome reward's time limit: "truncation" (a time-out is not an outcome; the
            # learner bootstraps it) or "failure" (a terminal failure like a jam, with the time
            # left in the observation, obs.time_left). Under "thesis" a time-out is always a
            # terminal failure (eq 4.4's -1)
            time_limit="truncation",
            **REWARD_WEIGHTS,
            force_scale_N=LIMITS.max_force_N[0],  # |f_xy| is measured in units of this
            stiffness_scale_N_m=1000.0,  # ||k_xy|| is measured in N/mm
            # not in eq (4.4): the stiffness term extended to K_theta, for the K_theta compliance
            # strategy (our extension). 0 = the thesis's reward; DualExtract's training profiles
            # set it (train/configs/DualExtract.json; docs/guide/training.md, "Rotational stiffness
            # term")
            w_stf_rot=0.0,
            rot_stiffness_scale_Nm_rad=GAINS.rotational_stiffness_Nm_rad,
            # not in eq (4.4) either: a penalty on the extraction force |f_z| itself, the
            # quantity of R3 (eq 4.4 only penalises |f_xy|). 0 = the thesis's reward
            w_fz=0.0,
            fz_scale_N=1.0,
            # the outcome reward's own settings (envs/reward.py OUTCOME_WEIGHTS); its contact
            # cost reads |f| in units of force_scale_N above
            **OUTCOME_WEIGHTS,
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
            # (docs/research/index.md, "Self-inflicted failures")
            commands=False,
            # the share of the time limit still left (1 at the start, 0 at episode_length):
            # needed when a time-out is an outcome (reward_config.time_limit "failure"), else
            # the time-out cannot be predicted from the observation
            time_left=False,
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
            # shifts toward a real robot (docs/research/transfer.md), all off by default (each
            # off value leaves the env's computation as it was, bit for bit). The F/T sensor as
            # the policy observes it (metrics, reward and the jam rule keep the true wrench):
            # white Gaussian noise per control step (SD of each force / torque component) ...
            ft_noise_force_N=0.0,
            ft_noise_torque_Nm=0.0,
            # ... plus a bias: an initial offset per episode (Gaussian, SD per component) that
            # drifts as a random walk (SD per sqrt(s)), carried in state.info["ft_bias"]
            ft_bias_force_N=0.0,
            ft_bias_torque_Nm=0.0,
            ft_drift_force_N_sqrt_s=0.0,
            ft_drift_torque_Nm_sqrt_s=0.0,
            # latencies in control steps: the policy sees the observation of this many steps
            # ago; the robot applies the action of this many steps ago (holding its command
            # until the first one arrives)
            obs_latency_steps=0,
            action_latency_steps=0,
            # tool-frame calibration error: where the controller believes the tool (tip) frame
            # is, relative to the true one, drawn per episode uniform in (lo, hi): along the peg
            # axis (mm, + = towards the flange: an L_C error of this size), across it (mm, in a
            # random direction) and a tilt of its axis (deg, about a random axis across it)
            tool_axial_mm=(0.0, 0.0),
            tool_lateral_mm=(0.0, 0.0),
            tool_tilt_deg=(0.0, 0.0),
            # the payload (peg) mass as a factor on the preset's, drawn per episode uniform in
            # (lo, hi); the robot does not know it: the F/T tare and the law's gravity
            # compensation keep the nominal mass
            payload_mass_scale=(1.0, 1.0),
        ),
        # a stuck joint (corrosion, glue; docs/guide/stuck.md; envs/stuck.py): the peg starts
        # welded to the hole and the weld releases for the rest of the episode once the axial
        # F/T force |F_z| of a control step's substeps reaches the episode's breakaway force,
        # drawn uniform in breakaway_N (N). Off: no weld in the scene (the env as before)
        stuck=config_dict.create(
            enabled=False,
            breakaway_N=(20.0, 50.0),
            timeconst_s=0.005,  # the weld's solref time constant (its stiffness), s
        ),
    )


def env_spec(config: config_dict.ConfigDict) -> PegHoleSpec | TaskSpec:
    """The peg-hole of an env config: the preset's spec with ``geometry``'s changes, or the
    task folder's parts (the ``task`` entry of MeshExtract's config)."""
    if "task" in config:
        return task_spec(config)
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
    for key, value in changes.items():
        problem = _geometry_value_problem(getattr(spec, key), value)
        if problem:
            raise UserInputError(f"env config geometry: {key} {problem}, got {value!r}")
    changes = {k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()}
    try:
        return with_changes(spec, **changes)
    except (InfeasibleGeometryError, TypeError) as exc:
        raise UserInputError(f"env config geometry {text}: {exc}") from None


def task_spec(config: config_dict.ConfigDict) -> TaskSpec:
    """The parts of the task folder ``config.task`` (checked whole: geometry/task.py); a
    task env takes neither a preset nor ``geometry`` changes."""
    if not config.task:
        raise UserInputError(
            "this env needs a task folder: --set env.task=DIR (made by peghole task make or "
            "peghole task builtin)"
        )
    if config.preset or config.get("geometry", ""):
        raise UserInputError(
            "a task env takes its parts from env.task: leave preset and geometry empty"
        )
    return load_task(config.task)


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _geometry_value_problem(preset_value, value) -> str | None:
    """What is wrong with the type of a ``geometry`` change of a spec field (its range is
    checked by the spec itself), or None: a number (no true/false), a list of as many numbers
    for a tuple field (the dual radii), null only where the preset's value is null (the
    default depth)."""
    if isinstance(preset_value, tuple):
        ok = isinstance(value, list | tuple) and len(value) == len(preset_value)
        if not (ok and all(_is_number(v) for v in value)):
            return f"must be a list of {len(preset_value)} numbers"
        return None
    if value is None and preset_value is None:
        return None
    if not _is_number(value):
        return "must be a number" + (" or null" if preset_value is None else "")
    return None


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
    """A checked, locked copy of ``config`` with flat ``a.b.c`` ``overrides`` applied
    (``config`` itself is left as it is: a ``ConfigDict`` copy would share its groups)."""
    config = copy.deepcopy(config_dict.ConfigDict(config))
    if overrides is not None and not isinstance(overrides, dict):
        raise UserInputError(
            f"env config overrides must be a mapping of flat keys to values, got {overrides!r}"
        )
    if overrides:
        check_override_keys(config, overrides)
        if isinstance(overrides.get("geometry"), dict):  # --set env.geometry={...} parses to a dict
            overrides = {**overrides, "geometry": geometry_text(overrides["geometry"])}
        overrides = {k: _as_entry_type(_entry(config, k), v) for k, v in overrides.items()}
        for key, value in overrides.items():
            # the type, named by the full key (ConfigDict would store true as 1.0 in a number
            # entry, accept any type in an entry whose default is None, and name only the
            # last part of the key)
            want = _type_problem(key, _entry(config, key), value)
            if want:
                raise UserInputError(f"env config {key} must be {want}, got {value!r}")
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
        if isinstance(node, config_dict.ConfigDict):
            first = sorted(node.keys())[0]
            raise UserInputError(
                f"env config {key} is a group of entries ({', '.join(sorted(node.keys()))}): "
                f"set one of them, e.g. {key}.{first}=..."
            )


def _entry(config: config_dict.ConfigDict, key: str):
    """The value of flat key ``a.b.c`` (an existing entry)."""
    node = config
    for part in key.split("."):
        node = node[part]
    return node


def _as_entry_type(current, value):
    """``value`` in the form of the entry it overrides: a list as a tuple for a tuple entry,
    a whole float (``1e3`` on the command line) as an int for an integer entry."""
    if isinstance(value, list) and isinstance(current, tuple):
        return tuple(value)
    if (
        isinstance(current, int)
        and not isinstance(current, bool)
        and isinstance(value, float)
        and value.is_integer()
    ):
        return int(value)
    return value


def _type_problem(key: str, current, value) -> str | None:
    """What type the entry ``key`` (now ``current``) needs if ``value`` lacks it, or None."""
    if key in FLAGS:
        return None if isinstance(value, bool) else "true or false"
    if key in TEXT:
        ok = isinstance(value, str) or (value is None and key in OPTIONAL)
        return None if ok else "text" + (" or null" if key in OPTIONAL else "")
    if key in TUPLES:
        ok = isinstance(value, tuple) and len(value) == TUPLES[key]
        return None if ok else f"a list of {TUPLES[key]} numbers"
    if value is None and key in OPTIONAL:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return "a number (not true or false)" if isinstance(value, bool) else "a number"
    if isinstance(current, int) and not isinstance(current, bool) and not isinstance(value, int):
        return "an integer"
    return None


def leaves(config: config_dict.ConfigDict, prefix: str = ""):
    """``(flat key, value)`` of every entry of an env config (groups walked, not returned)."""
    for k, v in config.items():
        if isinstance(v, config_dict.ConfigDict):
            yield from leaves(v, f"{prefix}{k}.")
        else:
            yield prefix + k, v


#: entries that are switches (true / false)
FLAGS = frozenset(
    {
        "compliance_strategy",
        "compliance_rotation",
        "learn_compliance_centre",
        "obs.torques",
        "obs.stiffness",
        "obs.prev_action",
        "obs.commands",
        "obs.time_left",
        "stuck.enabled",
        "action.residual",
    }
)
#: entries that are text (``representation``: or None, the preset's default); their values are
#: checked where they are read (the preset, geometry, engine, impl and representation names)
TEXT = frozenset(
    {
        "preset",
        "geometry",
        "engine",
        "impl",
        "representation",
        "task",
        "reward_config.kind",
        "reward_config.time_limit",
    }
)
#: entries that are None for "the default" (else a number in range)
OPTIONAL = frozenset({"contact_cap", "representation"})
#: entries that hold several numbers (each within the entry's range): how many
TUPLES = {
    "limits.max_force_N": 3,
    "limits.max_torque_Nm": 3,
    "randomization.friction_scale": 2,
    "randomization.stiffness_N_m": 2,
    "randomization.tool_axial_mm": 2,
    "randomization.tool_lateral_mm": 2,
    "randomization.tool_tilt_deg": 2,
    "randomization.payload_mass_scale": 2,
    "stuck.breakaway_N": 2,
}
#: the (lo, hi) ranges of the ``randomization`` group (each drawn uniform in it per episode)
RANDOM_RANGES = tuple(k.split(".", 1)[1] for k in TUPLES if k.startswith("randomization."))


def _range_problem(rng, value) -> str | None:
    """What is wrong with ``value`` for ``rng``, naming the bound it crosses first."""
    problem = rng.problem(value)
    if problem is None or isinstance(value, bool) or not isinstance(value, int | float):
        return problem
    if not math.isfinite(value) or (rng.integer and value != int(value)):
        return problem
    if rng.lo is not None and (value <= rng.lo if rng.lo_open else value < rng.lo):
        bound, why = f"{'>' if rng.lo_open else '>='} {_num(rng.lo)}", rng.why_lo
    else:
        bound, why = f"{'<' if rng.hi_open else '<='} {_num(rng.hi)}", rng.why_hi
    kind = "an integer " if rng.integer else ""
    allowed = rng.describe().split(" in ", 1)[-1]  # the interval, e.g. [0, 1024]
    why = f"; {why}" if why else ""
    return f"must be {kind}{bound} (in {allowed}{why}), got {value!r}"


def check_config_values(config: config_dict.ConfigDict) -> None:
    """Every entry of the env config has its type, and every number is finite and in its
    range (:data:`peghole_mjx.core.validation.RANGES`, ``env.<key>``): checked before any model is
    built or compiled, naming the entry."""
    check_finite_tree(config.to_dict(), "env config")

    def need(cond: bool, what: str) -> None:
        if not cond:
            raise UserInputError(f"env config: {what}")

    for key, value in leaves(config):
        if key in OPTIONAL and value is None:
            continue
        if key in TEXT:
            need(isinstance(value, str), f"{key} must be text, got {value!r}")
        elif key in FLAGS:
            need(isinstance(value, bool), f"{key} must be true or false, got {value!r}")
        elif f"env.{key}" not in RANGES:
            raise UserInputError(f"env config: {key} is not an entry of the env config")
        else:
            rng = RANGES[f"env.{key}"]
            if key in TUPLES:
                n = TUPLES[key]
                need(
                    isinstance(value, tuple | list) and len(value) == n,
                    f"{key} must be {n} numbers, got {value!r}",
                )
                for v in value:
                    problem = _range_problem(rng, v)
                    need(problem is None, f"{key} = {tuple(value)!r}: each number {problem}")
            else:
                problem = _range_problem(rng, value)
                need(problem is None, f"{key} {problem}")

    n_sub = config.ctrl_dt / config.sim_dt
    need(
        abs(n_sub - round(n_sub)) <= 1e-6,
        f"ctrl_dt ({config.ctrl_dt:g} s) must be a whole multiple of sim_dt ({config.sim_dt:g} s)",
    )
    r = config.randomization
    for key in RANDOM_RANGES:
        lo, hi = r[key]
        need(lo <= hi, f"randomization.{key} must be a range (lo, hi), lo <= hi, got {r[key]!r}")
    kind = config.reward_config.kind
    need(
        kind in REWARD_KINDS,
        f"reward_config.kind must be one of {', '.join(REWARD_KINDS)}, got {kind!r}",
    )
    if kind == "outcome":
        problem = outcome_ordering_problem(config.reward_config, config.episode_length)
        need(problem is None, str(problem))
    time_limit = config.reward_config.time_limit
    need(
        time_limit in TIME_LIMITS,
        f"reward_config.time_limit must be one of {', '.join(TIME_LIMITS)}, got {time_limit!r}",
    )
    need(
        time_limit != "failure" or config.obs.time_left,
        "reward_config.time_limit 'failure' needs obs.time_left true: a time-out that ends the "
        "episode as a failure must be predictable from the observation",
    )
    lo, hi = config.stuck.breakaway_N
    need(lo <= hi, f"stuck.breakaway_N must be a range (lo, hi), lo <= hi, got {(lo, hi)!r}")
    spec = env_spec(config)
    mu = spec.friction * r.friction_scale[1]
    fr = RANGES["friction"]
    need(
        fr.problem(mu) is None,
        f"randomization.friction_scale gives friction {mu:g}, outside [0, {fr.hi:g}]",
    )
    s = config.stiffness
    need(
        s.k_xy_min_N_m <= s.k_xy_max_N_m and s.k_rot_min_Nm_rad <= s.k_rot_max_Nm_rad,
        "stiffness bounds must satisfy min <= max (k_xy_min_N_m <= k_xy_max_N_m, "
        "k_rot_min_Nm_rad <= k_rot_max_Nm_rad)",
    )
    need(
        s.compliance_centre_mm <= spec.length_mm,
        f"stiffness.compliance_centre_mm ({s.compliance_centre_mm:g}) must lie within the peg "
        f"(<= its length, {spec.length_mm:g} mm)",
    )
    if config.contact_cap is not None:
        rep = resolve_representation(spec, config.representation, impl=config.impl)
        contact_cap_for(spec, rep, int(config.contact_cap))  # below the measured maximum
        entry = contact_cap_entry(spec, rep)  # a task folder's own, or CONTACT_CAPS'
        if entry is not None:
            most = CONTACT_CAP_FACTOR * entry.measured_max
            need(
                config.contact_cap <= most,
                f"contact_cap must be 0 (no cap) or at most {most} ({CONTACT_CAP_FACTOR} x the "
                f"measured maximum of {entry.measured_max} active contacts of the {spec.kind} "
                f"scene, {rep}), got {config.contact_cap!r}",
            )
