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
import math
from dataclasses import dataclass
from typing import Any

# (UserInputError is imported where raised: peghole_mjx.errors imports the geometry specs,
# which read RANGES while this module may still be loading)

#: the largest peg-hole dimension (mm) the iiwa 14 scene holds within the robot's reach: its
#: inverse kinematics reaches the inserted pose of a 700 mm peg, not of an 800 mm one
MAX_PART_MM = 700.0


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


def _num(x: float | None) -> str:
    if x is not None and x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return f"{x:g}"


POSITIVE = Range(0.0, lo_open=True)
SEED = Range(0, 2**32 - 1, integer=True)

#: name -> allowed range (names as the user sees them: option or config key)
RANGES: dict[str, Range] = {
    # physics
    "friction": Range(0.0, 2.0),
    "mass_kg": Range(0.0, 100.0, lo_open=True),
    "size_mm": Range(0.0, MAX_PART_MM, lo_open=True, why_hi="the limit of the robot's reach"),
    "clearance_mm": Range(0.0, 50.0, lo_open=True),
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
    # a policy's network (policy.json), checked before anything is allocated
    "observation_size": Range(1, 4096, integer=True),
    "action_size": Range(1, 64, integer=True),
}
#: most hidden layers a network may have
MAX_HIDDEN_LAYERS = 8


def check(name: str, value: Any, label: str | None = None, kind: str | None = None):
    """``value`` if it lies in ``RANGES[kind or name]``, else :class:`UserInputError`.

    Integers come back as ``int`` (a whole float such as ``1e6`` is accepted).
    """
    from peghole_mjx.errors import UserInputError

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
    from peghole_mjx.errors import UserInputError

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
    import json

    return json.dumps(json_safe(obj), allow_nan=False, **kw)


def loads(text: str) -> Any:
    """Parse strict JSON: a bare ``NaN`` or ``Infinity`` (not JSON) raises ValueError."""
    import json

    def bare(name: str):
        raise ValueError(f"not JSON: bare {name}")

    return json.loads(text, parse_constant=bare)
