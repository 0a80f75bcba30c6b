"""``peghole task make | builtin | show``: the commands (their parser:
:mod:`peghole_mjx.envs.task_cli`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.envs.task_make import ContactRun, TaskCaps, make_builtin, make_task
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.decompose import CoacdParams


def _caps_and_run(args: argparse.Namespace, vertices: int = tf.MAX_HULL_VERTICES):
    caps = TaskCaps(args.max_hulls, vertices, args.max_contacts)
    return caps, ContactRun(args.contact_worlds, args.contact_steps)


def _report(doc: dict, args: argparse.Namespace, out: Path | None = None) -> int:
    if args.json:
        print(dumps(doc, indent=2))
        return 0
    c, k = doc["checks"], doc["contacts"]
    print(f"task {doc['name']} ({doc['source'].get('pieces', '?')} pieces)")
    print(
        f"  pieces: peg {doc['peg']['hulls']}, hole {doc['hole']['hulls']} (<= "
        f"{max(doc['peg']['hull_vertices_max'], doc['hole']['hull_vertices_max'])} vertices); "
        f"contact pairs {k['pairs']}"
    )
    cl = c["clearance"]
    print(
        f"  clearance: radial {cl['radial_mm']:.4f} mm (meshes); diametral "
        f"{cl['effective_min_mm']:.4f}-{cl['effective_max_mm']:.4f} mm (pieces)"
    )
    print(
        f"  peg length {doc['peg']['length_mm']:.2f} mm, start depth "
        f"{doc['poses']['start_depth_mm']:.2f} mm; drop test {c['drop_test']['gap_mm']:+.3f} mm; "
        f"sweep clear ({c['extraction_sweep']['steps']} steps)"
    )
    print(
        f"  contacts: at most {k['measured_max']} active, cap {k['cap']}; engines "
        f"{', '.join(doc['caps']['engines'])}; made in {doc['timing_s'].get('total', '?')} s"
    )
    for w in c["hull_intrusion"]["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    if out is not None:
        print(f"wrote {out}: peghole envs rollout --env MeshExtract --set task={out}")
    return 0


def _shared(args: argparse.Namespace, caps: TaskCaps, run: ContactRun) -> dict:
    """The keyword arguments ``make_task`` and ``make_builtin`` share."""
    return {
        "friction": args.friction,
        "peg_mass_kg": args.peg_mass,
        "caps": caps,
        "contacts": run,
        "progress": not args.json,
        "force": args.force,
    }


def cmd_make(args: argparse.Namespace) -> int:
    params = CoacdParams.from_args(args)
    caps, run = _caps_and_run(args, args.max_ch_vertex)
    doc = make_task(
        args.peg_mesh,
        args.hole_mesh,
        args.out,
        units=args.units,
        params=params,
        pieces=args.pieces,
        coacd_max_s=args.coacd_max_s,
        **_shared(args, caps, run),
    )
    return _report(doc, args, args.out)


def cmd_builtin(args: argparse.Namespace) -> int:
    caps, run = _caps_and_run(args)
    doc = make_builtin(args.name, args.clearance_mm, args.out, **_shared(args, caps, run))
    return _report(doc, args, args.out)


def cmd_show(args: argparse.Namespace) -> int:
    tf.load_task(args.folder)  # every file, hash and cap checked
    try:
        doc = tf.read_task_json(args.folder)
        return _report(doc, args)
    except (KeyError, TypeError) as exc:
        raise UserInputError(f"task folder {args.folder}: task.json lacks {exc}") from None
