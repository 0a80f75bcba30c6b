"""Per-world MJX cost of task folders: MeshExtract on each task's convex pieces.

For each task folder given (``peghole task builtin SHAPE`` or ``peghole task make``), the
MeshExtract env on its MJX-JAX engine is measured as the scenes of :mod:`benchmarks.perf.cost`
are (:func:`benchmarks.perf.cost.measure_env`, the same method): ``mjx.Data`` bytes per world,
XLA's cost analysis (bytes accessed, FLOPs) per world of the env step, the physics step and
its stages, the HBM roofline estimate from the env-step bytes, and the compile time of
``jit(vmap(env.step))`` for 8 worlds (the persistent compilation cache off: a compile, not a
load). Each row also carries the task's convex pieces, their vertices and its contact cap
(``task.json``) and the folder's digest (the SHA-256 of its ``manifest.json``, which lists the
SHA-256 of every file). RectExtract and DualExtract in their default representations are
shown beside them from the committed ``cost_<device>.json`` of the same device, not rerun.

Run ``python -m benchmarks.perf.task_cost --tasks runs/tasks_builtin_c0.1/*`` (minutes per
task on 2 CPU cores: the mesh pairs' collision functions compile one by one); writes
``benchmarks/results/perf/task_cost_<device>.json`` after each task, and its CSV (one row per
task, from the JSON) at the end. A rerun skips the tasks whose row is there with the same
folder digest (``--force`` measures them again).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from tqdm import tqdm

from benchmarks.common import (
    PERF_RESULTS,
    device_label,
    load_average,
    out_file,
    rel,
    table,
    versions_field,
    write_rows,
)
from benchmarks.perf.cost import cost_variant, measure_env, without_persistent_cache
from benchmarks.perf.engines import gpu_kind
from benchmarks.perf.roofline import GPU_BANDWIDTH
from peghole_mjx import envs
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import provenance, utc_now
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.parts import DUAL_DEFAULT_REPRESENTATION, RECT_DEFAULT_REPRESENTATION

#: the committed task-cost measurement (2-core CPU) that the docs table reads
TASK_COST_JSON = PERF_RESULTS / "task_cost_cpu-2core.json"
#: the preset scenes shown beside the tasks: (scene, env, representation) of cost_<device>.json
REFERENCE_SCENES = (
    ("rect", "RectExtract", RECT_DEFAULT_REPRESENTATION),
    ("dual", "DualExtract", DUAL_DEFAULT_REPRESENTATION),
)
#: the figures copied from a cost entry into a row (the rest of the entry stays in its file)
_FIGURES = (
    "n_geoms",
    "n_pairs",
    "contacts_allocated",
    "constraint_rows",
    "mjx_data_bytes_per_world",
    "n_substeps",
    "xla",
    "roofline",
    "env_step_compile_s",
    "env_step_compile_cpu_s",
    "env_step_compile_worlds",
)


def folder_digest(folder: str | Path) -> str:
    """The SHA-256 of a task folder's ``manifest.json`` (the folder checked first: a folder
    that is not a complete task is a one-line :class:`~peghole_mjx.core.errors.UserInputError`)."""
    folder = Path(folder)
    tf.read_manifest(folder)
    return fileio.sha256_file(folder / tf.MANIFEST)


def task_figures(folder: str | Path) -> dict:
    """A task's size from its ``task.json`` (pieces, most vertices of a piece, contact pairs,
    measured contacts and cap) and its hull files (vertices in all)."""
    doc = tf.read_task_json(folder)
    spec = tf.load_task(folder)
    src = doc.get("source", {})
    return {
        "task": doc.get("name", Path(folder).name),
        "source": src.get("builtin") or src.get("kind", ""),
        "clearance_mm": src.get("clearance_mm"),
        "peg_pieces": doc["peg"]["hulls"],
        "hole_pieces": doc["hole"]["hulls"],
        "peg_piece_vertices_max": doc["peg"]["hull_vertices_max"],
        "hole_piece_vertices_max": doc["hole"]["hull_vertices_max"],
        "vertices": sum(len(h) for h in (*spec.peg_hulls, *spec.hole_hulls)),
        "contact_pairs": doc["contacts"]["pairs"],
        "contact_measured_max": doc["contacts"]["measured_max"],
        "contact_cap": doc["contacts"]["cap"],
    }


def task_row(folder: str | Path, compile_worlds: int = 8) -> dict:
    """The cost row of one task folder: its figures, digest and the MJX cost of MeshExtract on
    it (:func:`benchmarks.perf.cost.measure_env`)."""
    folder = Path(folder)
    digest = folder_digest(folder)
    t0 = time.perf_counter()
    env = envs.load("MeshExtract", config_overrides={"task": str(folder), "engine": "mjx"})
    build_s = time.perf_counter() - t0
    return {
        **task_figures(folder),
        "folder": rel(folder.resolve()),
        "digest": digest,
        "env": "MeshExtract",
        "engine": "mjx",
        "env_build_s": round(build_s, 1),
        **measure_env(env, compile_worlds),
        "measured": utc_now(),
        "load_average": load_average(),
    }


def reference_rows(cost_json: Path) -> list[dict]:
    """RectExtract and DualExtract in their default representation, cap and geometry, from a
    committed ``cost_<device>.json`` (none if it is missing)."""
    if not cost_json.is_file():
        return []
    data = json.loads(cost_json.read_text())
    out = []
    for scene, name, rep in REFERENCE_SCENES:
        for e in data["entries"] + data.get("extra_entries", []):
            if (e["scene"], e["representation"]) == (scene, rep) and not cost_variant(e):
                out.append(
                    {
                        "task": f"{name} ({rep})",
                        "env": name,
                        "representation": rep,
                        "from": rel(cost_json),
                        "measured": e.get("measured", data["date"]),
                        **{k: e[k] for k in _FIGURES if k in e},
                    }
                )
                break
    return out


# ----------------------------------------------------------------------------- docs table
def _mb(x: dict, stage: str) -> str:
    return f"{x[stage]['bytes_per_world'] / 1e6:.2f}"


def _mflop(x: dict, stage: str) -> str:
    return f"{x[stage]['flops_per_world'] / 1e6:.2f}"


def _compile_s(r: dict) -> str:
    cpu = r.get("env_step_compile_cpu_s")
    return f"{r['env_step_compile_s']}" + (f" ({cpu})" if cpu is not None else "")


@table("task_cost")
def task_cost_table() -> str:
    """Per-world MJX cost of the built-in irregular tasks beside the preset scenes."""
    path = TASK_COST_JSON
    if not path.is_file():
        return (
            f"No measurement yet (`{rel(path)}`): run `python -m benchmarks.perf.task_cost "
            "--tasks DIR ...`."
        )
    data = json.loads(path.read_text())
    v = data["versions"]
    gpus = list(data["gpus"])
    lines = [
        f"From [`{rel(path)}`]({rel(path)}) ({data['device']}; {data['date']}; mujoco "
        f"{v.get('mujoco')}, mujoco-mjx {v.get('mujoco-mjx')}, jax {v.get('jax')}). "
        f"{data.get('note', '')}".rstrip(),
        "",
        "| task | pieces (peg + hole) | vertices | contact pairs | contact cap (measured) "
        "| MJX contacts | constraint rows | mjx.Data B/world | XLA MB per world: env step "
        "| physics step | collision | XLA MFLOP per world: env step | physics step "
        f"| env-step compile s, wall (CPU), {data['compile_worlds']} worlds | {gpus[0]} estimate, "
        "physics steps/s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"] + data.get("reference", []):
        x = r["xla"]
        if "digest" in r:
            size = (
                f"{r['peg_pieces']} + {r['hole_pieces']} | {r['vertices']} | "
                f"{r['contact_pairs']} | {r['contact_cap']} ({r['contact_measured_max']})"
            )
            name = r["task"]
        else:
            size = f"- | - | {r['n_pairs']} | -"
            name = f"{r['task']}, from [`{Path(r['from']).name}`]({r['from']})"
        est = r["roofline"][gpus[0]]["xla_traffic_estimate_physics_steps_per_s"]
        lines.append(
            f"| {name} | {size} | {r['contacts_allocated']} | {r['constraint_rows']} | "
            f"{r['mjx_data_bytes_per_world']} | {_mb(x, 'env_step')} | "
            f"{_mb(x, 'physics_step')} | {_mb(x, 'collision')} | {_mflop(x, 'env_step')} | "
            f"{_mflop(x, 'physics_step')} | {_compile_s(r)} | {est:.3g} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", type=Path, nargs="+", required=True, help="task folders")
    ap.add_argument("--out", type=out_file, default=None)
    ap.add_argument("--force", action="store_true", help="measure tasks already in --out again")
    ap.add_argument("--compile-worlds", type=int, default=8)
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    digests = {folder: folder_digest(folder) for folder in args.tasks}  # every folder first
    without_persistent_cache()
    label = device_label(gpu_kind())
    out_path = args.out or PERF_RESULTS / f"task_cost_{label}.json"
    old = json.loads(out_path.read_text()) if out_path.is_file() else {}
    rows = {r["folder"]: r for r in old.get("rows", [])}  # a folder's row, replaced in place
    note = args.note or old.get("note", "")
    for folder in tqdm(args.tasks, desc="task cost", unit="task", file=sys.stderr):
        had = rows.get(rel(folder.resolve()), {})
        same = (had.get("digest"), had.get("env_step_compile_worlds"))
        if not args.force and same == (digests[folder], args.compile_worlds):
            tqdm.write(f"[task_cost] {folder}: in {out_path.name} with the same digest, skipped")
            continue
        r = task_row(folder, args.compile_worlds)
        rows[r["folder"]] = r
        x = r["xla"]
        tqdm.write(
            f"[task_cost] {r['task']}: {r['peg_pieces']} + {r['hole_pieces']} pieces, cap "
            f"{r['contact_cap']}: env step {x['env_step']['bytes_per_world'] / 1e6:.2f} MB "
            f"{x['env_step']['flops_per_world'] / 1e6:.2f} MFLOP, physics step "
            f"{x['physics_step']['bytes_per_world'] / 1e6:.2f} MB "
            f"{x['physics_step']['flops_per_world'] / 1e6:.2f} MFLOP per world; compile "
            f"{r['env_step_compile_s']} s"
        )
        result = {
            **provenance(),
            "note": note,
            "command": "python -m benchmarks.perf.task_cost " + " ".join(argv or sys.argv[1:]),
            "compile_worlds": args.compile_worlds,
            "gpus": GPU_BANDWIDTH,
            "method": __doc__.split("\n\n", 1)[1].split("Run ``")[0].strip(),
            "rows": list(rows.values()),
            "reference": reference_rows(PERF_RESULTS / f"cost_{label}.json"),
        }
        fileio.write_text(out_path, json.dumps(result, indent=2, default=float) + "\n")
    if out_path.is_file():
        write_rows(out_path.with_suffix(".csv"), csv_rows(json.loads(out_path.read_text())))
    print(out_path)
    return 0


def csv_rows(result: dict) -> list[dict]:
    """One row per task of a task_cost JSON: sizes, XLA bytes and FLOPs per world (MB,
    MFLOP), compile time, with the file's device, versions and date."""
    versions = versions_field(result["versions"])
    out = []
    for r in result["rows"]:
        x = r["xla"]
        row = {k: r[k] for k in ("task", "folder", "peg_pieces", "hole_pieces", "contact_cap")}
        row |= {k: r[k] for k in ("contacts_allocated", "constraint_rows")}
        row["mjx_data_bytes_per_world"] = r["mjx_data_bytes_per_world"]
        for stage in ("env_step", "physics_step", "collision"):
            row[f"{stage}_MB_per_world"] = round(x[stage]["bytes_per_world"] / 1e6, 3)
            row[f"{stage}_MFLOP_per_world"] = round(x[stage]["flops_per_world"] / 1e6, 3)
        row["env_step_compile_s"] = r["env_step_compile_s"]
        row["env_step_compile_cpu_s"] = r.get("env_step_compile_cpu_s")
        row |= {"device": result["device"], "versions": versions, "date": result["date"]}
        out.append(row)
    return out


if __name__ == "__main__":
    sys.exit(main())
