"""Task folders: a peg-hole as convex pieces with its frames, measurements and checks.

A task folder is what ``peghole task make`` (a user's meshes, CoACD) and ``peghole task
builtin`` (the parts of :mod:`peghole_mjx.geometry.shapes`, exact pieces) write, and what the
``MeshExtract`` env reads (``--set env.task=DIR``): :func:`load_task` returns a
:class:`TaskSpec`, the spec-like object that :func:`peghole_mjx.geometry.mjcf.build_scene`
builds the iiwa scene from, as it does from a preset's spec.

Frames (metres), those of the presets (:mod:`peghole_mjx.geometry.parts`):

* hole frame: origin at the hole mouth, on the peg's axis: x, y of the peg's tip point at
  the start pose (the centre of its lowest downward faces, the peg centred in its clearance),
  z of the top of the hole part; +z the extraction direction (the meshes' +z);
* peg frame: origin at the peg's mount (its top face, above the tip point), +z from the
  mount to the tip, x along the hole frame's -x (the half turn about y with which the peg
  hangs from the flange); the tip at ``(0, 0, length)``.

Files (format :data:`FORMAT_VERSION`), each listed with its SHA-256 in ``manifest.json``:

| file | what |
|---|---|
| ``manifest.json`` | format name and version, package version, each other file's SHA-256 |
| ``task.json`` | lengths, depths, friction, mass, clearances, contact and hull caps, checks |
| ``peg_hulls.json`` | the peg's convex pieces: a list of vertex lists (m, peg frame) |
| ``hole_hulls.json`` | the hole part's convex pieces: a list of vertex lists (m, hole frame) |
| ``peg.stl``, ``hole.stl`` | the input solids, hole frame, start pose (m): for the checks |
| ``scene.xml`` | the env's scene built from these (iiwa, peg on the flange, hole part): to view |

A folder is read only whole: a missing or altered file (its SHA-256 differs), another format
version, hulls beyond the caps are refused in one line (:func:`load_task`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy.spatial import ConvexHull

from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import load_json_object

#: the format of a task folder (``manifest.json``'s ``format``) and its version: a folder of
#: another version is refused (rebuild it with the ``peghole task`` command that made it)
FORMAT = "peghole_mjx task"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
TASK_FILE = "task.json"
PEG_HULLS = "peg_hulls.json"
HOLE_HULLS = "hole_hulls.json"
PEG_MESH = "peg.stl"
HOLE_MESH = "hole.stl"
SCENE = "scene.xml"
#: every file of a folder besides the manifest (all hashed in it)
FILES = (TASK_FILE, PEG_HULLS, HOLE_HULLS, PEG_MESH, HOLE_MESH, SCENE)

#: convex pieces per part allowed: beyond this MJX's compile time and the contact pairs
#: (peg pieces x hole pieces) grow out of hand (the exact dual mesh scene has 34 pairs)
MAX_HULLS = 64
#: vertices per convex piece: CoACD's ``max_ch_vertex`` default, the size MJX-JAX's
#: mesh-mesh separating-axis test is used with in this project
MAX_HULL_VERTICES = 64
#: contact pairs (peg pieces x hole pieces) allowed
MAX_PAIRS = 1024
#: the most active contacts a task may need: MuJoCo Warp's per-world contact buffer of the
#: env config (``naconmax``, 64); a task measured above it is refused
MAX_CONTACTS = 64
#: MJX-JAX merges a convex piece's coplanar faces into polygons of at most this many
#: vertices and down-samples larger ones (``mujoco.mjx._src.mesh._MAX_HULL_FACE_VERTICES``,
#: mujoco-mjx 3.17.0): a task with a larger face runs on the ``mujoco`` engine only
MJX_MAX_FACE_VERTICES = 20
#: the collision representation name of a task's pieces (``env.representation``)
REPRESENTATION = "hulls"


@dataclass(frozen=True, eq=False)
class TaskSpec:
    """The peg-hole of a task folder, read by the scene builder like a preset's spec.

    Lengths in mm like the presets' (``length_mm``: mount to tip; ``hole_depth_mm``: the tip's
    rest depth below the mouth, on the bottom; ``start_depth_mm``: its depth at the start pose,
    ``tip_gap_mm`` above the rest; ``floor_mm``: the hole part's lowest point below the rest),
    the hulls in metres (peg frame, hole frame). ``clearance_mm``: the hulls' effective
    diametral clearance (the least free travel over the directions measured, MuJoCo distance
    queries); ``radial_clearance_mm``: the meshes' (the smallest gap beside the peg).
    """

    name: str
    peg_hulls: tuple[np.ndarray, ...]
    hole_hulls: tuple[np.ndarray, ...]
    length_mm: float
    hole_depth_mm: float
    start_depth_mm: float
    floor_mm: float
    friction: float
    peg_mass_kg: float
    clearance_mm: float
    radial_clearance_mm: float
    contact_measured_max: int
    contact_cap: int
    max_face_vertices: int
    folder: str = ""
    kind: Literal["mesh"] = field(default="mesh", init=False)

    @property
    def n_pairs(self) -> int:
        return len(self.peg_hulls) * len(self.hole_hulls)

    @property
    def mjx_ok(self) -> bool:
        """Whether MJX-JAX collides the pieces as they are (no face down-sampled)."""
        return self.max_face_vertices <= MJX_MAX_FACE_VERTICES


def max_face_vertices(hulls) -> int:
    """The most vertices of one planar face over the convex hulls (coplanar triangles merged),
    the count MJX-JAX limits (:data:`MJX_MAX_FACE_VERTICES`)."""
    most = 0
    for h in hulls:
        hull = ConvexHull(np.asarray(h, float))
        eq = hull.equations  # (nfacet, 4): unit normal and offset
        scale = max(float(np.ptp(h, axis=0).max()), 1e-12)
        key = np.round(eq / np.array([1e-6, 1e-6, 1e-6, 1e-6 * scale]))
        _, inverse = np.unique(key, axis=0, return_inverse=True)
        for f in np.unique(inverse):
            verts = np.unique(hull.simplices[inverse.ravel() == f])
            most = max(most, len(verts))
    return most


def hulls_json(hulls, frame: str) -> str:
    """A hull file's text: the vertex lists in metres (float64 written exactly: repr)."""
    rows = [[[float(v) for v in p] for p in np.asarray(h, float)] for h in hulls]
    return json.dumps({"units": "m", "frame": frame, "hulls": rows}, separators=(",", ":"))


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def manifest_json(files: dict[str, bytes], package_version: str) -> str:
    """``manifest.json`` for the folder's other files (name -> bytes)."""
    return (
        json.dumps(
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "peghole_mjx": package_version,
                "files": {name: sha256_bytes(data) for name, data in sorted(files.items())},
            },
            indent=2,
        )
        + "\n"
    )


def _bad(folder: Path, what: str) -> UserInputError:
    return UserInputError(f"task folder {folder}: {what}")


def read_manifest(folder: str | Path) -> dict[str, Any]:
    """The checked manifest of a task folder: its format and version, and every file of
    :data:`FILES` present with the SHA-256 it lists. One-line errors name what is wrong."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserInputError(
            f"task folder {folder} not found (make one with peghole task make or peghole task "
            "builtin)"
        )
    path = folder / MANIFEST
    if not path.is_file():
        raise _bad(folder, f"no {MANIFEST}: not a task folder (peghole task make writes one)")
    man = load_json_object(
        path,
        lambda why: CorruptFileError(f"task folder {folder}: {MANIFEST} is damaged ({why})"),
    )
    if man.get("format") != FORMAT:
        raise _bad(folder, f"{MANIFEST} is not a {FORMAT!r} manifest")
    version = man.get("format_version")
    if version != FORMAT_VERSION:
        raise _bad(
            folder,
            f"format version {version!r}; this peghole_mjx reads version {FORMAT_VERSION}: "
            "rebuild it with peghole task make (or peghole task builtin)",
        )
    listed = man.get("files")
    if not isinstance(listed, dict):
        raise CorruptFileError(f"task folder {folder}: {MANIFEST} lists no files")
    for name in FILES:
        f = folder / name
        if name not in listed or not f.is_file():
            raise _bad(folder, f"{name} is missing: rebuild the task")
        got = hashlib.sha256(f.read_bytes()).hexdigest()
        if got != listed[name]:
            raise _bad(
                folder,
                f"{name} does not match its SHA-256 in {MANIFEST} (altered or damaged): "
                "rebuild the task",
            )
    return man


def _hulls(folder: Path, name: str, frame: str) -> tuple[np.ndarray, ...]:
    doc = load_json_object(
        folder / name,
        lambda why: CorruptFileError(f"task folder {folder}: {name} is damaged ({why})"),
    )
    rows = doc.get("hulls")
    if doc.get("units") != "m" or doc.get("frame") != frame or not isinstance(rows, list):
        raise CorruptFileError(f"task folder {folder}: {name} is not a {frame}-frame hull file")
    out = []
    for i, h in enumerate(rows):
        a = np.asarray(h, float) if isinstance(h, list) else np.zeros((0, 0))
        if a.ndim != 2 or a.shape[1] != 3 or len(a) < 4 or not np.isfinite(a).all():
            raise CorruptFileError(f"task folder {folder}: {name} hull {i} is not 4+ 3D points")
        out.append(a)
    return tuple(out)


def check_caps(
    n_peg: int, n_hole: int, vertices_max: int, max_hulls: int, max_vertices: int
) -> None:
    """Refuse more convex pieces, vertices or contact pairs than the caps allow, in one line."""
    for label, n in (("peg", n_peg), ("hole", n_hole)):
        if n > max_hulls:
            raise UserInputError(
                f"the {label} has {n} convex pieces, more than the cap of {max_hulls}: "
                "decompose it more coarsely (a higher --threshold, or --max-convex-hull)"
            )
    if vertices_max > max_vertices:
        raise UserInputError(
            f"a convex piece has {vertices_max} vertices, more than the cap of {max_vertices} "
            "(--max-ch-vertex)"
        )
    if n_peg * n_hole > MAX_PAIRS:
        raise UserInputError(
            f"{n_peg} peg pieces x {n_hole} hole pieces = {n_peg * n_hole} contact pairs, more "
            f"than the cap of {MAX_PAIRS}: decompose the parts more coarsely"
        )


def _number(doc: dict, key: str, folder: Path) -> float:
    node: Any = doc
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    if isinstance(node, bool) or not isinstance(node, int | float) or not math.isfinite(node):
        raise CorruptFileError(f"task folder {folder}: {TASK_FILE} has no number {key}")
    return float(node)


def load_task(folder: str | Path) -> TaskSpec:
    """The :class:`TaskSpec` of a task folder, every file checked against its SHA-256 first.

    Cached per folder while its files are unchanged (their sizes and modification times)."""
    folder = Path(folder).expanduser().resolve()
    read_manifest(folder)  # the whole folder checked: format, version, files, hashes
    stamp = tuple((f, (folder / f).stat().st_mtime_ns, (folder / f).stat().st_size) for f in FILES)
    return _load(str(folder), stamp)


@functools.lru_cache(maxsize=8)
def _load(folder_text: str, stamp: tuple) -> TaskSpec:
    folder = Path(folder_text)
    doc = load_json_object(
        folder / TASK_FILE,
        lambda why: CorruptFileError(f"task folder {folder}: {TASK_FILE} is damaged ({why})"),
    )
    peg, hole = _hulls(folder, PEG_HULLS, "peg"), _hulls(folder, HOLE_HULLS, "hole")
    caps = doc.get("caps", {})
    check_caps(
        len(peg),
        len(hole),
        max(len(h) for h in (*peg, *hole)),
        int(caps.get("max_hulls", MAX_HULLS)),
        int(caps.get("max_hull_vertices", MAX_HULL_VERTICES)),
    )
    measured = int(_number(doc, "contacts.measured_max", folder))
    cap = int(_number(doc, "contacts.cap", folder))
    if measured > int(caps.get("max_contacts", MAX_CONTACTS)):
        raise UserInputError(
            f"task folder {folder}: {measured} active contacts measured, more than the cap of "
            f"{caps.get('max_contacts', MAX_CONTACTS)}"
        )
    return TaskSpec(
        name=str(doc.get("name", folder.name)),
        peg_hulls=peg,
        hole_hulls=hole,
        length_mm=_number(doc, "peg.length_mm", folder),
        hole_depth_mm=_number(doc, "poses.rest_depth_mm", folder),
        start_depth_mm=_number(doc, "poses.start_depth_mm", folder),
        floor_mm=_number(doc, "hole.floor_mm", folder),
        friction=_number(doc, "friction", folder),
        peg_mass_kg=_number(doc, "peg.mass_kg", folder),
        clearance_mm=_number(doc, "checks.clearance.effective_min_mm", folder),
        radial_clearance_mm=_number(doc, "checks.clearance.radial_mm", folder),
        contact_measured_max=measured,
        contact_cap=cap,
        max_face_vertices=int(_number(doc, "caps.max_face_vertices", folder)),
        folder=str(folder),
    )


def read_task_json(folder: str | Path) -> dict[str, Any]:
    """``task.json`` of a checked task folder (for reports: ``peghole task show``)."""
    folder = Path(folder)
    read_manifest(folder)
    return load_json_object(
        folder / TASK_FILE,
        lambda why: CorruptFileError(f"task folder {folder}: {TASK_FILE} is damaged ({why})"),
    )
