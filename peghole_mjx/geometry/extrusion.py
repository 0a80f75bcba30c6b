"""Exact convex pieces of parts that are (stepped) extrusions along the extraction axis, +z.

Most real peg-holes are prisms along the way the peg comes out: a peg of constant
cross-section, a block whose cavity has straight walls over its depth and a floor under it.
For such a part the exact convex decomposition is a 2-D problem, solved here instead of
CoACD's approximate 3-D one:

1. **recognise** (:func:`extrusion_bands`): every vertex lies on one of a few z-levels (within
   :data:`TOLERANCE_MM`), every face is horizontal (its vertices on one level) or vertical
   (its outline seen from +z a line to within the tolerance). Then the cross-section is
   constant between consecutive levels: the part is a stack of z-bands, each the extrusion of
   its own cross-section (a polygon with holes, sliced at the band's mid-height by
   manifold3d). A part with a sloped face (a chamfer, a cone, a fillet) is not an extrusion;
2. **decompose** (:func:`convex_polygons`): each cross-section is triangulated (manifold3d,
   holes included) and the triangles merged greedily while the union stays convex
   (Hertel-Mehlhorn: at most four times the fewest convex pieces); a convex polygon of more
   than :data:`MAX_POLYGON_VERTICES` vertices is cut by chords into smaller ones;
3. **extrude** (:func:`extrusion_pieces`): each convex polygon becomes a prism over its band
   (2 x its vertices), a polygon equal in consecutive bands one prism over both.

The pieces are the part: their union is the mesh and they do not overlap, so the clearance
of the pieces is the mesh's (no hull error). Lengths in metres unless named ``_mm``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull

from peghole_mjx.core._optional import optional_import
from peghole_mjx.geometry.specs import MM

#: how far (mm) a vertex may lie from its z-level, and a wall face lean from the vertical over
#: its outline, for the part to count as an extrusion: 1 micrometre, a hundredth of the
#: smallest clearance the built-ins use (0.1 mm diametral) and MuJoCo's steady penetration
TOLERANCE_MM = 1e-3
#: z-levels a part may have (bands + 1): more is a shape CoACD handles better (a stepped cone)
MAX_LEVELS = 17
#: vertices of one convex cross-section polygon: its prism's end faces stay within MJX-JAX's
#: 20-vertex face limit (geometry/task.py MJX_MAX_FACE_VERTICES) and the prism (2 x 20) within
#: the 64-vertex cap per piece
MAX_POLYGON_VERTICES = 20


def _cad(name: str):
    return optional_import(name, "exact pieces of extruded parts (peghole task make)")


@dataclass
class Band:
    """One z-band of an extrusion: heights (m) and its cross-section's loops (mm, outer loops
    counter-clockwise, holes clockwise)."""

    z0: float
    z1: float
    loops: list[np.ndarray]


@dataclass
class ExtrusionResult:
    """A part recognised as an extrusion (``bands``) or not (``why``)."""

    bands: list[Band] = field(default_factory=list)
    why: str = ""

    @property
    def ok(self) -> bool:
        return bool(self.bands)


def _levels(z: np.ndarray, tol: float) -> np.ndarray | None:
    """The z-levels of sorted-and-clustered ``z`` (gaps > tol split clusters); None when a
    cluster spans more than ``tol``."""
    zs = np.sort(z)
    cuts = np.flatnonzero(np.diff(zs) > tol) + 1
    groups = np.split(zs, cuts)
    if any(g[-1] - g[0] > tol for g in groups):
        return None
    return np.array([0.5 * (g[0] + g[-1]) for g in groups])


def _simplify_loop(loop: np.ndarray, tol: float) -> np.ndarray:
    """Drop repeated and collinear vertices (those within ``tol`` of their neighbours' line)."""
    pts = [p for p in np.asarray(loop, float)]
    changed = True
    while changed and len(pts) > 3:
        changed = False
        for i in range(len(pts)):
            a, b, c = pts[i - 1], pts[i], pts[(i + 1) % len(pts)]
            ac = c - a
            n = float(np.hypot(*ac))
            ab = b - a
            dev = abs(ab[0] * ac[1] - ab[1] * ac[0]) / n if n > tol else float(np.hypot(*ab))
            if dev <= tol:
                del pts[i]
                changed = True
                break
    return np.array(pts)


def _signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def extrusion_bands(mesh, tol_mm: float = TOLERANCE_MM) -> ExtrusionResult:
    """Recognise ``mesh`` (a watertight trimesh, metres) as a stack of z-bands of constant
    cross-section (module docstring), or say why not."""
    manifold3d = _cad("manifold3d")
    tol = tol_mm * MM
    v = np.asarray(mesh.vertices, float)
    f = np.asarray(mesh.faces)
    levels = _levels(v[:, 2], tol)
    if levels is None:
        return ExtrusionResult(why="its vertices do not lie on distinct z-levels")
    if len(levels) > MAX_LEVELS:
        return ExtrusionResult(why=f"{len(levels)} z-levels, more than {MAX_LEVELS}")
    level_of = np.searchsorted(levels, v[:, 2] - tol)
    tri = v[f]
    flat = (level_of[f] == level_of[f][:, :1]).all(axis=1)
    xy = tri[~flat][:, :, :2]
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    cross = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    longest = np.max(
        np.linalg.norm(xy - np.roll(xy, 1, axis=1), axis=2), axis=1
    )  # the outline's length
    lean = cross / np.maximum(longest, tol)
    if len(lean) and lean.max() > tol:
        k = int(np.argmax(lean))
        return ExtrusionResult(
            why=f"a face is neither horizontal nor vertical (it leans {lean[k] / MM:.3g} mm "
            f"over its outline, tolerance {tol_mm:g} mm)"
        )
    scaled = manifold3d.Manifold(
        manifold3d.Mesh64(vert_properties=v / MM, tri_verts=np.asarray(f, np.uint32))
    )
    if scaled.status() != manifold3d.Error.NoError:
        return ExtrusionResult(why=f"manifold3d cannot read it ({scaled.status()})")
    bands: list[Band] = []
    for z0, z1 in itertools.pairwise(levels):
        section = scaled.slice(0.5 * (z0 + z1) / MM)
        loops = [_simplify_loop(p, tol_mm) for p in section.to_polygons()]
        loops = [p for p in loops if len(p) >= 3 and abs(_signed_area(p)) > tol_mm**2]
        if not loops:
            return ExtrusionResult(why=f"an empty cross-section at z = {0.5 * (z0 + z1) / MM:g} mm")
        if bands and _same_loops(bands[-1].loops, loops, tol_mm):
            bands[-1].z1 = float(z1)  # an extra level on the walls only: one band
        else:
            bands.append(Band(float(z0), float(z1), loops))
    return ExtrusionResult(bands=bands)


def _canonical(poly: np.ndarray, tol: float) -> tuple:
    key = [tuple(np.round(p / tol).astype(int)) for p in poly]
    i = key.index(min(key))
    return tuple(key[i:] + key[:i])


def _same_loops(a: list[np.ndarray], b: list[np.ndarray], tol: float) -> bool:
    return sorted(_canonical(p, tol) for p in a) == sorted(_canonical(p, tol) for p in b)


def _is_convex(poly: np.ndarray, eps: float) -> bool:
    """Every turn left or straight (never back), and one turn round in all."""
    d = np.roll(poly, -1, axis=0) - poly
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    dn = np.roll(d, -1, axis=0)
    cross = d[:, 0] * dn[:, 1] - d[:, 1] * dn[:, 0]
    dot = np.sum(d * dn, axis=1)
    turning = float(np.sum(np.arctan2(cross, dot)))
    return bool((cross >= -eps).all() and (dot > -1 + eps).all() and turning < 2 * np.pi + 1e-6)


def _merge(p: list[int], q: list[int], a: int, b: int) -> list[int]:
    """``p`` holds the edge a -> b, ``q`` the edge b -> a: their union's cycle."""
    i = p.index(b)
    p_rot = p[i:] + p[:i]  # b ... a
    j = q.index(a)
    q_rot = q[j:] + q[:j]  # a ... b
    return p_rot + q_rot[1:-1]


def _split_large(poly: np.ndarray, most: int) -> list[np.ndarray]:
    """Cut a convex polygon by chords into convex polygons of at most ``most`` vertices."""
    out = []
    rest = poly
    while len(rest) > most:
        out.append(rest[:most])
        rest = np.concatenate([rest[:1], rest[most - 1 :]])
    out.append(rest)
    return out


def convex_polygons(
    loops: list[np.ndarray], tol_mm: float = TOLERANCE_MM, most: int = MAX_POLYGON_VERTICES
) -> list[np.ndarray]:
    """A region's loops (outer counter-clockwise, holes clockwise) as convex polygons
    (counter-clockwise, at most ``most`` vertices): triangulated, then triangles merged across
    their shared edges while the union stays convex (Hertel-Mehlhorn), longest edges first."""
    manifold3d = _cad("manifold3d")
    pts = np.concatenate(loops)
    tris = np.asarray(manifold3d.triangulate([np.asarray(p, float) for p in loops], tol_mm))
    pieces: dict[int, list[int]] = {}
    for k, t in enumerate(tris):
        t = [int(i) for i in t]
        if _signed_area(pts[t]) < 0:
            t = t[::-1]
        if abs(_signed_area(pts[t])) > 0:
            pieces[k] = t
    owner: dict[tuple[int, int], int] = {}
    for k, t in pieces.items():
        for a, b in zip(t, t[1:] + t[:1], strict=True):
            owner[(a, b)] = k
    diagonals = sorted(
        {(min(a, b), max(a, b)) for (a, b) in owner if (b, a) in owner},
        key=lambda e: -float(np.linalg.norm(pts[e[0]] - pts[e[1]])),
    )
    for a, b in diagonals:
        kp, kq = owner.get((a, b)), owner.get((b, a))
        if kp is None or kq is None or kp == kq:
            continue
        merged = _merge(pieces[kp], pieces[kq], a, b)
        if len(set(merged)) != len(merged) or not _is_convex(pts[merged], 1e-9):
            continue
        del pieces[kq]
        pieces[kp] = merged
        owner.pop((a, b), None)
        owner.pop((b, a), None)
        for e in zip(merged, merged[1:] + merged[:1], strict=True):
            owner[e] = kp
    out = []
    for cycle in pieces.values():
        poly = _simplify_loop(pts[cycle], tol_mm)
        out += _split_large(poly, most)
    return out


def _prism(poly_mm: np.ndarray, z0: float, z1: float) -> np.ndarray:
    k = len(poly_mm)
    xy = np.asarray(poly_mm, float) * MM
    return np.concatenate(
        [np.column_stack([xy, np.full(k, z0)]), np.column_stack([xy, np.full(k, z1)])]
    )


def extrusion_pieces(
    bands: list[Band], tol_mm: float = TOLERANCE_MM, most: int = MAX_POLYGON_VERTICES
) -> list[np.ndarray]:
    """The convex pieces (vertex arrays, metres) of a stack of bands: each band's convex
    polygons as prisms over it; a polygon equal in consecutive bands one prism over both."""
    open_: dict[tuple, tuple[np.ndarray, float, float]] = {}  # key -> polygon, z0, z1
    done: list[np.ndarray] = []
    for band in bands:
        current = {}
        for poly in convex_polygons(band.loops, tol_mm, most):
            key = _canonical(poly, tol_mm)
            prev = open_.pop(key, None)
            if prev is not None and abs(prev[2] - band.z0) <= tol_mm * MM:
                current[key] = (prev[0], prev[1], band.z1)
            else:
                if prev is not None:
                    done.append(_prism(*prev))
                current[key] = (poly, band.z0, band.z1)
        done += [_prism(*p) for p in open_.values()]
        open_ = current
    done += [_prism(*p) for p in open_.values()]
    return done


@dataclass
class PartPieces:
    """A part's convex pieces and how they were made (``task.json``'s ``source.decomposition``)."""

    hulls: list[np.ndarray]
    record: dict[str, Any]


def exact_pieces(mesh, tol_mm: float = TOLERANCE_MM) -> PartPieces | str:
    """The exact convex pieces of ``mesh`` if it is a stepped extrusion along +z, else the
    reason it is not (one phrase). The pieces' summed volume must be the mesh's (within
    1e-6): a check that they tile it without overlap."""
    res = extrusion_bands(mesh, tol_mm)
    if not res.ok:
        return res.why
    hulls = extrusion_pieces(res.bands, tol_mm)
    volume = pieces_volume(hulls)
    if abs(volume - float(mesh.volume)) > 1e-6 * abs(float(mesh.volume)):
        return (
            f"its exact pieces' volume {volume / MM**3:.6g} mm^3 differs from the mesh's "
            f"{float(mesh.volume) / MM**3:.6g} mm^3"
        )
    record = {
        "method": "exact extrusion",
        "tolerance_mm": tol_mm,
        "bands_mm": [[round(b.z0 / MM, 6), round(b.z1 / MM, 6)] for b in res.bands],
        "cross_section_vertices": [int(sum(len(p) for p in b.loops)) for b in res.bands],
        "pieces": len(hulls),
        "how": "every face horizontal or vertical, every vertex on a z-level (within the "
        "tolerance): each band's cross-section triangulated and merged into convex polygons "
        "(Hertel-Mehlhorn), each extruded over its band; the pieces' union is the mesh",
    }
    return PartPieces(hulls, record)


def pieces_volume(hulls: list[np.ndarray]) -> float:
    """The summed volume of convex pieces (m^3): the part's volume when they do not overlap."""
    return float(sum(ConvexHull(np.asarray(h, float)).volume for h in hulls))


def mesh_free_travel_mm(peg, hole, direction, most_mm: float = 5.0, tol_mm: float = 1e-4) -> float:
    """How far (mm) the peg mesh moves along the horizontal ``direction`` before it meets the
    hole mesh (their intersection gains volume): the meshes' own free travel, to compare with
    the pieces' (:func:`peghole_mjx.geometry.task_check.place_and_check`). Bisection on
    manifold3d booleans, in mm."""
    manifold3d = _cad("manifold3d")

    def solid(m):
        return manifold3d.Manifold(
            manifold3d.Mesh64(
                vert_properties=np.asarray(m.vertices, float) / MM,
                tri_verts=np.asarray(m.faces, np.uint32),
            )
        )

    p, h = solid(peg), solid(hole)
    u = np.asarray(direction, float)
    u = u / np.linalg.norm(u)
    tiny = 1e-9 * max(p.volume(), 1.0)

    def hits(s: float) -> bool:
        return (p.translate(tuple(u * s)) ^ h).volume() > tiny

    lo, hi = 0.0, most_mm
    if not hits(hi):
        return float("inf")
    while hi - lo > tol_mm:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if hits(mid) else (mid, hi)
    return lo


__all__ = [
    "MAX_LEVELS",
    "MAX_POLYGON_VERTICES",
    "TOLERANCE_MM",
    "Band",
    "ExtrusionResult",
    "PartPieces",
    "convex_polygons",
    "exact_pieces",
    "extrusion_bands",
    "extrusion_pieces",
    "mesh_free_travel_mm",
    "pieces_volume",
]
