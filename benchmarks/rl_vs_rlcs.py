"""RL vs RL + compliance strategy: the comparison of the thesis's Fig 4.5 (claim C4.1).

Reads two finished (or stopped) training runs of the same env, one trained with
``--compliance-strategy on`` and one with ``off`` (same profile and seed), and writes

* ``benchmarks/results/rl_vs_rlcs_<env>[_<tag>]_<device>.json``: every evaluation of both runs
  (success, mean/peak |F_z|, mean |F_xy|, discounted return), the training-episode force
  statistics over the run, and the verdict on C4.1 ("RL + CS gives lower, steadier F_z over
  training than RL without it");
* ``benchmarks/results/rl_vs_rlcs_<env>[_<tag>]_<device>.png``: the learning curves of both runs
  (Figs 4.5-4.7 panels, :func:`peghole_mjx.training.plots.plot_curves`).

Usage::

    peghole train --env RectExtract --compliance-strategy on  --profile cpu --out runs/rect_cs
    peghole train --env RectExtract --compliance-strategy off --profile cpu --out runs/rect_nocs
    python -m benchmarks.rl_vs_rlcs --cs runs/rect_cs --no-cs runs/rect_nocs
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.bench_common import RESULTS, device_label, utc_now, versions_dict
from peghole_mjx.errors import UserInputError
from peghole_mjx.training.plots import read_metrics

#: evaluation columns of metrics.csv copied into the result (without the ``eval/`` prefix)
EVAL_KEYS = (
    "success_rate",
    "mean_time_s",
    "mean_fz_N",
    "peak_fz_N",
    "mean_fxy_N",
    "mean_discounted_return",
)


def _float(x: str | None) -> float:
    try:
        return float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return float("nan")


def run_record(run: Path) -> dict:
    """Config, evaluations and training-force statistics of one run."""
    rows = read_metrics(run)  # a clear error if ``run`` is not a training run
    meta = json.loads((run / "run.json").read_text())
    cfg = meta["config"]
    evals = [
        {"step": int(float(r["step"])), **{k: _float(r.get(f"eval/{k}")) for k in EVAL_KEYS}}
        for r in rows
    ]
    # training-episode |F_z| after the first evaluation (the random-policy phase excluded)
    train_fz = np.array([_float(r.get("train/mean_fz_N")) for r in rows[1:]])
    train_fz = train_fz[np.isfinite(train_fz)]
    learned = [e for e in evals if e["step"] > 0]
    return {
        "run": str(run),
        "compliance_strategy": bool(cfg.get("env_overrides", {}).get("compliance_strategy")),
        "env": cfg["env"],
        "profile": cfg.get("profile"),
        "seed": cfg.get("seed"),
        "env_steps": evals[-1]["step"] if evals else 0,
        "evaluations": evals,
        "train_mean_fz_N": float(train_fz.mean()) if len(train_fz) else float("nan"),
        "train_std_fz_N": float(train_fz.std()) if len(train_fz) else float("nan"),
        "train_windows": len(train_fz),  # metrics rows (evaluation intervals) averaged
        "eval_mean_fz_N": float(np.nanmean([e["mean_fz_N"] for e in learned]))
        if learned
        else float("nan"),
        "eval_mean_success": float(np.nanmean([e["success_rate"] for e in learned]))
        if learned
        else float("nan"),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cs", type=Path, required=True, help="run trained with the CS on")
    p.add_argument("--no-cs", type=Path, required=True, help="run trained with the CS off")
    p.add_argument("--device", default=None, help="GPU name, e.g. 'H100' (default: this CPU)")
    p.add_argument("--note", default="", help="free-text conditions, stored in the JSON")
    p.add_argument("--tag", default="", help="file-name tag of a variant, e.g. 'slow'")
    p.add_argument("--results", type=Path, default=RESULTS, help="output folder")
    args = p.parse_args(argv)

    try:
        cs, nocs = run_record(args.cs), run_record(args.no_cs)
    except UserInputError as e:
        raise SystemExit(str(e)) from None
    if not cs["compliance_strategy"] or nocs["compliance_strategy"]:
        raise SystemExit("--cs needs a run with the CS on, --no-cs one with it off")
    if cs["env"] != nocs["env"]:
        raise SystemExit(f"the runs train different envs: {cs['env']} vs {nocs['env']}")
    lower = cs["train_mean_fz_N"] < nocs["train_mean_fz_N"]
    steadier = cs["train_std_fz_N"] < nocs["train_std_fz_N"]
    label = device_label(None if args.device in (None, "cpu") else args.device)
    short = {"RectExtract": "rect", "DualExtract": "dual"}[cs["env"]]
    tag = f"_{args.tag}" if args.tag else ""
    stem = args.results / f"rl_vs_rlcs_{short}{tag}_{label}"
    result = {
        "benchmark": "rl_vs_rlcs",
        "env": cs["env"],
        "device": label,
        "date": utc_now(),
        "versions": versions_dict(("mujoco", "mjx", "jax")),
        "note": args.note,
        "rl_cs": cs,
        "rl": nocs,
        "force_reduction_train_pct": 100.0 * (1 - cs["train_mean_fz_N"] / nocs["train_mean_fz_N"]),
        "c4_1": {
            "claim": "RL + CS gives lower, steadier F_z over training than RL without it (Fig 4.5)",
            "lower": bool(lower),
            "steadier": bool(steadier),
            "verdict": "confirmed" if lower and steadier else "not confirmed",
        },
    }
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")

    from peghole_mjx.training.plots import plot_curves

    plot_curves(
        [args.cs, args.no_cs],
        stem.with_suffix(".png"),
        title=f"{cs['env']}: RL vs RL + compliance strategy ({label})",
    )
    print(
        json.dumps(
            {
                "rl_cs_train_fz": round(cs["train_mean_fz_N"], 3),
                "rl_train_fz": round(nocs["train_mean_fz_N"], 3),
                "c4_1": result["c4_1"]["verdict"],
                "out": str(stem.with_suffix(".json")),
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
