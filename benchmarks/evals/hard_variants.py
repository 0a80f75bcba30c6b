"""How often the scripted Ch 2-3 method fails in an env: failure rate by cause.

The scripted baseline (``peghole_mjx.envs.rollout.scripted_policy``: fixed compliance with the
compliance centre at the tip, straight pull at 20 mm/s) is rolled out on ``--episodes``
randomised episodes of one registered env (by default the hard variants ``RectExtractHard``
and ``DualExtractHard``, docs/index.md "Hard variants"). Each episode ends in success or in
one failure cause: ``jam`` (the env's jamming rule: lateral contact force above
``jam_force_N`` = 0.9 x 20 N, E11's lateral force limit, for ``jam_time_s``), ``timeout``
(``episode_length`` reached), ``nan`` or ``overflow`` (MuJoCo Warp only).

``--alt KEY=VALUE ...``: the same episodes (same seed, the first ``--alt-episodes`` of them)
are rolled out again with the fixed method's settings changed (e.g. a lower K_theta); the
result counts how many of the fixed method's failures the changed method extracts, the
check that a failure is jamming of the fixed method, not an episode no controller can solve.

Writes ``benchmarks/results/evals/hard_variants_<env>_<device>.json`` (device, versions, date,
episodes, seed, success rate with its Wilson 95 % interval, counts by cause, mean and peak
|F_z|). Slices of ``--batch`` episodes are saved under ``--parts`` as they finish, so an
interrupted run continues where it stopped::

    python -m benchmarks.evals.hard_variants --env RectExtractHard --episodes 256
    python -m benchmarks.evals.hard_variants --env DualExtractHard --episodes 256 \\
        --alt stiffness.k_rot_Nm_rad=30 --alt-episodes 64
    # explore a lever on a default env
    python -m benchmarks.evals.hard_variants --env RectExtract --episodes 64 --out /tmp/x.json \\
        --set randomization.angular_error_deg=0.9
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import EVALS_RESULTS, cpu_label, out_file, parse_overrides, wilson
from peghole_mjx import envs
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.files.provenance import provenance

CAUSES = ("jam", "timeout", "nan", "overflow")


def failure_causes(ep: dict[str, np.ndarray]) -> np.ndarray:
    """Per episode: ``success`` or its failure cause (nan and overflow before jam, then
    timeout; the env flags jamming only while the peg is not out)."""
    out = np.full(len(ep["success"]), "timeout", dtype=object)
    out[ep["jammed"] > 0] = "jam"
    out[ep["overflow"] > 0] = "overflow"
    out[ep["nan"] > 0] = "nan"
    out[ep["success"] > 0] = "success"
    return out


def summarise(ep: dict[str, np.ndarray]) -> dict:
    """Success rate (Wilson 95 %), counts by cause, mean and peak |F_z| (N)."""
    cause = failure_causes(ep)
    n, k = len(cause), int((cause == "success").sum())
    return {
        "episodes": n,
        "success_rate": round(k / n, 4),
        "success_ci95": wilson(k, n),
        "failure_rate": round(1 - k / n, 4),
        "failure_ci95": [round(1 - w, 4) for w in wilson(k, n)[::-1]],
        "failures_by_cause": {c: int((cause == c).sum()) for c in CAUSES},
        "mean_fz_N": round(float(ep["mean_fz_N"].mean()), 4),
        "peak_fz_N": round(float(ep["peak_fz_N"].mean()), 4),  # mean of per-episode peaks
        "max_peak_fz_N": round(float(ep["peak_fz_N"].max()), 4),
        "mean_fxy_N": round(float(ep["mean_fxy_N"].mean()), 4),
        # per outcome: how many, mean of the per-episode mean and peak |F_z|; a wedged peg
        # holds |F_z| at the controller's 60 N axial force limit
        "fz_by_outcome_N": {
            c: {
                "n": int((cause == c).sum()),
                "mean_fz": round(float(ep["mean_fz_N"][cause == c].mean()), 3),
                "peak_fz": round(float(ep["peak_fz_N"][cause == c].mean()), 3),
                "min_peak_fz": round(float(ep["peak_fz_N"][cause == c].min()), 3),
            }
            for c in ("success", *CAUSES)
            if (cause == c).any()
        },
        "mean_time_s": (
            round(float(ep["extraction_time_s"][cause == "success"].mean()), 3) if k else None
        ),
    }


def run(name, overrides, episodes, seed, batch, parts_root, progress=True):
    """The scripted rollout of env ``name`` with ``overrides``: (env, per-episode arrays, s)."""
    # MJX pinned: the engine of the committed results and of their slices' keys (the env
    # default became auto, 2026-12-05)
    env = envs.load(name, config_overrides={"engine": "mjx", **(overrides or {})})
    # slices are keyed to the env's whole config (not its name: a changed hard_config must
    # not reuse the old slices), the seed and the batch
    key = [name, env.config.to_dict(), seed, batch]
    tag = hashlib.sha1(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:10]
    parts = parts_root / f"{name}_{tag}" if parts_root is not None else None
    t0 = time.perf_counter()
    res = rollout(
        env,
        scripted_policy(env),
        episodes,
        seed=seed,
        batch=batch,
        parts_dir=parts,
        progress=progress,
    )
    return env, res.per_episode, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", default="RectExtractHard", help="a registered env name")
    p.add_argument("--episodes", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--batch", type=int, default=64, help="worlds at once (one compiled shape)")
    p.add_argument("--set", nargs="*", metavar="KEY=VALUE", help="env config overrides")
    p.add_argument("--alt", nargs="*", metavar="KEY=VALUE", help="the changed method's overrides")
    p.add_argument("--alt-episodes", type=int, default=32)
    p.add_argument(
        "--parts",
        type=Path,
        default=Path(os.environ.get("TMPDIR", "/tmp")) / "peghole_hard_variants",
        help="folder of the finished slices (resume)",
    )
    p.add_argument(
        "--out",
        type=out_file,
        help="default: benchmarks/results/evals/hard_variants_<env>_<device>.json",
    )
    args = p.parse_args(argv)
    if args.episodes < 1 or args.batch < 1:
        raise SystemExit("--episodes and --batch must be >= 1")
    overrides = parse_overrides(args.set)
    env, ep, wall = run(args.env, overrides, args.episodes, args.seed, args.batch, args.parts)
    c = env.config
    result = {
        "benchmark": "hard_variants",
        "env": args.env,
        "overrides": overrides,
        "preset": c.preset,
        "representation": env.representation,
        "method": "scripted (fixed compliance at the tip, straight pull at 20 mm/s)",
        "fixed_compliance": {
            "k_xy_N_m": c.stiffness.k_xy_N_m,
            "k_rot_Nm_rad": c.stiffness.k_rot_Nm_rad,
            "compliance_centre_mm": c.stiffness.compliance_centre_mm,
        },
        "randomization": c.randomization.to_dict(),
        "jam_rule": {"jam_force_N": c.jam_force_N, "jam_time_s": c.jam_time_s},
        "episode_length_s": c.episode_length * c.ctrl_dt,
        "seed": args.seed,
        "batch": args.batch,
        **provenance(),
        "wall_s": round(wall, 1),
        **summarise(ep),
    }
    print(json.dumps({k: result[k] for k in ("env", "overrides", "episodes")}), flush=True)
    print(json.dumps({k: v for k, v in summarise(ep).items()}), flush=True)
    if args.alt:
        alt = {**overrides, **parse_overrides(args.alt)}
        n = min(args.alt_episodes, args.episodes)
        _, ep_alt, _ = run(args.env, alt, n, args.seed, min(args.batch, n), args.parts)
        fixed_fail = failure_causes({k: v[:n] for k, v in ep.items()}) != "success"
        alt_ok = ep_alt["success"] > 0
        result["alternative"] = {
            "overrides": parse_overrides(args.alt),
            "episodes": n,
            **summarise(ep_alt),
            "fixed_failures": int(fixed_fail.sum()),
            "fixed_failures_extracted": int((fixed_fail & alt_ok).sum()),
            "fixed_successes_failed": int((~fixed_fail & ~alt_ok).sum()),
        }
        print(json.dumps(result["alternative"]), flush=True)
    out = args.out or EVALS_RESULTS / f"hard_variants_{args.env}_{cpu_label()}.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
