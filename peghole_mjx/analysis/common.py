"""Shared parameter conventions and input validation for the analytic models.

Public functions take millimetres, newtons and radians (argument names carry ``_mm``,
``_N_per_mm``, ``_Nmm_per_rad``, ``_rad``). The models compute in that same consistent system
(mm, N, N mm, rad); they are dimensionally homogeneous, which the tests check by rescaling to
SI (m, N, N m).

Rest pose of the compliance (thesis Sec 2.4, Fig 2.6b, and Sec 3.2, Fig 3.6): the nominal pose
has the tip (middle of the tip line) on the hole axis with the initial tilt ``theta0``; the
manipulator's spring rest pose is that nominal pose translated by the lateral error ``delta0``
(at the compliance centre) and rotated by the angular error ``beta0`` about the compliance
centre::

    x_m = delta0 - L_C sin(theta0),    theta_m = theta0 + beta0.

This reproduces the thesis's combinations ``delta0 + L_C beta0`` (tip offset) and
``theta0 -/+ beta0`` (rotational rest) in (2.13)-(2.14) up to the sign convention.
"""

from __future__ import annotations

import math

import numpy as np

from peghole_mjx.core.errors import UserInputError

#: Erratum E3: the thesis's initial angle "-0.9 rad" is read as -0.9 degrees.
THETA0_DEG = -0.9
THETA0_RAD = math.radians(THETA0_DEG)
#: Largest angle accepted by the small-angle models (about 11.5 degrees).
MAX_ANGLE_RAD = 0.2


def _arr(name: str, value) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise UserInputError(f"{name} must be a number, got {value!r}") from None
    if not np.all(np.isfinite(a)):
        raise UserInputError(f"{name} must be finite, got {value!r}")
    return a


def check_positive(name: str, value) -> np.ndarray:
    """Stiffnesses, lengths: finite and strictly positive."""
    a = _arr(name, value)
    if np.any(a <= 0):
        raise UserInputError(f"{name} must be > 0, got {np.min(a):g}")
    return a


def check_nonnegative(name: str, value) -> np.ndarray:
    a = _arr(name, value)
    if np.any(a < 0):
        raise UserInputError(f"{name} must be >= 0, got {np.min(a):g}")
    return a


def check_compliance_centre(L_C_mm, length_mm: float) -> np.ndarray:
    """``0 <= L_C <= L``: the compliance centre lies on the peg (thesis assumption)."""
    a = _arr("L_C_mm", L_C_mm)
    if np.any((a < 0) | (a > length_mm)):
        bad = a[(a < 0) | (a > length_mm)].ravel()[0]
        raise UserInputError(
            f"L_C_mm must lie on the peg, within [0, {length_mm:g}] mm (the peg length); "
            f"got {bad:g}"
        )
    return a


def check_angle(name: str, value) -> np.ndarray:
    """Angles must be small (|a| <= 0.2 rad). A value like -0.9 rad is erratum E3."""
    a = _arr(name, value)
    if np.any(np.abs(a) > MAX_ANGLE_RAD):
        bad = a[np.abs(a) > MAX_ANGLE_RAD].ravel()[0]
        hint = ""
        if math.isclose(abs(bad), 0.9, rel_tol=1e-3):
            hint = (
                f"; the thesis's '-0.9 rad' is -0.9 deg = {THETA0_RAD:.5f} rad "
                "(erratum E3, docs/research/errata.md)"
            )
        raise UserInputError(
            f"{name} = {bad:g} rad is outside the small-angle model (|angle| <= "
            f"{MAX_ANGLE_RAD} rad){hint}"
        )
    return a


def check_friction(mu) -> np.ndarray:
    a = _arr("mu", mu)
    if np.any((a < 0) | (a > 2)):
        raise UserInputError(f"friction coefficient mu must be in [0, 2], got {mu!r}")
    return a


def check_depth(h0_mm, length_mm: float) -> np.ndarray:
    a = check_positive("h0_mm", h0_mm)
    if np.any(a > length_mm):
        raise UserInputError(
            f"initial depth h0_mm = {np.max(a):g} exceeds the peg length {length_mm:g} mm"
        )
    return a


def rest_pose(L_C_mm, delta0_mm, beta0_rad, theta0_rad) -> tuple[np.ndarray, np.ndarray]:
    """Spring rest pose ``(x_m, theta_m)`` of the compliance centre (see module docstring)."""
    L_C = np.asarray(L_C_mm, float)
    theta0 = np.asarray(theta0_rad, float)
    return (
        np.asarray(delta0_mm, float) - L_C * np.sin(theta0),
        theta0 + np.asarray(beta0_rad, float),
    )
