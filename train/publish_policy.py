"""Publish a finished training run as a pretrained policy inside the package.

    python train/publish_policy.py RUN_DIR rect --episodes 256

copies ``RUN_DIR/final_policy`` into ``peghole_mjx/policies/<name>_extract/`` with the run's
``metrics.csv``, ``curves.png`` and ``summary.json``, evaluates it against the scripted
baseline (``evaluation.json``, the same as ``peghole evaluate <name> --episodes N --json``)
and writes ``benchmarks/results/train_<name>_cpu.json`` (or ``_gpu``) for the benchmark
tables.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("name", choices=("rect", "dual"))
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from peghole_mjx.policies import PRETRAINED
    from peghole_mjx.training.evaluate import evaluate

    dest = PRETRAINED[args.name]
    dest.mkdir(parents=True, exist_ok=True)
    for f in ("policy.json", "params.npz"):
        shutil.copy2(args.run / "final_policy" / f, dest / f)
    for f in ("metrics.csv", "curves.png", "summary.json"):
        if (args.run / f).exists():
            shutil.copy2(args.run / f, dest / f)
    res = evaluate(args.name, args.episodes, seed=args.seed)
    (dest / "evaluation.json").write_text(json.dumps(res, indent=2) + "\n")

    summary = json.loads((args.run / "summary.json").read_text())
    rows = (args.run / "metrics.csv").read_text().splitlines()
    kind = "cpu" if summary["device"].startswith("cpu") else "gpu"
    bench = {
        "env": summary["env"],
        "time_to_success_s": summary["time_to_95pct_success_s"],
        "success_threshold": 0.95,
        "final_success_rate": summary["final_eval"].get("success_rate"),
        "train_wall_s": summary["wall_s"],
        "env_steps": summary["env_steps"],
        "evaluation": {
            k: res[k] for k in ("policy", "baseline", "force_reduction_pct", "episodes")
        },
        "metrics_rows": len(rows) - 1,
        "device": summary["device"],
        "versions": summary["versions"],
        "date": summary["date"],
        "note": "wall clock includes JIT compilation and evaluations; CPU runs shared the 2 cores "
        "with other jobs",
    }
    out = ROOT / "benchmarks" / "results" / f"train_{args.name}_{kind}.json"
    out.write_text(json.dumps(bench, indent=2) + "\n")
    print(dest, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
