"""The parsers of ``peghole experiment compliance``, ``sweep`` and ``contact-check``; the
commands are in :mod:`peghole_mjx.experiments.commands`, imported when one runs
(:mod:`peghole_mjx.core.lazy`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg

COMMANDS = "peghole_mjx.experiments.commands"
ENGINE_HELP = (
    "auto (default: mujoco where JAX has no GPU, else mjx; mjx with --x64), mjx (MJX-JAX, all "
    "worlds in one batch, float32 unless --x64) or mujoco (MuJoCo C, float64, all worlds in "
    "one mujoco.batch)"
)


def add_parser(subparsers) -> None:
    """Add ``experiment`` and its three experiments to ``subparsers``."""
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
    c.set_defaults(func=command(f"{COMMANDS}:run"))

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
        help="fixed MJX elliptic-cone Newton Hessian (peghole_mjx/sim/mjx_fixes.py; default on)",
    )
    w.add_argument(
        "--speed-mm-s",
        type=float,
        default=None,
        help="pull speed, mm/s (default 20; the thesis does not state it, see "
        "benchmarks/studies/pull_speed.py)",
    )
    w.add_argument(
        "--x64",
        action="store_true",
        help="run in float64 (float32 does not resolve pulls slower than a few mm/s)",
    )
    w.add_argument("--engine", default="auto", help=ENGINE_HELP)
    w.add_argument("--out", required=True, type=Path, help="output folder (resumable)")
    w.add_argument(
        "--force",
        action="store_true",
        help="replace the results of a sweep of other parameters in --out (without it such "
        "a sweep is refused; a rerun of the same parameters resumes)",
    )
    w.set_defaults(func=command(f"{COMMANDS}:run_sweep"))

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
    k.add_argument("--engine", default="auto", help=ENGINE_HELP)
    k.add_argument(
        "--append",
        action="store_true",
        help="keep the runs already in --out (a rerun of the same preset, variant, "
        "precision and engine replaces its row)",
    )
    k.set_defaults(func=command(f"{COMMANDS}:run_contact_check"))
