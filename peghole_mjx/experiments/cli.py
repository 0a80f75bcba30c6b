"""``peghole experiment compliance``: the simulated compliance-centre extraction experiment."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from peghole_mjx.errors import CorruptFileError, UserInputError
from peghole_mjx.validation import arg


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("experiment", help="simulated experiments of the thesis")
    sub = p.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    c = sub.add_parser("compliance", help="extraction with L_C at tip/centre/top (Sec 2.5, 3.4)")
    c.add_argument("--geometry", required=True, help="rect or dual")
    c.add_argument("--quick", action="store_true", help="one preset (rect-2 / dual-2), 2 repeats")
    c.add_argument(
        "--repeats", type=arg("repeats"), default=None, help="repeats per L_C (default 6)"
    )
    c.add_argument("--presets", default=None, help="comma-separated preset names")
    c.add_argument("--seed", type=arg("seed"), default=0)
    c.add_argument("--out", required=True, type=Path, help="output directory")
    c.set_defaults(func=run)

    w = sub.add_parser(
        "sweep",
        help="the compliance experiment over a regime grid (K_theta, beta0, mu, ...), resumable",
        description="Batched, resumable regime sweep of the compliance-centre experiment; "
        "writes compliance_sweep_<geometry>.json/.csv and figures into --out. Rerun the same "
        "command to resume. List options override the named grid's values.",
    )
    w.add_argument("--geometry", required=True, help="rect or dual")
    w.add_argument("--grid", default="cpu", help="cpu (default), full or tiny")
    w.add_argument("--presets", default=None, help="comma-separated presets")
    w.add_argument("--k-rot", default=None, help="K_theta values, N m/rad, comma-separated")
    w.add_argument("--k-lat", default=None, help="lateral stiffness values, N/m")
    w.add_argument("--beta0", default=None, help="beta0 values, deg (thesis sign)")
    w.add_argument(
        "--theta0",
        type=float,
        default=None,
        help="commanded initial tilt of every beta0 cell, deg (thesis Table 2.2: -0.9; default 0)",
    )
    w.add_argument("--delta0", default=None, help="delta0 values, mm")
    w.add_argument("--mu", default=None, help="friction values")
    w.add_argument(
        "--repeats", type=arg("sweep_repeats"), default=None, help="draws per cell and L_C (16)"
    )
    w.add_argument("--seed", type=arg("seed"), default=0)
    w.add_argument(
        "--batch-worlds", type=arg("batch_worlds"), default=96, help="worlds per compiled batch"
    )
    w.add_argument(
        "--representation",
        default=None,
        help="collision representation (default: rect edges, dual mesh)",
    )
    w.add_argument(
        "--compensate-joint-damping",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the law cancels the arm's joint damping (default on)",
    )
    w.add_argument(
        "--fix-cone-hessian",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="fixed MJX elliptic-cone Newton Hessian (peghole_mjx/mjx_fixes.py; default on)",
    )
    w.add_argument(
        "--speed-mm-s",
        type=float,
        default=None,
        help="pull speed, mm/s (default 20; the thesis does not state it, see "
        "benchmarks/pull_speed.py)",
    )
    w.add_argument(
        "--x64",
        action="store_true",
        help="run in float64 (float32 does not resolve pulls slower than a few mm/s)",
    )
    w.add_argument("--out", required=True, type=Path, help="output folder (resumable)")
    w.set_defaults(func=run_sweep)

    k = sub.add_parser(
        "contact-check",
        help="does a tilted rect peg hold two-point contact? (per-world contact quality)",
        description="Pulls the standard tilted rect case (L_C at the tip, K_theta 300 N m/rad, "
        "delta0 ~2 mm, beta0 ~-0.2 deg, mu 0.266) under each variant of step size and contact "
        "settings and reports penetration, wall switches, both-walls fraction, peak/mean "
        "contact force and agreement with the quasi-static oracle.",
    )
    k.add_argument("--preset", action="append", default=None, help="rect preset (repeatable)")
    k.add_argument(
        "--variant", action="append", default=None, help="variant name (repeatable) or all"
    )
    k.add_argument("--worlds", type=arg("worlds"), default=8)
    k.add_argument("--seed", type=arg("seed"), default=0)
    k.add_argument("--out", type=Path, default=None, help="JSON file to write")
    k.add_argument("--json", action="store_true", help="print the JSON instead of a table")
    k.add_argument(
        "--x64", action="store_true", help="run in float64 (jax_enable_x64) instead of float32"
    )
    k.add_argument(
        "--append",
        action="store_true",
        help="keep the runs already in --out (a rerun of the same preset, variant and "
        "precision replaces its row)",
    )
    k.set_defaults(func=run_contact_check)


def run(args: argparse.Namespace) -> int:
    from peghole_mjx.experiments.compliance import ExperimentConfig
    from peghole_mjx.experiments.report import run_experiment
    from peghole_mjx.geometry.specs import PRESETS

    if args.geometry not in ("rect", "dual"):
        raise UserInputError(f"--geometry must be rect or dual, not {args.geometry!r}")
    cfg = ExperimentConfig(geometry=args.geometry, seed=args.seed)
    if args.quick:
        cfg = ExperimentConfig.quick(args.geometry, seed=args.seed)
    if args.presets:
        names = tuple(n.strip() for n in args.presets.split(",") if n.strip())
        bad = [n for n in names if n not in PRESETS or PRESETS[n].kind != args.geometry]
        if bad:
            raise UserInputError(f"unknown {args.geometry} preset(s): {', '.join(bad)}")
        _no_duplicates("--presets", names)
        cfg = dataclasses.replace(cfg, presets=names)
    if args.repeats is not None:
        cfg = dataclasses.replace(cfg, repeats=args.repeats)
    summary, files = run_experiment(cfg, args.out)
    for f in files:
        print(f)
    for preset, pk in summary["peak_force_N"].items():
        print(
            f"{preset}: peak |F| by L_C (mm) {pk}; tip vs top "
            f"{summary['reduction_tip_vs_top_pct'][preset]} % (thesis 77.1), tip vs centre "
            f"{summary['reduction_tip_vs_centre_pct'][preset]} % (thesis 55.6)"
        )
    return 0


def _floats(text: str | None, name: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UserInputError(f"--{name} takes comma-separated numbers, got {text!r}") from None
    if not vals:
        raise UserInputError(f"the sweep grid is empty: --{name} has no values")
    return vals


def run_sweep(args: argparse.Namespace) -> int:
    from peghole_mjx.experiments import sweep

    if args.geometry not in sweep.GRIDS:
        raise UserInputError(f"--geometry must be rect or dual, not {args.geometry!r}")
    grids = sweep.GRIDS[args.geometry]
    if args.grid not in grids:
        raise UserInputError(f"--grid must be one of {', '.join(grids)}, not {args.grid!r}")
    grid = grids[args.grid]
    changes = {
        "k_rot_Nm_rad": _floats(args.k_rot, "k-rot"),
        "k_lat_N_m": _floats(args.k_lat, "k-lat"),
        "beta0_deg": _floats(args.beta0, "beta0"),
        "delta0_mm": _floats(args.delta0, "delta0"),
        "mu": _floats(args.mu, "mu"),
    }
    if args.presets is not None:
        changes["presets"] = tuple(p.strip() for p in args.presets.split(",") if p.strip())
    if args.repeats is not None:
        changes["repeats"] = args.repeats
    if args.theta0 is not None:
        changes["theta0_deg"] = args.theta0
    grid = dataclasses.replace(grid, **{k: v for k, v in changes.items() if v is not None})
    grid.check()
    if grid.geometry != args.geometry:
        raise UserInputError(f"the presets are not {args.geometry} presets")
    from peghole_mjx.experiments.compliance import ExperimentConfig
    from peghole_mjx.geometry.parts import resolve_representation
    from peghole_mjx.geometry.specs import PRESETS

    if args.representation is not None:
        resolve_representation(PRESETS[grid.presets[0]], args.representation, impl="jax")
    if args.speed_mm_s is not None:
        sweep.check_value("speed_mm_s", args.speed_mm_s, "--speed-mm-s", "mm/s")
    exp = ExperimentConfig(
        representation=args.representation,
        compensate_joint_damping=args.compensate_joint_damping,
        fix_cone_hessian=args.fix_cone_hessian,
    )
    if args.speed_mm_s is not None:
        exp = dataclasses.replace(exp, speed_m_s=args.speed_mm_s * 1e-3)
    if args.x64:
        import jax

        jax.config.update("jax_enable_x64", True)
    cfg = sweep.SweepConfig(
        grid=grid, seed=args.seed, batch_worlds=args.batch_worlds, experiment=exp, x64=args.x64
    )
    result = sweep.run_sweep(cfg, args.out)
    for f in sweep.write_figures(result, args.out):
        print(f)
    print(sweep.summary_table(result))
    return 0


def _no_duplicates(option: str, names) -> None:
    seen = set()
    for n in names:
        if n in seen:
            raise UserInputError(f"{option} lists {n} twice")
        seen.add(n)


def read_contact_runs(path: Path) -> list[dict]:
    """The runs of an existing contact-check JSON (for ``--append``), schema-checked before any
    simulation: an object whose ``runs`` is a list of runs, each with a preset, a variant
    name, a summary and its worlds. Anything else is refused in one line naming the file."""
    from peghole_mjx.validation import load_json_object

    def bad(why: str):
        return CorruptFileError(
            f"--append: {path} is not a contact-check JSON ({why}); give another --out or "
            "move that file away"
        )

    doc = load_json_object(path, bad)
    runs = doc.get("runs")
    if not isinstance(runs, list):
        raise bad('no "runs" list' if runs is None else f'"runs" is a {type(runs).__name__}')
    for i, r in enumerate(runs):
        ok = (
            isinstance(r, dict)
            and isinstance(r.get("preset"), str)
            and isinstance(r.get("variant"), dict)
            and isinstance(r["variant"].get("name"), str)
            and isinstance(r.get("precision", "float32"), str)
            and isinstance(r.get("summary"), dict)
            and isinstance(r.get("worlds"), list)
        )
        if not ok:
            raise bad(f"runs[{i}] lacks its preset, variant name, summary or worlds")
    return runs


def contact_output_bytes(n_runs: int, worlds: int, old_bytes: int = 0) -> int:
    """An upper estimate of the contact-check JSON, bytes (about 0.5 kB per world)."""
    return old_bytes + 64 * 2**10 + n_runs * (4 * 2**10 + worlds * 2**10)


def run_contact_check(args: argparse.Namespace) -> int:
    import json
    import sys

    import numpy as np

    from peghole_mjx import fileio
    from peghole_mjx.experiments import compliance as cx
    from peghole_mjx.experiments import contact_check as cc
    from peghole_mjx.experiments import outputs
    from peghole_mjx.experiments.sweep import clean_json
    from peghole_mjx.provenance import provenance

    if args.x64:
        import jax

        jax.config.update("jax_enable_x64", True)
    presets = args.preset or ["rect-2", "rect-3"]
    names = args.variant or ["experiment", "envs"]
    if "all" in names:
        names = list(cc.VARIANTS)
    unknown = [n for n in names if n not in cc.VARIANTS]
    if unknown:
        raise UserInputError(
            f"unknown variant(s) {', '.join(unknown)}; known: {', '.join(cc.VARIANTS)}"
        )
    _no_duplicates("--preset", presets)
    _no_duplicates("--variant", names)
    for p in presets:  # all of them before the first simulation
        cc.check_preset(p)
    if args.out is not None and args.out.is_dir():
        raise UserInputError(f"--out {args.out} is a folder; give a JSON file path")
    if args.append and args.out is None:
        raise UserInputError("--append needs --out")
    old = []
    if args.out is not None:
        fileio.check_out_file(args.out)
        if args.append and args.out.exists():
            old = read_contact_runs(args.out)
        old_bytes = args.out.stat().st_size if args.out.exists() else 0
        need = contact_output_bytes(len(presets) * len(names), args.worlds, old_bytes)
        fileio.check_room(args.out.parent, need, "--out")
    runs = []
    for p in presets:
        for n in names:
            r = cc.run_variant(p, cc.VARIANTS[n], worlds=args.worlds, seed=args.seed)
            runs.append(r)
            if not args.json:
                print(cc.table_row(r), flush=True)
    cx.check_not_all_nan(
        np.array([w["nan"] for r in runs for w in r["worlds"]], bool),
        "the contact check",
        "the variants' contact settings (step size, contact time constant) or float32 "
        "rounding: try --x64",
    )
    for r in runs:
        if r["summary"].get("failure"):
            print(
                f"warning: {r['preset']} {r['variant']['name']}: {r['summary']['failure']}",
                file=sys.stderr,
            )
    new_keys = {(r["preset"], r["variant"]["name"], r["precision"]) for r in runs}
    kept = [
        r
        for r in old
        if (r["preset"], r["variant"]["name"], r.get("precision", "float32")) not in new_keys
    ]
    runs = kept + runs
    doc = clean_json(
        {
            "bounds": cc.BOUNDS,
            "case": cc.case_dict(),
            "runs": runs,
            **provenance(),
        }
    )
    if args.json:
        print(json.dumps(doc, indent=1))
    if args.out is not None:
        outputs.write_json(args.out, doc)
        if not args.json:
            print(args.out)
    return 0
