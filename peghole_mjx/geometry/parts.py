"""Exact convex decomposition of the canonical peg-hole parts.

MuJoCo and MJX collide every mesh as its convex hull, so a non-convex part (a block with a
hole, two pegs joined by a bridge) must be a set of convex pieces on one body. For the
thesis's shapes the decomposition is exact and written down here, no CoACD needed:

* rectangular hole block: four wall boxes around the hole and a floor box;
* rectangular peg: one box;
* dual hole block: for each round hole (a regular ``n``-gon inscribed in the circle of radius
  ``R``) one convex wedge per polygon edge, reaching radially out to ``R + wall``, and a floor;
* dual peg: two ``n``-gon prisms (vertices on the circle of radius ``r``, same orientation as
  the hole polygons) and a bridge box on top.

Because each peg polygon is the hole polygon scaled about the same centre, the free travel of
the centred peg is ``R - r`` towards a vertex and ``(R - r) cos(pi / n)`` towards an edge
midpoint: the effective clearance is within ``1 - cos(pi / n)`` (1.9 % for n = 16) of the
nominal one. ``peghole models check`` measures it with MuJoCo's distance queries.

Frames (metres): the hole frame has its origin at the centre of the hole mouth, +z up (the
extraction direction), +x along the rect hole's width ``w`` / the line through both dual holes.
The peg frame has its origin at the peg's mount (top), +z pointing from the mount to the tip;
when the peg hangs in the hole its z is the hole's -z and its x the hole's -x (a half turn
about y), so the symmetric parts line up.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec, RectSpec

GeomKind = Literal["box", "mesh"]


@dataclass(frozen=True)
class ConvexPart:
    """One convex collision piece, in its owner's frame (metres).

    ``kind == "box"``: ``half_size`` and ``pos``; ``kind == "mesh"``: ``vertices`` (N x 3) given
    directly in the owner's frame (``pos`` is zero). ``group`` tags pieces that may touch each
    other (peg prism i only meets hole i's pieces), ``None`` meaning any.
    """

    name: str
    kind: GeomKind
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    half_size: np.ndarray | None = None
    vertices: np.ndarray | None = None
    group: int | None = None

    @property
    def volume(self) -> float:
        if self.kind == "box":
            return float(8.0 * np.prod(self.half_size))
        from scipy.spatial import ConvexHull

        return float(ConvexHull(self.vertices).volume)

    def corners(self) -> np.ndarray:
        """Vertices of the piece in the owner's frame."""
        if self.kind == "mesh":
            return np.asarray(self.vertices)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return self.pos + signs * self.half_size


def regular_polygon(
    radius: float, n: int, centre_xy: tuple[float, float] = (0.0, 0.0)
) -> np.ndarray:
    """Vertices (n x 2) of a regular n-gon inscribed in a circle, first vertex on +x."""
    phi = 2.0 * np.pi * np.arange(n) / n
    return np.stack([centre_xy[0] + radius * np.cos(phi), centre_xy[1] + radius * np.sin(phi)], 1)


def prism(polygon_xy: np.ndarray, z0: float, z1: float) -> np.ndarray:
    """Vertices of a prism over a convex polygon between heights z0 and z1."""
    n = len(polygon_xy)
    return np.concatenate(
        [
            np.column_stack([polygon_xy, np.full(n, z0)]),
            np.column_stack([polygon_xy, np.full(n, z1)]),
        ]
    )


def hole_centres_m(spec: DualSpec) -> np.ndarray:
    """Hole centres (2 x 2, metres) in the hole frame: on the x axis, symmetric about 0."""
    half = 0.5 * spec.hole_distance_mm * MM
    return np.array([[-half, 0.0], [half, 0.0]])


def peg_centres_m(spec: DualSpec) -> np.ndarray:
    """Peg axis positions (2 x 2, metres) in the peg frame.

    The peg frame's x is the hole frame's -x, so peg 1 sits at +x here to hang over hole 1.
    """
    half = 0.5 * spec.peg_distance_mm * MM
    return np.array([[half, 0.0], [-half, 0.0]])


def hole_parts(spec: PegHoleSpec) -> list[ConvexPart]:
    """Convex pieces of the hole block in the hole frame (mouth at z = 0, material below)."""
    depth = spec.hole_depth_mm * MM
    wall, floor = spec.wall_mm * MM, spec.floor_mm * MM
    if isinstance(spec, RectSpec):
        hw, hv = 0.5 * spec.hole_w_mm * MM, 0.5 * spec.hole_v_mm * MM
        zc = -0.5 * depth
        return [
            ConvexPart(
                "hole_wall_px",
                "box",
                np.array([hw + wall / 2, 0, zc]),
                np.array([wall / 2, hv + wall, depth / 2]),
            ),
            ConvexPart(
                "hole_wall_nx",
                "box",
                np.array([-hw - wall / 2, 0, zc]),
                np.array([wall / 2, hv + wall, depth / 2]),
            ),
            ConvexPart(
                "hole_wall_py",
                "box",
                np.array([0, hv + wall / 2, zc]),
                np.array([hw, wall / 2, depth / 2]),
            ),
            ConvexPart(
                "hole_wall_ny",
                "box",
                np.array([0, -hv - wall / 2, zc]),
                np.array([hw, wall / 2, depth / 2]),
            ),
            ConvexPart(
                "hole_floor",
                "box",
                np.array([0, 0, -depth - floor / 2]),
                np.array([hw + wall, hv + wall, floor / 2]),
            ),
        ]
    parts: list[ConvexPart] = []
    n = spec.n_sides
    for i, (centre, R_mm) in enumerate(zip(hole_centres_m(spec), spec.hole_radii_mm, strict=True)):
        R = R_mm * MM
        inner = regular_polygon(R, n, tuple(centre))
        outer = centre + (inner - centre) * (R + wall) / R
        for k in range(n):
            j = (k + 1) % n
            quad = np.array([inner[k], inner[j], outer[j], outer[k]])
            parts.append(
                ConvexPart(
                    f"hole{i + 1}_wedge{k:02d}", "mesh", vertices=prism(quad, -depth, 0.0), group=i
                )
            )
        parts.append(
            ConvexPart(
                f"hole{i + 1}_floor",
                "box",
                np.array([centre[0], centre[1], -depth - floor / 2]),
                np.array([R + wall, R + wall, floor / 2]),
                group=i,
            )
        )
    return parts


def peg_parts(spec: PegHoleSpec, single_hull: bool = False) -> list[ConvexPart]:
    """Convex pieces of the peg in the peg frame (mount at z = 0, tip at z = peg_tip_z_m).

    ``single_hull=True`` returns the convex hull of the whole peg as ONE piece: what PyBullet
    (and MuJoCo, for a single non-convex mesh) collides. For the dual peg the hull fills the
    space between the pegs, so it cannot enter the holes (thesis Sec 1.6, result R6).
    """
    if single_hull:
        verts = np.concatenate([p.corners() for p in peg_parts(spec)])
        return [ConvexPart("peg_hull", "mesh", vertices=verts)]
    length = spec.length_mm * MM
    if isinstance(spec, RectSpec):
        half = np.array([spec.peg_w_mm * MM / 2, spec.peg_v_mm * MM / 2, length / 2])
        return [ConvexPart("peg_body", "box", np.array([0, 0, length / 2]), half)]
    bridge = spec.bridge_mm * MM
    parts: list[ConvexPart] = []
    for i, (centre, r_mm) in enumerate(zip(peg_centres_m(spec), spec.peg_radii_mm, strict=True)):
        poly = regular_polygon(r_mm * MM, spec.n_sides, tuple(centre))
        parts.append(
            ConvexPart(
                f"peg{i + 1}", "mesh", vertices=prism(poly, bridge, bridge + length), group=i
            )
        )
    r_max = max(spec.peg_radii_mm) * MM
    half_x = 0.5 * spec.peg_distance_mm * MM + r_max
    parts.append(
        ConvexPart(
            "peg_bridge", "box", np.array([0, 0, bridge / 2]), np.array([half_x, r_max, bridge / 2])
        )
    )
    return parts


def peg_tip_z_m(spec: PegHoleSpec) -> float:
    """Distance from the peg mount to the peg tip along the peg's +z (metres)."""
    extra = spec.bridge_mm if isinstance(spec, DualSpec) else 0.0
    return (spec.length_mm + extra) * MM


def peg_volumes(parts: list[ConvexPart]) -> np.ndarray:
    return np.array([p.volume for p in parts])
