"""The env's metrics and episode statistics: declared once, read by every consumer.

* :data:`ENV_METRICS`: the keys of ``State.metrics`` at every step (the named reward terms,
  the episode quantities, the per-step readings).
* :data:`EPISODE_METRICS` + :data:`RETURN_KEYS`: what a finished episode is described by (the
  rollout's per-episode record; the training loop's finished episodes).
* :data:`STATS`: the statistics over episodes, in the column order of ``metrics.csv``;
  :func:`summarize` computes them from per-episode arrays (evaluation, ``RolloutSummary``),
  :func:`episode_totals` + :func:`summarize_totals` from running sums (training episodes,
  summed inside the jitted step).
* :func:`accumulate_return`: the undiscounted and discounted return of running episodes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

#: the named reward terms of both reward kinds (:func:`peghole_mjx.envs.reward.reward_terms`,
#: :func:`~peghole_mjx.envs.reward.outcome_terms`; a term a kind lacks is 0), logged as
#: reward/<term>
REWARD_TERMS = (
    "progress",
    "force",
    "stiffness",
    "rot_stiffness",
    "extraction_force",
    "end",
    "time",
)
#: how an episode ended and its force statistics (their values at the step where done = 1)
EPISODE_METRICS = (
    "success",  # 1 when the tip is success_margin_mm above the mouth
    "failure",  # 1 on jamming, NaN, contact overflow or the time limit
    "jammed",
    "nan",  # the world went NaN (or the action was NaN)
    "overflow",  # MuJoCo Warp dropped contacts (impl="warp" only)
    "extraction_time_s",  # on success; 0 otherwise
    "mean_fz_N",  # mean |F_z| over the episode's steps so far
    "peak_fz_N",
    "mean_fxy_N",
)
#: readings of the current step
STEP_METRICS = ("fz_N", "fxy_N", "depth_mm", "k_xy_N_m", "k_rot_Nm_rad")
ENV_METRICS = (*(f"reward/{t}" for t in REWARD_TERMS), *EPISODE_METRICS, *STEP_METRICS)
#: a stuck joint's entries (envs/stuck.py), in ``State.metrics`` and in the per-episode record
#: only with the env config's ``stuck.enabled``: 1 once the weld has released, the time of the
#: release from the episode start (s, 0 while it holds) and the episode's breakaway force (N)
STUCK_METRICS = ("released", "release_time_s", "breakaway_N")
#: undiscounted return and sum_i gamma^i r_i (eq 4.1 with E9's exponent) of an episode
RETURN_KEYS = ("return", "discounted_return")
#: what describes a finished episode
EPISODE_RECORD = (*EPISODE_METRICS, *RETURN_KEYS)


def zero_metrics(stuck: bool = False) -> dict[str, jax.Array]:
    """``State.metrics`` of a reset state (with ``stuck``: also :data:`STUCK_METRICS`)."""
    return {n: jnp.zeros(()) for n in (*ENV_METRICS, *(STUCK_METRICS if stuck else ()))}


def record_keys(metrics: Mapping) -> tuple[str, ...]:
    """The per-episode record's keys for an env whose ``State.metrics`` is ``metrics``:
    :data:`EPISODE_RECORD`, and :data:`STUCK_METRICS` where the env has a stuck joint."""
    return EPISODE_RECORD + (STUCK_METRICS if STUCK_METRICS[0] in metrics else ())


def zero_returns(shape=()) -> dict[str, jax.Array]:
    """Return accumulators of episodes that have not started (``gamma_t`` = gamma^t)."""
    return {
        "return": jnp.zeros(shape),
        "discounted_return": jnp.zeros(shape),
        "gamma_t": jnp.ones(shape),
    }


def accumulate_return(acc: Mapping[str, jax.Array], reward: jax.Array, gamma: float):
    """The accumulators after one more reward (the one function both rollouts and training use)."""
    return {
        "return": acc["return"] + reward,
        "discounted_return": acc["discounted_return"] + acc["gamma_t"] * reward,
        "gamma_t": acc["gamma_t"] * gamma,
    }


@dataclass(frozen=True)
class Stat:
    """A statistic over finished episodes.

    ``of``: the per-episode record entry; ``kind``: ``"episodes"`` (how many), ``"rate"`` (the
    fraction with ``of`` > 0), ``"count"`` (how many with ``of`` > 0), ``"mean"``,
    ``"mean_of_successes"`` (mean over the successful episodes). ``logged``: a column of
    ``metrics.csv`` for evaluations (``eval/<name>``); ``train``: also for training episodes
    (``train/<name>``).
    """

    name: str
    of: str
    kind: str
    logged: bool = True
    train: bool = True


#: in the column order of metrics.csv
STATS = (
    Stat("episodes", "success", "episodes"),
    Stat("success_rate", "success", "rate"),
    Stat("mean_time_s", "extraction_time_s", "mean_of_successes"),  # extraction time
    Stat("mean_fz_N", "mean_fz_N", "mean"),  # mean over episodes of the per-episode mean |F_z|
    Stat("peak_fz_N", "peak_fz_N", "mean"),  # mean over episodes of the per-episode peak |F_z|
    Stat("mean_fxy_N", "mean_fxy_N", "mean"),  # ... of the per-episode mean |F_xy|
    Stat("mean_return", "return", "mean"),
    Stat("mean_discounted_return", "discounted_return", "mean"),
    Stat("nan_worlds", "nan", "count"),
    Stat("jammed", "jammed", "count", train=False),
    Stat("overflow_worlds", "overflow", "count", logged=False, train=False),
    # failures that are neither jamming, NaN nor overflow: the time limit
    Stat("timeouts", "timeout", "count", logged=False, train=False),
)
#: statistics logged for evaluations / for training episodes (metrics.csv, TensorBoard)
EVAL_STATS = tuple(s.name for s in STATS if s.logged)
TRAIN_STATS = tuple(s.name for s in STATS if s.train)


def _per_episode(e: Mapping, of: str):
    if of == "timeout":
        xp = jnp if isinstance(e["failure"], jax.Array) else np
        return xp.asarray(
            (e["failure"] > 0) & (e["jammed"] == 0) & (e["nan"] == 0) & (e["overflow"] == 0),
            e["failure"].dtype,
        )
    return e[of]


def summarize(e: Mapping[str, np.ndarray]) -> dict[str, float | int]:
    """Every :data:`STATS` entry from per-episode arrays (keys :data:`EPISODE_RECORD`)."""
    ok = np.asarray(e["success"]) > 0
    out: dict[str, float | int] = {}
    for s in STATS:
        v = np.asarray(_per_episode(e, s.of))
        if s.kind == "episodes":
            out[s.name] = len(v)
        elif s.kind == "rate":
            out[s.name] = float((v > 0).mean())
        elif s.kind == "count":
            out[s.name] = int((v > 0).sum())
        elif s.kind == "mean":
            out[s.name] = float(v.mean())
        else:  # mean_of_successes
            out[s.name] = float(v[ok].mean()) if ok.any() else float("nan")
    return out


def stuck_summary(e: Mapping[str, np.ndarray]) -> dict[str, float | int] | None:
    """A stuck joint's statistics from per-episode arrays (None without one): episodes whose
    weld released, their share, their mean release time (s; NaN when none released) and the
    mean breakaway force of all episodes (N)."""
    if STUCK_METRICS[0] not in e:
        return None
    rel = np.asarray(e["released"]) > 0
    t = np.asarray(e["release_time_s"])
    return {
        "released": int(rel.sum()),
        "release_rate": float(rel.mean()),
        "mean_release_time_s": float(t[rel].mean()) if rel.any() else float("nan"),
        "mean_breakaway_N": float(np.mean(e["breakaway_N"])),
    }


#: the sums :func:`episode_totals` returns (``episodes`` and the per-episode entries summed)
TOTAL_KEYS = ("episodes", *dict.fromkeys(s.of for s in STATS if s.train and s.kind != "episodes"))


def episode_totals(ended: Mapping[str, jax.Array], done: jax.Array) -> dict[str, jax.Array]:
    """Sums over the episodes that end now (``done``) of what :data:`TRAIN_STATS` need (jit)."""
    totals = {"episodes": done.sum()}
    for s in STATS:
        if s.train and s.kind != "episodes":
            v = _per_episode(ended, s.of)
            if s.kind in ("rate", "count"):
                v = (v > 0).astype(jnp.float32)
            totals[s.of] = jnp.where(done, v, 0.0).sum()
    return totals


def summarize_totals(t: Mapping[str, float]) -> dict[str, float | int]:
    """:data:`TRAIN_STATS` from the sums of :func:`episode_totals` (nothing but ``episodes``
    when no episode ended; no ``mean_time_s`` when none succeeded)."""
    n = t["episodes"]
    if n == 0:
        return {"episodes": 0}
    out: dict[str, float | int] = {}
    for s in STATS:
        if not s.train:
            continue
        if s.kind == "episodes":
            out[s.name] = int(n)
        elif s.kind == "count":
            out[s.name] = int(t[s.of])
        elif s.kind == "mean_of_successes":
            if t["success"] > 0:
                out[s.name] = t[s.of] / t["success"]
        else:  # rate, mean
            out[s.name] = t[s.of] / n
    return out
