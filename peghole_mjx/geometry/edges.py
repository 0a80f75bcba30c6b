"""Edge-capsule contacts for the rectangular peg-hole (representation ``edges``).

MJX-JAX's box-box routine (``collision_convex._box_box``, mujoco-mjx 3.17) misses shallow
contacts of a slightly tilted peg box against a wall box: from the same state MuJoCo C finds
two contacts per wall at 0.7-0.9 um penetration and MJX none, so the tilted peg falls in, is
thrown out on the next step and chatters between the walls (docs/research/contact.md). A straight
rigid
peg in a hole can only touch the walls with its tip edges, and the peg's sides can only be
touched by the hole's mouth edges; so the contact features are modelled directly:

* each of the peg's four tip edges is a capsule of radius ``rho`` whose surface is tangent to
  the peg's side and tip faces (the edge rounded by ``rho``), colliding with the four wall
  boxes and the floor box (capsule-box: two contact points per pair);
* each of the hole's four mouth edges is a capsule of radius ``rho`` tangent to the wall's inner
  and top faces, colliding with the peg box (capsule-box);
* parallel tip and mouth capsules collide with each other (the tip leaving the mouth).

The peg box and the wall boxes keep their shape, mass and looks but do not collide with each
other. The rounding changes the contact point by ``rho (1 - cos theta)``: nanometres at the
tilts of a 0.05-0.6 mm clearance.
"""

from __future__ import annotations

import mujoco
import numpy as np

from peghole_mjx.geometry.specs import MM, RectSpec

#: radius of the edge capsules, m
EDGE_RADIUS_M = 0.5e-3


def _capsule(body: mujoco.MjsBody, name: str, a, b, rho: float) -> None:
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=[*a, *b],
        size=[rho, 0, 0],
        contype=0,
        conaffinity=0,
        density=0,
        group=3,
        rgba=[0.9, 0.2, 0.2, 0.5],
    )


def add_peg_edges(body: mujoco.MjsBody, spec: RectSpec, rho: float = EDGE_RADIUS_M) -> list[str]:
    """The peg's four tip-edge capsules (peg frame: tip at z = L, x along the width)."""
    hx, hy, z = spec.peg_w_mm * MM / 2 - rho, spec.peg_v_mm * MM / 2 - rho, spec.length_mm * MM
    z -= rho
    names = []
    for sx in (1, -1):
        n = f"peg_edge_x{'p' if sx > 0 else 'n'}"
        _capsule(body, n, (sx * hx, -hy, z), (sx * hx, hy, z), rho)
        names.append(n)
    for sy in (1, -1):
        n = f"peg_edge_y{'p' if sy > 0 else 'n'}"
        _capsule(body, n, (-hx, sy * hy, z), (hx, sy * hy, z), rho)
        names.append(n)
    return names


def add_mouth_edges(body: mujoco.MjsBody, spec: RectSpec, rho: float = EDGE_RADIUS_M) -> list[str]:
    """The hole's four mouth-edge capsules (hole frame: mouth at z = 0, width along x)."""
    hw, hv = spec.hole_w_mm * MM / 2, spec.hole_v_mm * MM / 2
    names = []
    for sx in (1, -1):
        n = f"mouth_edge_x{'p' if sx > 0 else 'n'}"
        _capsule(body, n, (sx * (hw + rho), -hv, -rho), (sx * (hw + rho), hv, -rho), rho)
        names.append(n)
    for sy in (1, -1):
        n = f"mouth_edge_y{'p' if sy > 0 else 'n'}"
        _capsule(body, n, (-hw, sy * (hv + rho), -rho), (hw, sy * (hv + rho), -rho), rho)
        names.append(n)
    return names


def edge_pairs(
    peg_edges: list[str], mouth_edges: list[str], peg_box: str, hole_boxes: list[str]
) -> list[tuple[str, str]]:
    """The (geom1, geom2) contact pairs of the edge model; geom1 is on the peg, so the
    contact normal points from the peg into the hole part."""
    pairs = [(e, h) for e in peg_edges for h in hole_boxes]
    pairs += [(peg_box, m) for m in mouth_edges]
    # parallel tip and mouth edges (x-edges with x-edges, y-edges with y-edges); the peg frame's
    # x is the hole frame's -x, so the peg's +x edge meets the mouth's -x edge
    flip = {"p": "n", "n": "p"}
    for e in peg_edges:
        axis, side = e[-2], e[-1]
        other = flip[side] if axis == "x" else side
        pairs.append((e, f"mouth_edge_{axis}{other}"))
    return pairs


def check_radius(spec: RectSpec, rho: float) -> float:
    """``rho`` must be positive and leave the peg's faces: below a quarter of its smaller side."""
    lim = 0.25 * min(spec.peg_w_mm, spec.peg_v_mm) * MM
    if not (np.isfinite(rho) and 0.0 < rho < lim):
        raise ValueError(f"edge radius {rho} m must be in (0, {lim:g}) m")
    return float(rho)
