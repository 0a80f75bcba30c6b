"""Regenerate the README's result tables from the committed files in benchmarks/results/.

Each table sits between ``<!-- table:NAME -->`` and ``<!-- /table:NAME -->`` markers, so every
number in the README traces to a committed result file. Run: ``python benchmarks/readme_tables.py``
(``--check`` exits 1 if the README is out of date; the test suite runs that check).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
README = ROOT / "README.md"


def models_check() -> str:
    data = json.loads((RESULTS / "models_check.json").read_text())
    lines = [
        f"Device: {data['device']}; mujoco {data['versions'].get('mujoco')}, "
        f"mujoco-mjx {data['versions'].get('mujoco-mjx')}, jax {data['versions'].get('jax')}; "
        f"{data['date']}.",
        "",
        "| preset | nominal mm | effective mm | error % | drop gap mm (C / MJX) | MJX-JAX ok "
        "| convex geoms | result |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in data["presets"]:
        mjx_gap = "-" if r["drop_test_gap_mjx_mm"] is None else f"{r['drop_test_gap_mjx_mm']:.3f}"
        lines.append(
            f"| {r['preset']} | {r['nominal_clearance_mm']:.3f} | "
            f"{r['effective_clearance_mm']:.4f} | {r['clearance_error_pct']:+.2f} | "
            f"{r['drop_test_gap_mujoco_mm']:.3f} / {mjx_gap} | {r['mjx_jax_ok']} | "
            f"{r['n_convex_geoms']} | {'pass' if r['passed'] else 'FAIL'} |"
        )
    return "\n".join(lines)


def env_rollouts() -> str:
    data = json.loads((RESULTS / "env_rollouts.json").read_text())
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


TABLES = {"models_check": models_check, "env_rollouts": env_rollouts}


def render(text: str) -> str:
    for name, fn in TABLES.items():
        pattern = re.compile(rf"(<!-- table:{name} -->\n).*?(<!-- /table:{name} -->)", re.S)
        if not pattern.search(text):
            raise SystemExit(f"README has no markers for table {name!r}")
        text = pattern.sub(lambda m, fn=fn: m.group(1) + fn() + "\n" + m.group(2), text)
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--check", action="store_true", help="exit 1 if README is out of date")
    args = ap.parse_args()
    old = README.read_text()
    new = render(old)
    if args.check:
        if new != old:
            print("README tables are out of date: run python benchmarks/readme_tables.py")
            return 1
        return 0
    README.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
