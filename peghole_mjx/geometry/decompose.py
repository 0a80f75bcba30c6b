"""User CAD parts: load, convex-decompose with CoACD, measure the deviation, write an MJCF.

Convention for user meshes: both parts in their ASSEMBLED pose (peg fully in the hole), in the
same frame, +z the extraction direction, units given by ``units`` (CAD default: mm).

The deviation of a decomposition is measured, not assumed: points sampled on the surface of
the union of hulls are projected onto the input surface. ``excess`` is the largest distance of
a hull point lying OUTSIDE the input solid (material the simulation has and the part has not:
for a hole block, this is how far the hulls intrude into the hole). A warning is raised when
the excess of either part exceeds ``WARN_FRACTION`` of the radial clearance, because the
hulls then eat the clearance.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import RANGES, check, dumps
from peghole_mjx.files import fileio
from peghole_mjx.geometry.mjcf import SimOptions, _set_options
from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec, RectSpec

#: warn when the hulls' excess deviation exceeds this fraction of the radial clearance
WARN_FRACTION = 0.25
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def _cad(name: str):
    """Module ``name`` of the ``cad`` extra, or a one-line error naming the install command."""
    return optional_import(name, "decomposing CAD parts (peghole models decompose)")


class DecompositionWarning(UserWarning):
    """The convex decomposition deviates from the part by a large fraction of the clearance."""


#: the CoACD parameters a command sets (``add_coacd_arguments``), each range-checked
COACD_OPTIONS = (
    "threshold",
    "max_convex_hull",
    "preprocess_resolution",
    "resolution",
    "mcts_iterations",
    "max_ch_vertex",
    "seed",
)


@dataclass(frozen=True)
class CoacdParams:
    """CoACD parameters exposed on the command line (see ``coacd.run_coacd``)."""

    threshold: float = 0.01  # concavity threshold: smaller = more, tighter hulls
    max_convex_hull: int = -1
    preprocess_mode: str = "auto"
    preprocess_resolution: int = 50
    resolution: int = 2000
    mcts_nodes: int = 20
    mcts_iterations: int = 150
    mcts_max_depth: int = 3
    max_ch_vertex: int = 64  # MJX: keep hulls small (stack notes: <= 64)
    seed: int = 0

    @classmethod
    def from_args(cls, args: Any) -> CoacdParams:
        """The options of a command's parsed arguments (``add_coacd_arguments``)."""
        return cls(**{n: getattr(args, n) for n in COACD_OPTIONS})

    def __post_init__(self):
        """Refuse values CoACD aborts on or never finishes with (ranges in
        ``peghole_mjx.core.validation.RANGES``)."""
        for name in COACD_OPTIONS:
            check(name, getattr(self, name), f"CoACD {name}")
        if self.preprocess_mode not in ("auto", "on", "off"):
            raise UserInputError("CoACD preprocess_mode must be auto, on or off")


def load_mesh(path: str | Path, units: str = "mm"):
    """Load an STL/OBJ/PLY file as one watertight trimesh in metres.

    Raises :class:`UserInputError` for a missing file, an unreadable or empty mesh, or a mesh
    that is not watertight (open edges: no inside/outside, no volume).
    """
    trimesh = _cad("trimesh")

    path = Path(path)
    if units not in UNITS:
        raise UserInputError(f"unknown units {units!r}; choose one of {sorted(UNITS)}")
    if not path.is_file():
        raise UserInputError(f"mesh file not found: {path}")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except ImportError:  # trimesh guesses a text encoding (an optional module) for garbage
        raise UserInputError(f"cannot read mesh {path}: not a valid STL, OBJ or PLY file") from None
    except Exception as exc:  # trimesh raises many types for malformed files
        raise UserInputError(f"cannot read mesh {path}: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise UserInputError(f"{path} holds no triangles")
    mesh.merge_vertices()
    if not mesh.is_watertight:
        from trimesh.grouping import group_rows  # the cad extra: imported where it is used

        open_edges = len(group_rows(mesh.edges_sorted, require_count=1))
        raise UserInputError(
            f"{path} is not a closed manifold solid ({open_edges} open edges): "
            "repair it in CAD (close holes, remove duplicate faces) and export again"
        )
    if mesh.volume <= 0:
        mesh.invert()
    mesh.apply_scale(UNITS[units])
    return mesh


#: the most faces a mesh given to CoACD may have (decided 2026-12-04): CoACD on a 786 000-face
#: mesh ran over 15 minutes; a peg or hole part exported from CAD needs far fewer
COACD_MAX_FACES = 200_000

#: seconds the CoACD child is given to end after SIGTERM before it is killed
COACD_KILL_AFTER_S = 2.0
#: seconds between two looks of the parent at a CoACD child's log
WATCH_S = 0.25


def _in_child(args: list[str], stdout: Path | None = None, watch=None) -> int:
    """``python ARGS`` in a child process; its exit status. CoACD is native code that holds
    the GIL and ignores SIGINT/SIGTERM for its whole run: here the parent waits, calling
    ``watch()`` every :data:`WATCH_S` seconds (which may raise to stop the child), and on
    Ctrl-C or SIGTERM (the CLI's ``Terminated``) or any error it terminates the child (SIGKILL
    after :data:`COACD_KILL_AFTER_S`) before re-raising. ``stdout``: a file the child's
    standard output is appended to; its standard error is dropped (a child reports in its
    result files, :mod:`peghole_mjx.geometry.coacd_child`)."""
    with open(stdout if stdout is not None else os.devnull, "ab") as out:
        proc = subprocess.Popen(
            [sys.executable, *args], stdin=subprocess.DEVNULL, stdout=out,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            while True:
                try:
                    return proc.wait(WATCH_S)
                except subprocess.TimeoutExpired:
                    if watch is not None:
                        watch()
        finally:
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(COACD_KILL_AFTER_S)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


def run_coacd(mesh, params: CoacdParams = CoacdParams(), watch=None, log=None) -> list[np.ndarray]:
    """Convex hulls (list of vertex arrays, metres) of ``mesh`` by CoACD.

    A mesh of more than :data:`COACD_MAX_FACES` faces is refused in one line. CoACD runs in a
    child process (:func:`_in_child`) that Ctrl-C and SIGTERM end. With ``log`` (an object
    with ``feed(text)``, :class:`peghole_mjx.geometry.coacd_budget.CoacdLog`), CoACD's log is
    fed to it as it is written and ``watch(log)`` called after each look (it may raise to stop
    the run)."""
    trimesh = _cad("trimesh")
    _cad("coacd")  # a missing extra is named here, not in the child

    n_faces = len(mesh.faces)
    if n_faces > COACD_MAX_FACES:
        name = getattr(mesh, "metadata", {}).get("file_name") or "the mesh"
        raise UserInputError(
            f"{name} has {n_faces} faces, more than CoACD is given ({COACD_MAX_FACES}): "
            "simplify it first, e.g. trimesh's mesh.simplify_quadric_decimation(face_count="
            f"{COACD_MAX_FACES // 2}) or MeshLab's Quadric Edge Collapse Decimation, and export "
            "it again"
        )
    kwargs = dict(
        threshold=params.threshold,
        max_convex_hull=params.max_convex_hull,
        preprocess_mode=params.preprocess_mode,
        preprocess_resolution=params.preprocess_resolution,
        resolution=params.resolution,
        mcts_nodes=params.mcts_nodes,
        mcts_iterations=params.mcts_iterations,
        mcts_max_depth=params.mcts_max_depth,
        decimate=True,  # enforce max_ch_vertex (CoACD ignores it otherwise)
        max_ch_vertex=params.max_ch_vertex,
        seed=params.seed,
    )
    with tempfile.TemporaryDirectory(prefix="peghole-coacd-") as tmp:
        folder = Path(tmp)
        np.savez(folder / "mesh.npz", vertices=mesh.vertices, faces=mesh.faces)
        options = {**kwargs, "log_level": "error" if log is None else "info"}
        (folder / "options.json").write_text(json.dumps(options))
        path = folder / "coacd.log"
        path.touch()
        with open(path, "rb") as f:

            def look() -> None:
                log.feed(f.read().decode(errors="replace"))
                if watch is not None:
                    watch(log)

            argv = ["-m", "peghole_mjx.geometry.coacd_child", tmp]
            code = _in_child(argv, path, watch=None if log is None else look)
            if log is not None:
                log.feed(f.read().decode(errors="replace"))
        if (folder / "error.txt").exists():
            raise UserInputError(f"CoACD failed: {(folder / 'error.txt').read_text()}")
        if not (folder / "pieces.npz").exists():
            raise UserInputError(
                f"CoACD ended without a result (its process exited with {code}: out of memory "
                "or a crash); simplify the mesh or change the CoACD parameters"
            )
        with np.load(folder / "pieces.npz") as z:
            parts = [(z[f"v{i}"], z[f"f{i}"]) for i in range(len(z.files) // 2)]
    hulls = []
    for verts, faces in parts:
        hull = trimesh.Trimesh(verts, faces).convex_hull
        hulls.append(np.asarray(hull.vertices))
    return hulls


#: the most point x triangle pairs :func:`contains` sums winding numbers over (else trimesh's
#: ray test); and per chunk of points (memory: about 200 bytes a pair)
WINDING_MAX_PAIRS = 200_000_000
WINDING_CHUNK_PAIRS = 250_000


def contains(mesh, pts: np.ndarray, on_surface: bool | None = None) -> np.ndarray:
    """Which of ``pts`` lie inside the closed, outward-oriented ``mesh``: its generalised
    winding number at each point (the solid angles of its triangles summed, Van Oosterom and
    Strackee) above one half, in NumPy; trimesh's ray test (``mesh.contains``) past
    :data:`WINDING_MAX_PAIRS`. Decided 2026-12-05 (docs/research/models.md, time of task
    make): trimesh's ray test without embree took 20 s of the stepped pin's 22 s of checks
    (40 000 points, its 64-facet bore), the winding numbers give the same verdicts. A point
    whose winding number is not near a whole number (on the surface, or in the plane of a
    face beside it, where the solid angles' signed zeros decide) takes the ray test, or is
    given ``on_surface`` when that is not None (a caller measuring depth: such a point is
    on the surface, depth zero; the ray test took 7.6 s of a fine pair's 10 s of checks)."""
    pts = np.asarray(pts, float)
    tri = np.asarray(mesh.triangles, float)
    if len(pts) * len(tri) > WINDING_MAX_PAIRS or not len(pts):
        return np.asarray(mesh.contains(pts), bool)
    step = max(1, WINDING_CHUNK_PAIRS // len(tri))
    w = np.empty(len(pts))
    for i in range(0, len(pts), step):
        p = pts[i : i + step, None, :]
        a, b, c = tri[None, :, 0] - p, tri[None, :, 1] - p, tri[None, :, 2] - p
        la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        ab = np.einsum("pfi,pfi->pf", a, b)
        bc = np.einsum("pfi,pfi->pf", b, c)
        ca = np.einsum("pfi,pfi->pf", c, a)
        prod = la * lb * lc
        half = np.arctan2(det, prod + ab * lc + bc * la + ca * lb)
        # a point in a triangle's plane sees no solid angle of it (the atan2 of a signed zero
        # would give +-pi)
        w[i : i + step] = np.where(np.abs(det) <= 1e-12 * prod, 0.0, half).sum(1)
    w /= 2 * np.pi
    inside = w > 0.5
    # a point on the surface (or in the plane of a face it touches) has no whole winding
    # number: those few go to the ray test, as before
    edge = np.abs(w - np.round(w)) > 0.25
    if edge.any() and on_surface is not None:
        inside[edge] = on_surface
    elif edge.any():
        inside[edge] = np.asarray(mesh.contains(pts[edge]), bool)
    return inside


def distance_to(mesh, pts: np.ndarray) -> np.ndarray:
    """Distance (m) from each of ``pts`` (m) to the surface of ``mesh`` (m), computed in
    millimetres: trimesh 5.2's closest point on a triangle of a metre-scaled fine mesh falls
    back to the triangle's corners (its zero tolerance): 0.265 mm for a 0.15 mm intrusion of
    a 9,216-face hole (2026-12-05, ``tests/test_coacd_budget.py``)."""
    trimesh = _cad("trimesh")
    _cad("rtree")  # trimesh's proximity queries
    mesh_mm = mesh.copy()
    mesh_mm.apply_scale(1.0 / MM)
    _, dist, _ = trimesh.proximity.closest_point(mesh_mm, np.asarray(pts, float) / MM)
    return np.asarray(dist) * MM


@dataclass(frozen=True)
class Deviation:
    """Deviation of a set of hulls from the input surface, mm."""

    excess_mm: float  # max distance of hull-surface points outside the input solid
    excess_p95_mm: float
    n_hulls: int
    hull_vertices_max: int


def measure_deviation(
    mesh, hulls: list[np.ndarray], n_samples: int = 20000, seed: int = 0
) -> Deviation:
    """Sample the hulls' surfaces; measure how far the points outside the part lie from it."""
    trimesh = _cad("trimesh")

    rng = np.random.default_rng(seed)
    hull_meshes = [trimesh.Trimesh(h).convex_hull for h in hulls]
    areas = np.array([h.area for h in hull_meshes])
    counts = rng.multinomial(n_samples, areas / areas.sum())
    pts = np.concatenate(
        [
            trimesh.sample.sample_surface(h, max(int(c), 1), seed=int(rng.integers(1 << 31)))[0]
            for h, c in zip(hull_meshes, counts, strict=True)
        ]
    )
    outside = ~contains(mesh, pts)  # hull surface where the part has no material
    excess = np.zeros(0)  # every point inside (or on) the part: no excess
    if outside.any():
        excess = distance_to(mesh, pts[outside])
    return Deviation(
        excess_mm=float(excess.max() / MM) if len(excess) else 0.0,
        excess_p95_mm=float(np.percentile(excess, 95) / MM) if len(excess) else 0.0,
        hull_vertices_max=max(len(h) for h in hulls),
        n_hulls=len(hulls),
    )


def estimate_radial_clearance_mm(peg, hole) -> float:
    """Radial clearance of the assembled pair: the smallest gap between the peg's side faces
    (normals within 10 degrees of horizontal) and the hole surface, mm."""
    trimesh = _cad("trimesh")

    pts, face_idx = trimesh.sample.sample_surface(peg, 20000, seed=1)
    side = np.abs(peg.face_normals[face_idx][:, 2]) < math.sin(math.radians(10))
    z_lo, z_hi = hole.bounds[:, 2]
    side &= (pts[:, 2] > z_lo) & (pts[:, 2] < z_hi)
    if not side.any():
        raise UserInputError(
            "the peg's side faces do not overlap the hole in height: "
            "export both parts in their assembled pose, +z = extraction"
        )
    hole_side = hole.submesh(
        [np.abs(hole.face_normals[:, 2]) < math.sin(math.radians(10))], append=True
    )
    dist = distance_to(hole_side, pts[side])
    return float(dist.min() / MM)


#: how deep the peg may reach into the hole part (and the hole into the peg) in the assembled
#: pose, mm: MuJoCo's steady contact penetration (micrometres); parts that touch pass
INTERFERENCE_TOL_MM = 1e-3
#: surface points sampled on each part for the peg-hole checks (plus every vertex)
CHECK_SAMPLES = 4000


def _fmt_mm(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v / MM:.3g}" for v in p) + ") mm"


def _surface_points(mesh, n: int, seed: int) -> np.ndarray:
    trimesh = _cad("trimesh")
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.concatenate([np.asarray(pts), np.asarray(mesh.vertices)])


def _deepest_inside(solid, pts: np.ndarray) -> tuple[float, np.ndarray | None]:
    """Largest depth (m) of ``pts`` inside ``solid`` and where (None if none is inside)."""
    inside = pts[contains(solid, pts, on_surface=False)]  # a surface point: depth zero
    if not len(inside):
        return 0.0, None
    dist = distance_to(solid, inside)
    i = int(np.argmax(dist))
    return float(dist[i]), inside[i]


@dataclass(frozen=True)
class Overlap:
    """The two solids' intersection by a boolean (manifold3d)."""

    volume_mm3: float
    bounds: np.ndarray | None  # (2, 3) m, None when the solids share no volume


def overlap(peg, hole) -> Overlap | None:
    """The intersection of two watertight meshes (metres) by manifold3d's boolean, or None
    when manifold3d cannot read one of them. Decided 2026-12-05 (docs/research/models.md,
    bounded CoACD): the sampled interference check took 29 s of a 3,072 / 9,216-face pair's
    31 s in winding numbers; the boolean takes 0.02 s and bounds the points worth testing."""
    manifold3d = _cad("manifold3d")
    solids = []
    for mesh in (peg, hole):
        solid = manifold3d.Manifold(
            manifold3d.Mesh64(
                vert_properties=np.asarray(mesh.vertices, float) / MM,
                tri_verts=np.asarray(mesh.faces, np.uint32),
            )
        )
        if solid.status() != manifold3d.Error.NoError:
            return None
        solids.append(solid)
    inter = solids[0] ^ solids[1]
    if inter.is_empty():
        return Overlap(0.0, None)
    box = np.asarray(inter.bounding_box(), float).reshape(2, 3) * MM
    return Overlap(float(inter.volume()), box)


def _within(pts: np.ndarray, box: np.ndarray | None, pad: float) -> np.ndarray:
    """The points of ``pts`` inside ``box`` grown by ``pad`` (none when ``box`` is None)."""
    if box is None:
        return pts[:0]
    keep = np.all((pts >= box[0] - pad) & (pts <= box[1] + pad), axis=1)
    return pts[keep]


def check_assembly(peg, hole, units: str = "mm") -> None:
    """Refuse parts that are not a peg in its hole, before any decomposition or MJCF.

    ``peg`` and ``hole`` are watertight meshes in metres in the assembled pose. Each
    failed condition raises :class:`UserInputError` naming it, in this order:

    1. size: each part's largest extent lies in ``RANGES["cad_part_mm"]`` (wrong ``--units``
       give a part a thousand times too small or large); the two parts are not one solid
       (equal bounds and volume: the same file given twice);
    2. peg inside the hole: the peg reaches below the hole part's top, and every sampled point
       of the peg within the hole part's height is surrounded by the hole part (a horizontal
       ray in each of +x, -x, +y, -y meets it) - a peg beside the block, or the two files
       swapped, fail;
    3. no interference: no sampled point of either part lies deeper than
       :data:`INTERFERENCE_TOL_MM` inside the other (the depth, where, and the intersection
       volume); only the points within the bounds of the parts' intersection (a boolean,
       :func:`overlap`) are tested, since no other point can lie inside the other part;
    4. extractable along +z: no sampled point of the peg has hole material straight above it
       (the upward ray from it meets the hole part beyond the tolerance): no undercut.

    The checks are sampled (:data:`CHECK_SAMPLES` surface points per part and every vertex):
    a feature narrower than the sample spacing can escape them.
    """
    rng = RANGES["cad_part_mm"]
    for label, mesh in (("peg", peg), ("hole", hole)):
        extent = float(np.max(mesh.extents)) / MM
        if rng.problem(extent):
            raise UserInputError(
                f"not a peg-hole (part size): the {label} part is {extent:.6g} mm across "
                f"with --units {units}, outside [{rng.lo:g}, {rng.hi:g}] mm "
                f"({rng.why_lo if extent < rng.lo else rng.why_hi}); are the units right?"
            )
    tol = INTERFERENCE_TOL_MM * MM
    same_bounds = np.allclose(peg.bounds, hole.bounds, rtol=0.0, atol=tol)
    if same_bounds and abs(peg.volume - hole.volume) <= 1e-6 * abs(hole.volume):
        raise UserInputError(
            "not a peg-hole (two parts): the peg and the hole part are the same solid (equal "
            "bounds and volume): give the peg's file, then the hole part's"
        )
    top = float(hole.bounds[1, 2])
    if peg.bounds[0, 2] >= top - tol:
        raise UserInputError(
            "not a peg-hole (peg inside the hole): the peg's lowest point is "
            f"{(peg.bounds[0, 2] - top) / MM:.4g} mm above the hole part's top; export both "
            "parts in their assembled pose (peg fully inserted), +z = extraction"
        )
    peg_pts = _surface_points(peg, CHECK_SAMPLES, seed=2)
    z = peg_pts[:, 2]
    below = peg_pts[(z < top - tol) & (z > hole.bounds[0, 2] + tol)]  # within the block's height
    if not len(below):
        raise UserInputError(
            "not a peg-hole (peg inside the hole): no part of the peg lies within the hole "
            "part's height; export both parts in their assembled pose (peg fully inserted)"
        )
    for axis, sign in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        d = np.zeros(3)
        d[axis] = sign
        hit = hole.ray.intersects_any(below, np.tile(d, (len(below), 1)))
        if not hit.all():
            p = below[np.argmin(hit)]
            name = ("+" if sign > 0 else "-") + "xy"[axis]
            raise UserInputError(
                "not a peg-hole (peg inside the hole): "
                f"{100 * (1 - hit.mean()):.0f} % of the peg's points below the hole part's top "
                f"are not in its cavity (e.g. at {_fmt_mm(p)}, no hole part towards {name}); "
                "are the files in the order PEG_MESH HOLE_MESH, in the assembled pose?"
            )
    # a point deeper than tol inside the other part lies in their intersection: only the
    # points in its bounds (grown by tol) are tested, all of them without manifold3d
    shared = overlap(peg, hole)
    hole_pts = _surface_points(hole, CHECK_SAMPLES, seed=3)
    if shared is not None:
        peg_pts_in = _within(peg_pts, shared.bounds, 2 * tol)
        hole_pts = _within(hole_pts, shared.bounds, 2 * tol)
    else:
        peg_pts_in = peg_pts
    depth, where = _deepest_inside(hole, peg_pts_in) if len(peg_pts_in) else (0.0, None)
    label = "the peg reaches into the hole part"
    if depth <= tol and len(hole_pts):
        depth, where = _deepest_inside(peg, hole_pts)
        label = "the hole part reaches into the peg"
    if depth > tol:
        vol_text = "" if shared is None else f", interference volume {shared.volume_mm3:.4g} mm^3"
        raise UserInputError(
            f"not a peg-hole (no interference): {label} up to {depth / MM:.4g} mm deep at "
            f"{_fmt_mm(where)}{vol_text} (tolerance {INTERFERENCE_TOL_MM:g} mm): the peg "
            "must be smaller than its hole"
        )
    up = np.tile([0.0, 0.0, 1.0], (len(peg_pts), 1))
    locs, idx, _ = hole.ray.intersects_location(peg_pts, up, multiple_hits=True)
    if len(idx):
        rise = locs[:, 2] - peg_pts[idx, 2]
        blocked = rise > 2 * tol  # a hit at the start point: the parts touch there
        if blocked.any():
            k = int(np.argmin(np.where(blocked, rise, np.inf)))
            raise UserInputError(
                "not a peg-hole (extractable along +z): the hole part lies "
                f"{rise[k] / MM:.4g} mm straight above the peg's point at "
                f"{_fmt_mm(peg_pts[idx[k]])} (an undercut): the peg cannot be pulled out "
                "along +z"
            )


def estimate_output_bytes(params: CoacdParams, n_hulls: tuple[int, int] | None = None) -> int:
    """An upper estimate of what ``decompose`` writes (MJCF + report.json), bytes: per hull
    its vertices as text, per peg-hull x hole-hull pair one ``<pair>`` line. Before CoACD the
    hull counts are the cap (or 64 per part when uncapped)."""
    if n_hulls is None:
        n = params.max_convex_hull if params.max_convex_hull > 0 else 64
        n_hulls = (n, n)
    per_hull = params.max_ch_vertex * 3 * 26 + 400
    pairs = n_hulls[0] * n_hulls[1] * 300
    return (n_hulls[0] + n_hulls[1]) * per_hull + pairs + 64 * 1024


@dataclass
class DecomposeReport:
    """What ``peghole models decompose`` measured and wrote."""

    peg: Deviation
    hole: Deviation
    radial_clearance_mm: float
    warn_threshold_mm: float
    warnings: list[str] = field(default_factory=list)
    mjcf: str = ""
    hole_depth_mm: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def _assembled_sites(peg, hole) -> tuple[np.ndarray, np.ndarray | None]:
    """Peg tip (centre of its lowest downward face) and the hole bottom under it (or None)."""
    down = np.flatnonzero(peg.face_normals[:, 2] < -0.9)
    if not len(down):
        raise UserInputError("the peg has no downward-facing end face (+z must be extraction)")
    centres = peg.triangles_center[down]
    tip = centres[np.argmin(centres[:, 2])]
    origins = np.array([[tip[0], tip[1], tip[2] + 1e-6]])
    locs, _, _ = hole.ray.intersects_location(origins, np.array([[0.0, 0.0, -1.0]]))
    bottom = None
    if len(locs):
        bottom = locs[np.argmax(locs[:, 2])]
    return tip, bottom


def write_user_mjcf(
    peg,
    hole,
    peg_hulls: list[np.ndarray],
    hole_hulls: list[np.ndarray],
    out: Path,
    friction: float,
    peg_mass_kg: float | None = None,
    sim=None,
) -> tuple[Path, float | None]:
    """Free peg + fixed hole block MJCF with every hull pair as a contact pair, written
    atomically to ``out/user_peghole.xml``.

    Returns the XML path and the hole depth (m) if a hole bottom was found under the peg.
    The keyframe ``mouth`` lifts the peg so that its tip is at the top of the hole block.
    """
    xml, depth = user_mjcf(peg, hole, peg_hulls, hole_hulls, friction, peg_mass_kg, sim)
    out.mkdir(parents=True, exist_ok=True)
    return fileio.write_text(out / "user_peghole.xml", xml), depth


def user_mjcf(
    peg,
    hole,
    peg_hulls: list[np.ndarray],
    hole_hulls: list[np.ndarray],
    friction: float,
    peg_mass_kg: float | None = None,
    sim=None,
) -> tuple[str, float | None]:
    """The MJCF text of :func:`write_user_mjcf` (compiled once to check it) and the depth."""
    sim = sim or SimOptions()
    s = mujoco.MjSpec()
    s.modelname = "user_peghole"
    _set_options(s, sim)
    s.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[1, 1, 0.05],
        contype=0,
        conaffinity=0,
        pos=[0, 0, hole.bounds[0, 2]],
    )
    s.worldbody.add_light(name="top_light", pos=[0, 0, 1.5], dir=[0, 0, -1])
    tip, bottom = _assembled_sites(peg, hole)
    hole_body = s.worldbody.add_body(name="hole", mocap=True)
    peg_body = s.worldbody.add_body(name="peg")
    peg_body.add_freejoint(name="peg_free")
    mass = peg_mass_kg if peg_mass_kg is not None else 1200.0 * peg.volume  # ~PLA density
    peg_names = add_hull_geoms(s, peg_body, "peg", peg_hulls, mass=mass, rgba=(0.2, 0.45, 0.85, 1))
    hole_names = add_hull_geoms(s, hole_body, "hole", hole_hulls, rgba=(0.75, 0.72, 0.65, 1))
    for a in peg_names:
        for b in hole_names:
            s.add_pair(
                name=f"{a}__{b}",
                geomname1=a,
                geomname2=b,
                condim=3,
                friction=[friction, friction, 0, 0, 0],
                solref=list(sim.solref),
                solimp=list(sim.solimp),
            )
    peg_body.add_site(name="peg_tip", pos=tip.tolist(), size=[0.002] * 3, group=3)
    depth = None
    if bottom is not None:
        hole_body.add_site(name="hole_bottom", pos=bottom.tolist(), size=[0.002] * 3, group=3)
        depth = float(hole.bounds[1, 2] - bottom[2])
    lift = hole.bounds[1, 2] - tip[2]
    s.add_key(name="mouth", qpos=[0, 0, lift, 1, 0, 0, 0])
    compile_pieces(s, "the decomposed parts")
    return s.to_xml(), depth


def hull_volume(vertices: np.ndarray) -> float:
    """The volume of the convex hull of ``vertices`` (n, 3)."""
    return float(ConvexHull(np.asarray(vertices, float)).volume)


def add_hull_geoms(
    spec: mujoco.MjSpec,
    body,
    prefix: str,
    hulls: list[np.ndarray],
    mass: float | None = None,
    rgba: tuple[float, ...] | None = None,
) -> list[str]:
    """Add one mesh geom ``{prefix}_hull{i:03d}`` per convex piece to ``body`` (collisions
    through explicit pairs only); ``mass`` is shared among the pieces by volume. Returns the
    geom names."""
    shares = None
    if mass is not None:
        vols = np.array([hull_volume(h) for h in hulls])
        shares = mass * vols / vols.sum()
    names = []
    for i, h in enumerate(hulls):
        name = f"{prefix}_hull{i:03d}"
        mesh = spec.add_mesh(name=f"{name}_mesh")
        mesh.uservert = np.asarray(h, float).ravel().tolist()
        geom = body.add_geom(
            name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh.name, contype=0, conaffinity=0
        )
        if shares is not None:
            geom.mass = shares[i]
        if rgba is not None:
            geom.rgba = list(rgba)
        names.append(name)
    return names


def compile_pieces(spec: mujoco.MjSpec, what: str) -> mujoco.MjModel:
    """``spec.compile()``, MuJoCo's refusal (e.g. a piece too thin for its mesh inertia) as
    one line naming ``what``."""
    try:
        return spec.compile()
    except ValueError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UserInputError(f"MuJoCo cannot build {what}: {first}") from None


def decompose_parts(
    peg_path: str | Path,
    hole_path: str | Path,
    out_dir: str | Path,
    *,
    units: str = "mm",
    params: CoacdParams = CoacdParams(),
    friction: float = 0.266,
    peg_mass_kg: float | None = None,
    clearance_mm: float | None = None,
    warn_fraction: float = WARN_FRACTION,
) -> DecomposeReport:
    """The whole user-part pipeline: load, decompose, measure, write MJCF and report.json."""
    friction = check("friction", friction)
    warn_fraction = check("warn_fraction", warn_fraction)
    if peg_mass_kg is not None:
        peg_mass_kg = check("peg_mass_kg", peg_mass_kg, kind="mass_kg")
    if clearance_mm is not None:
        clearance_mm = check("clearance_mm", clearance_mm)
    peg = load_mesh(peg_path, units)
    hole = load_mesh(hole_path, units)
    check_assembly(peg, hole, units)  # a peg in its hole, before any decomposition or MJCF

    out = Path(out_dir)
    fileio.check_out_dir(out)
    fileio.check_room(out, estimate_output_bytes(params))
    if clearance_mm is None:
        clearance_mm = estimate_radial_clearance_mm(peg, hole)
    if clearance_mm <= 0:
        raise UserInputError(
            f"radial clearance {clearance_mm:.4f} mm: the peg touches or overlaps the hole in "
            "the assembled pose; pass --clearance-mm if that is intended"
        )
    peg_hulls = run_coacd(peg, params)
    hole_hulls = run_coacd(hole, params)
    dev_peg = measure_deviation(peg, peg_hulls)
    dev_hole = measure_deviation(hole, hole_hulls)
    limit = warn_fraction * clearance_mm
    msgs = []
    for label, dev in (("peg", dev_peg), ("hole", dev_hole)):
        if dev.excess_mm > limit:
            msg = (
                f"{label} hulls deviate up to {dev.excess_mm:.3f} mm outside the part, more "
                f"than {warn_fraction:.0%} of the {clearance_mm:.3f} mm radial clearance "
                f"({limit:.3f} mm): lower --threshold or raise --resolution"
            )
            msgs.append(msg)
            warnings.warn(msg, DecompositionWarning, stacklevel=2)
    xml, depth = user_mjcf(peg, hole, peg_hulls, hole_hulls, friction, peg_mass_kg)
    path = out / "user_peghole.xml"
    report = DecomposeReport(
        dev_peg,
        dev_hole,
        clearance_mm,
        limit,
        msgs,
        str(path),
        None if depth is None else depth / MM,
    )
    files = {path: xml, out / "report.json": dumps(report.as_dict(), indent=2)}
    fileio.check_room(out, sum(len(v.encode()) for v in files.values()) + (1 << 20))
    fileio.write_many(files)  # both files or neither
    return report


def cad_meshes(spec: PegHoleSpec, sections: int = 128):
    """CAD-like (true round, not polygonal) peg and hole-block meshes of a spec, in mm,
    in the assembled pose (peg fully inserted, hole mouth at z = 0, +z up). For round trips."""
    trimesh = _cad("trimesh")
    _cad("manifold3d")  # trimesh's boolean difference

    depth = spec.hole_depth_mm
    if isinstance(spec, RectSpec):
        w, v, t, f = spec.hole_w_mm, spec.hole_v_mm, spec.wall_mm, spec.floor_mm
        block = trimesh.creation.box([w + 2 * t, v + 2 * t, depth + f])
        block.apply_translation([0, 0, -(depth + f) / 2])
        cavity = trimesh.creation.box([w, v, depth + 1.0])
        cavity.apply_translation([0, 0, -depth / 2 + 0.5])
        hole = block.difference(cavity)
        peg = trimesh.creation.box([spec.peg_w_mm, spec.peg_v_mm, spec.length_mm])
        peg.apply_translation([0, 0, -depth + spec.length_mm / 2])
        return peg, hole
    assert isinstance(spec, DualSpec)
    t, f = spec.wall_mm, spec.floor_mm
    half_h = 0.5 * spec.hole_distance_mm
    Rm = max(spec.hole_radii_mm)
    block = trimesh.creation.box([2 * half_h + 2 * (Rm + t), 2 * (Rm + t), depth + f])
    block.apply_translation([0, 0, -(depth + f) / 2])
    cavities = []
    for x, R in zip((-half_h, half_h), spec.hole_radii_mm, strict=True):
        c = trimesh.creation.cylinder(radius=R, height=depth + 1.0, sections=sections)
        c.apply_translation([x, 0, -depth / 2 + 0.5])
        cavities.append(c)
    hole = block.difference(cavities[0]).difference(cavities[1])
    half_p = 0.5 * spec.peg_distance_mm
    pieces = []
    for x, r in zip((-half_p, half_p), spec.peg_radii_mm, strict=True):
        c = trimesh.creation.cylinder(radius=r, height=spec.length_mm, sections=sections)
        c.apply_translation([x, 0, -depth + spec.length_mm / 2])
        pieces.append(c)
    rmax = max(spec.peg_radii_mm)
    bridge = trimesh.creation.box([2 * half_p + 2 * rmax, 2 * rmax, spec.bridge_mm])
    bridge.apply_translation([0, 0, -depth + spec.length_mm + spec.bridge_mm / 2])
    pieces.append(bridge)
    peg = pieces[0].union(pieces[1]).union(pieces[2])
    return peg, hole
