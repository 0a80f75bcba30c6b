"""Convex pieces of parts that are solids of revolution about the extraction axis, +z.

Pins, bushings, stepped pins, tapered pins and round (stepped, tapered) bores are exported
from CAD as M-gons of many facets (32-256): exactly as extrusions
(:mod:`peghole_mjx.geometry.extrusion`) a round bore of M facets needs about M pieces, more
than the cap (64) for a fine export, and a cone is no extrusion at all. Here the round
features are rebuilt as N-gons with N chosen from the clearance:

1. **recognise** (:func:`revolution_bands`): every vertex lies on one of a few z-levels
   (within :data:`TOLERANCE_MM`); the part is sliced (manifold3d) at a quarter and three
   quarters of each band between consecutive levels. The peg's slices are one loop each,
   *round* (at least :data:`MIN_ROUND_VERTICES` vertices, all at one radius from their
   centre within the tolerance); a hole part's slices hold one round loop (the cavity) and
   outer loops equal in both slices (the block's walls), or no round loop (the floor). The
   radius is linear in z within a band (a cylinder or a cone), so the two slices give it at
   both ends of the band;
2. **N** (:func:`choose_sides`): the fewest sides (at least 8) whose sagitta, the largest
   radius r times (1 - cos(pi / N)), is at most :data:`SAGITTA_FRACTION` of the radial
   clearance; the mesh's own facet count when that is fewer (then the N-gon is the mesh's);
3. **pieces** (:func:`revolution_pieces`): a peg band is the frustum of two N-gons (the hull
   of the N-gon of radius r0 at z0 and of r1 at z1), cut by chords into pieces of at most
   :data:`~peghole_mjx.geometry.extrusion.MAX_POLYGON_VERTICES` vertices a face; a cavity
   band is N wedges, each the hull of one N-gon edge at both ends and the same edge's
   directions on the block's inscribed circle (the block's corners outside that circle are
   left out, as the built-in holes' wedges); a floor band (no cavity) is the extrusion of
   its cross-section (Hertel-Mehlhorn, as the extrusions).

The N-gons of the two parts share their phase (a vertex at +x) and are homothetic, so the
pieces' free travel between them is the circles' within (1 - cos(pi / N)) of the clearance.
Lengths in metres unless named ``_mm``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.extrusion import (
    MAX_LEVELS,
    MAX_POLYGON_VERTICES,
    TOLERANCE_MM,
    _levels,
    _signed_area,
    _simplify_loop,
    convex_polygons,
)
from peghole_mjx.geometry.specs import MM

#: a round feature's N-gon may lie inside its circle by at most this fraction of the radial
#: clearance (its sagitta r (1 - cos(pi / N))): 10 %, so that the pieces' clearance is the
#: circles' to within 10 % even if the two parts' N-gons were out of phase (in phase, as
#: built, within (1 - cos(pi / N)) of it)
SAGITTA_FRACTION = 0.10
#: the fewest sides of a round feature's N-gon
MIN_SIDES = 8
#: a loop of at least this many vertices, all at one radius from their centre, is round
MIN_ROUND_VERTICES = 12


def _cad(name: str):
    return optional_import(name, "pieces of revolved parts (peghole task make)")


@dataclass
class RevBand:
    """One z-band of a revolved part: heights (m); the round loop's radius at both ends (mm,
    0 for none) and centre (mm); the other loops (mm; a hole part's walls or floor)."""

    z0: float
    z1: float
    r0_mm: float
    r1_mm: float
    centre_mm: tuple[float, float]
    facets: int
    others: list[np.ndarray] = field(default_factory=list)

    @property
    def round(self) -> bool:
        return self.r0_mm > 0


@dataclass
class RevolutionResult:
    """A part recognised as revolved about +z (``bands``) or not (``why``)."""

    bands: list[RevBand] = field(default_factory=list)
    why: str = ""

    @property
    def ok(self) -> bool:
        return bool(self.bands)

    @property
    def max_radius_mm(self) -> float:
        return max((max(b.r0_mm, b.r1_mm) for b in self.bands), default=0.0)


def _round(loop: np.ndarray, tol_mm: float) -> tuple[float, np.ndarray, int] | None:
    """(radius, centre, vertices) when ``loop`` (mm) is round: enough vertices, all at one
    radius from their centre within ``tol_mm``, spread all round; else None."""
    if len(loop) < MIN_ROUND_VERTICES:
        return None
    c = loop.mean(axis=0)
    d = loop - c
    r = np.hypot(d[:, 0], d[:, 1])
    if r.max() - r.min() > tol_mm:
        return None
    ang = np.sort(np.arctan2(d[:, 1], d[:, 0]))
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))
    if gaps.max() > 2.5 * 2 * np.pi / len(loop):
        return None
    return float(r.mean()), c, len(loop)


def _loops(section, tol_mm: float) -> list[np.ndarray]:
    loops = [_simplify_loop(p, tol_mm) for p in section.to_polygons()]
    return [p for p in loops if len(p) >= 3 and abs(_signed_area(p)) > tol_mm**2]


def _same(a: list[np.ndarray], b: list[np.ndarray], tol_mm: float) -> bool:
    if len(a) != len(b):
        return False
    key = sorted((len(p), *np.round(p.mean(axis=0) / tol_mm)) for p in a)
    return key == sorted((len(p), *np.round(p.mean(axis=0) / tol_mm)) for p in b) and all(
        any(len(p) == len(q) and np.allclose(np.sort(p, 0), np.sort(q, 0), atol=tol_mm) for q in b)
        for p in a
    )


def revolution_bands(mesh, part: str, tol_mm: float = TOLERANCE_MM) -> RevolutionResult:
    """Recognise ``mesh`` (a watertight trimesh, metres) as a ``part`` ("peg" or "hole")
    revolved about +z (module docstring), or say why not."""
    manifold3d = _cad("manifold3d")
    tol = tol_mm * MM
    v = np.asarray(mesh.vertices, float)
    levels = _levels(v[:, 2], tol)
    if levels is None:
        return RevolutionResult(why="its vertices do not lie on distinct z-levels")
    if len(levels) > MAX_LEVELS:
        return RevolutionResult(why=f"{len(levels)} z-levels, more than {MAX_LEVELS}")
    solid = manifold3d.Manifold(
        manifold3d.Mesh64(vert_properties=v / MM, tri_verts=np.asarray(mesh.faces, np.uint32))
    )
    if solid.status() != manifold3d.Error.NoError:
        return RevolutionResult(why=f"manifold3d cannot read it ({solid.status()})")
    bands: list[RevBand] = []
    for z0, z1 in itertools.pairwise(levels):
        za, zb = (z0 + 0.25 * (z1 - z0)) / MM, (z0 + 0.75 * (z1 - z0)) / MM
        la, lb = _loops(solid.slice(za), tol_mm), _loops(solid.slice(zb), tol_mm)
        # a hole part's round outer wall (a bushing, counter-clockwise) is a wall, not a bore
        bore = part == "peg" or None
        ra = [(p, _round(p, tol_mm) if bore or _signed_area(p) < 0 else None) for p in la]
        rb = [(p, _round(p, tol_mm) if bore or _signed_area(p) < 0 else None) for p in lb]
        round_a = [x for x in ra if x[1] is not None]
        round_b = [x for x in rb if x[1] is not None]
        others_a = [p for p, x in ra if x is None]
        others_b = [p for p, x in rb if x is None]
        where = f"z = {0.5 * (z0 + z1) / MM:g} mm"
        if len(round_a) > 1 or len(round_a) != len(round_b):
            return RevolutionResult(why=f"not one round loop about the axis at {where}")
        if not _same(others_a, others_b, 10 * tol_mm):
            return RevolutionResult(why=f"its walls change within the band at {where}")
        if part == "peg" and (others_a or not round_a):
            return RevolutionResult(why=f"its cross-section at {where} is not one round loop")
        if part == "hole" and not others_a:
            return RevolutionResult(why=f"no walls around the bore at {where}")
        if not round_a:
            bands.append(RevBand(float(z0), float(z1), 0.0, 0.0, (0.0, 0.0), 0, others_a))
            continue
        (pa, (rad_a, ca, na)), (_, (rad_b, cb, nb)) = round_a[0], round_b[0]
        if part == "hole" and _signed_area(pa) > 0:
            return RevolutionResult(why=f"its round loop at {where} is not a bore")
        if np.hypot(*(ca - cb)) > 10 * tol_mm or na != nb:
            return RevolutionResult(why=f"its round loop moves within the band at {where}")
        slope = (rad_b - rad_a) / (zb - za)
        r0 = rad_a + slope * (z0 / MM - za)
        r1 = rad_a + slope * (z1 / MM - za)
        if min(r0, r1) <= tol_mm:
            return RevolutionResult(why=f"its round loop closes to a point at {where}")
        centre = (float(0.5 * (ca + cb)[0]), float(0.5 * (ca + cb)[1]))
        bands.append(RevBand(float(z0), float(z1), float(r0), float(r1), centre, na, others_a))
    if not any(b.round for b in bands):
        return RevolutionResult(why="no round loop about the axis")
    return RevolutionResult(bands=bands)


def sagitta_mm(radius_mm: float, sides: int) -> float:
    """How far (mm) a regular ``sides``-gon inscribed in a circle of ``radius_mm`` lies inside
    it at its edges' midpoints: r (1 - cos(pi / N))."""
    return radius_mm * (1.0 - math.cos(math.pi / sides))


def choose_sides(radius_mm: float, clearance_mm: float, facets: int = 0) -> int:
    """The fewest sides N >= :data:`MIN_SIDES` with sagitta <= :data:`SAGITTA_FRACTION` of
    the radial clearance; ``facets`` (the mesh's own) when fewer than that."""
    bound = SAGITTA_FRACTION * clearance_mm
    n = max(MIN_SIDES, math.ceil(math.pi / math.acos(max(-1.0, 1.0 - bound / radius_mm))))
    return min(n, facets) if facets >= MIN_SIDES else n


def _ngon(radius_mm: float, sides: int, centre_mm) -> np.ndarray:
    phi = 2 * np.pi * np.arange(sides) / sides
    return (np.stack([np.cos(phi), np.sin(phi)], 1) * radius_mm + np.asarray(centre_mm)) * MM


def _layer(xy: np.ndarray, z: float) -> np.ndarray:
    return np.column_stack([xy, np.full(len(xy), z)])


def _chunks(sides: int, most: int) -> list[list[int]]:
    """The N-gon's vertex indices cut by chords into convex polygons of <= ``most`` vertices."""
    if sides <= most:
        return [list(range(sides))]
    out, rest = [], list(range(sides))
    while len(rest) > most:
        out.append(rest[:most])
        rest = rest[:1] + rest[most - 1 :]
    out.append(rest)
    return out


def _inscribed_mm(others: list[np.ndarray], centre_mm) -> float:
    """The distance (mm) from ``centre_mm`` to the nearest edge of the walls' loops."""
    c = np.asarray(centre_mm, float)
    best = math.inf
    for p in others:
        a, b = p, np.roll(p, -1, axis=0)
        ab = b - a
        t = np.clip(np.sum((c - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-30), 0, 1)
        d = np.hypot(*(a + t[:, None] * ab - c).T)
        best = min(best, float(d.min()))
    return best


def count_pieces(bands: list[RevBand], part: str, sides: int, tol_mm: float = TOLERANCE_MM) -> int:
    """How many pieces :func:`revolution_pieces` makes (without making them)."""
    per_round = len(_chunks(sides, MAX_POLYGON_VERTICES)) if part == "peg" else sides
    n = 0
    for b in bands:
        n += per_round if b.round else len(convex_polygons(b.others, tol_mm))
    return n


def revolution_pieces(
    bands: list[RevBand], part: str, sides: int, tol_mm: float = TOLERANCE_MM
) -> list[np.ndarray]:
    """The convex pieces (vertex arrays, metres) of a revolved part's bands (module doc)."""
    out: list[np.ndarray] = []
    for b in bands:
        if not b.round:
            for poly in convex_polygons(b.others, tol_mm):
                xy = np.asarray(poly, float) * MM
                out.append(np.concatenate([_layer(xy, b.z0), _layer(xy, b.z1)]))
            continue
        lo, hi = _ngon(b.r0_mm, sides, b.centre_mm), _ngon(b.r1_mm, sides, b.centre_mm)
        if part == "peg":
            for idx in _chunks(sides, MAX_POLYGON_VERTICES):
                out.append(np.concatenate([_layer(lo[idx], b.z0), _layer(hi[idx], b.z1)]))
            continue
        wall = _inscribed_mm(b.others, b.centre_mm)
        outer = _ngon(wall, sides, b.centre_mm)
        for i in range(sides):
            j = (i + 1) % sides
            ring = np.array([i, j])
            out.append(
                np.concatenate(
                    [
                        _layer(lo[ring], b.z0),
                        _layer(outer[ring], b.z0),
                        _layer(hi[ring], b.z1),
                        _layer(outer[ring], b.z1),
                    ]
                )
            )
    return out


@dataclass
class RevolvedPair:
    """Both parts' pieces, the sides N and the record for ``task.json``."""

    peg_hulls: list[np.ndarray]
    hole_hulls: list[np.ndarray]
    sides: int
    records: dict[str, dict[str, Any]]


METHOD = "revolution N-gons"


def revolved_pair(
    peg, hole, radial_clearance_mm: float, max_hulls: int, tol_mm: float = TOLERANCE_MM
) -> RevolvedPair | str:
    """The pieces of a peg and hole that are both revolved about +z (module doc), else the
    reason they are not (one phrase). Refused in one line (UserInputError), before the pieces
    are made, when the N the clearance needs gives more pieces than ``max_hulls``."""
    res = {
        "peg": revolution_bands(peg, "peg", tol_mm),
        "hole": revolution_bands(hole, "hole", tol_mm),
    }
    for label, r in res.items():
        if not r.ok:
            return f"the {label} part: {r.why}"
    radius = max(r.max_radius_mm for r in res.values())
    facets = min(b.facets for r in res.values() for b in r.bands if b.round)
    sides = choose_sides(radius, radial_clearance_mm, facets)
    counts = {k: count_pieces(r.bands, k, sides, tol_mm) for k, r in res.items()}
    if max(counts.values()) > max_hulls:
        label = max(counts, key=counts.get)
        raise UserInputError(
            f"the round {label} part needs N = {sides} sides (sagitta <= "
            f"{SAGITTA_FRACTION:.0%} of the {radial_clearance_mm:.4g} mm radial clearance at "
            f"r = {radius:.4g} mm), {counts[label]} pieces, more than the cap of {max_hulls} "
            "(--max-hulls): give a larger clearance or --max-hulls, or use --pieces coacd"
        )
    hulls = {k: revolution_pieces(r.bands, k, sides, tol_mm) for k, r in res.items()}
    records = {}
    for k, r in res.items():
        records[k] = {
            "method": METHOD,
            "tolerance_mm": tol_mm,
            "sides": sides,
            "mesh_facets": min(b.facets for b in r.bands if b.round),
            "sagitta_mm": round(sagitta_mm(radius, sides), 6),
            "sagitta_bound": f"r (1 - cos(pi / N)) <= {SAGITTA_FRACTION:g} x radial clearance "
            f"{radial_clearance_mm:.4g} mm at the largest radius {radius:.4g} mm (or N = the "
            "mesh's facets when fewer)",
            "bands_mm": [
                [round(b.z0 / MM, 6), round(b.z1 / MM, 6), round(b.r0_mm, 6), round(b.r1_mm, 6)]
                for b in r.bands
            ],
            "pieces": len(hulls[k]),
            "how": "round loops rebuilt as N-gons in phase (vertex at +x): a peg band the "
            "frustum of two N-gons cut into <= 20-vertex pieces, a bore band N wedges out to "
            "the block's inscribed circle (its corners left out), a floor band extruded",
        }
    return RevolvedPair(hulls["peg"], hulls["hole"], sides, records)


__all__ = [
    "METHOD",
    "MIN_ROUND_VERTICES",
    "MIN_SIDES",
    "SAGITTA_FRACTION",
    "RevBand",
    "RevolutionResult",
    "RevolvedPair",
    "choose_sides",
    "count_pieces",
    "revolution_bands",
    "revolution_pieces",
    "revolved_pair",
    "sagitta_mm",
]
