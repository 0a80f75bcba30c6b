"""Rectangular peg-hole extraction in 3D (thesis Ch 3): jamming cases 1-5.

Axes (Figs 3.2, 3.5): the hole is ``w`` (along ``y``) by ``v`` (along ``x``), the peg ``w'`` by
``v'``; ``theta``, ``phi``, ``psi`` are rotations about ``x``, ``y``, ``z``. The compliance
centre lies on the peg axis ``L_C`` above the tip (``L_C = 0``: at the peg end).

Every case is re-derived (docs/research/analysis.md); none of the printed coefficient sets is used:

* **case 1, two-point contact** (Fig 3.4a, root eq 3.23): the peg tilts in the ``y-z`` plane
  (``theta``) and, yawed by ``psi``, touches the ``y`` walls with two vertical corners; in the
  ``y-z`` plane this is the planar two-point template with the effective peg width
  ``w' cos psi + v' |sin psi|`` and no contact with the ``x`` walls. Erratum E7: the printed
  3.23 coefficients are those of case 3 (3.73); the re-derived case 1 has no ``delta_X`` term.
* **case 2, two-side contact** (Fig 3.4b, eq 3.47): line contacts on the two ``x`` walls,
  tilt ``phi``: the planar template in the ``x-z`` plane with widths ``v``, ``v'``.
* **case 3, two-side + one-plane** (Fig 3.4c, eq 3.73): line contacts on the ``y`` walls
  (tilt ``theta``) with a face pressed flat on an ``x`` wall by the ``x`` spring
  (``N3 = K_X (|x_m| - (v - v')/2)``); its friction ``mu N3`` (vertical, acting at the middle
  of the inserted face) adds to ``F_z`` and to the moment balance.
* **case 4, two-edge contact** (Fig 3.4d, eq 3.97): the peg yawed until two diagonal vertical
  edges touch the ``x`` walls, ``v' cos psi + w' sin psi = v``; roots in ``psi``.
* **case 5, three-edge contact** (Fig 3.4e, eq 3.118): case 4 plus a third edge on a ``y``
  wall; roots in ``psi`` of ``N3 = 0``.

The initial tilt ``theta0`` (-0.9 deg, erratum E3) is applied in the plane of the analysed
case; the out-of-plane initial tilt is zero (a face flat on a wall in case 3 needs it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from peghole_mjx.analysis import common, oracle, planar
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.specs import RectSpec, check_rect_extractable, get_preset, validate

CASES = (1, 2, 3, 4, 5)
CASE_NAMES = {
    1: "two-point contact",
    2: "two-side contact",
    3: "two-side + one-plane contact",
    4: "two-edge contact",
    5: "three-edge contact",
}
#: Parameter values of the analytic studies (Figs 3.12-3.42).
DEFAULTS = dict(
    K_x_N_per_mm=0.3,
    K_y_N_per_mm=0.3,
    K_theta_Nmm_per_rad=30e4,
    K_phi_Nmm_per_rad=30e4,
    K_psi_Nmm_per_rad=30e4,
    delta_x_mm=2.0,
    delta_y_mm=2.0,
    delta_theta_rad=0.0,
    delta_phi_rad=0.0,
    delta_psi_rad=0.0,
    theta0_rad=common.THETA0_RAD,
)
FIGURE_PRESET = "rect-1"


def check_geometry(spec: RectSpec) -> RectSpec:
    """Validate sizes and the rectangular extractability condition ``w' < w, v' < v``."""
    if not isinstance(spec, RectSpec):
        raise UserInputError(f"expected a rectangular peg-hole spec, got {type(spec).__name__}")
    validate(spec)
    check_rect_extractable(spec.hole_w_mm, spec.hole_v_mm, spec.peg_w_mm, spec.peg_v_mm)
    return spec


def _spec(spec) -> RectSpec:
    if isinstance(spec, str):
        spec = get_preset(spec)
    return check_geometry(spec)


@dataclass(frozen=True)
class RectParams:
    """Validated parameters (mm, N, rad)."""

    L_C: np.ndarray
    K_x: np.ndarray
    K_y: np.ndarray
    K_theta: np.ndarray
    K_phi: np.ndarray
    K_psi: np.ndarray
    delta_x: np.ndarray
    delta_y: np.ndarray
    delta_theta: np.ndarray
    delta_phi: np.ndarray
    delta_psi: np.ndarray
    theta0: np.ndarray
    h0: np.ndarray
    mu: np.ndarray


def params(spec: RectSpec, L_C_mm, h0_mm=None, mu=None, **kw) -> RectParams:
    """Validate user parameters (defaults: :data:`DEFAULTS`)."""
    unknown = set(kw) - set(DEFAULTS)
    if unknown:
        raise UserInputError(f"unknown rect parameter(s): {sorted(unknown)}")
    v = {**DEFAULTS, **kw}
    L = spec.length_mm
    return RectParams(
        L_C=common.check_compliance_centre(L_C_mm, L),
        K_x=common.check_positive("K_x_N_per_mm", v["K_x_N_per_mm"]),
        K_y=common.check_positive("K_y_N_per_mm", v["K_y_N_per_mm"]),
        K_theta=common.check_positive("K_theta_Nmm_per_rad", v["K_theta_Nmm_per_rad"]),
        K_phi=common.check_positive("K_phi_Nmm_per_rad", v["K_phi_Nmm_per_rad"]),
        K_psi=common.check_positive("K_psi_Nmm_per_rad", v["K_psi_Nmm_per_rad"]),
        delta_x=common._arr("delta_x_mm", v["delta_x_mm"]),
        delta_y=common._arr("delta_y_mm", v["delta_y_mm"]),
        delta_theta=common.check_angle("delta_theta_rad", v["delta_theta_rad"]),
        delta_phi=common.check_angle("delta_phi_rad", v["delta_phi_rad"]),
        delta_psi=common.check_angle("delta_psi_rad", v["delta_psi_rad"]),
        theta0=common.check_angle("theta0_rad", v["theta0_rad"]),
        h0=common.check_depth(spec.hole_depth_mm if h0_mm is None else h0_mm, L),
        mu=common.check_friction(spec.friction if mu is None else mu),
    )


@dataclass(frozen=True)
class PlanarCase:
    """A case 1-3 reduced to its plane: "+"/"-" pairs (world frame), springs (unmirrored),
    and the plane-contact friction ``f3`` (N)."""

    plus: planar.ContactPair
    minus: planar.ContactPair
    K: np.ndarray
    K_rot: np.ndarray
    x_m: np.ndarray
    theta_m: np.ndarray
    f3: np.ndarray
    N3: np.ndarray
    fits: np.ndarray


def plane_contact_force(spec: RectSpec, p: RectParams) -> np.ndarray:
    """Normal force (N) of the case 3 face on the ``x`` wall: the ``x`` spring pushes the peg
    flat on the nearer wall once its rest position is beyond the clearance."""
    half = 0.5 * (spec.hole_v_mm - spec.peg_v_mm)
    return p.K_x * np.maximum(np.abs(p.delta_x) - half, 0.0)


def planar_case(spec: RectSpec, case: int, p: RectParams) -> PlanarCase:
    """Reduce case 1, 2 or 3 to the planar template."""
    if case == 2:
        Wh, Wp = spec.hole_v_mm, spec.peg_v_mm
        K, Kr, delta, dang = p.K_x, p.K_phi, p.delta_x, p.delta_phi
        f3 = N3 = np.zeros(())
    elif case in (1, 3):
        Wh = spec.hole_w_mm
        if case == 1:
            psi = p.delta_psi
            Wp = spec.peg_w_mm * np.cos(psi) + spec.peg_v_mm * np.abs(np.sin(psi))
            f3 = N3 = np.zeros(())
        else:
            Wp = spec.peg_w_mm
            N3 = plane_contact_force(spec, p)
            f3 = p.mu * N3
        K, Kr, delta, dang = p.K_y, p.K_theta, p.delta_y, p.delta_theta
    else:
        raise UserInputError(f"case {case} is not a planar case (1, 2, 3)")
    Wh = np.asarray(Wh, float)
    Wp = np.asarray(Wp, float)
    fits = Wp < Wh
    if not np.any(fits):
        raise UserInputError(
            f"case {case}: the yawed peg (effective width {np.max(Wp):g} mm) no longer fits "
            f"the hole ({float(np.max(Wh)):g} mm): two-edge contact (case 4) applies; reduce "
            "delta_psi_rad"
        )
    # where the yaw exceeds the two-edge contact yaw, case 1 cannot occur (case 4 applies):
    # evaluate with a fitting width and blank the result in two_contact_region
    Wp = np.where(fits, Wp, Wh - 1e-3)
    plus = planar.ContactPair(-Wh / 2, -Wp / 2, Wh / 2, Wp / 2)
    minus = planar.ContactPair(Wh / 2, Wp / 2, -Wh / 2, -Wp / 2)
    x_m, theta_m = common.rest_pose(p.L_C, delta, dang, p.theta0)
    return PlanarCase(plus, minus, K, Kr, x_m, theta_m, np.asarray(f3), np.asarray(N3), fits)


@dataclass(frozen=True)
class RectRegion:
    """Two-contact region of a planar case (depths of the peg tip below the mouth, mm)."""

    case: int
    plus: planar.Region
    minus: planar.Region
    h_lo: np.ndarray
    h_hi: np.ndarray
    length: np.ndarray


def two_contact_region(
    spec: RectSpec | str, case: int, L_C_mm, h0_mm=None, mu=None, refine: bool = False, **kw
) -> RectRegion:
    """Boundary depths of the two-contact region of case 1, 2 or 3 (roots of the re-derived
    3.23, 3.47, 3.73). Vectorised over every numeric argument."""
    spec = _spec(spec)
    case = int(case)
    if case not in (1, 2, 3):
        raise UserInputError(f"two_contact_region handles cases 1-3, got {case}")
    p = params(spec, L_C_mm, h0_mm, mu, **kw)
    pc = planar_case(spec, case, p)
    L = spec.length_mm
    sp = planar.Springs(pc.K, pc.K_rot, p.L_C, pc.x_m, pc.theta_m)
    spm = planar.Springs(pc.K, pc.K_rot, p.L_C, -pc.x_m, -pc.theta_m)
    rp = planar.two_point_region(pc.plus, sp, p.mu, p.h0, L, f3=pc.f3, refine=refine)
    rm = planar.two_point_region(
        planar.mirror_pair(pc.minus), spm, p.mu, p.h0, L, f3=pc.f3, refine=refine
    )
    with np.errstate(all="ignore"):
        lo = np.where(pc.fits, np.fmin(rp.h_lo, rm.h_lo), np.nan)
        hi = np.where(pc.fits, np.fmax(rp.h_hi, rm.h_hi), np.nan)
    return RectRegion(case, rp, rm, lo, hi, np.where(pc.fits, rp.length + rm.length, 0.0))


def two_contact_forces(
    spec: RectSpec | str,
    case: int,
    depth_mm,
    L_C_mm,
    configuration: str = "-",
    exact: bool = False,
    **kw,
) -> planar.TwoPointForces:
    """Contact and extraction forces of case 1-3 in the two-contact state at ``depth_mm``
    (thesis 3.14-3.16, 3.40-3.41, 3.66-3.67, re-derived). Case 3's ``F_z`` includes the plane
    friction ``mu N3``."""
    spec = _spec(spec)
    p = params(spec, L_C_mm, **kw)
    pc = planar_case(spec, int(case), p)
    mirrored = configuration == "-"
    pair = planar.mirror_pair(pc.minus) if mirrored else pc.plus
    sgn = -1.0 if mirrored else 1.0
    sp = planar.Springs(pc.K, pc.K_rot, p.L_C, sgn * pc.x_m, sgn * pc.theta_m)
    s = planar.s_from_depth(pair, common.check_positive("depth_mm", depth_mm))
    return planar.two_point_forces(pair, sp, p.mu, s, f3=pc.f3, exact=exact)


def oracle_body(
    spec: RectSpec | str, case: int, L_C_mm, **kw
) -> tuple[oracle.PlanarBody, tuple[frozenset[int], ...]]:
    """The planar oracle's body for case 1, 2 or 3 (its four candidate contacts)."""
    spec = _spec(spec)
    p = params(spec, L_C_mm, **kw)
    pc = planar_case(spec, int(case), p)
    body = oracle.PlanarBody(
        contacts=oracle.category_contacts(pc.plus, pc.minus),
        K_x=pc.K,
        K_theta=pc.K_rot,
        L_C=p.L_C,
        x_m=pc.x_m,
        theta_m=pc.theta_m,
        mu=p.mu,
        length=spec.length_mm,
        plane_friction=pc.f3,
    )
    return body, (frozenset({0, 1}), frozenset({2, 3}))


# ----------------------------------------------------------------------------------------
# Cases 4 and 5: edge contacts under yaw
# ----------------------------------------------------------------------------------------


def contact_yaw(spec: RectSpec) -> float:
    """Exact yaw ``psi*`` at which two diagonal vertical edges touch both ``x`` walls:
    ``v' cos psi + w' sin psi = v`` (eqs 3.76, 3.99)."""
    vp, wp, v = spec.peg_v_mm, spec.peg_w_mm, spec.hole_v_mm
    rho = np.hypot(vp, wp)
    return float(np.arctan2(wp, vp) - np.arccos(v / rho))


@dataclass(frozen=True)
class EdgeResult:
    """Case 4 or 5 at the contact yaw ``psi_contact``.

    ``N``: edge normal forces (N); ``F_z``: extraction force ``mu sum N``; ``roots_psi``: the
    re-derived boundary roots in ``psi`` (3.97 for case 4: ``N1 = 0`` and ``N2 = 0``; 3.118 for
    case 5: ``N3 = 0``); ``in_region``: whether ``psi_contact`` lies where every ``N >= 0``;
    ``min_depth_mm``: smallest depth at which the edge lines can carry the tilting moment
    (the only place where ``L_C`` enters; NaN if never)."""

    case: int
    psi_contact: float
    N: np.ndarray
    F_z: np.ndarray
    roots_psi: tuple[np.ndarray, np.ndarray]
    in_region: np.ndarray
    min_depth_mm: np.ndarray


def edge_contact(spec: RectSpec | str, case: int, L_C_mm, mu=None, **kw) -> EdgeResult:
    """Cases 4 (two-edge) and 5 (three-edge) for a peg yawed positively (``psi > 0``).

    Case 4 (x walls touched by corners 1 = (v'/2, -w'/2) and 2 = (-v'/2, w'/2); compliance
    centre forced to the hole axis in ``x``)::

        N1 - N2 = f_sX = K_X x_m,   (N1 + N2) |y1| = K_psi (psi_m - psi),
        |y1| = w'/2 cos psi - v'/2 sin psi,
        roots (small angle): psi = (K_psi psi_m +/- K_X x_m w'/2) / (K_psi +/- K_X x_m v'/2).

    Case 5 adds corner 3 = (-v'/2, -w'/2) on the ``y = -w/2`` wall::

        N3 = K_Y (y_C - y_m),  y_C = -w/2 + v'/2 sin psi + w'/2 cos psi,
        N3 = 0:  -(w'/4) psi^2 + (v'/2) psi + (w' - w)/2 - y_m = 0     (3.118 re-derived).

    Neither root involves ``L_C`` (claim C3.3). ``L_C`` only sets ``min_depth_mm``: the edge
    lines must carry the moment of the lateral spring force about the compliance centre.
    """
    spec = _spec(spec)
    case = int(case)
    if case not in (4, 5):
        raise UserInputError(f"edge_contact handles cases 4 and 5, got {case}")
    p = params(spec, L_C_mm, None, mu, **kw)
    vp, wp, w = spec.peg_v_mm, spec.peg_w_mm, spec.hole_w_mm
    psi = contact_yaw(spec)
    psi_m = p.delta_psi
    x_m, y_m = p.delta_x, p.delta_y
    c, s = np.cos(psi), np.sin(psi)
    y1 = vp / 2 * s - wp / 2 * c  # < 0
    x3 = -vp / 2 * c + wp / 2 * s
    f_sx = p.K_x * x_m  # x_C = 0
    if case == 4:
        N3 = np.zeros_like(np.asarray(f_sx + p.K_psi, float))
        S = p.K_psi * (psi_m - psi) / (-y1)
        roots = (
            (p.K_psi * psi_m + p.K_x * x_m * wp / 2) / (p.K_psi + p.K_x * x_m * vp / 2),
            (p.K_psi * psi_m - p.K_x * x_m * wp / 2) / (p.K_psi - p.K_x * x_m * vp / 2),
        )
    else:
        y_C = -w / 2 + vp / 2 * s + wp / 2 * c
        N3 = p.K_y * (y_C - y_m)
        S = -(p.K_psi * (psi_m - psi) + x3 * N3) / y1
        roots = planar.quadratic_roots(-wp / 4, vp / 2, (wp - w) / 2 - y_m)
    N1 = 0.5 * (S + f_sx)
    N2 = 0.5 * (S - f_sx)
    N = np.stack(np.broadcast_arrays(N1, N2, N3), axis=-1)
    in_region = np.all(N >= 0, axis=-1)
    F_z = p.mu * N.sum(axis=-1)
    # tilting moment about y carried by the x-wall edge lines (heights zeta_i in [0, h]):
    # N2 zeta2 - N1 zeta1 = T;  T = -L_C f_sx - mu (N1 x1 + N2 x2) - K_phi phi_m  (phi_m = 0)
    x1 = vp / 2 * c + wp / 2 * s
    T = -p.L_C * f_sx - p.mu * (N1 * x1 - N2 * x1)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(T >= 0, T / N2, -T / N1)
    min_depth = np.where(in_region & (need >= 0), need, np.nan)
    return EdgeResult(
        case, psi, N, F_z, (np.asarray(roots[0]), np.asarray(roots[1])), in_region, min_depth
    )
