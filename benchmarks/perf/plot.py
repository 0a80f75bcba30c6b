"""Plots of the throughput results: ``throughput_<device>_<scene>.png`` under
``benchmarks/results/perf/``, physics steps/s vs worlds, log-log, one line per engine (one
figure per scene and device CSV).

Run: ``python -m benchmarks.perf.plot`` (reads every ``throughput_*.csv`` in the results
folder, the ``_quick`` ones excepted unless ``--include-quick``). The time-to-success figure is
drawn by ``python -m benchmarks.baselines.time_to_success --plot``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from matplotlib.figure import Figure

from benchmarks.common import ENGINES, PERF_RESULTS, RETIRED_ENGINES, read_csv

STYLE = {
    "mjx-jax": ("tab:blue", "o"),
    "mjx-warp": ("tab:purple", "D"),
    "mujoco-c": ("tab:orange", "s"),
    "mujoco-c-rollout": ("tab:red", "^"),
    "pybullet": ("tab:green", "v"),
    "mujoco": ("tab:brown", "P"),
    "mujoco-1t": ("tab:pink", "X"),
    "batch-ceiling": ("tab:gray", "*"),
}
#: the engines a committed CSV may hold (retired ones keep their measured rows)
CSV_ENGINES = (*ENGINES, *RETIRED_ENGINES)
assert set(STYLE) == set(CSV_ENGINES), "every engine of the CSV needs a line style"


def plot_throughput(csv_path: Path, out_dir: Path) -> list[Path]:
    """One PNG per scene of a throughput CSV: physics steps/s vs worlds per engine."""
    rows = read_csv(csv_path)
    device = csv_path.stem.removeprefix("throughput_")
    outs = []
    for scene in sorted({r["scene"] for r in rows}):
        fig = Figure(figsize=(6.4, 4.4))
        ax = fig.subplots()
        for engine in CSV_ENGINES:
            pts = sorted(
                (r["worlds"], r["physics_steps_per_s"])
                for r in rows
                if r["engine"] == engine and r["scene"] == scene and r["physics_steps_per_s"]
            )
            if not pts:
                continue
            color, marker = STYLE[engine]
            retired = RETIRED_ENGINES.get(engine)
            label = f"{engine} (retired {retired})" if retired else engine
            ax.plot(*zip(*pts, strict=True), marker=marker, color=color, label=label)
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
        outs.append(out)
    return outs


def main(argv: list[str] | None = None) -> int:
    """Draw every throughput CSV of ``--results``."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=PERF_RESULTS)
    ap.add_argument("--include-quick", action="store_true")
    args = ap.parse_args(argv)
    outs = []
    for csv_path in sorted(args.results.glob("throughput_*.csv")):
        if csv_path.stem.endswith("_quick") and not args.include_quick:
            continue
        outs += plot_throughput(csv_path, args.results)
    for o in outs:
        print(f"wrote {o}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
