"""The commands of ``peghole analyze`` (:mod:`peghole_mjx.analysis.cli` is the parser)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # figures are written to files, also without a display
import matplotlib.pyplot as plt

from peghole_mjx.analysis import claims, dual, figures, jamming, rect
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import command_parameters, writing_files
from peghole_mjx.geometry.specs import get_preset

#: upper estimates of what ``analyze`` writes, checked against the free disk before the work:
#: a figure family's CSV and PNG (the largest, 3.28-3.42, writes 0.55 MB), jamming.png + .json
FIGURE_FAMILY_BYTES = 2 << 20
JAMMING_BYTES = 2 << 20


def cmd_figure(args) -> int:
    """``peghole analyze figure``."""
    ids = figures.resolve(args.id)
    fileio.check_out_dir(args.out)
    fileio.check_room(args.out, len(ids) * FIGURE_FAMILY_BYTES + (1 << 20))
    t0 = time.perf_counter()
    # one writer per folder, only the program's own files replaced (2026-12-05): a family's
    # files depend on its id alone, so a rerun is always of the same parameters
    files = {p: {"family": fid} for fid in ids for p in figures.family_paths(fid, args.out)}
    with writing_files(files, "peghole analyze figure", lock=args.out, has_force=False):
        for fid in ids:
            csv_path, png_path = figures.write_family(fid, args.out)
            print(f"{fid}: {csv_path} {png_path}")
    print(
        f"wrote {len(ids)} famil{'y' if len(ids) == 1 else 'ies'} in "
        f"{time.perf_counter() - t0:.1f} s"
    )
    return 0


#: characters of a claim's evidence shown in the human-readable output (``--json``: all)
EVIDENCE_CHARS = 600


def cmd_claims(args) -> int:
    """``peghole analyze claims``: each claim, then the summary (``--json``: the list)."""
    result = claims.evaluate()
    if args.json:
        print(dumps(result, indent=2))
        return 0
    for c in result:
        verdict = "reproduced" if c["reproduced"] else "not reproduced"
        print(f"{c['id']}: {verdict}. {c['statement']}")
        evidence = dumps(c["evidence"])
        more = f" ... ({len(evidence)} characters; --json for all)"
        cut = evidence if len(evidence) <= EVIDENCE_CHARS else evidence[:EVIDENCE_CHARS] + more
        print(f"    evidence: {cut}")
    print()
    print("\n".join(claims.summary_lines(result)))
    return 0


def _parse_wrench(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise UserInputError(f"--wrench must be three numbers F_x,F_z,M, got {text!r}")
    return vals  # type: ignore[return-value]


def cmd_jamming(args) -> int:
    """``peghole analyze jamming``."""
    if args.geometry == "dual":
        spec = dual.check_geometry(get_preset(args.preset or dual.FIGURE_PRESET))
        plus, _ = dual.category_pairs(spec, args.category)
        label = f"dual {args.preset or dual.FIGURE_PRESET}, state {args.category}"
    else:
        spec = rect.check_geometry(get_preset(args.preset or rect.FIGURE_PRESET))
        if args.case not in (1, 2, 3):
            raise UserInputError("--case must be 1, 2 or 3 for a jamming diagram")
        p = rect.params(spec, 0.0)
        plus = rect.planar_case(spec, args.case, p).plus
        label = f"rect {args.preset or rect.FIGURE_PRESET}, case {args.case}"
    if not hasattr(spec, "kind") or args.geometry != spec.kind:
        raise UserInputError(f"preset {args.preset!r} is not a {args.geometry} peg-hole")
    r = abs(float(plus.w_peg)) / 2
    two_c = float(plus.two_c)
    mu = spec.friction if args.mu is None else args.mu
    if not 0 < args.depth <= spec.length_mm:
        raise UserInputError(f"--depth must be in (0, {spec.length_mm:g}] mm")
    s_min = jamming.two_point_min_depth_mm(r, two_c)
    if args.depth <= s_min:
        raise UserInputError(
            f"--depth {args.depth:g} mm is not deeper than {s_min:.4g} mm, the shallowest "
            f"depth at which this peg ({2 * r:g} mm wide, clearance {two_c:.3g} mm) can be in "
            "two-point contact: no jamming diagram there"
        )
    if not args.out:
        return _jamming(args, spec, label, plus, r, two_c, mu)
    fileio.check_out_dir(args.out)
    fileio.check_room(args.out, JAMMING_BYTES)
    params = command_parameters(args)
    files = {Path(args.out) / name: params for name in ("jamming.png", "jamming.json")}
    # one writer per folder, the program's own files, the same parameters unless --force
    with writing_files(files, "peghole analyze jamming", args.force, lock=args.out):
        return _jamming(args, spec, label, plus, r, two_c, mu)


def _jamming(args, spec, label: str, plus, r: float, two_c: float, mu: float) -> int:
    d = jamming.diagram(args.depth, r, mu)
    out = {
        "geometry": label,
        "depth_mm": args.depth,
        "half_width_mm": r,
        "mu": mu,
        "lambda": d.lam,
        "corners_fx_m": d.corners.tolist(),
    }
    points = []
    if args.wrench:
        Fx, Fz, M = _parse_wrench(args.wrench)
        f, m = jamming.normalise(Fx, Fz, M, r)
        ext = bool(jamming.extracts(Fx, Fz, M, args.depth, r, mu))
        exact = {
            cfg: jamming.jams_exact(Fx, Fz, M, args.depth, r, mu, two_c, cfg) for cfg in ("+", "-")
        }
        out.update(
            wrench_N_N_Nmm=[Fx, Fz, M],
            fx=float(f),
            m=float(m),
            verdict="extracts" if ext else "jams",
            exact_static_equilibrium={"config_+": exact["+"], "config_-": exact["-"]},
        )
        points.append((float(f), float(m), "wrench"))
    if args.out:
        outdir = Path(args.out)
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
        jamming.plot(ax, d, points, title=f"{label}, h = {args.depth:g} mm, lambda = {d.lam:.3g}")
        fig.tight_layout()
        with fileio.atomic_open(outdir / "jamming.png", "wb") as fh:
            fig.savefig(fh, dpi=110, format="png")
        plt.close(fig)
        fileio.write_text(outdir / "jamming.json", dumps(out, indent=2))
        out["png"] = str(outdir / "jamming.png")
    print(dumps(out, indent=2))
    return 0
