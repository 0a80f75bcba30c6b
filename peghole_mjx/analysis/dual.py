"""Dual peg-hole extraction in 2D (thesis Ch 2): the three two-point categories.

Geometry (Fig 2.1): hole radii ``R_H1, R_H2`` with axes ``D_H`` apart, peg radii ``r_P1, r_P2``
with axes ``D_P`` apart, pegs of length ``L`` joined rigidly. World origin: midway between
the hole axes at the mouth. Body origin: midway between the peg axes on the tip line. The
compliance centre lies on the body's symmetry axis, ``L_C`` above the tip line (Sec 2.2 (c)).

The categories of Fig 2.5, each a :class:`~.planar.ContactPair` in its "+" configuration
(tilt > 0, tips displaced towards ``+x``) and its "-" mirror:

* ``"5"`` - two points in one peg-hole (state 5/6): the mouth corner of hole i on one side
  of peg i and the opposite tip corner of peg i on the wall of hole i. The deeper peg carries
  it (peg 1 for "+", peg 2 for "-"), effective widths ``2 R_Hi``, ``2 r_Pi``.
* ``"10"`` - outer surfaces (state 10): the outer mouth corner of one hole on the outer side of
  its peg and the outer tip corner of the other peg on the outer wall of the other hole;
  widths ``D_H + R_H1 + R_H2`` and ``D_P + r_P1 + r_P2`` (the thesis's ``2R``, ``2r``).
* ``"9"`` - inner surfaces (state 9): the inverted peg-hole of eqs 2.36-2.38; the septum
  between the holes (width ``D_H - R_H1 - R_H2 = 2R'``) plays the peg, the gap between the
  pegs (``D_P - r_P1 - r_P2 = 2r'``) the hole.

Closed forms (re-derived, docs/research/analysis.md): boundary quadratics (2.14), (2.29), (2.43) via
:func:`.planar.boundary_quadratics`; two-point forces (2.19)-(2.20), (2.33)-(2.34), (2.48) via
:func:`.planar.two_point_forces`; one-point forces (2.17)-(2.18), (2.21), (2.31)-(2.32),
(2.35), (2.46)-(2.47), (2.49) via :func:`.planar.one_point_tip` / :func:`.planar.one_point_mouth`.
Extractability (2.1)-(2.3) is :func:`peghole_mjx.geometry.specs.check_dual_extractable`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from peghole_mjx.analysis import common, oracle, planar
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.specs import (
    DualSpec,
    InfeasibleGeometryError,
    check_dual_extractable,
    get_preset,
    validate,
)

CATEGORIES = ("5", "10", "9")
CATEGORY_NAMES = {
    "5": "two-point contact in one peg-hole (state 5)",
    "10": "outer surfaces of the pegs on the holes (state 10)",
    "9": "inner surfaces of the pegs on the holes (state 9)",
}
#: Parameter values of the analytic studies (Figs 2.11-2.18).
DEFAULTS = dict(
    K_x_N_per_mm=0.4,
    K_theta_Nmm_per_rad=30e4,
    delta0_mm=2.0,
    beta0_rad=0.0,
    theta0_rad=common.THETA0_RAD,
)
#: Geometry of the analytic studies: Table 2.2 sample 2 (r = 6.0 mm; see docs/research/analysis.md).
FIGURE_PRESET = "dual-2"


def _check_category(category: str) -> str:
    category = str(category)
    if category not in CATEGORIES:
        raise UserInputError(f"unknown dual category {category!r}; choose one of 5, 10, 9")
    return category


def category_pairs(spec: DualSpec, category: str) -> tuple[planar.ContactPair, planar.ContactPair]:
    """World-frame ``("+", "-")`` contact pairs of ``category`` for ``spec``."""
    category = _check_category(category)
    (R1, R2), (r1, r2) = spec.hole_radii_mm, spec.peg_radii_mm
    DH, DP = spec.hole_distance_mm, spec.peg_distance_mm
    if category == "5":
        plus = planar.ContactPair(-DH / 2 - R1, -DP / 2 - r1, -DH / 2 + R1, -DP / 2 + r1)
        minus = planar.ContactPair(DH / 2 + R2, DP / 2 + r2, DH / 2 - R2, DP / 2 - r2)
    elif category == "10":
        plus = planar.ContactPair(-DH / 2 - R1, -DP / 2 - r1, DH / 2 + R2, DP / 2 + r2)
        minus = planar.ContactPair(DH / 2 + R2, DP / 2 + r2, -DH / 2 - R1, -DP / 2 - r1)
    else:
        plus = planar.ContactPair(DH / 2 - R2, DP / 2 - r2, -DH / 2 + R1, -DP / 2 + r1)
        minus = planar.ContactPair(-DH / 2 + R1, -DP / 2 + r1, DH / 2 - R2, DP / 2 - r2)
    return plus, minus


def check_geometry(spec: DualSpec) -> DualSpec:
    """Validate ``spec``: sizes, eqs (2.1)-(2.3) (raises ``InfeasibleGeometryError``)."""
    if not isinstance(spec, DualSpec):
        raise UserInputError(f"expected a dual peg-hole spec, got {type(spec).__name__}")
    validate(spec)
    (R1, R2), (r1, r2) = spec.hole_radii_mm, spec.peg_radii_mm
    check_dual_extractable(R1, R2, r1, r2, spec.hole_distance_mm, spec.peg_distance_mm)
    return spec


@dataclass(frozen=True)
class DualParams:
    """Validated compliance and error parameters (mm, N, rad; arrays broadcast)."""

    L_C: np.ndarray
    K_x: np.ndarray
    K_theta: np.ndarray
    delta0: np.ndarray
    beta0: np.ndarray
    theta0: np.ndarray
    h0: np.ndarray
    mu: np.ndarray


def params(
    spec: DualSpec,
    L_C_mm,
    K_x_N_per_mm=DEFAULTS["K_x_N_per_mm"],
    K_theta_Nmm_per_rad=DEFAULTS["K_theta_Nmm_per_rad"],
    delta0_mm=DEFAULTS["delta0_mm"],
    beta0_rad=DEFAULTS["beta0_rad"],
    theta0_rad=DEFAULTS["theta0_rad"],
    h0_mm=None,
    mu=None,
) -> DualParams:
    """Validate the user parameters (``UserInputError`` on bad values)."""
    L = spec.length_mm
    return DualParams(
        L_C=common.check_compliance_centre(L_C_mm, L),
        K_x=common.check_positive("K_x_N_per_mm", K_x_N_per_mm),
        K_theta=common.check_positive("K_theta_Nmm_per_rad", K_theta_Nmm_per_rad),
        delta0=np.asarray(common._arr("delta0_mm", delta0_mm)),
        beta0=common.check_angle("beta0_rad", beta0_rad),
        theta0=common.check_angle("theta0_rad", theta0_rad),
        h0=common.check_depth(spec.hole_depth_mm if h0_mm is None else h0_mm, L),
        mu=common.check_friction(spec.friction if mu is None else mu),
    )


def _springs(p: DualParams, mirrored: bool) -> planar.Springs:
    x_m, theta_m = common.rest_pose(p.L_C, p.delta0, p.beta0, p.theta0)
    sgn = -1.0 if mirrored else 1.0
    return planar.Springs(p.K_x, p.K_theta, p.L_C, sgn * x_m, sgn * theta_m)


@dataclass(frozen=True)
class DualRegion:
    """Two-point region of a category (depths in mm, NaN when empty): per configuration and
    combined (``h_lo``/``h_hi`` outer bounds, ``length`` total)."""

    category: str
    plus: planar.Region
    minus: planar.Region
    h_lo: np.ndarray
    h_hi: np.ndarray
    length: np.ndarray


def combine(a: planar.Region, b: planar.Region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Union of the regions of the two mirror configurations (they never overlap: opposite
    tilt signs)."""
    with np.errstate(all="ignore"):
        lo = np.fmin(a.h_lo, b.h_lo)
        hi = np.fmax(a.h_hi, b.h_hi)
    return lo, hi, a.length + b.length


def two_point_region(
    spec: DualSpec | str,
    category: str,
    L_C_mm,
    K_x_N_per_mm=DEFAULTS["K_x_N_per_mm"],
    K_theta_Nmm_per_rad=DEFAULTS["K_theta_Nmm_per_rad"],
    delta0_mm=DEFAULTS["delta0_mm"],
    beta0_rad=DEFAULTS["beta0_rad"],
    theta0_rad=DEFAULTS["theta0_rad"],
    h0_mm=None,
    mu=None,
    refine: bool = False,
) -> DualRegion:
    """Boundary depths of the two-point region of a dual category (eqs 2.14/2.29/2.43 roots).

    Vectorised: every numeric argument may be an array; they broadcast together. Depths are
    those of the middle of the tip line below the mouth, in mm; ``h0_mm`` (default: the hole
    depth) caps the search. ``refine=True`` polishes the small-angle roots on the exact
    statics.
    """
    if isinstance(spec, str):
        spec = get_preset(spec)  # type: ignore[assignment]
    spec = check_geometry(spec)  # type: ignore[arg-type]
    category = _check_category(category)
    p = params(
        spec, L_C_mm, K_x_N_per_mm, K_theta_Nmm_per_rad, delta0_mm, beta0_rad, theta0_rad, h0_mm, mu
    )
    plus, minus = category_pairs(spec, category)
    if not np.all(np.asarray(plus.two_c) > 0):
        raise InfeasibleGeometryError(
            f"category {category} clearance > 0", "no clearance in this contact category", {}
        )
    L = spec.length_mm
    rp = planar.two_point_region(plus, _springs(p, False), p.mu, p.h0, L, refine=refine)
    rm = planar.two_point_region(
        planar.mirror_pair(minus), _springs(p, True), p.mu, p.h0, L, refine=refine
    )
    lo, hi, length = combine(rp, rm)
    return DualRegion(category=category, plus=rp, minus=rm, h_lo=lo, h_hi=hi, length=length)


@dataclass(frozen=True)
class DualForces:
    """Forces at one depth for one configuration (N, N mm, rad, mm)."""

    two_point: planar.TwoPointForces
    tip_only: planar.OnePointState
    mouth_only: planar.OnePointState


def forces(
    spec: DualSpec | str,
    category: str,
    depth_mm,
    L_C_mm,
    configuration: str = "-",
    exact: bool = False,
    **kw,
) -> DualForces:
    """Two-point contact forces (2.19)-(2.20), (2.33)-(2.34), (2.48) and the one-point states
    (2.17)-(2.18)/(2.21), (2.31)-(2.32)/(2.35), (2.46)-(2.47)/(2.49) of a configuration
    (``"+"`` or ``"-"``) at ``depth_mm`` (small-angle closed forms; ``exact=True`` solves the
    two-point statics exactly). Forces of the "-" configuration are returned in the mirrored
    frame (lateral force and moment change sign in the world frame)."""
    if isinstance(spec, str):
        spec = get_preset(spec)  # type: ignore[assignment]
    spec = check_geometry(spec)  # type: ignore[arg-type]
    p = params(spec, L_C_mm, **kw)
    plus, minus = category_pairs(spec, category)
    if configuration not in ("+", "-"):
        raise UserInputError("configuration must be '+' or '-'")
    mirrored = configuration == "-"
    pair = planar.mirror_pair(minus) if mirrored else plus
    sp = _springs(p, mirrored)
    depth = common.check_positive("depth_mm", depth_mm)
    s = planar.s_from_depth(pair, depth)
    return DualForces(
        two_point=planar.two_point_forces(pair, sp, p.mu, s, exact=exact),
        tip_only=planar.one_point_tip(pair, sp, p.mu),
        mouth_only=planar.one_point_mouth(pair, sp, p.mu, s),
    )


def oracle_body(
    spec: DualSpec, category: str | None, L_C_mm, **kw
) -> tuple[oracle.PlanarBody, tuple[frozenset[int], ...]]:
    """The numerical oracle's body for a category (its four contacts in isolation) or, with
    ``category=None``, the full dual peg-hole with all eight contacts. Also returns the
    oracle's contact-index sets that mean "two-point state of this category"."""
    spec = check_geometry(spec)
    p = params(spec, L_C_mm, **kw)
    x_m, theta_m = common.rest_pose(p.L_C, p.delta0, p.beta0, p.theta0)
    if category is None:
        contacts = full_contacts(spec)
        target = ()
    else:
        plus, minus = category_pairs(spec, category)
        contacts = oracle.category_contacts(plus, minus)
        target = (frozenset({0, 1}), frozenset({2, 3}))
    body = oracle.PlanarBody(
        contacts=contacts,
        K_x=p.K_x,
        K_theta=p.K_theta,
        L_C=p.L_C,
        x_m=x_m,
        theta_m=theta_m,
        mu=p.mu,
        length=spec.length_mm,
    )
    return body, target


def full_contacts(spec: DualSpec) -> tuple[oracle.Contact, ...]:
    """All eight candidate contacts of the dual peg-hole (hole i corners on peg i sides, peg i
    tip corners on hole i walls)."""
    (R1, R2), (r1, r2) = spec.hole_radii_mm, spec.peg_radii_mm
    DH, DP = spec.hole_distance_mm, spec.peg_distance_mm
    out = []
    for i, (xh, xp, R, r) in enumerate(((-DH / 2, -DP / 2, R1, r1), (DH / 2, DP / 2, R2, r2)), 1):
        out += [
            oracle.Contact(oracle.ON_SIDE, xh - R, xp - r, +1, f"H{i}L-corner/P{i}"),
            oracle.Contact(oracle.ON_SIDE, xh + R, xp + r, -1, f"H{i}R-corner/P{i}"),
            oracle.Contact(oracle.ON_WALL, xh - R, xp - r, -1, f"P{i}L-tip/H{i}"),
            oracle.Contact(oracle.ON_WALL, xh + R, xp + r, +1, f"P{i}R-tip/H{i}"),
        ]
    return tuple(out)
