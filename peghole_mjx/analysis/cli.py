"""``peghole analyze``: figures, claims and jamming diagrams of the quasi-static model.

The parser; the commands are in :mod:`peghole_mjx.analysis.commands`, imported when one runs
(:mod:`peghole_mjx.core.lazy`: ``peghole --help`` does not import matplotlib's pyplot, 1 s on the
2-core CPU, 2026-12-02)."""

from __future__ import annotations

from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg, finite_float


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
    f.set_defaults(func=command("peghole_mjx.analysis.commands:cmd_figure"))

    c = sub.add_parser(
        "claims",
        help="evaluate the analytic claims C2.1-C2.5, C3.1-C3.5",
        description="Evaluate each analytic claim of the thesis against the model at the "
        "thesis's parameters and print id, verdict, statement and evidence, then a summary: "
        "how many are reproduced, one line per claim and, for one not reproduced, the regime "
        "where it holds if any (a compliant rotational stiffness, erratum E12).",
    )
    c.add_argument(
        "--json",
        action="store_true",
        help="print a JSON list (id, statement, reproduced, evidence, regime) instead",
    )
    c.set_defaults(func=command("peghole_mjx.analysis.commands:cmd_claims"))

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
    j.add_argument(
        "--force",
        action="store_true",
        help="replace a jamming.png and jamming.json written with other parameters (only the "
        "program's own: a file it did not write is never replaced)",
    )
    j.set_defaults(func=command("peghole_mjx.analysis.commands:cmd_jamming"))
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
