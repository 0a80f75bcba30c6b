"""The built-in irregular parts as tasks: build figures and the scripted baseline per shape.

For each built-in shape (``peghole_mjx/geometry/shapes.py``: cylinder, keyed, l_section, hex,
three_pin, tapered) at one diametral clearance: ``peghole task builtin`` (its pieces, vertices,
measured clearance, contact cap and wall time to build), then the scripted Ch 2-3 baseline of
the MeshExtract env on it (``peghole envs rollout --policy scripted`` on the ``mujoco``
engine: success, time, forces, failures by cause and the rollout's wall time).

    python -m benchmarks.evals.task_builtins --clearance-mm 0.1 --episodes 16

Writes ``benchmarks/results/evals/task_builtins_<device>.json`` (device, versions, date, one
row per shape); the docs table ``task_builtins`` (docs/guide/tasks.md) is generated from it
(``python -m benchmarks.tables``). The task folders go to ``--tasks`` (default
``runs/tasks_builtin_c<clearance>``); a shape whose folder is already there is read, not
rebuilt (its build figures are those recorded in its task.json).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import EVALS_RESULTS, ROOT, cpu_label, fmt_num, out_file, rel, table
from peghole_mjx import envs
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.envs.task_make import make_builtin
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.shapes import BUILTINS

OUT = EVALS_RESULTS / f"task_builtins_{cpu_label()}.json"


def shape_row(folder: Path, episodes: int, seed: int = 0) -> dict:
    """One shape's row: its task.json's build figures and a scripted rollout on it."""
    doc = tf.read_task_json(folder)
    cl = doc["checks"]["clearance"]
    row = {
        "shape": doc["name"],
        "clearance_mm": doc["source"].get("clearance_mm"),
        "peg_hulls": doc["peg"]["hulls"],
        "hole_hulls": doc["hole"]["hulls"],
        "hull_vertices_max": max(doc["peg"]["hull_vertices_max"], doc["hole"]["hull_vertices_max"]),
        "pairs": doc["contacts"]["pairs"],
        "radial_clearance_mm": cl["radial_mm"],
        "effective_clearance_mm": [cl["effective_min_mm"], cl["effective_max_mm"]],
        "contacts_measured_max": doc["contacts"]["measured_max"],
        "contact_cap": doc["contacts"]["cap"],
        "engines": doc["caps"]["engines"],
        "build_s": doc["timing_s"]["total"],
    }
    if episodes:
        env = envs.load("MeshExtract", config_overrides={"task": str(folder), "engine": "mujoco"})
        t0 = time.perf_counter()
        res = rollout(env, scripted_policy(env), episodes, seed=seed, progress=False)
        wall = time.perf_counter() - t0
        row["scripted"] = {
            **res.summary().as_dict(),
            "wall_s": round(wall, 2),
            "compile_s": round(res.compile_s, 2),
            "run_s": round(res.run_s, 2),
        }
    return row


@table("task_builtins")
def task_builtins_table() -> str:
    """One row per built-in shape: pieces, clearance, contacts, build time, scripted pull."""
    data = json.loads(OUT.read_text())
    lines = [
        f"{data['device']}, {data['date'][:10]}, diametral clearance "
        f"{data['clearance_mm']:g} mm; scripted baseline: {data['episodes']} episodes, seed "
        f"{data['seed']}, engine mujoco ([`{OUT.name}`]({rel(OUT)})).",
        "",
        "| shape | pieces peg / hole | vertices max | pairs | radial clearance mm (meshes) | "
        "diametral mm (pieces, min-max) | contacts max / cap | engines | build s | "
        "scripted success | mean time s | peak F_z N | failures (jam / time-out) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        s = r.get("scripted") or {}
        eff = r["effective_clearance_mm"]
        lines.append(
            f"| {r['shape']} | {r['peg_hulls']} / {r['hole_hulls']} | {r['hull_vertices_max']} | "
            f"{r['pairs']} | {r['radial_clearance_mm']:.4f} | {eff[0]:.4f}-{eff[1]:.4f} | "
            f"{r['contacts_measured_max']} / {r['contact_cap']} | {', '.join(r['engines'])} | "
            f"{r['build_s']:.0f} | {fmt_num(s.get('success_rate'), '.3f')} | "
            f"{fmt_num(s.get('mean_time_s'), '.2f')} | {fmt_num(s.get('peak_fz_N'), '.2f')} | "
            f"{s.get('jammed', '-')} / {s.get('timeouts', '-')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clearance-mm", type=float, default=0.1)
    ap.add_argument("--episodes", type=int, default=16, help="scripted episodes per shape")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shapes", default=",".join(BUILTINS))
    ap.add_argument("--tasks", type=Path, help="folder of the task folders")
    ap.add_argument("--out", type=out_file, default=OUT)
    args = ap.parse_args(argv)
    tasks = args.tasks or ROOT / "runs" / f"tasks_builtin_c{args.clearance_mm:g}"
    rows = []
    for shape in args.shapes.split(","):
        folder = tasks / shape
        if not (folder / tf.MANIFEST).is_file():
            make_builtin(shape, args.clearance_mm, folder, progress=True)
        row = shape_row(folder, args.episodes, args.seed)
        print(json.dumps(row), flush=True)
        rows.append(row)
    meta = {
        **provenance(),
        "clearance_mm": args.clearance_mm,
        "episodes": args.episodes,
        "seed": args.seed,
        "rows": rows,
    }
    args.out.write_text(json.dumps(meta, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
