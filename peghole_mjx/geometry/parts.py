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

That is the ``mesh`` collision representation of the dual parts (each wedge and each prism is
one SHARED mesh placed by a pose, so MJX builds one collision group per mesh pair type, not
one per wedge). Two more representations trade exactness for cost (:data:`REPRESENTATIONS`,
chosen by :func:`resolve_representation`, the one place that knows the defaults):

* ``capsule`` (the dual default): each peg is a capsule of radius ``r`` whose segment runs from
  the bridge to the tip; each hole is ``n`` boxes whose inner faces form an ``n``-gon
  CIRCUMSCRIBING the hole circle (face distance ``R`` from the axis), and the walls and floor
  reach ``r`` deeper than the hole depth, so the rounded end below the tip clears the floor
  when the tip (the ``peg_tip`` site, the segment's end) is at the nominal bottom. All
  capsule-box pairs are one MJX collision group (2 contact points each, no mesh SAT).
  The free travel is ``R - r`` towards a face and ``(R - r) / cos(pi / n)`` towards a polygon
  vertex: the effective clearance is within ``+1 / cos(pi / n) - 1`` (+1.96 % for n = 16).
* ``cylinder`` (MuJoCo Warp only): true cylinders against the same box walls (nominal depth:
  the tip is flat); MJX-JAX has no cylinder-box collision.

The rectangular parts are boxes in both of their representations; ``edges`` (the default) lets
them meet only through tip- and mouth-edge capsules (:mod:`peghole_mjx.geometry.edges`).

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
from scipy.spatial import ConvexHull

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec, RectSpec
from peghole_mjx.geometry.task import REPRESENTATION as TASK_REPRESENTATION
from peghole_mjx.geometry.task import TaskSpec

GeomKind = Literal["box", "mesh", "capsule", "cylinder"]

#: the collision representations of the dual parts (see the module docstring)
REPRESENTATIONS = ("capsule", "mesh", "cylinder")
#: the rectangular parts' representations: "edges" (the default: the peg box and wall boxes
#: meet only through tip- and mouth-edge capsules, geometry/edges.py; MJX's box-box routine
#: misses shallow tilted contacts) or "box" (peg box against wall boxes)
RECT_REPRESENTATIONS = ("edges", "box")
RECT_DEFAULT_REPRESENTATION = "edges"
#: the dual default (the GPU-scale one: 4.05 MB of XLA traffic per world-step at its contact cap
#: vs the mesh scene's 67.2 MB; benchmarks/results/perf/cost_cpu-2core.json)
DUAL_DEFAULT_REPRESENTATION = "capsule"
#: representations each simulator implementation can collide
IMPL_REPRESENTATIONS = {
    "jax": ("capsule", "mesh", "box", "edges"),
    "warp": ("capsule", "mesh", "cylinder", "box", "edges"),
    "c": ("capsule", "mesh", "cylinder", "box", "edges"),
}


def resolve_representation(
    spec: PegHoleSpec | TaskSpec, representation: str | None = None, impl: str | None = None
) -> str:
    """The collision representation a scene of ``spec`` is built with, validated.

    ``None`` selects the default (``capsule`` for the dual parts, ``edges`` for the rect
    parts). ``impl`` (``"jax"``, ``"warp"``, ``"c"`` or
    ``None`` for no check) must be able to collide it: ``cylinder`` needs MuJoCo Warp (or C).
    Raises :class:`UserInputError` with one line naming the problem. A task folder's parts
    (:class:`~peghole_mjx.geometry.task.TaskSpec`) have one representation, its convex pieces
    (``hulls``).
    """
    if isinstance(spec, TaskSpec):
        if representation not in (None, TASK_REPRESENTATION):
            raise UserInputError(
                f"representation {representation!r}: a task folder's parts are its convex "
                f"pieces, representation {TASK_REPRESENTATION!r} (or null)"
            )
        return TASK_REPRESENTATION
    if representation is not None and representation not in (
        *REPRESENTATIONS,
        *RECT_REPRESENTATIONS,
    ):
        raise UserInputError(
            f"unknown collision representation {representation!r}; choose one of "
            f"{', '.join(REPRESENTATIONS)} (dual) or {', '.join(RECT_REPRESENTATIONS)} (rect)"
        )
    if isinstance(spec, RectSpec):
        rep = representation or RECT_DEFAULT_REPRESENTATION
        if rep not in RECT_REPRESENTATIONS:
            raise UserInputError(
                f"representation {rep!r} is the dual parts'; for the rect parts choose one of "
                f"{', '.join(RECT_REPRESENTATIONS)}"
            )
        return rep
    rep = representation or DUAL_DEFAULT_REPRESENTATION
    if rep in RECT_REPRESENTATIONS:
        raise UserInputError(
            f"representation {rep!r} is the rectangular parts'; for the dual parts choose one "
            f"of {', '.join(REPRESENTATIONS)}"
        )
    if impl is not None and rep not in IMPL_REPRESENTATIONS.get(impl, ()):
        raise UserInputError(
            f"representation {rep!r} cannot run with impl={impl!r}: MJX-JAX has no "
            "cylinder-box collision; use 'capsule' or 'mesh', or impl='warp' (MuJoCo Warp)"
        )
    return rep


#: radius of the rounded mouth lips of the capsule holes (0: none, the mouth edge is the walls'
#: box edge): a capsule along each wall's top inner edge, its inner surface at distance R
LIP_RADIUS_MM = 0.0
#: a quarter turn about x: a capsule's axis (local z) onto the local y
_QUAT_X_M90 = np.array([np.cos(-np.pi / 4), np.sin(-np.pi / 4), 0.0, 0.0])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def _quat_z(angle: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation by ``angle`` about z."""
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


def _mat_from_quat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@dataclass(frozen=True)
class ConvexPart:
    """One convex collision piece, placed in its owner's frame by ``pos`` and ``quat`` (metres).

    ``kind == "box"``: ``half_size`` (3); ``"capsule"`` / ``"cylinder"``: ``half_size`` =
    (radius, half length of the segment along the local z); ``"mesh"``: ``vertices`` (N x 3) in
    the piece's local frame. Pieces with the same ``mesh`` name share one mesh asset (their
    local vertices are equal). ``group`` tags pieces that may touch each other (peg i only meets
    hole i's pieces), ``None`` meaning any.
    """

    name: str
    kind: GeomKind
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    half_size: np.ndarray | None = None
    vertices: np.ndarray | None = None
    group: int | None = None
    quat: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    mesh: str | None = None

    @property
    def volume(self) -> float:
        if self.kind == "box":
            return float(8.0 * np.prod(self.half_size))
        if self.kind in ("capsule", "cylinder"):
            r, h = self.half_size
            cap = 4.0 / 3.0 * np.pi * r**3 if self.kind == "capsule" else 0.0
            return float(np.pi * r**2 * 2 * h + cap)

        return float(ConvexHull(self.vertices).volume)

    def local_corners(self) -> np.ndarray:
        """Vertices of the piece (capsule, cylinder: of its bounding box) in its own frame."""
        if self.kind == "mesh":
            return np.asarray(self.vertices)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        if self.kind == "box":
            half = np.asarray(self.half_size)
        else:
            r, h = self.half_size
            half = np.array([r, r, h + (r if self.kind == "capsule" else 0.0)])
        return signs * half

    def corners(self) -> np.ndarray:
        """Vertices of the piece (capsule, cylinder: of its bounding box) in the owner's frame."""
        return self.pos + self.local_corners() @ _mat_from_quat(self.quat).T


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


def hole_parts(spec: PegHoleSpec | TaskSpec, representation: str | None = None) -> list[ConvexPart]:
    """Convex pieces of the hole block in the hole frame (mouth at z = 0, material below).

    ``representation``: see :func:`resolve_representation` (``None``: the default). A task
    folder's hole part: its convex pieces (``hole_hull000``, ...).
    """
    if isinstance(spec, TaskSpec):
        return [
            ConvexPart(f"hole_hull{i:03d}", "mesh", vertices=np.asarray(h))
            for i, h in enumerate(spec.hole_hulls)
        ]
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
    rep = resolve_representation(spec, representation)
    n = spec.n_sides
    parts: list[ConvexPart] = []
    for i, (centre, R_mm) in enumerate(zip(hole_centres_m(spec), spec.hole_radii_mm, strict=True)):
        R = R_mm * MM
        cx, cy = centre
        if rep == "mesh":
            # wedge k is wedge 0 turned by 2 pi k / n about the hole axis: one shared mesh
            inner = regular_polygon(R, n)
            outer = inner * (R + wall) / R
            quad = np.array([inner[0], inner[1], outer[1], outer[0]])
            wedge = prism(quad, -depth, 0.0)
            for k in range(n):
                parts.append(
                    ConvexPart(
                        f"hole{i + 1}_wedge{k:02d}",
                        "mesh",
                        pos=np.array([cx, cy, 0.0]),
                        vertices=wedge,
                        group=i,
                        quat=_quat_z(2 * np.pi * k / n),
                        mesh=f"hole_wedge_R{R_mm:g}",
                    )
                )
            bottom = depth
        else:
            # boxes whose inner faces lie at distance R: an n-gon circumscribing the circle
            # (face k's normal at angle 2 pi (k + 1/2) / n, between the mesh polygon's
            # vertices k and k + 1); the capsule's walls reach r deeper for its rounded end
            extra = spec.peg_radii_mm[i] * MM if rep == "capsule" else 0.0
            bottom = depth + extra
            half_t = (R + wall) * np.tan(np.pi / n)  # reaches the neighbour's outer corner
            lip = LIP_RADIUS_MM * MM if rep == "capsule" else 0.0
            top = 2 * lip  # the wall boxes start below the lips
            for k in range(n):
                phi = 2 * np.pi * (k + 0.5) / n
                rc = R + wall / 2
                parts.append(
                    ConvexPart(
                        f"hole{i + 1}_wall{k:02d}",
                        "box",
                        pos=np.array(
                            [cx + rc * np.cos(phi), cy + rc * np.sin(phi), -(bottom + top) / 2]
                        ),
                        half_size=np.array([wall / 2, half_t, (bottom - top) / 2]),
                        group=i,
                        quat=_quat_z(phi),
                    )
                )
                if lip:
                    rl = R + lip
                    parts.append(
                        ConvexPart(
                            f"hole{i + 1}_lip{k:02d}",
                            "capsule",
                            pos=np.array([cx + rl * np.cos(phi), cy + rl * np.sin(phi), -lip]),
                            half_size=np.array([lip, R * np.tan(np.pi / n)]),
                            group=i,
                            quat=_quat_mul(_quat_z(phi), _QUAT_X_M90),
                        )
                    )
        parts.append(
            ConvexPart(
                f"hole{i + 1}_floor",
                "box",
                np.array([cx, cy, -bottom - floor / 2]),
                np.array([R + wall, R + wall, floor / 2]),
                group=i,
            )
        )
    return parts


def peg_parts(
    spec: PegHoleSpec | TaskSpec, single_hull: bool = False, representation: str | None = None
) -> list[ConvexPart]:
    """Convex pieces of the peg in the peg frame (mount at z = 0, tip at z = peg_tip_z_m).

    ``representation``: see :func:`resolve_representation` (``None``: the default). The
    capsule's rounded end reaches ``r`` beyond the tip (the hole's walls and floor are that
    much deeper); the ``peg_tip`` site stays at the end of its segment.

    ``single_hull=True`` returns the convex hull of the whole peg as ONE piece: what PyBullet
    (and MuJoCo, for a single non-convex mesh) collides. For the dual peg the hull fills the
    space between the pegs, so it cannot enter the holes (thesis Sec 1.6, result R6).
    """
    if isinstance(spec, TaskSpec):  # a task folder's peg: its convex pieces
        if single_hull:
            return [ConvexPart("peg_hull", "mesh", vertices=np.concatenate(spec.peg_hulls))]
        return [
            ConvexPart(f"peg_hull{i:03d}", "mesh", vertices=np.asarray(h))
            for i, h in enumerate(spec.peg_hulls)
        ]
    if single_hull:
        verts = np.concatenate([p.corners() for p in peg_parts(spec, representation="mesh")])
        return [ConvexPart("peg_hull", "mesh", vertices=verts)]
    length = spec.length_mm * MM
    if isinstance(spec, RectSpec):
        half = np.array([spec.peg_w_mm * MM / 2, spec.peg_v_mm * MM / 2, length / 2])
        return [ConvexPart("peg_body", "box", np.array([0, 0, length / 2]), half)]
    rep = resolve_representation(spec, representation)
    bridge = spec.bridge_mm * MM
    parts: list[ConvexPart] = []
    for i, (centre, r_mm) in enumerate(zip(peg_centres_m(spec), spec.peg_radii_mm, strict=True)):
        r = r_mm * MM
        if rep == "mesh":
            poly = regular_polygon(r, spec.n_sides)
            part = ConvexPart(
                f"peg{i + 1}",
                "mesh",
                pos=np.array([centre[0], centre[1], 0.0]),
                vertices=prism(poly, bridge, bridge + length),
                group=i,
                mesh=f"peg_prism_r{r_mm:g}",
            )
        else:  # capsule or cylinder: the segment from the bridge to the tip
            part = ConvexPart(
                f"peg{i + 1}",
                rep,
                pos=np.array([centre[0], centre[1], bridge + length / 2]),
                half_size=np.array([r, length / 2]),
                group=i,
            )
        parts.append(part)
    r_max = max(spec.peg_radii_mm) * MM
    half_x = 0.5 * spec.peg_distance_mm * MM + r_max
    parts.append(
        ConvexPart(
            "peg_bridge", "box", np.array([0, 0, bridge / 2]), np.array([half_x, r_max, bridge / 2])
        )
    )
    return parts


def peg_tip_z_m(spec: PegHoleSpec | TaskSpec) -> float:
    """Distance from the peg mount to the peg tip along the peg's +z (metres)."""
    extra = spec.bridge_mm if isinstance(spec, DualSpec) else 0.0
    return (spec.length_mm + extra) * MM


def peg_volumes(parts: list[ConvexPart]) -> np.ndarray:
    return np.array([p.volume for p in parts])
