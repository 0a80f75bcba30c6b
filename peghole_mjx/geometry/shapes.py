"""The built-in family of irregular peg-holes, generated in code with their exact convex pieces.

The thesis's future work (Ch 5.3) names irregular, cylindrical and multi-peg parts. Six are
built here at a diametral clearance ``clearance_mm`` (0.1-0.4 mm), sized like the thesis's dual
parts (round pegs of 6-10 mm radius, 40-50 mm long, thesis Table 2.2):

| name | peg | hole |
|---|---|---|
| ``cylinder`` | a round peg, r 10 mm (16-gon), 50 mm long, 40 mm in the hole | round blind hole |
| ``keyed`` | a D-flat shaft: r 10 mm with a flat 7 mm from the axis (16 vertices) | D-shaped hole |
| ``l_section`` | an L-section: 30 x 30 mm outside, arms 10 mm thick | L-shaped hole |
| ``hex`` | a hexagonal peg, 20 mm across flats | hexagonal hole |
| ``three_pin`` | 3 pins r 3 mm (12-gon), 10 mm apart, on a plate; 20 mm deep | 3 holes, 1 block |
| ``tapered`` | the ``cylinder`` peg | the ``cylinder`` hole, its mouth chamfered 2 mm x 45 deg |

Each hole is its peg's cross-section with every edge moved out by half the clearance (the
gap across parallel faces is the clearance exactly). The pieces are exact: the peg's convex
pieces are its prisms (the L: two boxes), the hole part's are one convex wedge per edge of
each hole polygon (its inner face on the hole's wall, its outer face ``WALL_MM`` out), and a
floor; the L's block is cut into boxes on the grid of its corners. The meshes (trimesh solids,
for the checks of :func:`peghole_mjx.geometry.decompose.check_assembly` and the deviation of
the pieces) are the peg's pieces joined and the block minus the cavity, by manifold3d
booleans. All in the assembled pose: the peg on the hole's bottom, hole mouth at z = 0, +z up,
metres.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check
from peghole_mjx.geometry.specs import MM

#: the built-in shapes (see the module table)
BUILTINS = ("cylinder", "keyed", "l_section", "hex", "three_pin", "tapered")
#: hole material around each hole (mm) and under it
WALL_MM = 10.0
FLOOR_MM = 10.0
#: the chamfer of the ``tapered`` hole's mouth (mm, 45 deg)
CHAMFER_MM = 2.0
#: polygon sides of the round pegs: within MJX-JAX's 20-vertex face limit (geometry/task.py)
ROUND_SIDES = 16
PIN_SIDES = 12


def _cad(name: str):
    return optional_import(name, "generating the built-in parts (peghole task builtin)")


@dataclass
class BuiltinParts:
    """A built-in peg-hole: meshes and exact convex pieces (metres, assembled pose)."""

    name: str
    clearance_mm: float
    peg_mesh: object  # trimesh.Trimesh
    hole_mesh: object
    peg_hulls: list[np.ndarray]
    hole_hulls: list[np.ndarray]
    description: str


def _circle(radius: float, n: int, centre=(0.0, 0.0), phase: float = 0.0) -> np.ndarray:
    phi = phase + 2 * np.pi * np.arange(n) / n
    return np.stack([centre[0] + radius * np.cos(phi), centre[1] + radius * np.sin(phi)], 1)


def offset_convex(poly: np.ndarray, d: float) -> np.ndarray:
    """A counter-clockwise convex polygon with every edge moved out by ``d`` (parallel)."""
    p = np.asarray(poly, float)
    e = np.roll(p, -1, axis=0) - p
    n = np.stack([e[:, 1], -e[:, 0]], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)  # outward normal of edge i (i -> i + 1)
    n_prev = np.roll(n, 1, axis=0)  # of edge i - 1
    s = n_prev + n
    return p + d * s / (1.0 + np.sum(n_prev * n, axis=1))[:, None]


def _prism(poly: np.ndarray, z0: float, z1: float) -> np.ndarray:
    k = len(poly)
    return np.concatenate(
        [np.column_stack([poly, np.full(k, z0)]), np.column_stack([poly, np.full(k, z1)])]
    )


def _box(x0, x1, y0, y1, z0, z1) -> np.ndarray:
    return _prism(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), z0, z1)


def _wedges(
    cavity: np.ndarray, z0: float, z1: float, wall: float, mouth: np.ndarray | None = None
) -> list[np.ndarray]:
    """One convex wedge per edge of the convex ``cavity`` polygon between heights z0 and z1,
    its inner face on the edge, its outer face ``wall`` out. ``mouth``: the cavity polygon at
    z1 when it differs (a chamfer: the inner face slopes)."""
    outer = offset_convex(cavity, wall)
    top = cavity if mouth is None else mouth
    out = []
    k = len(cavity)
    for i in range(k):
        j = (i + 1) % k
        lo = np.array([cavity[i], cavity[j], outer[j], outer[i]])
        hi = np.array([top[i], top[j], outer[j], outer[i]])
        out.append(
            np.concatenate(
                [np.column_stack([lo, np.full(4, z0)]), np.column_stack([hi, np.full(4, z1)])]
            )
        )
    return out


def _hull_mesh(vertices: np.ndarray):
    trimesh = _cad("trimesh")
    return trimesh.Trimesh(vertices=vertices).convex_hull


def _union(meshes):
    trimesh = _cad("trimesh")
    _cad("manifold3d")
    return trimesh.boolean.union(meshes, engine="manifold") if len(meshes) > 1 else meshes[0]


def _block_minus(block_vertices: np.ndarray, cavities: list[np.ndarray]):
    trimesh = _cad("trimesh")
    _cad("manifold3d")
    block = _hull_mesh(block_vertices)
    cut = _union([_hull_mesh(c) for c in cavities])
    return trimesh.boolean.difference([block, cut], engine="manifold")


def _convex_peg_hole(name, description, peg_poly, c, length, depth, chamfer=0.0) -> BuiltinParts:
    """A prismatic peg of convex cross-section ``peg_poly`` (mm) in its hole."""
    hole_poly = offset_convex(peg_poly, 0.5 * c)
    outer = offset_convex(hole_poly, WALL_MM)
    lo, hi = outer.min(axis=0), outer.max(axis=0)
    floor = _box(lo[0], hi[0], lo[1], hi[1], -depth - FLOOR_MM, -depth)
    peg = _prism(peg_poly, -depth, length - depth)
    if chamfer:
        mouth = offset_convex(hole_poly, chamfer)
        hulls = _wedges(hole_poly, -depth, -chamfer, WALL_MM)
        hulls += _wedges(hole_poly, -chamfer, 0.0, WALL_MM, mouth=mouth)
        # the cavity to cut: the straight hole and the cone of the chamfer, 1 mm above the top
        cone = np.concatenate(
            [
                np.column_stack([hole_poly, np.full(len(hole_poly), -chamfer)]),
                np.column_stack(
                    [offset_convex(hole_poly, chamfer + 1.0), np.full(len(hole_poly), 1.0)]
                ),
            ]
        )
        cavities = [_prism(hole_poly, -depth, 1.0), cone]
    else:
        hulls = _wedges(hole_poly, -depth, 0.0, WALL_MM)
        cavities = [_prism(hole_poly, -depth, 1.0)]
    hulls.append(floor)
    block = _box(lo[0], hi[0], lo[1], hi[1], -depth - FLOOR_MM, 0.0)
    return _finish(name, c, description, [peg], hulls, _block_minus(block, cavities))


def _finish(name, c, description, peg_hulls, hole_hulls, hole_mesh) -> BuiltinParts:
    peg_mesh = _union([_hull_mesh(h) for h in peg_hulls])
    peg_mesh.apply_scale(MM)
    hole_mesh.apply_scale(MM)
    return BuiltinParts(
        name=name,
        clearance_mm=c,
        peg_mesh=peg_mesh,
        hole_mesh=hole_mesh,
        peg_hulls=[np.asarray(h, float) * MM for h in peg_hulls],
        hole_hulls=[np.asarray(h, float) * MM for h in hole_hulls],
        description=description,
    )


def _keyed_polygon(radius: float, flat: float, n: int) -> np.ndarray:
    """A D-flat cross-section: ``n`` points on the circle's arc below the flat at y = flat,
    counter-clockwise from the flat's left end; the flat is the last edge."""
    a = np.arcsin(flat / radius)  # the flat's right end at angle a, its left end at pi - a
    phi = np.linspace(np.pi - a, 2 * np.pi + a, n)
    return np.stack([radius * np.cos(phi), radius * np.sin(phi)], 1)


def _l_section(c: float) -> BuiltinParts:
    """An L-section peg (two boxes) in an L-shaped hole: the block cut into boxes on the grid
    of the hole's and the block's corners (every cell outside the hole is one piece)."""
    arm, t, length, depth = 30.0, 10.0, 50.0, 40.0
    d = 0.5 * c
    peg = [_box(0, arm, 0, t, -depth, length - depth), _box(0, t, t, arm, -depth, length - depth)]
    holes = [(-d, arm + d, -d, t + d), (-d, t + d, -d, arm + d)]  # the peg's boxes, grown by d
    edges = [-d - WALL_MM, -d, t + d, arm + d, arm + d + WALL_MM]
    hulls = []
    for x0, x1 in itertools.pairwise(edges):
        for y0, y1 in itertools.pairwise(edges):
            cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            if any(a < cx < b and e < cy < f for a, b, e, f in holes):
                continue
            hulls.append(_box(x0, x1, y0, y1, -depth, 0.0))
    lo, hi = edges[0], edges[-1]
    hulls.append(_box(lo, hi, lo, hi, -depth - FLOOR_MM, -depth))
    block = _box(lo, hi, lo, hi, -depth - FLOOR_MM, 0.0)
    cavities = [_box(a, b, e, f, -depth, 1.0) for a, b, e, f in holes]
    desc = "L-section peg, 30 x 30 mm, arms 10 mm thick, 50 mm long, 40 mm in an L-shaped hole"
    return _finish("l_section", c, desc, peg, hulls, _block_minus(block, cavities))


def _three_pin(c: float) -> BuiltinParts:
    """Three pins on one plate in three holes of one block (a connector)."""
    r, pitch, pin_len, depth, plate = 3.0, 10.0, 25.0, 20.0, 6.0
    wall = 3.0  # each hole's wedges stop short of the next hole (pitch - 2 R > wall)
    xs = (-pitch, 0.0, pitch)
    peg, hulls, cavities = [], [], []
    for x in xs:
        pin = _circle(r, PIN_SIDES, (x, 0.0))
        peg.append(_prism(pin, -depth, pin_len - depth))
        hole = offset_convex(pin, 0.5 * c)
        hulls += _wedges(hole, -depth, 0.0, wall)
        cavities.append(_prism(hole, -depth, 1.0))
    top = pin_len - depth
    half_x, half_y = pitch + r + 2.0, r + 2.0
    peg.append(_box(-half_x, half_x, -half_y, half_y, top, top + plate))
    bx, by = pitch + r + wall + 4.0, r + wall + 2.0
    hulls.append(_box(-bx, bx, -by, by, -depth - FLOOR_MM, -depth))
    block = _box(-bx, bx, -by, by, -depth - FLOOR_MM, 0.0)
    desc = (
        "three-pin connector: pins r 3 mm, 10 mm apart, 20 mm in three holes of one block, on "
        "a 30 x 10 x 6 mm plate"
    )
    return _finish("three_pin", c, desc, peg, hulls, _block_minus(block, cavities))


def builtin_parts(name: str, clearance_mm: float) -> BuiltinParts:
    """The built-in peg-hole ``name`` (:data:`BUILTINS`) at diametral clearance ``clearance_mm``
    (``RANGES["builtin_clearance_mm"]``: 0.1-0.4 mm)."""
    if name not in BUILTINS:
        raise UserInputError(f"unknown built-in shape {name!r}; choose one of {list(BUILTINS)}")
    c = check("clearance_mm", clearance_mm, "--clearance-mm", kind="builtin_clearance_mm")
    if name in ("cylinder", "tapered"):
        poly = _circle(10.0, ROUND_SIDES)
        chamfer = CHAMFER_MM if name == "tapered" else 0.0
        desc = "round peg r 10 mm (16-gon), 50 mm long, 40 mm in a blind hole"
        if chamfer:
            desc += f", the hole's mouth chamfered {chamfer:g} mm x 45 deg"
        return _convex_peg_hole(name, desc, poly, c, 50.0, 40.0, chamfer)
    if name == "keyed":
        poly = _keyed_polygon(10.0, 7.0, ROUND_SIDES)
        desc = "D-flat shaft r 10 mm, flat 7 mm from the axis, 50 mm long, 40 mm in a D hole"
        return _convex_peg_hole(name, desc, poly, c, 50.0, 40.0)
    if name == "hex":
        poly = _circle(10.0 / np.cos(np.pi / 6), 6, phase=np.pi / 6)
        desc = "hexagonal peg 20 mm across flats, 50 mm long, 40 mm in a hexagonal hole"
        return _convex_peg_hole(name, desc, poly, c, 50.0, 40.0)
    if name == "l_section":
        return _l_section(c)
    return _three_pin(c)
