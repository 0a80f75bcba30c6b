"""Jamming diagram of a peg in two-point contact (thesis eqs 2.50-2.52, Whitney 1982).

The applied wrench ``(F_x, F_z, M)`` acts on the peg, ``M`` about the middle of the tip of the
(effective) peg of half-width ``r``, counter-clockwise positive with ``x`` to the right and
``z`` up; ``F_z > 0`` pulls the peg out. At depth ``h`` put ``lambda = h / (2 mu r)``,
``f = F_x / F_z`` and ``m = M / (r F_z)``.

Sliding out in two-point contact (both contacts at the friction limit) requires, for the "+"
configuration (mouth corner on the left, tip corner on the right wall)::

    m = lambda - f mu (lambda - 1)            (eq 2.50 with the left side read M/(r F_z))

and ``-lambda - f mu (lambda - 1)`` for the "-" mirror; one-point sliding bounds ``f`` by
``+-1/mu`` (eq 2.51). The four lines bound Whitney's parallelogram with corners
``(1/mu, 1)``, ``(-1/mu, 2 lambda - 1)``, ``(-1/mu, -1)``, ``(1/mu, 1 - 2 lambda)`` (the
re-derived eq 2.52). Inside, the pull extracts the peg; outside, the contact forces can
balance the wrench and the peg jams (or wedges).

:func:`jams_exact` is the first-principles check: the peg jams in a configuration when
``-W`` lies in the cone spanned by the four friction-cone edges of its two contacts (static
equilibrium exists), computed with exact geometry by non-negative least squares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from peghole_mjx.analysis import common


@dataclass(frozen=True)
class Diagram:
    """Whitney parallelogram at one depth: ``lam`` (= h / (2 mu r)), corner points in
    ``(F_x/F_z, M/(r F_z))`` coordinates, in order around the boundary."""

    lam: float
    mu: float
    corners: np.ndarray


def diagram(depth_mm: float, half_width_mm: float, mu: float) -> Diagram:
    """The jamming parallelogram (eqs 2.50-2.52 re-derived)."""
    h = float(common.check_positive("depth_mm", depth_mm))
    r = float(common.check_positive("half_width_mm", half_width_mm))
    mu = float(common.check_positive("mu", mu))
    lam = h / (2 * mu * r)
    corners = np.array(
        [[1 / mu, 1.0], [-1 / mu, 2 * lam - 1], [-1 / mu, -1.0], [1 / mu, 1 - 2 * lam]]
    )
    return Diagram(lam=lam, mu=mu, corners=corners)


def normalise(F_x_N, F_z_N, M_Nmm, half_width_mm) -> tuple[np.ndarray, np.ndarray]:
    """``(F_x/F_z, M/(r F_z))`` of a wrench."""
    F_z = np.asarray(F_z_N, float)
    if np.any(F_z <= 0):
        raise common.UserInputError("the extraction force F_z must be > 0 (pulling out)")
    return np.asarray(F_x_N, float) / F_z, np.asarray(M_Nmm, float) / (half_width_mm * F_z)


def extracts(F_x_N, F_z_N, M_Nmm, depth_mm, half_width_mm, mu) -> np.ndarray:
    """True where the wrench lies inside the parallelogram (the peg slides out)."""
    d = diagram(depth_mm, half_width_mm, mu)
    f, m = normalise(F_x_N, F_z_N, M_Nmm, half_width_mm)
    line = -f * d.mu * (d.lam - 1)
    return (np.abs(f) < 1 / d.mu) & (m < d.lam + line) & (m > -d.lam + line)


def two_point_min_depth_mm(half_width_mm: float, two_c_mm: float) -> float:
    """The shallowest depth (mm) at which a peg of width ``2 r`` in a hole ``2 c`` wider can
    touch both walls: its diagonal must span the hole, ``sqrt((2r + 2c)^2 - (2r)^2)``."""
    wp, wh = 2 * half_width_mm, 2 * half_width_mm + two_c_mm
    return float(np.sqrt(max(wh * wh - wp * wp, 0.0)))


def _edges(
    depth_mm: float, half_width_mm: float, mu: float, two_c_mm: float, configuration: str
) -> np.ndarray:
    """Wrench generators (columns: F_x, F_z, M about the tip middle) of the two contacts'
    friction cones in the exact two-point pose."""
    r, s = half_width_mm, depth_mm
    wp, wh = 2 * r, 2 * r + two_c_mm
    s_min = two_point_min_depth_mm(r, two_c_mm)
    if not s > s_min:
        raise common.UserInputError(
            f"depth {s:g} mm is not deeper than {s_min:.4g} mm: no two-point contact there"
        )
    t = np.arctan2(s, wp) - np.arccos(wh / np.hypot(wp, s))  # exact two-point tilt
    ct, st = np.cos(t), np.sin(t)
    n = np.array([ct, st])
    u = np.array([-st, ct])
    # contact A: mouth corner on the left side at axial distance s; B: right tip corner
    pA = -r * n + s * u
    pB = r * n
    gens = []
    for sgn_f in (+1, -1):
        fA = n - sgn_f * mu * u
        fB = np.array([-1.0, -sgn_f * mu])
        for p, f in ((pA, fA), (pB, fB)):
            gens.append([f[0], f[1], p[0] * f[1] - p[1] * f[0]])
    E = np.array(gens).T
    if configuration == "-":
        E = E * np.array([[-1.0], [1.0], [-1.0]])  # mirror x -> -x
    return E


def jams_exact(
    F_x_N: float,
    F_z_N: float,
    M_Nmm: float,
    depth_mm: float,
    half_width_mm: float,
    mu: float,
    two_c_mm: float,
    configuration: str = "+",
) -> bool:
    """First-principles jamming test: static equilibrium of the applied wrench with contact
    forces inside both friction cones exists (exact two-point pose, clearance ``two_c_mm``)."""
    E = _edges(depth_mm, half_width_mm, mu, two_c_mm, configuration)
    W = np.array([F_x_N, F_z_N, M_Nmm], float)
    scale = np.array([1.0, 1.0, 1.0 / max(depth_mm, half_width_mm)])
    _, res = nnls(E * scale[:, None], -W * scale)
    return bool(res <= 1e-9 * max(1.0, np.linalg.norm(W * scale)))


def plot(ax, d: Diagram, points: list[tuple[float, float, str]] | None = None, title: str = ""):
    """Draw the parallelogram (and wrench points ``(f, m, label)``) on a matplotlib axis."""
    c = np.vstack([d.corners, d.corners[:1]])
    ax.fill(c[:, 0], c[:, 1], color="tab:green", alpha=0.15, label="extracts (inside)")
    ax.plot(c[:, 0], c[:, 1], color="tab:green", lw=1.5)
    for f, m, label in points or []:
        ins = (abs(f) < 1 / d.mu) and (-d.lam < m + f * d.mu * (d.lam - 1) < d.lam)
        ax.plot(
            [f],
            [m],
            "o",
            color="tab:blue" if ins else "tab:red",
            label=f"{label}: {'extracts' if ins else 'jams'}",
        )
    ax.axhline(0, color="0.6", lw=0.5)
    ax.axvline(0, color="0.6", lw=0.5)
    ax.set_xlabel("F_x / F_z (-)")
    ax.set_ylabel("M / (r F_z) (-)")
    ax.set_title(title or f"Jamming diagram, lambda = h/(2 mu r) = {d.lam:.3g}")
    ax.legend(loc="best", fontsize=8)
