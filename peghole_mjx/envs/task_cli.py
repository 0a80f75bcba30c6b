"""``peghole task``: make a task folder (a trainable peg-hole for MeshExtract) and show one.

A command group of its own rather than an option of ``peghole models decompose``: a task folder
is more than the decomposed model (``models decompose`` writes an MJCF of the free peg and a
report): its frames and start pose, its checks on the pieces, the contact cap measured by
rolling out the env, hashes and a format version, and it is what ``--set env.task=DIR`` of
``envs``, ``train`` and ``evaluate`` reads. Both commands run one pipeline
(:mod:`peghole_mjx.envs.task_make`); the commands: :mod:`peghole_mjx.envs.task_commands`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.cli import add_coacd_arguments
from peghole_mjx.geometry.shapes import BUILTINS

COMMANDS = "peghole_mjx.envs.task_commands"


def _common(q: argparse.ArgumentParser) -> None:
    q.add_argument("--out", required=True, type=Path, help="the task folder to write")
    q.add_argument("--friction", type=arg("friction"), default=0.266, help="Coulomb friction")
    q.add_argument(
        "--peg-mass", type=arg("mass_kg"), help="peg mass in kg (default: PLA, 1200 kg/m^3)"
    )
    q.add_argument(
        "--max-hulls",
        type=arg("max_hulls"),
        default=tf.MAX_HULLS,
        help=f"cap of convex pieces per part (default {tf.MAX_HULLS})",
    )
    q.add_argument(
        "--max-contacts",
        type=arg("max_contacts"),
        default=tf.MAX_CONTACTS,
        help="cap of active contacts measured in the env's rollouts (default "
        f"{tf.MAX_CONTACTS}, the env's contact buffer naconmax)",
    )
    q.add_argument(
        "--contact-worlds",
        type=arg("contact_worlds"),
        default=4,
        help="worlds of the rollouts that measure the contacts",
    )
    q.add_argument(
        "--contact-steps",
        type=arg("contact_steps"),
        default=200,
        help="env steps of each of those rollouts (scripted and random policy)",
    )
    q.add_argument("--json", action="store_true", help="print task.json")
    q.add_argument(
        "--force",
        action="store_true",
        help="replace a task folder made with other parameters (only the program's own "
        "files: a folder holding others is refused)",
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("task", help="make a task folder (any peg-hole) for the MeshExtract env")
    tsub = p.add_subparsers(dest="task_cmd", metavar="SUBCOMMAND", required=True)
    m = tsub.add_parser(
        "make",
        help="a task folder from your peg and hole meshes (exact pieces or CoACD)",
        description="PEG_MESH and HOLE_MESH: STL/OBJ/PLY, closed solids, in their assembled "
        "pose (peg fully inserted), +z = extraction. Checks the pair (peg in its hole, no "
        "overlap, no undercut, a blind hole), cuts a part that is an extrusion along +z into "
        "its exact convex pieces and decomposes any other with CoACD, checks the pieces (start "
        "pose, "
        "clearance, an extraction sweep along +z, a drop test), measures the contacts in the "
        "MeshExtract env and writes the folder (all of it or nothing). Then: peghole train "
        "--env MeshExtract --set env.task=DIR.",
    )
    m.add_argument("peg_mesh", type=Path)
    m.add_argument("hole_mesh", type=Path)
    m.add_argument("--units", default="mm", choices=["mm", "cm", "m"], help="mesh units")
    m.add_argument(
        "--pieces",
        default="auto",
        choices=["auto", "exact", "revolve", "coacd"],
        help="auto (default): the exact convex pieces of a part that is an extrusion along +z "
        "(every face horizontal or vertical), N-gons for a pair revolved about +z, CoACD for "
        "any other part; exact: refuse a part that is not an extrusion; revolve: refuse a pair "
        "that is not revolved; coacd: CoACD for both",
    )
    m.add_argument(
        "--coacd-max-s",
        type=arg("coacd_max_s"),
        default=600.0,
        help="seconds CoACD may run on one part (default 600): its time and pieces are "
        "estimated by a coarse run first and a part over this or --max-hulls is refused",
    )
    add_coacd_arguments(
        m,
        vertex_default=tf.MAX_HULL_VERTICES,
        vertex_check="max_hull_vertices",
        vertex_help="vertices per piece: CoACD's decimation and the cap "
        f"(<= {tf.MAX_HULL_VERTICES})",
    )
    _common(m)
    m.set_defaults(func=command(f"{COMMANDS}:cmd_make"))

    b = tsub.add_parser(
        "builtin",
        help="a task folder of a built-in irregular part (exact pieces)",
        description="The built-in parts (geometry/shapes.py): "
        + ", ".join(BUILTINS)
        + ", at a diametral clearance of 0.1-0.4 mm, through the same checks as task make.",
    )
    b.add_argument("name", choices=BUILTINS)
    b.add_argument(
        "--clearance-mm",
        type=arg("builtin_clearance_mm"),
        default=0.2,
        help="diametral clearance, 0.1-0.4 mm (default 0.2)",
    )
    _common(b)
    b.set_defaults(func=command(f"{COMMANDS}:cmd_builtin"))

    s = tsub.add_parser("show", help="check a task folder (format, hashes) and summarise it")
    s.add_argument("folder", type=Path)
    s.add_argument("--json", action="store_true", help="print task.json")
    s.set_defaults(func=command(f"{COMMANDS}:cmd_show"))
