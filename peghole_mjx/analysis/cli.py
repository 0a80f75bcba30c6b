"""``peghole analyze``: figures, claims and jamming diagrams of the quasi-static model."""

from __future__ import annotations

import math
import time
from pathlib import Path

from peghole_mjx import fileio
from peghole_mjx.errors import UserInputError
from peghole_mjx.validation import arg, dumps, finite_float

#: upper estimates of what ``analyze`` writes, checked against the free disk before the work:
#: a figure family's CSV and PNG (the largest, 3.28-3.42, writes 0.55 MB), jamming.png + .json
FIGURE_FAMILY_BYTES = 2 << 20
JAMMING_BYTES = 2 << 20


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="quasi-static extraction mechanics (thesis Ch 2-3)",
        description="Quasi-static mechanics of dual and rectangular peg-hole extraction.",
    )
    sub = p.add_subparsers(dest="analyze_cmd", metavar="SUBCOMMAND")

    f = sub.add_parser(
        "figure",
        help="reproduce a figure family (CSV + PNG)",
        description="Evaluate a thesis figure family with the thesis's parameters and write "
        "fig_<ID>.csv (one row per parameter combination: boundary depths h_start_mm, "
        "h_end_mm and region_length_mm) and fig_<ID>.png. IDs: 2.11, 2.12-2.14, 2.15, "
        "2.16-2.18, 3.12, 3.13-3.18, 3.19-3.27, 3.28-3.42, a figure inside a family "
        "(e.g. 2.13), or all.",
    )
    f.add_argument("id", help="figure family id, a figure number inside one, or 'all'")
    f.add_argument("--out", required=True, help="output directory")
    f.set_defaults(func=_figure)

    c = sub.add_parser(
        "claims",
        help="evaluate the analytic claims C2.1-C2.5, C3.1-C3.5",
        description="Evaluate each analytic claim of the thesis against the model and print "
        "id, statement, reproduced and evidence.",
    )
    c.add_argument("--json", action="store_true", help="print a JSON list")
    c.set_defaults(func=_claims)

    j = sub.add_parser(
        "jamming",
        help="jamming diagram (eqs 2.50-2.52) and a wrench's verdict",
        description="Whitney jamming parallelogram of a two-point contact at a depth, in "
        "(F_x/F_z, M/(r F_z)) with M about the middle of the (effective) peg tip, "
        "counter-clockwise positive, F_z > 0 pulling out. Optionally classify a wrench "
        "(extracts / jams), checked also by the exact static-equilibrium test.",
    )
    j.add_argument("--geometry", choices=("dual", "rect"), required=True)
    j.add_argument("--preset", help="peg-hole preset (default dual-2 or rect-1)")
    j.add_argument("--category", default="5", help="dual contact category 5, 10 or 9 (default 5)")
    j.add_argument("--case", type=int, default=2, help="rect case 1, 2 or 3 (default 2)")
    j.add_argument("--depth", type=finite_float, required=True, help="insertion depth h (mm)")
    j.add_argument(
        "--mu", type=arg("friction"), help="friction coefficient in [0, 2] (default: the preset's)"
    )
    j.add_argument("--wrench", help="F_x,F_z,M in N,N,N mm (e.g. 0.5,2,10)")
    j.add_argument("--out", help="directory for jamming.png and jamming.json")
    j.set_defaults(func=_jamming)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _figure(args) -> int:
    from peghole_mjx.analysis import figures

    ids = figures.resolve(args.id)
    fileio.check_out_dir(args.out)
    fileio.check_room(args.out, len(ids) * FIGURE_FAMILY_BYTES + (1 << 20))
    t0 = time.perf_counter()
    for fid in ids:
        csv_path, png_path = figures.write_family(fid, args.out)
        print(f"{fid}: {csv_path} {png_path}")
    print(
        f"wrote {len(ids)} famil{'y' if len(ids) == 1 else 'ies'} in "
        f"{time.perf_counter() - t0:.1f} s"
    )
    return 0


def _claims(args) -> int:
    from peghole_mjx.analysis import claims

    result = claims.evaluate()
    if args.json:
        print(dumps(result, indent=2))
        return 0
    for c in result:
        print(f"{c['id']}: reproduced={str(c['reproduced']).lower()}  {c['statement']}")
        print("    evidence: " + dumps(c["evidence"])[:600])
    return 0


def _parse_wrench(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise UserInputError(f"--wrench must be three numbers F_x,F_z,M, got {text!r}")
    return vals  # type: ignore[return-value]


def _jamming(args) -> int:
    from peghole_mjx.analysis import dual, jamming, rect
    from peghole_mjx.geometry.specs import get_preset

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
    if args.out:
        fileio.check_out_dir(args.out)
        fileio.check_room(args.out, JAMMING_BYTES)
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
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

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
