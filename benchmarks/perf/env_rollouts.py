"""Batched rollouts of both environments with the scripted baseline and the random policy
(the row's ``episodes`` says how many).

Writes ``benchmarks/results/perf/env_rollouts.json`` (device, versions, date, per env and
policy the keys of ``peghole envs rollout --json`` plus compile time and steps/s). Run:
``python -m benchmarks.perf.env_rollouts [--episodes 64]``. Each row names the env's collision
representation; rows without one (before 2026-11-29) were measured on the dual mesh scene, then
the only one.
"""

from __future__ import annotations

import argparse
import json

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import PERF_RESULTS, out_file, table
from peghole_mjx import envs
from peghole_mjx.envs.cli import make_policy
from peghole_mjx.envs.rollout import rollout
from peghole_mjx.files.provenance import provenance

OUT = PERF_RESULTS / "env_rollouts.json"


@table("env_rollouts")
def env_rollouts_table() -> str:
    """The committed rollouts, one row per env and policy."""
    data = json.loads(OUT.read_text())
    lines = [
        f"Device: {data['device']}; {data['date']}.",
        "",
        "| env | preset | policy | episodes | success | mean time s | mean F_z N | peak F_z N | "
        "mean F_xy N | jammed | NaN worlds | compile s | env steps/s | physics steps/s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        lines.append(
            f"| {r['env']} | {r['preset']} | {r['policy']} | {r['episodes']} | "
            f"{r['success_rate']:.3f} | "
            f"{r['mean_time_s']:.2f} | {r['mean_fz_N']:.2f} | {r['peak_fz_N']:.2f} | "
            f"{r['mean_fxy_N']:.2f} | {r['jammed']} | {r['nan_worlds']} | {r['compile_s']} | "
            f"{r['env_steps_per_s']} | {r['physics_steps_per_s']} |"
        )
    return "\n".join(lines)


def main() -> None:
    """Run the rollouts and write ``--out``."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=64)
    ap.add_argument(
        "--random-episodes",
        type=int,
        default=16,
        help="episodes of the random policy (it runs to the time limit: costly)",
    )
    ap.add_argument("--out", type=out_file, default=OUT)
    args = ap.parse_args()
    rows = []
    for name in envs.ALL_ENVS:
        env = envs.load(name, config_overrides={"engine": "mjx"})  # the engine recorded
        for policy in ("scripted", "random"):
            n = args.episodes if policy == "scripted" else args.random_episodes
            res = rollout(env, make_policy(env, policy), n, seed=0)
            row = {
                "env": name,
                "preset": env.config.preset,
                "representation": env.representation,
                "policy": policy,
                **res.summary().as_dict(),
                "compile_s": round(res.compile_s, 1),
                "env_steps_per_s": round(res.env_steps_per_s, 1),
                "physics_steps_per_s": round(res.physics_steps_per_s, 1),
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
    args.out.write_text(
        json.dumps({**provenance(), "episodes": args.episodes, "rows": rows}, indent=2) + "\n"
    )


if __name__ == "__main__":
    main()
