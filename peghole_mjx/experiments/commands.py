"""``peghole experiment compliance``, ``sweep`` and ``contact-check``: the commands (their
parsers: :mod:`peghole_mjx.experiments.cli`)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
from pathlib import Path

import jax
import numpy as np

from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import load_json_object
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.experiments import outputs, report, sweep
from peghole_mjx.experiments.compliance import ExperimentConfig
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import OutputLock
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import PRESETS


def run(args: argparse.Namespace) -> int:
    """``peghole experiment compliance``: the experiment and its summary lines."""
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
    fileio.check_out_dir(args.out, "--out")
    # one writer per output (2026-12-04): a second compliance run into --out is refused
    command = f"peghole experiment compliance --geometry {args.geometry}"
    with OutputLock(args.out, command, inside=True):
        summary, files = report.run_experiment(cfg, args.out)
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
    """``peghole experiment sweep``: the regime sweep (resumable), its figures and table."""
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

    if args.representation is not None:
        resolve_representation(PRESETS[grid.presets[0]], args.representation, impl="jax")
    if args.speed_mm_s is not None:
        sweep.check_value("speed_mm_s", args.speed_mm_s, "--speed-mm-s", "mm/s")
    _check_engine(args)
    exp = ExperimentConfig(
        representation=args.representation,
        compensate_joint_damping=args.compensate_joint_damping,
        fix_cone_hessian=args.fix_cone_hessian,
        engine=args.engine,
    )
    if args.speed_mm_s is not None:
        exp = dataclasses.replace(exp, speed_m_s=args.speed_mm_s * 1e-3)
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    cfg = sweep.SweepConfig(
        grid=grid, seed=args.seed, batch_worlds=args.batch_worlds, experiment=exp, x64=args.x64
    )
    result = sweep.run_sweep(cfg, args.out, force=getattr(args, "force", False))
    for f in sweep.write_figures(result, args.out):
        print(f)
    print(sweep.summary_table(result))
    return 0


def _check_engine(args: argparse.Namespace) -> None:
    """``--engine`` is one of the experiment's engines (``auto`` made concrete in ``args``:
    :func:`~peghole_mjx.experiments.compliance.auto_engine`), and ``--x64`` goes with ``mjx``
    only (the ``mujoco`` engine always runs in float64); else one line."""
    args.engine = cx.check_engine(args.engine, args.x64)
    if args.engine != "mjx" and args.x64:
        raise UserInputError(
            f"--x64 sets MJX's precision; the {args.engine} engine always runs in float64"
        )


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
            and isinstance(r.get("engine", "mjx"), str)
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
    """``peghole experiment contact-check``: each preset under each variant, one row each."""
    _check_engine(args)
    if args.x64:
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
    with contextlib.ExitStack() as stack:
        if args.out is not None:
            fileio.check_out_file(args.out)
            # one writer per output (2026-12-04): two contact checks into one file
            stack.enter_context(OutputLock(args.out, "peghole experiment contact-check"))
        return _contact_check(args, presets, names)


def _contact_check(args: argparse.Namespace, presets: list[str], names: list[str]) -> int:
    old = []
    if args.out is not None:
        if args.append and args.out.exists():
            old = read_contact_runs(args.out)
        old_bytes = args.out.stat().st_size if args.out.exists() else 0
        need = contact_output_bytes(len(presets) * len(names), args.worlds, old_bytes)
        fileio.check_room(args.out.parent, need, "--out")
    runs = []
    for p in presets:
        for n in names:
            r = cc.run_variant(
                p, cc.VARIANTS[n], worlds=args.worlds, seed=args.seed, engine=args.engine
            )
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
    new_keys = {cc.run_key(r) for r in runs}
    kept = [r for r in old if cc.run_key(r) not in new_keys]
    runs = kept + runs
    doc = sweep.clean_json(
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
