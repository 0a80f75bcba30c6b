"""Plots of the benchmark results, PNGs under benchmarks/results/.

* ``throughput_<device>_<scene>.png``: physics steps/s vs worlds, log-log, one line per engine
  (one figure per scene and device CSV);
* ``time_to_success.png``: wall clock to the success threshold (or the budget, hatched, when
  it was not reached) of the seed stack (``seed_stack_*.json``) next to ours
  (``train_rect_<device>.json`` from ``benchmarks/time_to_success.py``, "pending" until one
  is committed).

Run: ``python -m benchmarks.plot`` (reads every ``throughput_*.csv`` in the results folder, the
``_quick`` ones excepted unless ``--include-quick``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from benchmarks.bench_common import ENGINES, RESULTS, read_csv

#: where "ours" (the Brax SAC stack, peghole_mjx/training) commits its time-to-success result
#: ours (benchmarks/time_to_success.py), one file per device like the seed stack's
OURS_GLOB = "train_rect_*.json"
#: keys read from a time-to-success JSON, first found wins (seed stack and ours share them)
TIME_KEYS = ("time_to_success_s", "time_to_95_s", "wall_clock_to_threshold_s")

STYLE = {
    "mjx-jax": ("tab:blue", "o"),
    "mjx-warp": ("tab:purple", "D"),
    "mujoco-c": ("tab:orange", "s"),
    "mujoco-c-rollout": ("tab:red", "^"),
    "pybullet": ("tab:green", "v"),
}


def time_to_success(path: Path) -> dict | None:
    """``{label, time_s, reached, budget_s, success, device}`` of a result JSON, or None.

    ``time_s`` is the wall clock to the threshold when reached, else the budget spent.
    """
    if not path.exists():
        return None
    d = json.loads(path.read_text())
    t = next((d[k] for k in TIME_KEYS if d.get(k) is not None), None)
    budget = d.get("budget_s", d.get("train_wall_s"))
    return {
        "time_s": t if t is not None else budget,
        "reached": t is not None,
        "budget_s": budget,
        "success": d.get("final_success_rate"),
        "threshold": d.get("success_threshold", 0.95),
        "device": d.get("device", "?"),
    }


def plot_throughput(csv_path: Path, out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_csv(csv_path)
    device = csv_path.stem.removeprefix("throughput_")
    outs = []
    for scene in sorted({r["scene"] for r in rows}):
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        for engine in ENGINES:
            pts = sorted(
                (r["worlds"], r["physics_steps_per_s"])
                for r in rows
                if r["engine"] == engine and r["scene"] == scene and r["physics_steps_per_s"]
            )
            if not pts:
                continue
            color, marker = STYLE[engine]
            ax.plot(*zip(*pts, strict=True), marker=marker, color=color, label=engine)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("worlds")
        ax.set_ylabel("physics steps / s (2 ms each)")
        devs = sorted({r["device"] for r in rows if r["scene"] == scene})
        ax.set_title(f"{scene} scene, {device}\n" + "; ".join(devs), fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        out = out_dir / f"throughput_{device}_{scene}.png"
        fig.savefig(out, dpi=120)
        plt.close(fig)
        outs.append(out)
    return outs


def plot_time_to_success(out_dir: Path, results: Path = RESULTS) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bars = []
    from benchmarks.seed_stack import result_files

    for p in result_files(results=results):  # RectExtract's only
        r = time_to_success(p)
        if r:
            bars.append((f"seed stack\n(PyBullet + SB3)\n{p.stem.split('_', 2)[-1]}", r))
    ours = sorted(results.glob(OURS_GLOB))
    for p in ours:
        bars.append((f"ours\n(MJX + Brax SAC)\n{p.stem.split('_', 2)[-1]}", time_to_success(p)))
    if not ours:
        bars.append(("ours\n(MJX + Brax SAC)", None))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for i, (label, r) in enumerate(bars):
        if r is None:
            ax.bar(i, 0.0, color="lightgrey")
            ax.text(i, 0.0, "pending", ha="center", va="bottom")
            continue
        ax.bar(
            i,
            r["time_s"],
            color="tab:green" if "seed" in label else "tab:blue",
            hatch=None if r["reached"] else "//",
            edgecolor="black",
        )
        txt = (
            f"{r['time_s']:.0f} s"
            if r["reached"]
            else f"not reached in {r['time_s']:.0f} s\n(success {r['success']:.2f})"
        )
        ax.text(i, r["time_s"], txt, ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(bars)), [b[0] for b in bars], fontsize=8)
    ax.set_ylabel("training wall clock to the success threshold, s")
    thr = next((r["threshold"] for _, r in bars if r), 0.95)
    ax.set_title(f"RectExtract: time to {thr:.0%} success (hatched: budget, not reached)")
    ax.set_ylim(0, max([r["time_s"] for _, r in bars if r] + [1.0]) * 1.3)
    fig.tight_layout()
    out = out_dir / "time_to_success.png"
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--include-quick", action="store_true")
    args = ap.parse_args(argv)
    outs = []
    for csv_path in sorted(args.results.glob("throughput_*.csv")):
        if csv_path.stem.endswith("_quick") and not args.include_quick:
            continue
        outs += plot_throughput(csv_path, args.results)
    outs.append(plot_time_to_success(args.results, args.results))
    for o in outs:
        print(f"wrote {o}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
