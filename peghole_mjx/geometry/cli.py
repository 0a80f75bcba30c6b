"""``peghole models``: check the presets, build scenes, decompose a user's CAD parts.

A command module: ``models check`` and ``models decompose --drop-test`` drop the free peg with
:mod:`peghole_mjx.sim.free` (physics is stepped in ``sim/`` only), the one import of a layer
above geometry (named in ``.importlinter``)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import textwrap
import warnings
from pathlib import Path

import mujoco
from tqdm import tqdm

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import arg, dumps
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import command_parameters, writing_files
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry import check, decompose, mjcf
from peghole_mjx.geometry.parts import (
    RECT_REPRESENTATIONS,
    REPRESENTATIONS,
    resolve_representation,
)
from peghole_mjx.geometry.specs import PRESETS, dual_spec, get_preset, rect_spec, validate
from peghole_mjx.sim import free

_size = arg("size_mm")


def _pair(text: str) -> tuple[float, float]:
    """Parse ``"60.1x40.1"`` (mm) into a pair of sizes."""
    try:
        a, b = text.lower().split("x")
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WxV in mm, e.g. 60.1x40.1, got {text!r}"
        ) from None
    return _size(a), _size(b)


def add_coacd_arguments(
    p: argparse.ArgumentParser,
    vertex_default: int = 64,
    vertex_check: str = "max_ch_vertex",
    vertex_help: str = "vertices per hull cap",
) -> None:
    """CoACD's options (:class:`~peghole_mjx.geometry.decompose.CoacdParams`), shared by
    ``models decompose`` and ``task make``; ``--max-ch-vertex`` differs per command."""
    p.add_argument(
        "--threshold", type=arg("threshold"), default=0.01, help="CoACD concavity threshold"
    )
    p.add_argument(
        "--resolution", type=arg("resolution"), default=2000, help="CoACD sampling resolution"
    )
    p.add_argument("--preprocess-resolution", type=arg("preprocess_resolution"), default=50)
    p.add_argument(
        "--max-convex-hull",
        type=arg("max_convex_hull"),
        default=-1,
        help="CoACD hull cap (-1: none)",
    )
    p.add_argument(
        "--max-ch-vertex", type=arg(vertex_check), default=vertex_default, help=vertex_help
    )
    p.add_argument("--mcts-iterations", type=arg("mcts_iterations"), default=150)
    p.add_argument("--seed", type=arg("seed"), default=0, help="CoACD's seed")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("models", help="peg-hole models: check, build, decompose")
    msub = p.add_subparsers(dest="models_cmd", metavar="SUBCOMMAND", required=True)

    c = msub.add_parser(
        "check",
        help="measure effective clearance and drop-test every preset (MuJoCo C and MJX-JAX)",
        description="For every preset and collision representation: effective clearance by "
        "MuJoCo distance queries, min and max over directions (pass: within 2 % of nominal in "
        "every direction of a round hole, along the axes of a rect hole, whose diagonal travel "
        "is sqrt(2) - 1 = 41.42 % longer by design and shown as 'diag'), a free-peg drop test "
        "in MuJoCo C and MJX-JAX (pass: tip within 1 mm "
        "of the hole bottom; cylinder: MuJoCo C only), the geoms, contact pairs, MJX contacts "
        "allocated, constraint rows and contact cap. Every preset is checked in each of its "
        "representations (dual: capsule, mesh, cylinder; rect: edges, box) unless "
        "--representation is given. Exit status 0 only if every row passes.",
    )
    c.add_argument(
        "--representation",
        action="append",
        help="collision representation to check (repeatable): dual capsule, mesh or cylinder; "
        "rect edges or box; default: all of the preset's",
    )
    c.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    c.add_argument(
        "--preset",
        action="append",
        choices=sorted(PRESETS),
        help="check only this preset (repeatable); default: all six",
    )
    c.add_argument("--no-mjx", action="store_true", help="skip the MJX-JAX drop test (faster)")
    c.add_argument(
        "--out",
        type=Path,
        help="also write the rows with device, versions and date to this JSON file",
    )
    c.add_argument(
        "--force",
        action="store_true",
        help="replace an --out file written with other parameters (only the program's own: a file "
        "it did not write is never replaced)",
    )
    c.set_defaults(func=cmd_check)

    b = msub.add_parser(
        "build",
        help="write a complete scene (iiwa + peg on its flange + hole block + floor) as MJCF",
        description="Write scene.xml (robot) and free_peg.xml (peg alone) to --out. Either "
        "--preset NAME, or --geometry rect|dual with custom dimensions in mm.",
    )
    b.add_argument("--preset", choices=sorted(PRESETS))
    b.add_argument("--geometry", choices=["rect", "dual"])
    b.add_argument("--hole", type=_pair, help="rect: hole W x V in mm, e.g. 60.1x40.1")
    b.add_argument("--peg", type=_pair, help="rect: peg W' x V' in mm, e.g. 59.8x39.8")
    b.add_argument("--hole-radius", type=_size, help="dual: hole radius R in mm")
    b.add_argument("--peg-radius", type=_size, help="dual: peg radius r in mm")
    b.add_argument("--distance", type=_size, help="dual: centre distance D (pegs and holes), mm")
    b.add_argument("--length", type=_size, help="peg length in mm (hole depth = length)")
    b.add_argument(
        "--friction", type=arg("friction"), help="Coulomb friction in [0, 2] (default: preset's)"
    )
    b.add_argument(
        "--representation",
        help="collision representation: dual capsule (default), mesh (exact 16-gon parts) or "
        "cylinder (MuJoCo Warp only); rect edges (default: edge capsules) or box",
    )
    b.add_argument(
        "--contact-cap",
        type=int,
        help="MJX max_contact_points (default: the measured cap of the scene; 0: none)",
    )
    b.add_argument("--out", required=True, type=Path, help="output directory")
    b.add_argument(
        "--force",
        action="store_true",
        help="replace scenes written with other parameters (only the program's own: a file "
        "it did not write is never replaced)",
    )
    b.set_defaults(func=cmd_build)

    d = msub.add_parser(
        "decompose",
        help="convex-decompose a user's peg and hole meshes (CoACD) and write an MJCF",
        description="PEG_MESH and HOLE_MESH: STL/OBJ/PLY, closed solids, in their assembled "
        "pose (peg fully inserted), +z = extraction direction. Reports each decomposition's "
        "deviation from its input surface, warns when the hulls intrude more than "
        "--warn-fraction of the radial clearance, writes user_peghole.xml and report.json.",
    )
    d.add_argument("peg_mesh", type=Path)
    d.add_argument("hole_mesh", type=Path)
    d.add_argument("--out", required=True, type=Path)
    d.add_argument("--units", default="mm", choices=["mm", "cm", "m"], help="mesh units")
    add_coacd_arguments(d)
    d.add_argument(
        "--clearance-mm",
        type=arg("clearance_mm"),
        help="radial clearance; default: measured from the assembled meshes",
    )
    d.add_argument("--warn-fraction", type=arg("warn_fraction"), default=0.25)
    d.add_argument("--friction", type=arg("friction"), default=0.266)
    d.add_argument("--peg-mass", type=arg("mass_kg"), help="peg mass in kg (default: PLA density)")
    d.add_argument(
        "--drop-test",
        action="store_true",
        help="also drop the free peg into the decomposed hole (MuJoCo C)",
    )
    d.add_argument("--json", action="store_true", help="print the report as JSON")
    d.add_argument(
        "--force",
        action="store_true",
        help="replace a user_peghole.xml and report.json written with other parameters (only "
        "the program's own: a file it did not write is never replaced)",
    )
    d.set_defaults(func=cmd_decompose)


def cmd_check(args: argparse.Namespace) -> int:
    if not args.out:
        return _check(args)
    fileio.check_out_file(args.out)
    # one writer, the program's own file, of the same parameters unless --force (2026-12-05)
    with writing_files({args.out: command_parameters(args)}, "peghole models check", args.force):
        return _check(args)


def _check(args: argparse.Namespace) -> int:
    names = args.preset or list(PRESETS)
    jobs = []
    for name in names:
        spec = PRESETS[name]
        own = RECT_REPRESENTATIONS if spec.kind == "rect" else REPRESENTATIONS
        asked = args.representation or list(own)
        for r in asked:  # one line for an unknown name
            if r not in (*REPRESENTATIONS, *RECT_REPRESENTATIONS):
                resolve_representation(spec, r)
        got = [r for r in dict.fromkeys(asked) if r in own]
        if not got:  # only the other geometry's representations were asked for
            resolve_representation(spec, asked[0])
        jobs += [(name, spec, r) for r in got]
    if args.out:  # about 1 kB of JSON per row and the provenance: checked before the work
        fileio.check_room(args.out, 4096 * (len(jobs) + 4) + (1 << 20))
    rows = []
    for name, spec, rep in tqdm(
        jobs, desc="models check", unit="row", file=sys.stderr, disable=len(jobs) == 1 or args.json
    ):
        rows.append(free.check_spec(name, spec, mjx_too=not args.no_mjx, representation=rep))
    if args.out:
        fileio.write_text(
            args.out,
            dumps({**provenance(), "presets": [r.as_dict() for r in rows]}, indent=2) + "\n",
        )
    if args.json:
        print(dumps([r.as_dict() for r in rows], indent=2))
    else:
        hdr = (
            f"{'preset':8} {'repr':8} {'nominal mm':>10} {'eff min mm':>10} {'eff max mm':>10} "
            f"{'clearance err %':>25} {'drop gap mm':>11} {'mjx_jax':>7} {'geoms':>5} "
            f"{'pairs':>5} {'contacts':>8} {'rows':>5} {'cap':>4}  result"
        )
        print(hdr)
        print("-" * len(hdr))
        for r in rows:
            print(
                f"{r.preset:8} {r.representation:8} {r.nominal_clearance_mm:10.4f} "
                f"{r.effective_clearance_mm:10.4f} {r.effective_clearance_max_mm:10.4f} "
                f"{clearance_error_text(r, PRESETS[r.preset].kind):>25} "
                f"{r.drop_test_gap_mm:11.3f} {r.mjx_jax_ok!s:>7} {r.n_geoms:5d} "
                f"{r.n_pairs:5d} {r.contacts_allocated or '-'!s:>8} "
                f"{r.constraint_rows or '-'!s:>5} {r.contact_cap:4d}  "
                + ("pass" if r.passed else "FAIL: " + "; ".join(r.failures))
            )
        print()
        print(textwrap.fill(CLEARANCE_LEGEND, width=100))
    return 0 if all(r.passed for r in rows) else 1


#: below ``peghole models check``'s table: what its clearance column says (docs/research/models.md)
CLEARANCE_LEGEND = (
    "clearance err %: the effective clearance (free travel of the peg, measured by MuJoCo "
    "distance queries) minus the nominal, in % of the nominal; pass: within "
    f"{100 * check.CLEARANCE_TOLERANCE:g} %. Round holes: min..max over the directions, all "
    "checked (the 16-gon's faces and corners). Rect holes: checked along the axes, where the "
    "nominal clearance is defined; 'diag' is the travel along a diagonal, longer by the "
    "geometry of a rectangular gap (sqrt(2) - 1 = +41.42 % for equal gaps on both axes): shown, "
    "not an error."
)


def clearance_error_text(r: check.PresetReport, kind: str) -> str:
    """The clearance column of a check row: ``min..max`` % over the directions for a round
    hole (all checked); for a rect hole the axes' value checked against the tolerance, and the
    diagonal's, when it differs by more than the tolerance, marked ``diag``."""
    lo, hi = r.clearance_error_pct, r.clearance_error_max_pct
    if kind != "rect":
        return f"{lo:+.2f}..{hi:+.2f}"
    if hi - lo <= 100 * check.CLEARANCE_TOLERANCE:
        return f"{lo:+.2f} (axes)"
    return f"{lo:+.2f} (axes; diag {hi:+.2f})"


def spec_from_args(args: argparse.Namespace):
    """A validated spec from ``--preset`` or custom ``--geometry`` dimensions."""
    if args.preset and args.geometry:
        raise UserInputError("give either --preset or --geometry, not both")
    if args.preset:
        spec = get_preset(args.preset)
    elif args.geometry == "rect":
        missing = [f for f in ("hole", "peg", "length") if getattr(args, f) is None]
        if missing:
            raise UserInputError("--geometry rect needs " + ", ".join(f"--{m}" for m in missing))
        spec = rect_spec(args.hole, args.peg, args.length)
    elif args.geometry == "dual":
        need = ("hole_radius", "peg_radius", "distance", "length")
        missing = [f for f in need if getattr(args, f) is None]
        if missing:
            raise UserInputError(
                "--geometry dual needs " + ", ".join("--" + m.replace("_", "-") for m in missing)
            )
        spec = dual_spec(args.hole_radius, args.peg_radius, args.distance, args.length)
    else:
        raise UserInputError("give --preset NAME or --geometry rect|dual with dimensions")
    if getattr(args, "friction", None) is not None:
        spec = validate(dataclasses.replace(spec, friction=args.friction))
    return spec


def cmd_build(args: argparse.Namespace) -> int:
    """Both scenes are written together (both files or neither): ``mjcf.write_scenes``."""
    spec = spec_from_args(args)
    params = command_parameters(args)
    files = {Path(args.out) / name: params for name in ("scene.xml", "free_peg.xml")}
    # one writer per folder, the program's own files, the same parameters unless --force
    with writing_files(files, "peghole models build", args.force, lock=args.out):
        scene, free, rep = mjcf.write_scenes(spec, args.out, args.representation, args.contact_cap)
    print(f"wrote {scene} and {free} (collision representation: {rep})")
    print(
        f"  nominal diametral clearance {spec.clearance_mm:.3f} mm; view with: "
        f"python -m mujoco.viewer --mjcf={scene}"
    )
    return 0


def cmd_decompose(args: argparse.Namespace) -> int:
    fileio.check_out_dir(args.out)
    params = decompose.CoacdParams.from_args(args)
    run = command_parameters(args)
    for key in ("peg_mesh", "hole_mesh"):  # the meshes' bytes, not only their names
        if Path(getattr(args, key)).is_file():
            run[f"{key}_sha256"] = fileio.sha256_file(getattr(args, key))
    files = {Path(args.out) / name: run for name in ("user_peghole.xml", "report.json")}
    # one writer per folder, the program's own files, the same parameters unless --force;
    # checked before CoACD (2026-12-05)
    with writing_files(files, "peghole models decompose", args.force, lock=args.out):
        return _decompose(args, params)


def _decompose(args: argparse.Namespace, params) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", decompose.DecompositionWarning)  # reported below instead
        report = decompose.decompose_parts(
            args.peg_mesh,
            args.hole_mesh,
            args.out,
            units=args.units,
            params=params,
            friction=args.friction,
            peg_mass_kg=args.peg_mass,
            clearance_mm=args.clearance_mm,
            warn_fraction=args.warn_fraction,
        )
    out = report.as_dict()
    if args.drop_test:
        if report.hole_depth_mm is None:
            raise UserInputError("no hole bottom under the peg (a through hole?): no drop test")
        m = mujoco.MjModel.from_xml_path(report.mjcf)
        gap = free.drop_gap_mujoco(m, report.hole_depth_mm * 1e-3)
        out["drop_test_gap_mm"] = gap
        out["drop_test_passed"] = gap <= check.DROP_TOLERANCE_MM
        fileio.write_text(Path(args.out) / "report.json", dumps(out, indent=2))
    if args.json:
        print(dumps(out, indent=2))
    else:
        for part in ("peg", "hole"):
            dv = out[part]
            print(
                f"{part}: {dv['n_hulls']} hulls (<= {dv['hull_vertices_max']} vertices), "
                f"excess max {dv['excess_mm']:.4f} mm (p95 {dv['excess_p95_mm']:.4f} mm)"
            )
        print(
            f"radial clearance {report.radial_clearance_mm:.4f} mm; warn above "
            f"{report.warn_threshold_mm:.4f} mm"
        )
        if "drop_test_gap_mm" in out:
            print(
                f"drop test: tip ends {out['drop_test_gap_mm']:.3f} mm above the hole bottom "
                f"({'pass' if out['drop_test_passed'] else 'FAIL'})"
            )
        print(f"wrote {report.mjcf}")
    for msg in report.warnings:
        print(f"warning: {msg}", file=sys.stderr)
    return 0 if out.get("drop_test_passed", True) else 1
