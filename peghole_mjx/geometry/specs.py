"""Parametric peg-hole specifications, thesis presets and the extractability conditions.

This module is the single source of truth for every peg-hole dimension used in the project.
Dimensions are given and stored in millimetres (the thesis's unit); the ``*_m`` properties
give SI values for the simulator.

Extractability (thesis Sec 2.3.1 and Sec 3.2):

* dual peg-hole, eqs (2.1)-(2.3)::

      (2.1)  r_P1 < R_H1  and  r_P2 < R_H2
      (2.2)  D_P + r_P1 + r_P2 < D_H + R_H1 + R_H2
      (2.3)  D_P - r_P1 - r_P2 > D_H - R_H1 - R_H2

* rectangular peg-hole: ``w' < w`` and ``v' < v``.

Errata decisions (see ``docs/research/errata.md``): E1 (dual sample 3 is r = 6.05 mm, not 6.5 mm)
and
E2 (rect sample 3 is 60.05 x 40.05 mm, not 60.5 x 40.5 mm) are applied to the presets; the
printed values are rejected by :func:`validate` with an :class:`InfeasibleGeometryError`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

from peghole_mjx.core.errors import InfeasibleGeometryError
from peghole_mjx.core.validation import RANGES

MM = 1e-3  # metres per millimetre


@dataclass(frozen=True)
class RectSpec:
    """Rectangular peg in a rectangular blind hole (thesis Ch 3, Table 3.2).

    The hole is ``hole_w x hole_v`` and ``depth`` deep; the peg is ``peg_w x peg_v`` in cross
    section and ``length`` long, all in mm. ``friction`` is the static Coulomb coefficient.
    """

    hole_w_mm: float
    hole_v_mm: float
    peg_w_mm: float
    peg_v_mm: float
    length_mm: float
    depth_mm: float | None = None  # hole depth; defaults to the peg length (h0 = L)
    friction: float = 0.266
    peg_mass_kg: float = 0.4
    wall_mm: float = 20.0  # hole-block wall thickness around the hole
    floor_mm: float = 20.0  # hole-block thickness below the hole bottom
    kind: Literal["rect"] = field(default="rect", init=False)

    @property
    def hole_depth_mm(self) -> float:
        return self.length_mm if self.depth_mm is None else self.depth_mm

    @property
    def clearance_mm(self) -> float:
        """Nominal diametral clearance: the smaller of ``w - w'`` and ``v - v'``."""
        return min(self.hole_w_mm - self.peg_w_mm, self.hole_v_mm - self.peg_v_mm)

    @property
    def radial_clearance_mm(self) -> float:
        """Per-side clearance of the centred peg (half the diametral clearance)."""
        return 0.5 * self.clearance_mm


@dataclass(frozen=True)
class DualSpec:
    """Two round pegs joined by a bridge, in two round blind holes (thesis Ch 2, Table 2.2).

    Radii and centre distances follow Fig 2.1: hole radii ``R_H1, R_H2``, peg radii
    ``r_P1, r_P2``, hole centre distance ``D_H`` and peg centre distance ``D_P``, all in mm.
    """

    hole_radii_mm: tuple[float, float]
    peg_radii_mm: tuple[float, float]
    hole_distance_mm: float
    peg_distance_mm: float
    length_mm: float
    depth_mm: float | None = None  # hole depth; defaults to the peg length (h0 = L)
    friction: float = 0.01
    peg_mass_kg: float = 0.6
    bridge_mm: float = 10.0  # thickness of the bridge that joins the two pegs
    wall_mm: float = 15.0  # hole-block material around each hole
    floor_mm: float = 15.0
    n_sides: int = 16  # polygon sides used for the round pegs and holes
    kind: Literal["dual"] = field(default="dual", init=False)

    @property
    def hole_depth_mm(self) -> float:
        return self.length_mm if self.depth_mm is None else self.depth_mm

    @property
    def clearance_mm(self) -> float:
        """Nominal diametral clearance of the tighter peg: ``2 min(R_Hi - r_Pi)``."""
        return 2.0 * min(R - r for R, r in zip(self.hole_radii_mm, self.peg_radii_mm, strict=True))

    @property
    def radial_clearance_mm(self) -> float:
        return 0.5 * self.clearance_mm

    @property
    def clearance_ratio(self) -> float:
        """Thesis Table 2.2 clearance ratio ``C = (R - r) / R`` of the first peg."""
        R, r = self.hole_radii_mm[0], self.peg_radii_mm[0]
        return (R - r) / R


PegHoleSpec = RectSpec | DualSpec


def _require_positive(values: dict[str, float]) -> None:
    """Every size is a real number (not a boolean) within ``RANGES["size_mm"]`` (the smallest
    part MuJoCo builds, the robot's reach), every mass within ``RANGES["mass_kg"]``."""
    for name, v in values.items():
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise InfeasibleGeometryError(
                "a number", f"{name} must be a number, got {v!r} ({type(v).__name__})", {}
            )
        if not math.isfinite(v):
            raise InfeasibleGeometryError("finite size", f"{name} must be a finite number", {})
        if v <= 0:
            raise InfeasibleGeometryError("positive size", f"{name} must be > 0", {name: v})
        limit = RANGES["mass_kg" if name.endswith("_kg") else "size_mm"]
        if limit.lo is not None and v < limit.lo:
            raise InfeasibleGeometryError(
                "minimum size",
                f"{name} is below {limit.lo:g} mm" + (f" ({limit.why_lo})" if limit.why_lo else ""),
                {name: v},
            )
        if v > limit.hi:
            raise InfeasibleGeometryError(
                "within reach" if name.endswith("_mm") else "mass limit",
                f"{name} exceeds {limit.hi:g}" + (f" ({limit.why_hi})" if limit.why_hi else ""),
                {name: v},
            )


def _pair_of(name: str, value) -> tuple[float, float]:
    """``value`` as a pair (two radii); a one-line error for anything else."""
    if not isinstance(value, tuple | list) or len(value) != 2:
        raise InfeasibleGeometryError(
            "a pair", f"{name} must be two numbers (one per peg or hole), got {value!r}", {}
        )
    return value[0], value[1]


def check_rect_extractable(hole_w: float, hole_v: float, peg_w: float, peg_v: float) -> None:
    """Rectangular extractability (thesis Sec 3.2): ``w' < w`` and ``v' < v``.

    Raises :class:`InfeasibleGeometryError` naming the violated inequality.
    """
    if not peg_w < hole_w:
        raise InfeasibleGeometryError(
            "w' < w", "the peg is not narrower than the hole", {"w'": peg_w, "w": hole_w}
        )
    if not peg_v < hole_v:
        raise InfeasibleGeometryError(
            "v' < v", "the peg is not thinner than the hole", {"v'": peg_v, "v": hole_v}
        )


def check_dual_extractable(
    R_H1: float, R_H2: float, r_P1: float, r_P2: float, D_H: float, D_P: float
) -> None:
    """Dual peg-hole extractability, thesis eqs (2.1)-(2.3).

    Raises :class:`InfeasibleGeometryError` naming the first violated equation.
    """
    if not (r_P1 < R_H1 and r_P2 < R_H2):
        raise InfeasibleGeometryError(
            "eq 2.1 (r_P < R_H)",
            "each peg must be smaller than its hole",
            {"r_P1": r_P1, "R_H1": R_H1, "r_P2": r_P2, "R_H2": R_H2},
        )
    if not D_P + r_P1 + r_P2 < D_H + R_H1 + R_H2:
        raise InfeasibleGeometryError(
            "eq 2.2 (outer edges)",
            "D_P + r_P1 + r_P2 must be < D_H + R_H1 + R_H2",
            {"D_P + r_P1 + r_P2": D_P + r_P1 + r_P2, "D_H + R_H1 + R_H2": D_H + R_H1 + R_H2},
        )
    if not D_P - r_P1 - r_P2 > D_H - R_H1 - R_H2:
        raise InfeasibleGeometryError(
            "eq 2.3 (inner edges)",
            "D_P - r_P1 - r_P2 must be > D_H - R_H1 - R_H2",
            {"D_P - r_P1 - r_P2": D_P - r_P1 - r_P2, "D_H - R_H1 - R_H2": D_H - R_H1 - R_H2},
        )


def validate(spec: PegHoleSpec) -> PegHoleSpec:
    """Check sizes and extractability of ``spec``; return it unchanged if feasible."""
    if isinstance(spec, RectSpec):
        _require_positive(
            {
                "hole_w_mm": spec.hole_w_mm,
                "hole_v_mm": spec.hole_v_mm,
                "peg_w_mm": spec.peg_w_mm,
                "peg_v_mm": spec.peg_v_mm,
                "length_mm": spec.length_mm,
                "hole_depth_mm": spec.hole_depth_mm,
                "peg_mass_kg": spec.peg_mass_kg,
                "wall_mm": spec.wall_mm,
                "floor_mm": spec.floor_mm,
            }
        )
        check_rect_extractable(spec.hole_w_mm, spec.hole_v_mm, spec.peg_w_mm, spec.peg_v_mm)
    elif isinstance(spec, DualSpec):
        (R1, R2) = _pair_of("hole_radii_mm", spec.hole_radii_mm)
        (r1, r2) = _pair_of("peg_radii_mm", spec.peg_radii_mm)
        if isinstance(spec.n_sides, bool) or not isinstance(spec.n_sides, int):
            raise InfeasibleGeometryError(
                "n_sides >= 8 and even", f"n_sides must be an integer, got {spec.n_sides!r}", {}
            )
        _require_positive(
            {
                "hole_radius_1_mm": R1,
                "hole_radius_2_mm": R2,
                "peg_radius_1_mm": r1,
                "peg_radius_2_mm": r2,
                "hole_distance_mm": spec.hole_distance_mm,
                "peg_distance_mm": spec.peg_distance_mm,
                "length_mm": spec.length_mm,
                "hole_depth_mm": spec.hole_depth_mm,
                "peg_mass_kg": spec.peg_mass_kg,
                "bridge_mm": spec.bridge_mm,
                "wall_mm": spec.wall_mm,
                "floor_mm": spec.floor_mm,
            }
        )
        check_dual_extractable(R1, R2, r1, r2, spec.hole_distance_mm, spec.peg_distance_mm)
        if spec.hole_distance_mm <= R1 + R2:
            raise InfeasibleGeometryError(
                "separate holes",
                "the two holes overlap (D_H must exceed R_H1 + R_H2)",
                {"D_H": spec.hole_distance_mm, "R_H1 + R_H2": R1 + R2},
            )
        if spec.n_sides < 8 or spec.n_sides % 2:
            raise InfeasibleGeometryError(
                "n_sides >= 8 and even",
                "round parts need an even number (>= 8) of polygon sides, so that the peg "
                "polygon lines up with the hole polygon after the peg frame's half turn",
                {"n": spec.n_sides},
            )
    else:
        raise TypeError(f"not a peg-hole spec: {type(spec).__name__}")
    if (
        isinstance(spec.friction, bool)
        or not isinstance(spec.friction, int | float)
        or not 0.0 <= spec.friction <= 2.0
    ):
        raise InfeasibleGeometryError(
            "0 <= mu <= 2", "friction out of range", {"mu": spec.friction}
        )
    if spec.hole_depth_mm > spec.length_mm:
        raise InfeasibleGeometryError(
            "depth <= length",
            "the hole is deeper than the peg is long (the peg could not be gripped out)",
            {"depth": spec.hole_depth_mm, "length": spec.length_mm},
        )
    return spec


def rect_spec(
    hole_mm: tuple[float, float], peg_mm: tuple[float, float], length_mm: float, **kw
) -> RectSpec:
    """Build and validate a :class:`RectSpec` from ``(w, v)`` pairs in mm."""
    spec = RectSpec(hole_mm[0], hole_mm[1], peg_mm[0], peg_mm[1], length_mm, **kw)
    return validate(spec)  # type: ignore[return-value]


def dual_spec(
    hole_radius_mm: float, peg_radius_mm: float, distance_mm: float, length_mm: float, **kw
) -> DualSpec:
    """Build and validate a symmetric :class:`DualSpec` (equal radii, D_P = D_H)."""
    spec = DualSpec(
        (hole_radius_mm, hole_radius_mm),
        (peg_radius_mm, peg_radius_mm),
        distance_mm,
        distance_mm,
        length_mm,
        **kw,
    )
    return validate(spec)  # type: ignore[return-value]


# Thesis presets. Rect: Table 3.2 (E2 applied to sample 3). Dual: Table 2.2 (E1 applied).
PRESETS: dict[str, PegHoleSpec] = {
    "rect-1": rect_spec((60.1, 40.1), (59.5, 39.5), 150.0),
    "rect-2": rect_spec((60.1, 40.1), (60.0, 40.0), 150.0),
    "rect-3": rect_spec((60.1, 40.1), (60.05, 40.05), 150.0),
    "dual-1": dual_spec(6.1, 5.7, 40.0, 50.0),
    "dual-2": dual_spec(6.1, 6.0, 40.0, 50.0),
    "dual-3": dual_spec(6.1, 6.05, 40.0, 50.0),
}


def get_preset(name: str) -> PegHoleSpec:
    """Return the preset ``name`` (``rect-1..3``, ``dual-1..3``) or raise a clear KeyError."""
    try:
        return PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}") from None


def with_changes(spec: PegHoleSpec, **changes) -> PegHoleSpec:
    """A validated copy of ``spec`` with fields replaced."""
    return validate(dataclasses.replace(spec, **changes))
