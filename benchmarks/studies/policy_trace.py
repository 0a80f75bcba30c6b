"""Why a policy's episodes end as they do: its control internals at each episode's end.

A published policy (``peghole_mjx.policies``) is run deterministically, as trained (its own
env config), on ``--episodes`` randomised episodes (the same start states as ``peghole
evaluate`` with the same seed). For each episode the trace keeps what the policy commanded
up to the step the episode ended: the accumulated feed-forward force (lateral |F_x|, |F_y|
and axial F_z, hole frame; + z pulls out), how far the commanded tip has moved sideways from
its start, the compliance-strategy gains (mean k_xy and K_theta), the mean pull command, and
the measured contact forces. Episodes are grouped by outcome (``success`` or the failure
cause of ``benchmarks.evals.hard_variants.failure_causes``), and jams are counted by whether the
lateral feed-forward was at its bound (``action.max_ff_xy_N``) when the jam ended the
episode, i.e. whether the policy pressed the peg into the wall itself.

Writes ``benchmarks/results/studies/policy_trace_<policy>_<device>.json`` (device, versions,
date)::

    python -m benchmarks.studies.policy_trace --policy rect_hard --episodes 32
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import STUDIES_RESULTS, cpu_label, out_file
from benchmarks.evals.hard_variants import failure_causes
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.rollout import episode_keys
from peghole_mjx.files.provenance import run_provenance
from peghole_mjx.policies import load_policy

#: the per-step quantities traced (all per world); ``ff`` is the accumulated feed-forward
#: force (N, hole frame), ``offset_mm`` the commanded tip's lateral distance from its start
TRACED = ("done", "fxy_N", "fz_N", "k_xy", "k_rot", "ff", "offset_mm", "pull", "depth_mm")
#: a feed-forward component within this fraction of its bound counts as at the bound
AT_BOUND = 0.99


def trace(bundle, env, episodes: int, seed: int, chunk: int = 25, progress: bool = True):
    """``(per_step, ended)``: per-step arrays ``(steps, episodes[, 3])`` of :data:`TRACED`
    up to the longest episode, and the env metrics at each episode's end (keys of
    ``State.metrics``). The start states are those of ``rollout(..., seed=seed)``
    (:func:`peghole_mjx.envs.rollout.episode_keys`)."""
    policy = bundle.policy_fn()
    rng, reset_keys = episode_keys(seed, episodes)
    states = jax.jit(jax.vmap(env.reset))(reset_keys)
    start = states.info["cmd_tip"]
    pull_index = 2  # the action's dz entry (extraction.decode_action)

    def one_step(carry, _):
        s, ended, finished, rng = carry
        rng, k = jax.random.split(rng)
        a = jax.vmap(policy, in_axes=(None, 0, 0))(
            bundle.params, s.obs, jax.random.split(k, episodes)
        )
        n = jax.vmap(env.step)(s, a)
        done_now = (n.done > 0) & ~finished
        ended = {m: jnp.where(done_now, n.metrics[m], ended[m]) for m in ended}
        rec = {
            "done": n.done > 0,
            "fxy_N": n.metrics["fxy_N"],
            "fz_N": n.metrics["fz_N"],
            "k_xy": n.info["k_xy"],
            "k_rot": n.info["k_rot"],
            "ff": n.info["wrench_ff"],
            "offset_mm": 1e3 * jnp.linalg.norm((n.info["cmd_tip"] - start)[:, :2], axis=-1),
            "pull": n.info["prev_action"][:, pull_index],  # the action as applied
            "depth_mm": n.metrics["depth_mm"],
        }
        return (n, ended, finished | done_now, rng), rec

    @jax.jit
    def run(s, ended, finished, rng):
        return jax.lax.scan(one_step, (s, ended, finished, rng), None, length=chunk)

    ended = {m: jnp.zeros(episodes) for m in states.metrics}
    finished = jnp.zeros(episodes, bool)
    carry, recs = (states, ended, finished, rng), []
    n_chunks = -(-env.config.episode_length // chunk)
    bar = tqdm(
        total=n_chunks * chunk, unit="step", desc="trace", file=sys.stderr, disable=not progress
    )
    for _ in range(n_chunks):
        carry, rec = run(*carry)
        recs.append(jax.tree.map(np.asarray, rec))
        bar.update(chunk)
        if bool(carry[2].all()):
            break
    bar.close()
    per_step = {k: np.concatenate([r[k] for r in recs]) for k in TRACED}
    return per_step, {k: np.asarray(v) for k, v in carry[1].items()}


def episode_rows(per_step, ended, ff_bound_xy: float, ctrl_dt: float) -> list[dict]:
    """One row per episode: outcome and the policy's commands up to its last step."""
    cause = failure_causes(ended)
    done = per_step["done"]
    rows = []
    for i in range(len(cause)):
        # the step the episode ended: its first done
        last = int(np.argmax(done[:, i])) if done[:, i].any() else done.shape[0] - 1
        ff = per_step["ff"][: last + 1, i]
        rows.append(
            {
                "episode": i,
                "outcome": str(cause[i]),
                "end_s": round((last + 1) * ctrl_dt, 2),
                "depth_end_mm": round(float(per_step["depth_mm"][last, i]), 2),
                "fxy_end_N": round(float(per_step["fxy_N"][last, i]), 2),
                "ff_xy_end_N": [round(float(v), 2) for v in ff[-1, :2]],
                "ff_xy_at_bound_end": bool(np.abs(ff[-1, :2]).max() >= AT_BOUND * ff_bound_xy),
                "ff_xy_max_N": round(float(np.abs(ff[:, :2]).max()), 2),
                "ff_z_end_N": round(float(ff[-1, 2]), 2),
                "offset_end_mm": round(float(per_step["offset_mm"][last, i]), 2),
                "mean_k_xy_N_m": round(float(per_step["k_xy"][: last + 1, i].mean()), 1),
                "mean_k_rot_Nm_rad": round(float(per_step["k_rot"][: last + 1, i].mean()), 1),
                "mean_pull": round(float(per_step["pull"][: last + 1, i].mean()), 3),
                "mean_fz_N": round(float(per_step["fz_N"][: last + 1, i].mean()), 2),
            }
        )
    return rows


def summarise(rows: list[dict]) -> dict:
    """Per outcome: count and means of the traced quantities; jams at the feed-forward bound."""
    out = {}
    for outcome in dict.fromkeys(r["outcome"] for r in rows):
        group = [r for r in rows if r["outcome"] == outcome]
        out[outcome] = {
            "n": len(group),
            "ff_xy_at_bound_end": sum(r["ff_xy_at_bound_end"] for r in group),
            **{
                k: round(float(np.mean([r[k] for r in group])), 2)
                for k in (
                    "end_s",
                    "fxy_end_N",
                    "ff_z_end_N",
                    "offset_end_mm",
                    "mean_k_xy_N_m",
                    "mean_k_rot_Nm_rad",
                    "mean_pull",
                    "mean_fz_N",
                )
            },
        }
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policy", required=True, help="a committed policy name or folder")
    p.add_argument("--episodes", type=int, default=32)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    p.add_argument(
        "--out",
        type=out_file,
        help="default: benchmarks/results/studies/policy_trace_<policy>_<device>.json",
    )
    args = p.parse_args(argv)
    try:
        if args.episodes < 1:
            raise UserInputError(f"--episodes must be >= 1, got {args.episodes}")
        bundle = load_policy(args.policy)
    except UserInputError as e:
        print(f"policy_trace: error: {e}", file=sys.stderr)
        return 2
    env = bundle.make_env(bundle.trained_engine())  # the engine the policy was trained on
    t0 = time.perf_counter()
    per_step, ended = trace(bundle, env, args.episodes, args.seed, progress=not args.no_progress)
    c = env.config
    rows = episode_rows(per_step, ended, c.action.max_ff_xy_N, c.ctrl_dt)
    result = {
        "benchmark": "policy_trace",
        "policy": str(args.policy),
        "policy_path": str(bundle.path),
        "env": bundle.env_name,
        "env_overrides": bundle.env_overrides,
        "ff_bound_xy_N": c.action.max_ff_xy_N,
        "jam_rule": {"jam_force_N": c.jam_force_N, "jam_time_s": c.jam_time_s},
        "episodes": args.episodes,
        "seed": args.seed,
        "config": "see policy, env_overrides, episodes, seed",
        **run_provenance(
            ["python", "-m", "benchmarks.studies.policy_trace", *(argv or sys.argv[1:])]
        ),
        "wall_s": round(time.perf_counter() - t0, 1),
        "by_outcome": summarise(rows),
        "rows": rows,
    }
    print(json.dumps(result["by_outcome"], indent=1))
    name = Path(str(args.policy)).name
    out = args.out or STUDIES_RESULTS / f"policy_trace_{name}_{cpu_label()}.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
