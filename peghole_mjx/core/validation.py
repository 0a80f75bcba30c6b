"""Checks at the edge: the one table of allowed ranges for user numbers, and JSON that parses.

Every number a user gives (a command-line option, a ``--set`` override, a config file entry)
is checked here for type, finiteness and range before any work starts. :data:`RANGES` is the
single source of truth: the argparse types (:func:`arg`), the training config, the env config,
the CoACD parameters and the peg-hole specs all read it. NaN and infinity are refused
everywhere. :func:`json_safe` turns undefined values (NaN, inf) into ``null``, so ``--json``
output and written reports are valid JSON.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import numbers
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from peghole_mjx.core.errors import UserInputError

# (UserInputError is imported where raised: peghole_mjx.core.errors imports the geometry specs,
# which read RANGES while this module may still be loading)

#: the largest peg-hole dimension (mm) the iiwa 14 scene holds within the robot's reach: its
#: inverse kinematics reaches the inserted pose of a 700 mm peg, not of an 800 mm one
MAX_PART_MM = 700.0
#: the smallest peg-hole dimension (mm): below it MuJoCo refuses the parts (mesh volumes and
#: body inertias under its mjMINVAL; the rect peg's 0.5 mm edge capsules meet) and the
#: contact model (0.2 mm solimp width, micrometre steady penetration) no longer resolves them
MIN_PART_MM = 1.0
#: why a size below MIN_PART_MM is refused (appended to the message)
WHY_MIN_PART = "the smallest part MuJoCo builds and this contact model resolves"
#: the largest extent of a user's CAD part (mm): the user scene's floor is 2 m across
MAX_CAD_PART_MM = 2000.0


@dataclass(frozen=True)
class Range:
    """An allowed interval; ``integer`` values must be whole numbers."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    why_lo: str = ""  # appended to the message of a value below the range
    why_hi: str = ""  # ... and above it (e.g. which limit it is)

    def describe(self) -> str:
        kind = "an integer" if self.integer else "a finite number"
        lo, hi = _num(self.lo), _num(self.hi)
        if self.lo is not None and self.hi is not None:
            a, b = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
            return f"{kind} in {a}{lo}, {hi}{b}"
        if self.lo is not None:
            return f"{kind} {'>' if self.lo_open else '>='} {lo}"
        if self.hi is not None:
            return f"{kind} {'<' if self.hi_open else '<='} {hi}"
        return kind

    def problem(self, value: Any) -> str | None:
        """None if ``value`` is allowed, else what is wrong with it."""
        value = plain_number(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            return f"must be {self.describe()}, got {value!r}"
        if not math.isfinite(value):
            return f"must be {self.describe()}, got {value!r}"
        if self.integer and value != int(value):
            return f"must be {self.describe()}, got {value!r}"
        lo_bad = self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo)
        hi_bad = self.hi is not None and (value >= self.hi if self.hi_open else value > self.hi)
        why = self.why_lo if lo_bad else self.why_hi if hi_bad else ""
        if lo_bad or hi_bad:
            return f"must be {self.describe()}, got {value!r}" + (f" ({why})" if why else "")
        return None


def plain_number(value: Any) -> Any:
    """A NumPy (or other ``numbers``) integer or real scalar as Python's ``int`` or ``float``
    (``np.int64(4)`` is an integer, decided 2026-12-04); booleans (``True``, ``np.True_``)
    and everything else unchanged, so they are refused as before."""
    if isinstance(value, bool | int | float) or type(value).__name__ in ("bool", "bool_"):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return value


def _num(x: float | None) -> str:
    if x is not None and x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return f"{x:g}"


POSITIVE = Range(0.0, lo_open=True)
SEED = Range(0, 2**32 - 1, integer=True)

#: the KUKA LBR iiwa's Cartesian impedance mode: translational stiffness 0-5000 N/m,
#: rotational 0-300 N m/rad, damping ratio 0.1-1 (the robot the thesis's gains are set on)
_KIND = "the iiwa's Cartesian impedance range"
IIWA_K_TRANS = Range(0.0, 5000.0, lo_open=True, why_hi=_KIND)
IIWA_K_ROT = Range(0.0, 300.0, lo_open=True, why_hi=_KIND)
#: the most a user may scale a measured contact maximum by in ``contact_cap`` (envs/config.py):
#: above 4x every scene's allocated contacts are covered, and the cap no longer caps anything
CONTACT_CAP_FACTOR = 4

#: the longest observation or action latency of the env config, control steps
MAX_LATENCY_STEPS = 10

#: env config ranges (see RANGES); "why" notes say which limit a bound is
ENV_RANGES: dict[str, Range] = {
    f"env.{k}": v
    for k, v in {
        # time steps and run length: 10 Hz-1 kHz control (the iiwa's FRI runs at <= 1 kHz),
        # 0.1-10 ms physics steps (MuJoCo's default is 2 ms)
        "ctrl_dt": Range(0.001, 0.1),
        "sim_dt": Range(1e-4, 0.01),
        "episode_length": Range(1, 1_000_000, integer=True),
        "mujoco_threads": Range(0, 1024, integer=True),  # 0 = every CPU
        # None (the measured default) or 0 (no cap) or a cap; its upper end is also held within
        # CONTACT_CAP_FACTOR x the scene's measured maximum (envs/config.py)
        "contact_cap": Range(0, 10_000, integer=True),
        "naconmax": Range(1, 4096, integer=True),
        "njmax": Range(1, 65_536, integer=True),
        # contact softness (0: MuJoCo's stiffest, 2 x sim_dt)
        "contact.timeconst_s": Range(0.0, 1.0),
        "contact.friction_timeconst_s": Range(0.0, 10.0),
        # the action's scales (0 switches an action component off)
        "action.max_step_offset_mm": Range(0.0, 10.0),
        "action.max_speed_m_s": Range(0.0, 1.0, lo_open=True, why_lo="the pull would never move"),
        "action.max_force_step_N": Range(0.0, 100.0),
        "action.max_ff_xy_N": Range(0.0, 500.0),
        "action.residual_scale": Range(
            0.0, 2.0, lo_open=True, why_lo="the residual policy would have no effect"
        ),
        # the impedance layer's wrench caps: at most 25x the thesis's (20/20/60 N, 3/3/1 N m)
        "limits.max_force_N": Range(0.0, 500.0, lo_open=True),
        "limits.max_torque_Nm": Range(0.0, 75.0, lo_open=True),
        # gains (the iiwa's Cartesian impedance ranges)
        "stiffness.k_xy_N_m": IIWA_K_TRANS,
        "stiffness.k_xy_min_N_m": IIWA_K_TRANS,
        "stiffness.k_xy_max_N_m": IIWA_K_TRANS,
        "stiffness.k_z_N_m": IIWA_K_TRANS,
        "stiffness.k_rot_Nm_rad": IIWA_K_ROT,
        "stiffness.k_rot_min_Nm_rad": IIWA_K_ROT,
        "stiffness.k_rot_max_Nm_rad": IIWA_K_ROT,
        "stiffness.damping_ratio": Range(0.1, 1.0, why_lo=_KIND, why_hi=_KIND),
        # L_C above the tip: within the peg (also held to the peg length, envs/config.py)
        "stiffness.compliance_centre_mm": Range(0.0, MAX_PART_MM),
        "stiffness.null_stiffness_Nm_rad": Range(0.0, 1000.0),
        "stiffness.null_damping_Nms_rad": Range(0.0, 100.0),
        # reward: weights >= 0 (a negative weight flips what a term rewards), scales > 0
        "reward_config.w_d": Range(0.0, 1000.0),
        "reward_config.w_f": Range(0.0, 1000.0),
        "reward_config.w_stf": Range(0.0, 1000.0),
        "reward_config.w_stf_rot": Range(0.0, 1000.0),
        "reward_config.w_fz": Range(0.0, 1000.0),
        "reward_config.r_success": Range(0.0, 1000.0),
        "reward_config.r_failure": Range(-1000.0, 0.0),
        "reward_config.force_scale_N": Range(0.0, 10_000.0, lo_open=True),
        "reward_config.stiffness_scale_N_m": Range(0.0, 1e6, lo_open=True),
        "reward_config.rot_stiffness_scale_Nm_rad": Range(0.0, 1e6, lo_open=True),
        "reward_config.fz_scale_N": Range(0.0, 10_000.0, lo_open=True),
        # the outcome reward (envs/reward.py): its discount, step cost, contact weight and
        # progress potential; the ordering of outcomes is checked on top (config.py)
        "reward_config.discount": Range(0.0, 1.0, lo_open=True, hi_open=True),
        "reward_config.time_cost": Range(0.0, 1000.0, lo_open=True),
        "reward_config.w_contact": Range(0.0, 1000.0),
        "reward_config.w_progress": Range(0.0, 1e6),
        # episode ends: margins and thresholds > 0 (at 0 every step would end the episode)
        "success_margin_mm": Range(0.0, MAX_PART_MM, lo_open=True),
        "jam_force_N": Range(0.0, 10_000.0, lo_open=True),
        "jam_time_s": Range(0.0, 3600.0, lo_open=True),
        # observation scales > 0 (an observation is divided by them)
        "obs.force_scale_N": Range(0.0, 10_000.0, lo_open=True),
        "obs.torque_scale_Nm": Range(0.0, 10_000.0, lo_open=True),
        "obs.k_xy_scale_N_m": Range(0.0, 1e6, lo_open=True),
        "obs.k_rot_scale_Nm_rad": Range(0.0, 1e6, lo_open=True),
        # episode-start randomisation: the hole within what the start pose's IK reaches (its
        # few Newton steps from the keyframe put the tip within 0.01 mm of a hole moved 100 mm
        # in x and y at any yaw, both scenes; at 150 mm it runs into a joint limit), tilts
        # within 30 deg
        "randomization.lateral_error_mm": Range(0.0, 50.0),
        "randomization.angular_error_deg": Range(0.0, 30.0),
        "randomization.hole_xy_mm": Range(0.0, 100.0, why_hi="the start pose's IK reach"),
        "randomization.hole_yaw_deg": Range(0.0, 180.0),
        "randomization.friction_scale": Range(0.0, 100.0),  # x the preset's mu, within friction
        "randomization.stiffness_N_m": Range(0.0, 5000.0, why_hi=_KIND),
        # shifts toward a real robot (envs/config.py): F/T noise and bias within the sensor's
        # range of an ATI Mini45 (145 N, 5 N m), latencies within 10 control steps (200 ms at
        # 50 Hz: the buffers are that long), tool-frame errors within 20 mm and 10 deg (a
        # calibration gone wrong, not a small error), payload 0.1x-10x the peg
        "randomization.ft_noise_force_N": Range(0.0, 145.0),
        "randomization.ft_noise_torque_Nm": Range(0.0, 5.0),
        "randomization.ft_bias_force_N": Range(0.0, 145.0),
        "randomization.ft_bias_torque_Nm": Range(0.0, 5.0),
        "randomization.ft_drift_force_N_sqrt_s": Range(0.0, 145.0),
        "randomization.ft_drift_torque_Nm_sqrt_s": Range(0.0, 5.0),
        "randomization.obs_latency_steps": Range(
            0, MAX_LATENCY_STEPS, integer=True, why_hi="the longest latency buffer"
        ),
        "randomization.action_latency_steps": Range(
            0, MAX_LATENCY_STEPS, integer=True, why_hi="the longest latency buffer"
        ),
        "randomization.tool_axial_mm": Range(-20.0, 20.0),
        "randomization.tool_lateral_mm": Range(-20.0, 20.0),
        "randomization.tool_tilt_deg": Range(-10.0, 10.0),
        "randomization.payload_mass_scale": Range(0.1, 10.0),
        # a stuck joint's breakaway force: > 0 (0 would release at the first step), up to 1000 N
        # (above the law's axial cap, a weld that never releases); the weld's time constant
        # from 1 ms (MuJoCo raises a solref below 2 x sim_dt to it) to 1 s
        "stuck.breakaway_N": Range(0.0, 1000.0, lo_open=True),
        "stuck.timeconst_s": Range(0.001, 1.0),
    }.items()
}

#: name -> allowed range (names as the user sees them: option or config key)
RANGES: dict[str, Range] = {
    # physics
    "friction": Range(0.0, 2.0),
    "mass_kg": Range(0.0, 100.0, lo_open=True),
    "size_mm": Range(
        MIN_PART_MM, MAX_PART_MM, why_lo=WHY_MIN_PART, why_hi="the limit of the robot's reach"
    ),
    # a user's CAD part (peghole models decompose): its largest extent after --units
    "cad_part_mm": Range(
        MIN_PART_MM, MAX_CAD_PART_MM, why_lo=WHY_MIN_PART, why_hi="the user scene's 2 m floor"
    ),
    "clearance_mm": Range(0.0, 50.0, lo_open=True),
    # a built-in task's diametral clearance (peghole task builtin; geometry/shapes.py): the
    # presets' range (dual-3 0.1 mm to 4x it)
    "builtin_clearance_mm": Range(0.1, 0.4),
    # a task folder's caps (peghole task make): convex pieces per part, vertices per piece,
    # active contacts (geometry/task.py); rollouts that measure the contacts
    "max_hulls": Range(1, 64, integer=True, why_hi="geometry/task.py MAX_HULLS"),
    "max_hull_vertices": Range(4, 64, integer=True, why_hi="geometry/task.py MAX_HULL_VERTICES"),
    "max_contacts": Range(1, 64, integer=True, why_hi="the env's contact buffer, naconmax 64"),
    "contact_worlds": Range(1, 64, integer=True),
    "contact_steps": Range(1, 10_000, integer=True),
    "warn_fraction": Range(0.0, 1.0, lo_open=True),
    "depth_mm": POSITIVE,
    # CoACD (its documented ranges; a threshold outside aborts or never ends)
    "threshold": Range(
        0.01, 1.0, why_lo="CoACD's documented range", why_hi="CoACD's documented range"
    ),
    "resolution": Range(100, 100_000, integer=True),
    "preprocess_resolution": Range(20, 100, integer=True),
    "max_ch_vertex": Range(4, 1024, integer=True, why_lo="a hull needs at least 4 vertices"),
    "max_convex_hull": Range(-1, 10_000, integer=True),  # -1: no cap; 0 is refused below
    "mcts_iterations": Range(1, 10_000, integer=True),
    # the seconds task make lets CoACD run on one part (geometry/coacd_budget.py)
    "coacd_max_s": Range(1.0, 86_400.0, why_hi="a day"),
    # the compliance experiments (experiment compliance | sweep | contact-check): grid values,
    # world counts; the stiffnesses are the iiwa's Cartesian impedance ranges
    "k_rot_Nm_rad": IIWA_K_ROT,
    "k_lat_N_m": IIWA_K_TRANS,
    "beta0_deg": Range(-5.0, 5.0, why_hi="the small-angle regime of the thesis"),
    "theta0_deg": Range(-5.0, 5.0, why_hi="the small-angle regime of the thesis"),
    "delta0_mm": Range(0.0, 10.0, why_hi="a positioning error: 5x the thesis's 2 mm"),
    "speed_mm_s": Range(0.0, 100.0, lo_open=True, why_hi="the thesis's speed limit, 0.1 m/s"),
    "repeats": Range(1, 1000, integer=True, why_hi="each L_C runs this many worlds"),
    "sweep_repeats": Range(
        2, 1000, integer=True, why_lo="intervals need two draws", why_hi="draws per cell"
    ),
    "grid_cells": Range(1, 10_000, integer=True, why_hi="the full grid has 480 cells"),
    "sweep_worlds": Range(1, 1_000_000, integer=True, why_hi="40x the full grid's worlds"),
    "batch_worlds": Range(1, 1 << 16, integer=True),
    "worlds": Range(1, 1 << 16, integer=True),
    # runs
    "seed": SEED,
    "episodes": Range(1, 1_000_000, integer=True),
    "batch": Range(1, 1_000_000, integer=True),
    "success_rate": Range(0.0, 1.0),
    # training hyperparameters (training.config.TrainConfig)
    "num_timesteps": Range(1, 10**12, integer=True),
    "num_envs": Range(1, 1 << 20, integer=True),
    "num_eval_envs": Range(1, 1 << 20, integer=True),
    "eval_every": Range(1, 10**12, integer=True),
    "batch_size": Range(1, 1 << 16, integer=True),
    "grad_updates_per_step": Range(1, 10_000, integer=True),
    "max_replay_size": Range(1, 10**9, integer=True),
    "min_replay_size": Range(0, 10**9, integer=True),
    "learning_rate": Range(0.0, 1.0, lo_open=True),
    "discounting": Range(0.0, 1.0, lo_open=True, hi_open=True),
    "tau": Range(0.0, 1.0, lo_open=True),
    "reward_scaling": Range(0.0, 1e6, lo_open=True),
    "alpha": Range(0.0, 1e6, lo_open=True),
    "alpha_init": Range(0.0, 1e6, lo_open=True),
    "hidden_layer_size": Range(1, 4096, integer=True),
    "steps_per_call": Range(1, 100_000, integer=True),
    "actor_delay_updates": Range(0, 10**9, integer=True),
    # a policy's network (policy.json), checked before anything is allocated
    "observation_size": Range(1, 4096, integer=True),
    "action_size": Range(1, 64, integer=True),
    # the env config (peghole_mjx/envs/config.py), one entry per numeric leaf, named "env." +
    # its flat key; a tuple entry's range holds for each of its numbers. Checked when the env
    # config is built, before any model is built or compiled (envs.config.check_config_values;
    # tests/test_faults_envs.py checks that every numeric leaf has its range here)
    **ENV_RANGES,
}
#: most hidden layers a network may have
MAX_HIDDEN_LAYERS = 8


def check(name: str, value: Any, label: str | None = None, kind: str | None = None):
    """``value`` if it lies in ``RANGES[kind or name]``, else :class:`UserInputError`.

    Integers come back as ``int`` (a whole float such as ``1e6`` is accepted).
    """
    rng = RANGES[kind or name]
    msg = rng.problem(value)
    if msg:
        raise UserInputError(f"{label or name} {msg}")
    if name == "max_convex_hull" and value == 0:
        raise UserInputError(f"{label or name} must be -1 (no cap) or >= 1, got 0")
    return int(value) if rng.integer else float(value)


def arg(kind: str):
    """An argparse ``type`` that parses a number and checks it against ``RANGES[kind]``."""
    rng = RANGES[kind]

    def parse(text: str):
        try:
            value = int(text) if rng.integer else float(text)
        except ValueError:
            try:
                value = float(text)  # "1e6" for an integer option
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"must be {rng.describe()}, got {text!r}"
                ) from None
        msg = rng.problem(value)
        if msg or (kind == "max_convex_hull" and value == 0):
            raise argparse.ArgumentTypeError(msg or "must be -1 (no cap) or >= 1, got 0")
        return int(value) if rng.integer else float(value)

    parse.__name__ = kind  # argparse names the type in its messages
    return parse


def key_value(text: str) -> tuple[str, object]:
    """An argparse ``type``: ``KEY=VALUE``, VALUE as JSON when it parses (``0.5``, ``true``,
    ``[0.8, 1.2]``, a list becoming a tuple), else as a Python literal (``False``, ``None``,
    ``(0.8, 1.2)``), else the text itself. The one parser of every ``--set``."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        try:
            parsed = ast.literal_eval(value)
        except (ValueError, SyntaxError, MemoryError, RecursionError):
            parsed = value
    if isinstance(parsed, list):
        parsed = tuple(parsed)
    return key.strip(), parsed


def finite_float(text: str) -> float:
    """An argparse ``type``: any finite float (NaN and infinity refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def check_finite_tree(tree: Any, where: str) -> None:
    """Every number in a nested dict/list/tuple is finite (names the first that is not)."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            check_finite_tree(v, f"{where}.{k}" if where else str(k))
    elif isinstance(tree, list | tuple):
        for i, v in enumerate(tree):
            check_finite_tree(v, f"{where}[{i}]")
    elif isinstance(tree, float) and not math.isfinite(tree):
        raise UserInputError(f"{where} must be a finite number, got {tree!r}")


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by ``None`` (JSON ``null``); numpy
    scalars and arrays become Python numbers and lists."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, str):  # numpy / jax values
        return json_safe(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps(obj: Any, **kw) -> str:
    """Strict JSON (``allow_nan=False``) of ``json_safe(obj)``."""
    return json.dumps(json_safe(obj), allow_nan=False, **kw)


def loads(text: str) -> Any:
    """Parse strict JSON: a bare ``NaN`` or ``Infinity`` (not JSON) raises ValueError."""

    def bare(name: str):
        raise ValueError(f"not JSON: bare {name}")

    depth = _max_nesting(text)
    if depth > MAX_JSON_DEPTH:
        raise ValueError(f"JSON nested {depth} deep (at most {MAX_JSON_DEPTH} read)")
    return json.loads(text, parse_constant=bare)


def load_json_object(path, bad) -> dict:
    """The JSON object in file ``path`` (strict: :func:`loads`), else ``bad(why)`` raised,
    ``bad`` building the caller's one-line error (which names the file and what to do)."""
    try:
        doc = loads(Path(path).read_text())
    except UnicodeDecodeError:
        raise bad("not text") from None
    except ValueError as exc:
        raise bad(f"not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        kind = {list: "list", str: "string"}.get(type(doc), type(doc).__name__)
        raise bad(f"a JSON object expected; got a JSON {kind}, not an object")
    return doc


#: deepest nesting of JSON read back (peghole's own files nest fewer than 10 levels); deeper
#: input would exhaust Python's recursion, so it is refused before parsing
MAX_JSON_DEPTH = 64


def _max_nesting(text: str) -> int:
    """Deepest ``[``/``{`` nesting of ``text``, outside strings (a linear scan, no recursion)."""
    depth = deepest = 0
    for tok in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', text):
        t = tok.group()
        if t in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif t in "]}":
            depth -= 1
    return deepest


#: the smallest force a reduction is computed from (decided 2026-12-04): below it a force is
#: contact noise (float32 MuJoCo/MJX, a frictionless oracle's 0 N), and a percentage of it
#: (-390 % of 0.0004 N) says nothing; such a reduction is "not resolved" (None, JSON null)
FORCE_FLOOR_N = 0.01


def reduction_pct(reduced: Any, reference: Any, floor_N: float = FORCE_FLOOR_N) -> float | None:
    """``100 (1 - reduced / reference)`` of two forces (N; arrays: their means), or None (not
    resolved) when either is below ``floor_N`` or not finite: a percentage of a force the
    simulation does not resolve is not reported."""
    a, b = float(_mean(reduced)), float(_mean(reference))
    if not (math.isfinite(a) and math.isfinite(b)) or min(abs(a), abs(b)) < floor_N:
        return None
    return 100.0 * (1.0 - a / b)


def _mean(x: Any) -> float:
    """The mean of a number or a (nested) sequence or array of numbers; NaN for none."""
    if hasattr(x, "mean") and hasattr(x, "size"):
        return float(x.mean()) if x.size else math.nan
    if isinstance(x, list | tuple):
        flat = [float(v) for v in x]
        return sum(flat) / len(flat) if flat else math.nan
    return float(x)
