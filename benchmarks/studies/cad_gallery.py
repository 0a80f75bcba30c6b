"""CAD gallery: seven peg-hole pairs generated in code, each through ``peghole task make`` and
a scripted rollout on the ``mujoco`` engine (issue 54).

    python -m benchmarks.studies.cad_gallery \
        --out benchmarks/results/studies/cad_gallery_cpu-2core.json

For each part: the ``task make`` time (total and per phase: meshes and pieces, checks,
contact count), the pieces per part and how they were made (exact extrusion, revolution
N-gons, CoACD), the measured (pieces, MuJoCo) and the meshes' (booleans) diametral clearance,
then ``peghole envs rollout --env MeshExtract --set task=DIR --policy scripted --episodes 2
--engine mujoco`` (its Python function) and whether the episodes extracted. A part that is
refused records the one-line reason. Resumable: each finished part is saved under
``<out stem>_parts/`` and not redone. Writes the JSON (rows and provenance) and a CSV beside it.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import manifold3d
import numpy as np
import trimesh

from peghole_mjx.core import progress as prog
from peghole_mjx.core import runtime
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps, loads
from peghole_mjx.envs import rollout
from peghole_mjx.envs.mesh_extract import MeshExtract, default_config
from peghole_mjx.envs.task_make import make_task
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import run_provenance
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.extrusion import mesh_free_travel_mm
from peghole_mjx.geometry.shapes import offset_convex

COLUMNS = (
    "part",
    "radial_clearance_mm",
    "status",
    "make_total_s",
    "meshes_and_pieces_s",
    "checks_s",
    "contacts_s",
    "peg_pieces",
    "hole_pieces",
    "decomposition",
    "sides",
    "pieces_diametral_min_mm",
    "pieces_diametral_max_mm",
    "mesh_diametral_min_mm",
    "mesh_diametral_max_mm",
    "contact_cap",
    "rollout_s",
    "episodes",
    "extracted",
    "note",
)


def _tm(m):
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def _block():
    return manifold3d.Manifold.cube((50, 50, 30), center=True).translate((0, 0, -15))


def _prism_pair(peg_poly, clearance: float, depth: float = 28.0, length: float = 45.0):
    """A prismatic peg resting on the bottom of a blind hole ``clearance`` larger all round
    (edges offset, mitred), ``depth`` deep in a 50 x 50 x 30 mm block; mm."""
    cs = manifold3d.CrossSection([np.asarray(peg_poly, float)])
    peg = manifold3d.Manifold.extrude(cs, length).translate((0, 0, -depth))
    cavity = cs.offset(clearance, manifold3d.JoinType.Miter, 10.0)
    cut = manifold3d.Manifold.extrude(cavity, depth + 1.0).translate((0, 0, -depth))
    return _tm(peg), _tm(_block() - cut)


def triangle(c: float):
    """Equilateral, 16 mm sides, 45 mm long (issue 54's pair)."""
    r = 16.0 / math.sqrt(3)
    tri = np.array(
        [[r * math.cos(a), r * math.sin(a)] for a in np.pi / 2 + 2 * np.pi * np.arange(3) / 3]
    )
    peg = manifold3d.Manifold.extrude(manifold3d.CrossSection([tri]), 45.0).translate((0, 0, -28))
    cut = manifold3d.Manifold.extrude(
        manifold3d.CrossSection([offset_convex(tri, c)]), 29.0
    ).translate((0, 0, -28))
    return _tm(peg), _tm(_block() - cut)


def keyed(c: float):
    """D-shaft r 8 mm, a flat 6 mm from the axis (24 arc points)."""
    a = math.asin(6.0 / 8.0)
    phi = np.linspace(np.pi - a, 2 * np.pi + a, 24)
    return _prism_pair(np.stack([8.0 * np.cos(phi), 8.0 * np.sin(phi)], 1), c)


def spline(c: float):
    """6-tooth spline: root r 7 mm, teeth to r 9 mm, 3 mm wide."""
    pts = []
    w = math.asin(1.5 / 9.0)
    for k in range(6):
        m = 2 * np.pi * k / 6
        for ang, rad in (
            (m - w, 7.0),
            (m - w, 9.0),
            (m + w, 9.0),
            (m + w, 7.0),
            (m + np.pi / 6, 7.0),
        ):
            pts.append([rad * math.cos(ang), rad * math.sin(ang)])
    return _prism_pair(np.array(pts), c)


def tslot(c: float):
    """T-section: a 24 x 6 mm bar on an 8 x 14 mm stem."""
    t = [[-4, -10], [4, -10], [4, 4], [12, 4], [12, 10], [-12, 10], [-12, 4], [-4, 4]]
    return _prism_pair(np.array(t, float), c)


def _rev(profile, segments: int = 64):
    return manifold3d.Manifold.revolve(
        manifold3d.CrossSection([np.asarray(profile, float)]), segments
    )


def stepped_pin(c: float):
    """r 4 mm (18 mm) under r 6 mm (27 mm), a 64-facet export, in a stepped blind bore."""
    peg = _rev([[0, -28], [4, -28], [4, -10], [6, -10], [6, 17], [0, 17]])
    cav = _rev([[0, -28], [4 + c, -28], [4 + c, -10], [6 + c, -10], [6 + c, 1], [0, 1]])
    return _tm(peg), _tm(_block() - cav)


def tapered_pin(c: float):
    """r 4 -> 6 mm over 45 mm, a 64-facet export, in a conical blind bore (radial ``c``)."""
    peg = _rev([[0, -28], [4, -28], [6, 17], [0, 17]])
    cav = _rev([[0, -28], [4 + c, -28], [4 + c + 2 * 29 / 45, 1], [0, 1]])
    return _tm(peg), _tm(_block() - cav)


def two_pin(c: float):
    """A 30 x 12 x 5 mm plate on two pins r 3 mm (16-facet), 20 mm apart, 20 mm into two round
    blind holes."""
    circle = manifold3d.CrossSection.circle(3.0, 16)
    plate = manifold3d.Manifold.cube((30, 12, 5), center=True).translate((0, 0, 4.5))
    pins = [manifold3d.Manifold.extrude(circle, 22.0).translate((x, 0, -20)) for x in (-10, 10)]
    peg = plate + pins[0] + pins[1]
    bore = manifold3d.CrossSection.circle(3.0 + c, 16)
    cuts = [manifold3d.Manifold.extrude(bore, 21.0).translate((x, 0, -20)) for x in (-10, 10)]
    return _tm(peg), _tm(_block() - cuts[0] - cuts[1])


#: name -> (generator, radial clearance mm)
PARTS: dict[str, tuple[Callable, float]] = {
    "triangle": (triangle, 0.25),
    "keyed_d_shaft": (keyed, 0.1),
    "spline_6_tooth": (spline, 0.1),
    "t_slot": (tslot, 0.25),
    "stepped_pin": (stepped_pin, 0.5),
    "tapered_pin": (tapered_pin, 0.25),
    "two_pin_connector": (two_pin, 0.2),
}


def _mesh_travel(out: Path) -> list[float]:
    """The meshes' diametral free travel at the task's start pose, the check's 8 directions."""
    peg, hole = trimesh.load(out / tf.PEG_MESH), trimesh.load(out / tf.HOLE_MESH)
    dirs = [(math.cos(math.pi * k / 8), math.sin(math.pi * k / 8), 0.0) for k in range(8)]
    return [
        mesh_free_travel_mm(peg, hole, u) + mesh_free_travel_mm(peg, hole, [-x for x in u])
        for u in dirs
    ]


def run_part(name: str, work: Path, episodes: int = 2) -> dict[str, Any]:
    """One part: meshes written as STL (mm), ``task make``, clearance, scripted rollout."""
    gen, c = PARTS[name]
    row: dict[str, Any] = dict.fromkeys(COLUMNS, "")
    row.update(part=name, radial_clearance_mm=c)
    peg, hole = gen(c)
    src = work / name
    src.mkdir(parents=True, exist_ok=True)
    peg.export(src / "peg.stl")
    hole.export(src / "hole.stl")
    out = work / f"{name}_task"
    t = time.perf_counter()
    try:
        doc = make_task(src / "peg.stl", src / "hole.stl", out)
    except UserInputError as e:
        row.update(status="refused", make_total_s=round(time.perf_counter() - t, 2), note=str(e))
        return row
    timing, dec = doc["timing_s"], doc["source"]["decomposition"]
    cl = doc["checks"]["clearance"]
    mesh = _mesh_travel(out)
    row.update(
        status="made",
        make_total_s=round(time.perf_counter() - t, 2),
        meshes_and_pieces_s=timing["meshes_and_pieces"],
        checks_s=timing["checks"],
        contacts_s=timing["contacts"],
        peg_pieces=doc["peg"]["hulls"],
        hole_pieces=doc["hole"]["hulls"],
        decomposition=doc["source"]["pieces"],
        sides=dec["peg"].get("sides", ""),
        pieces_diametral_min_mm=round(cl["effective_min_mm"], 4),
        pieces_diametral_max_mm=round(cl["effective_max_mm"], 4),
        mesh_diametral_min_mm=round(min(mesh), 4),
        mesh_diametral_max_mm=round(max(mesh), 4),
        contact_cap=doc["contacts"]["cap"],
    )
    t = time.perf_counter()
    env = MeshExtract(default_config(), {"task": str(out), "engine": "mujoco"})
    res = rollout.rollout(env, rollout.scripted_policy(env), episodes, progress=False)
    ok = np.asarray(res.per_episode["success"]) > 0
    row.update(rollout_s=round(time.perf_counter() - t, 2), episodes=episodes)
    row["extracted"] = int(ok.sum())
    return row


def main(argv: list[str] | None = None) -> int:
    """Run the gallery (resumable per part) and write the JSON and CSV."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--parts", nargs="*", default=list(PARTS), choices=list(PARTS))
    args = ap.parse_args(argv)
    command = ["python", "-m", "benchmarks.studies.cad_gallery", *(argv or sys.argv[1:])]
    parts_dir = args.out.with_name(args.out.stem + "_parts")
    parts_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    bar = prog.bar(len(args.parts), "cad gallery", unit="part")
    with tempfile.TemporaryDirectory() as tmp:
        # as `peghole task make` runs (2026-12-05): the CLI's XLA CPU flag and a compilation
        # cache, here a new one, so that each part compiles as in a first make
        # (docs/research/models.md, time of task make)
        os.environ.setdefault("PEGHOLE_JAX_CACHE", str(Path(tmp) / "jax_cache"))
        runtime.configure()
        for name in args.parts:
            saved = parts_dir / f"{name}.json"
            if saved.exists():
                rows.append(loads(saved.read_text()))
            else:
                bar.set_postfix_str(name)
                row = run_part(name, Path(tmp))
                fileio.write_text(saved, dumps(row, indent=2) + "\n")
                rows.append(row)
            bar.update()
    bar.close()
    doc = {
        "what": "issue 54's CAD gallery: task make and a scripted mujoco rollout per part",
        **run_provenance(command),
        "config": {
            "parts": {k: {"radial_clearance_mm": PARTS[k][1]} for k in args.parts},
            "task_make": "defaults (ContactRun: 4 worlds x 200 env steps per policy, the "
            "scripted run until every world ended an episode), runtime.configure() as the CLI "
            "(XLA CPU flag), a new JAX compilation cache",
            "rollout": "MeshExtract, scripted policy, 2 episodes, mujoco engine, seed 0",
            "resumed_parts_from": str(parts_dir),
        },
        "columns": list(COLUMNS),
        "rows": rows,
    }
    fileio.write_text(args.out, dumps(doc, indent=2) + "\n")
    lines = [",".join(COLUMNS)]
    for r in rows:
        lines.append(",".join(str(r[k]).replace(",", ";") for k in COLUMNS))
    fileio.write_text(args.out.with_suffix(".csv"), "\n".join(lines) + "\n")
    for r in rows:
        print({k: r[k] for k in COLUMNS if k != "note"}, r["note"][:160])
    return 0


if __name__ == "__main__":
    sys.exit(main())
