"""Generalisation matrix: a published policy on every preset of its geometry and on a held-out
geometry, beside the scripted baseline on the same episodes.

A policy is trained on one preset (rect-2 or dual-2). This runs it, and the scripted
fixed-compliance method (thesis Ch 2-3), on the three presets of its geometry (rect-1/2/3 or
dual-1/2/3) and on one custom geometry that is not a preset (:data:`HELD_OUT`, through the env
config's ``geometry`` entry), every other env setting as trained. Each cell is
:func:`peghole_mjx.training.evaluate.evaluate` with ``cross=True`` (its result records what
differs from the training env): policy and baseline meet the same randomised episodes (the
same seed in every cell), on the engine the policy was trained on unless ``--engine`` is
given (then every cell, a cross evaluation on that engine). Reported per cell and method:
success rate, mean extraction time (successful episodes), mean |F_z| and peak |F_z| (mean
over episodes of the per-episode peak), and the force reduction of the policy vs the
baseline.

    python -m benchmarks.evals.generalisation --policy rect --episodes 128
    python -m benchmarks.evals.generalisation --policy dual --episodes 128 --batch 128

Writes ``benchmarks/results/evals/generalisation_<policy>_<device>.json`` (device, versions,
date, episodes, seed, one entry per cell) and ``.csv`` (one row per cell and method); the docs
table ``generalisation`` is generated from the JSON (``python -m benchmarks.tables``). Each
finished cell is saved under ``--parts`` (default ``runs/generalisation_<policy>``; slices of
``--batch`` episodes there too), so an interrupted run continues where it stopped.
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import sys
import time
from pathlib import Path

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import (
    EVALS_RESULTS,
    ROOT,
    cpu_label,
    fmt_num,
    out_file,
    rel,
    table,
    versions_field,
    write_rows,
)
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.config import apply_overrides, env_spec, geometry_text
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import provenance, utc_now
from peghole_mjx.geometry.specs import PRESETS, get_preset, with_changes
from peghole_mjx.policies import PRETRAINED, load_policy
from peghole_mjx.sim.engines import ENGINES
from peghole_mjx.training.evaluate import evaluate, params_sha256, requested_config

#: the held-out geometry of each kind: spec fields changed from the training preset's, in mm.
#: rect: a 50 x 30 mm cross-section (the presets are all 60 x 40) with 0.2 mm clearance
#: (between rect-1's 0.6 and rect-2's 0.1); dual: 6.9 mm pegs in 7.1 mm holes 45 mm apart (the
#: presets: 5.7-6.05 mm pegs in 6.1 mm holes, 40 mm apart), 0.4 mm diametral clearance
HELD_OUT = {
    "rect": {"hole_w_mm": 50.1, "hole_v_mm": 30.1, "peg_w_mm": 49.9, "peg_v_mm": 29.9},
    "dual": {
        "hole_radii_mm": (7.1, 7.1),
        "peg_radii_mm": (6.9, 6.9),
        "hole_distance_mm": 45.0,
        "peg_distance_mm": 45.0,
    },
}
METRICS = ("success_rate", "mean_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N")
CUSTOM = "custom"
#: per method and cell: the metrics, the episode count and the failures by cause
KEPT = (*METRICS, "episodes", "jammed", "timeouts")


def cells(kind: str, presets: list[str] | None, custom: bool) -> dict[str, dict]:
    """``{cell name: env overrides}``: the presets of ``kind`` (or ``presets``), then the
    held-out geometry (on the training preset's remaining fields)."""
    names = presets if presets is not None else sorted(p for p in PRESETS if p.startswith(kind))
    for p in names:
        if get_preset(p).kind != kind:
            raise UserInputError(f"preset {p} is not a {kind} geometry")
    out = {p: {"preset": p} for p in names}
    if custom:
        out[CUSTOM] = {"geometry": geometry_text(HELD_OUT[kind])}
    return out


def describe(spec) -> str:
    """A one-line description of a spec's dimensions (the table's geometry column)."""
    if spec.kind == "rect":
        return (
            f"peg {spec.peg_w_mm:g} x {spec.peg_v_mm:g} in hole {spec.hole_w_mm:g} x "
            f"{spec.hole_v_mm:g} mm, clearance {spec.clearance_mm:.2f} mm"
        )
    return (
        f"pegs r {'/'.join(f'{r:g}' for r in spec.peg_radii_mm)} in holes R "
        f"{'/'.join(f'{r:g}' for r in spec.hole_radii_mm)} mm, D {spec.hole_distance_mm:g} mm, "
        f"clearance {spec.clearance_mm:.2f} mm"
    )


def run_cell(bundle, name, over, args, parts: Path) -> dict:
    """One cell: evaluated, or loaded from ``parts/<name>.json`` when it holds this cell."""
    key = {
        "params_sha256": params_sha256(bundle.params),
        "env_overrides": over,
        "episodes": args.episodes,
        "seed": args.seed,
        "batch": args.batch or args.episodes,
    }
    saved = parts / f"{name}.json"
    if saved.exists():
        old = json.loads(saved.read_text())
        if old.get("key") == key:
            print(f"{name}: loaded from {saved}", file=sys.stderr)
            res = old["result"]
            if "date" not in res:  # the cell's own date: when it was saved
                stamp = dt.datetime.fromtimestamp(saved.stat().st_mtime, dt.UTC)
                res["date"] = stamp.strftime("%Y-%m-%dT%H:%M:%SZ")
            return res
    t0 = time.perf_counter()
    slices = parts / "slices" / hashlib.sha256(json.dumps(over).encode()).hexdigest()[:8]
    res = evaluate(
        bundle,
        args.episodes,
        seed=args.seed,
        progress=not args.no_progress,
        env_overrides=over,
        batch=args.batch,
        parts_dir=slices,
        cross=True,
    )
    res["wall_s"] = round(time.perf_counter() - t0, 1)
    res["date"] = utc_now()
    parts.mkdir(parents=True, exist_ok=True)
    fileio.write_text(saved, json.dumps({"key": key, "result": res}, indent=2) + "\n")
    return res


def write(out: Path, head: dict, rows: list[dict]) -> None:
    """The JSON (``complete`` once every planned cell is in) and its CSV, one row per cell
    and method."""
    doc = {
        **head,
        **provenance(),
        "complete": [r["cell"] for r in rows] == head["cells_planned"],
        "cells": rows,
    }
    fileio.write_text(out, json.dumps(doc, indent=2) + "\n")
    csv_rows = [
        {
            "cell": r["cell"],
            "method": who,
            "geometry": r["describe"],
            **{k: r[who][k] for k in METRICS},
            "force_reduction_pct": r["force_reduction_pct"] if who == "policy" else "",
            "episodes": r[who]["episodes"],
            "seed": head["seed"],
            "device": doc["device"],
            "versions": versions_field(doc["versions"]),
            "date": r["date"],
        }
        for r in rows
        for who in ("policy", "baseline")
    ]
    write_rows(out.with_suffix(".csv"), csv_rows)


def _shown(path: Path) -> str:
    """``path`` relative to the repository when inside it."""
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


@table("generalisation")
def generalisation_table() -> str:
    """The committed generalisation matrices, one per policy file."""
    files = sorted(EVALS_RESULTS.glob("generalisation_*.json"))
    if not files:
        return "Not run yet (`python -m benchmarks.evals.generalisation --policy rect`)."
    lines = []
    for path in files:
        d = json.loads(path.read_text())
        where = rel(path)
        lines += [
            f"`{d['policy']}` ({d['env']}, trained on {d['trained_preset']}): "
            f"{d['episodes_per_cell']} randomised episodes per cell, seed {d['seed']}, the same "
            f"episodes for policy and baseline; {d['device']}, {d['date'][:10]}; from "
            f"[`{where}`]({where}) (`{d['command']}`)."
            + (
                ""
                if d.get("complete", True)
                else f" **Incomplete**: {len(d['cells'])} of {len(d['cells_planned'])} cells."
            ),
            "",
            "| geometry | method | success | mean time s | mean F_z N | peak F_z N "
            "| F_z vs baseline |",
            "|---|---|---|---|---|---|---|",
        ]
        for c in d["cells"]:
            name = c["cell"] if c["cell"] != "custom" else "held-out (not a preset)"
            if c["trained_on"]:
                name += " (trained)"
            red = c["force_reduction_pct"]
            for who, label in (("policy", "SAC"), ("baseline", "scripted")):
                r = c[who]
                geo = f"{name}: {c['describe']}" if who == "policy" else ""
                vs = (f"{-red:+.1f} %" if red is not None else "-") if who == "policy" else ""
                lines.append(
                    f"| {geo} | {label} | {r['success_rate']:.3f} | "
                    f"{fmt_num(r['mean_time_s'], '.2f')} | {r['mean_fz_N']:#.3g} | "
                    f"{r['peak_fz_N']:#.3g} | {vs} |"
                )
        lines.append("")
    return "\n".join(lines).rstrip()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "--policy",
        default="rect",
        help="pretrained name (rect, dual, rect_hard, dual_hard) or a folder",
    )
    ap.add_argument("--episodes", type=int, default=64, help="episodes per cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, help="worlds at once (default: all episodes)")
    ap.add_argument(
        "--presets", nargs="*", help="presets to run (default: the three of the policy's kind)"
    )
    ap.add_argument(
        "--engine",
        choices=ENGINES,
        help="the engine of every cell (default: the one the policy was trained on)",
    )
    ap.add_argument("--no-custom", action="store_true", help="skip the held-out geometry")
    ap.add_argument("--parts", type=Path, help="finished cells and slices (resumable)")
    ap.add_argument("--out", type=out_file, help="JSON to write (the CSV beside it)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    bundle = load_policy(args.policy)
    trained = requested_config(bundle)
    kind = get_preset(trained.preset).kind
    label = args.policy if args.policy in PRETRAINED else Path(args.policy).name
    parts = args.parts or Path("runs") / f"generalisation_{label}"
    out = args.out or EVALS_RESULTS / f"generalisation_{label}_{cpu_label()}.json"
    fileio.check_out_file(out)
    todo = cells(kind, args.presets, not args.no_custom)
    if not todo:
        raise UserInputError("no cells to run: give --presets NAME ... or drop --no-custom")
    if args.engine:
        todo = {name: {**over, "engine": args.engine} for name, over in todo.items()}
    with_changes(get_preset(trained.preset), **HELD_OUT[kind])  # the held-out spec is valid
    head = {
        "what": "generalisation matrix: policy and scripted baseline, same episodes per cell",
        "command": "python -m benchmarks.evals.generalisation " + " ".join(argv or sys.argv[1:]),
        "policy": _shown(bundle.path),
        "env": bundle.env_name,
        "trained_preset": trained.preset,
        "episodes_per_cell": args.episodes,
        "seed": args.seed,
        "batch": args.batch or args.episodes,
        "engine": args.engine or trained.engine,
        "held_out_geometry": json.loads(geometry_text(HELD_OUT[kind])),
        "cells_planned": list(todo),
    }
    rows = []
    for i, (name, over) in enumerate(todo.items(), 1):
        print(f"[{i}/{len(todo)}] {name}", file=sys.stderr, flush=True)
        res = run_cell(bundle, name, over, args, parts)
        spec = env_spec(apply_overrides(trained, over))
        rows.append(
            {
                "cell": name,
                "preset": res["preset"],
                "geometry": res["geometry"],
                "describe": describe(spec),
                "clearance_mm": round(spec.clearance_mm, 4),
                "trained_on": name == trained.preset,
                "differs_from_training": res["differs_from_training"],
                "policy": {k: res["policy"][k] for k in KEPT},
                "baseline": {k: res["baseline"][k] for k in KEPT},
                "force_reduction_pct": res["force_reduction_pct"],
                "wall_s": res.get("wall_s"),
                "date": res["date"],
            }
        )
        write(out, head, rows)  # after every cell: an interrupted run leaves the cells done
    for r in rows:
        p, b = r["policy"], r["baseline"]
        print(
            f"{r['cell']:8s} success {p['success_rate']:.3f}/{b['success_rate']:.3f}  "
            f"F_z {p['mean_fz_N']:.3g}/{b['mean_fz_N']:.3g} N  "
            f"reduction {r['force_reduction_pct']:.1f} %"
        )
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
