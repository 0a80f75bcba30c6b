"""The planar two-point contact template shared by every 2D jamming category.

Every two-point contact category of the thesis (dual states 5, 10, 9; rectangular cases 1-3)
is the same planar mechanism: a rigid body held at a compliance centre ``C`` by a lateral
spring ``K_x`` and a rotational spring ``K_theta`` is pulled out of a slot while

* contact **A**: a fixed corner of the hole at the mouth ``(X_A, 0)`` touches a straight side
  of the body (body lateral coordinate ``a_A``), and
* contact **B**: a tip corner of the body (body lateral coordinate ``a_B``) touches a wall
  ``x = X_B`` of the hole.

This module solves that mechanism once, in a fixed sign convention (the "+" configuration:
A pushes the body towards ``+x`` at the mouth, B pushes it towards ``-x`` at the tip, the tilt
``theta > 0`` moves the tip towards ``+x``). The mirrored ("-") configuration is obtained by
mirroring the geometry and the spring rest pose (:func:`mirror_pair`).

Frames and symbols (all lengths in mm, forces in N, moments in N mm, angles in rad; the
functions are dimensionally homogeneous, so any consistent unit system works):

* world: ``x`` lateral, ``z`` up, hole mouth at ``z = 0``;
* body: origin ``O`` at the middle of the tip line, lateral axis ``n = (cos t, sin t)``, axial
  axis ``u = (-sin t, cos t)``; a body point ``(a, s)`` sits at ``O + a n + s u``;
* ``C = O + L_C u`` (``L_C`` = distance of the compliance centre from the tip line);
* spring rest pose of ``C``: lateral ``x_m``, tilt ``theta_m``; the spring wrench on the body
  is ``F_x = -K_x (x_C - x_m)``, ``M = -K_theta (theta - theta_m)``; the vertical force ``F_z``
  (the extraction force) acts through ``C``;
* Coulomb friction opposes extraction: ``-mu u`` at A (the body slides along its own side),
  ``-mu z`` at B (the corner slides up the wall).

Exact two-point geometry (thesis eq 2.8 generalised)::

    w_p cos(theta) + s sin(theta) = w_h,   w_h = X_B - X_A,  w_p = a_B - a_A,

where ``s`` is the axial distance from the tip line to contact A (the thesis's ``h``). Its
small-angle form ``s theta = 2 c`` with ``2c = w_h - w_p`` is the thesis's eq 2.9.

Statics of the two-point state (re-derived; see docs/research/analysis.md)::

    F_sx + N_A (cos t + mu sin t) - N_B = 0
    M_s + N_A tau_A + N_B tau_B + tau_3 = 0
    tau_A = -(s - L_C) - mu a_A                       (exact)
    tau_B = a_B sin t - mu a_B cos t - L_C cos t - mu L_C sin t   (exact)

``tau_3`` is the moment of an optional extra vertical friction force ``f3`` acting on the
body axis at mid-insertion (the plane contact of rectangular case 3).

With the small-angle substitutions ``theta = 2c/s``, ``x_C = X_B - a_B - L_C theta`` the
contact forces are ``N_B = Q_B(s) / (s den)`` and ``N_A = Q_A(s) / (s^2 den)`` with ``den ~ s``,
so the boundaries of the two-point region are the roots of two quadratics in ``s``:

* ``N_B = 0`` (tip contact lost; the thesis's quadratic, eqs 2.14/2.29/2.43)::

      Q_B(s) = K_x D s^2 + [K_t t_m + K_x (2c L_C - D l_A) + f3 c] s
               - 2c (K_t + K_x L_C l_A) - 2 f3 c L_C

* ``N_A = 0`` (mouth contact lost)::

      Q_A(s) = (K_t t_m - K_x D l_B + f3 c) s^2
               - [2c K_t + 2c K_x (L_C l_B - a_B D) + 2 f3 c L_C] s + 4 c^2 K_x L_C a_B

with ``D = x_m - (X_B - a_B)``, ``l_A = L_C - mu a_A``, ``l_B = L_C + mu a_B``. The two-point
region is ``{s : Q_A(s) > 0 and Q_B(s) > 0}`` inside the geometric domain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ArrayLike = float | np.ndarray


@dataclass(frozen=True)
class ContactPair:
    """Geometry of one two-point configuration in the "+" template frame (lengths in mm).

    ``X_A``: world x of the mouth corner of contact A; ``a_A``: body lateral coordinate of the
    side it touches; ``X_B``: world x of the wall touched by the tip corner; ``a_B``: body
    lateral coordinate of that tip corner. Fields may be numpy arrays (broadcast together).
    """

    X_A: ArrayLike
    a_A: ArrayLike
    X_B: ArrayLike
    a_B: ArrayLike

    @property
    def w_hole(self) -> ArrayLike:
        return np.subtract(self.X_B, self.X_A)

    @property
    def w_peg(self) -> ArrayLike:
        return np.subtract(self.a_B, self.a_A)

    @property
    def two_c(self) -> ArrayLike:
        """Diametral clearance ``2c = w_h - w_p`` of the configuration (> 0 when extractable)."""
        return self.w_hole - self.w_peg


def mirror_pair(pair: ContactPair) -> ContactPair:
    """The "-" configuration of a category expressed in the "+" frame (mirror ``x -> -x``).

    Pass the geometry of the "-" contacts (A: corner pushing ``-x`` at the mouth, B: tip corner
    pushing ``+x``); the mirror image is a "+" configuration. Mirror the rest pose too
    (``x_m -> -x_m``, ``theta_m -> -theta_m``).
    """
    return ContactPair(
        X_A=np.negative(pair.X_A),
        a_A=np.negative(pair.a_A),
        X_B=np.negative(pair.X_B),
        a_B=np.negative(pair.a_B),
    )


@dataclass(frozen=True)
class Springs:
    """Compliance at the compliance centre: lateral ``K_x`` (N/mm), rotational ``K_theta``
    (N mm/rad), centre at ``L_C`` (mm) above the tip line; rest pose ``x_m`` (mm), ``theta_m``
    (rad). Fields may be arrays."""

    K_x: ArrayLike
    K_theta: ArrayLike
    L_C: ArrayLike
    x_m: ArrayLike
    theta_m: ArrayLike


def _f(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=float)


def exact_tilt(pair: ContactPair, s: ArrayLike) -> np.ndarray:
    """Exact two-point tilt ``theta(s)`` from ``w_p cos t + s sin t = w_h`` (eq 2.8, no
    small-angle approximation); NaN where the two contacts cannot coexist."""
    wp, wh, s = _f(pair.w_peg), _f(pair.w_hole), _f(s)
    rho = np.hypot(wp, s)
    phi = np.arctan2(s, wp)
    with np.errstate(invalid="ignore"):
        return phi - np.arccos(wh / rho)


def depth_from_s(pair: ContactPair, s: ArrayLike, exact: bool = True) -> np.ndarray:
    """Depth ``h`` of the body origin (middle of the tip line) below the mouth for a two-point
    state with contact A at axial distance ``s``: ``h = s cos t + a_A sin t``."""
    s = _f(s)
    if exact:
        t = exact_tilt(pair, s)
        return s * np.cos(t) + _f(pair.a_A) * np.sin(t)
    return s + _f(pair.a_A) * _f(pair.two_c) / s


def s_from_depth(pair: ContactPair, h: ArrayLike, iterations: int = 30) -> np.ndarray:
    """Inverse of :func:`depth_from_s` (fixed-point iteration, exact geometry)."""
    h = _f(h)
    s = np.array(h, dtype=float, copy=True)
    for _ in range(iterations):
        t = exact_tilt(pair, s)
        s = (h - _f(pair.a_A) * np.sin(t)) / np.cos(t)
    return s


def min_two_point_s(pair: ContactPair) -> np.ndarray:
    """Smallest ``s`` at which the two-point state exists: ``hypot(w_p, s) >= |w_h|``."""
    wp, wh = _f(pair.w_peg), _f(pair.w_hole)
    return np.sqrt(np.maximum(wh**2 - wp**2, 0.0))


# ----------------------------------------------------------------------------------------
# Small-angle closed forms
# ----------------------------------------------------------------------------------------


def boundary_quadratics(
    pair: ContactPair, springs: Springs, mu: ArrayLike, f3: ArrayLike = 0.0
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Coefficients ``(a, b, c)`` of ``Q_B(s)`` (``N_B = 0``) and ``Q_A(s)`` (``N_A = 0``).

    ``Q_B`` is the re-derived form of the thesis's quadratics (2.14), (2.29), (2.43), (3.23),
    (3.47), (3.73); ``Q_A`` is the companion condition the thesis does not print. ``f3`` is the
    extra vertical friction (N) of a plane contact (rect case 3), zero otherwise.
    """
    Kx, Kt, Lc = _f(springs.K_x), _f(springs.K_theta), _f(springs.L_C)
    tm, mu, f3 = _f(springs.theta_m), _f(mu), _f(f3)
    c2 = _f(pair.two_c)
    c = 0.5 * c2
    aA, aB = _f(pair.a_A), _f(pair.a_B)
    D = _f(springs.x_m) - (_f(pair.X_B) - aB)
    lA = Lc - mu * aA
    lB = Lc + mu * aB
    qb = (
        Kx * D,
        Kt * tm + Kx * (c2 * Lc - D * lA) + f3 * c,
        -c2 * (Kt + Kx * Lc * lA) - 2.0 * f3 * c * Lc,
    )
    qa = (
        Kt * tm - Kx * D * lB + f3 * c,
        -(c2 * Kt + c2 * Kx * (Lc * lB - aB * D) + 2.0 * f3 * c * Lc),
        c2 * c2 * Kx * Lc * aB,
    )
    return tuple(np.broadcast_arrays(*qb)), tuple(np.broadcast_arrays(*qa))  # type: ignore[return-value]


def quadratic_roots(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Real roots ``(r1 >= r2)`` of ``a x^2 + b x + c`` (NaN where none), numerically stable,
    degrading to the linear root when ``a`` is negligible."""
    a, b, c = np.broadcast_arrays(_f(a), _f(b), _f(c))
    disc = b * b - 4.0 * a * c
    scale = np.abs(b) + np.sqrt(np.abs(a * c)) + 1e-300
    lin = np.abs(a) * 1e6 < scale * 1e-6  # a negligible -> linear equation
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        q = -0.5 * (b + np.where(b >= 0, 1.0, -1.0) * sq)
        r_a = q / a
        r_b = c / q
        r1 = np.where(lin, -c / b, np.maximum(r_a, r_b))
        r2 = np.where(lin, np.nan, np.minimum(r_a, r_b))
    return r1, r2


def poly2(coef: tuple[np.ndarray, np.ndarray, np.ndarray], s: ArrayLike) -> np.ndarray:
    a, b, c = coef
    s = _f(s)
    return (a * s + b) * s + c


@dataclass(frozen=True)
class Region:
    """A two-point contact region in depth (mm). ``h_lo``/``h_hi``: outer boundaries (NaN when
    empty); ``length``: total length (a region can in principle be two intervals);
    ``roots_h``: the two roots ``h2 >= h2'`` of the thesis's quadratic ``Q_B`` mapped to depth
    (NaN where complex), kept for reference."""

    h_lo: np.ndarray
    h_hi: np.ndarray
    length: np.ndarray
    roots_h: tuple[np.ndarray, np.ndarray]

    @property
    def empty(self) -> np.ndarray:
        return ~(self.length > 0)


def _intervals_from_breaks(
    breaks: np.ndarray, inside: np.ndarray, to_h
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Union of the sub-intervals ``[breaks[k], breaks[k+1]]`` flagged by ``inside[..., k]``."""
    lo_s, hi_s = breaks[..., :-1], breaks[..., 1:]
    lo_h, hi_h = to_h(lo_s), to_h(hi_s)
    seg = np.where(inside, np.maximum(hi_h - lo_h, 0.0), 0.0)
    length = seg.sum(axis=-1)
    has = inside & (seg > 0)
    h_lo = np.where(has, lo_h, np.inf).min(axis=-1)
    h_hi = np.where(has, hi_h, -np.inf).max(axis=-1)
    h_lo = np.where(np.isfinite(h_lo), h_lo, np.nan)
    h_hi = np.where(np.isfinite(h_hi), h_hi, np.nan)
    return h_lo, h_hi, length


def two_point_region(
    pair: ContactPair,
    springs: Springs,
    mu: ArrayLike,
    h_max: ArrayLike,
    length: ArrayLike = np.inf,
    f3: ArrayLike = 0.0,
    refine: bool = False,
) -> Region:
    """Two-point region of one configuration from the boundary quadratics.

    The region is ``{s : N_A(s) > 0, N_B(s) > 0}`` within ``[s_min, min(s(h_max), length)]``
    (contact A must lie on the body side, ``s <= length``), mapped to the depth ``h`` of the
    body origin. ``refine=False`` is the pure small-angle closed form (roots of ``Q_A``,
    ``Q_B``; map ``h = s + 2c a_A / s``). ``refine=True`` polishes the same roots with Newton
    steps on the exact two-point statics and maps with the exact tilt (semi-analytic; agrees
    with the oracle to solver tolerance).
    """
    qb, qa = boundary_quadratics(pair, springs, mu, f3)
    roots = [*quadratic_roots(*qb), *quadratic_roots(*qa)]
    s_lo = np.maximum(min_two_point_s(pair), 1e-6 * np.abs(_f(pair.two_c)) + 1e-9)
    if refine:
        s_top = s_from_depth(pair, h_max)
    else:
        s_top = _f(h_max) - _f(pair.a_A) * _f(pair.two_c) / _f(h_max)
    s_hi = np.minimum(s_top, _f(length))

    if refine:
        roots = _exact_roots(pair, springs, mu, f3, s_lo, s_hi)
    shape = np.broadcast_shapes(np.shape(s_lo), np.shape(s_hi), *(np.shape(r) for r in roots))
    lo = np.broadcast_to(s_lo, shape)
    hi = np.broadcast_to(s_hi, shape)
    inner = [np.where((r > lo) & (r < hi), r, hi) for r in np.broadcast_arrays(*roots)]
    breaks = np.sort(np.stack([lo, *inner, hi], axis=-1), axis=-1)
    mid = 0.5 * (breaks[..., :-1] + breaks[..., 1:])

    def ex(v):
        return np.expand_dims(np.broadcast_to(_f(v), shape), -1)

    pair_e = ContactPair(ex(pair.X_A), ex(pair.a_A), ex(pair.X_B), ex(pair.a_B))
    if refine:
        sp_e = Springs(
            *(ex(getattr(springs, k)) for k in ("K_x", "K_theta", "L_C", "x_m", "theta_m"))
        )
        f = two_point_forces(pair_e, sp_e, ex(mu), mid, f3=ex(f3), exact=True)
        pos = (f.N_A > 0) & (f.N_B > 0)
    else:
        pos = (poly2(tuple(ex(q) for q in qb), mid) > 0) & (
            poly2(tuple(ex(q) for q in qa), mid) > 0
        )
    inside = pos & (breaks[..., 1:] > breaks[..., :-1])

    def to_h(s):  # a depth above the mouth (h < 0: tiny s, small-angle map) is the mouth
        return np.maximum(depth_from_s(pair_e, s, exact=refine), 0.0)

    h_lo, h_hi, length_h = _intervals_from_breaks(breaks, inside, to_h)
    r1, r2 = quadratic_roots(*qb)
    roots_h = (depth_from_s(pair, r1, exact=False), depth_from_s(pair, r2, exact=False))
    return Region(h_lo=h_lo, h_hi=h_hi, length=length_h, roots_h=roots_h)


def _exact_roots(pair, springs, mu, f3, s_lo, s_hi, n: int = 400, iters: int = 50):
    """Sign changes of the exact ``N_A(s)``, ``N_B(s)`` on ``[s_lo, s_hi]`` (fine scan, then
    bisection); returned padded with NaN, as a list of arrays."""
    s_lo, s_hi = np.broadcast_arrays(_f(s_lo), _f(s_hi))
    shape = np.broadcast_shapes(
        s_lo.shape,
        *(np.shape(_f(getattr(springs, k))) for k in ("K_x", "K_theta", "L_C", "x_m", "theta_m")),
        np.shape(_f(mu)),
        np.shape(_f(f3)),
        *(np.shape(_f(v)) for v in (pair.X_A, pair.a_A, pair.X_B, pair.a_B)),
    )

    def ex(v):
        return np.expand_dims(np.broadcast_to(_f(v), shape), -1)

    pe = ContactPair(ex(pair.X_A), ex(pair.a_A), ex(pair.X_B), ex(pair.a_B))
    se = Springs(*(ex(getattr(springs, k)) for k in ("K_x", "K_theta", "L_C", "x_m", "theta_m")))
    mue, f3e = ex(mu), ex(f3)
    frac = np.linspace(0.0, 1.0, n)
    lo, hi = ex(s_lo), ex(s_hi)
    grid = lo + (hi - lo) * frac

    def forces(sv):
        f = two_point_forces(pe, se, mue, sv, f3=f3e, exact=True)
        return f.N_A, f.N_B

    out = []
    vals = forces(grid)
    for which in (0, 1):
        v = vals[which]
        change = np.signbit(v[..., :-1]) != np.signbit(v[..., 1:])
        # keep up to two sign changes per entry
        idx = np.argsort(~change, axis=-1, kind="stable")[..., :2]
        has = np.take_along_axis(change, idx, -1)
        a = np.take_along_axis(grid[..., :-1], idx, -1)
        b = np.take_along_axis(grid[..., 1:], idx, -1)
        fa = forces(a)[which]
        for _ in range(iters):
            m = 0.5 * (a + b)
            fm = forces(m)[which]
            left = np.signbit(fm) == np.signbit(fa)
            a = np.where(left, m, a)
            fa = np.where(left, fm, fa)
            b = np.where(left, b, m)
        r = np.where(has, 0.5 * (a + b), np.nan)
        out += [r[..., 0], r[..., 1]]
    return out


@dataclass(frozen=True)
class TwoPointForces:
    """Contact forces of the two-point state at a depth (N, N mm, rad, mm)."""

    theta: np.ndarray
    x_C: np.ndarray
    N_A: np.ndarray
    N_B: np.ndarray
    F_x: np.ndarray
    M: np.ndarray
    F_z: np.ndarray


def two_point_forces(
    pair: ContactPair,
    springs: Springs,
    mu: ArrayLike,
    s: ArrayLike,
    f3: ArrayLike = 0.0,
    exact: bool = False,
) -> TwoPointForces:
    """Contact and extraction forces in the two-point state (thesis eqs 2.19-2.20, 2.33-2.34,
    2.48, re-derived).

    ``exact=False``: small-angle closed form (``theta = 2c/s``). ``exact=True``: the exact
    geometry and the exact 2x2 statics (the state the oracle solves). ``F_x``, ``M`` are the
    spring force and moment at the compliance centre; ``F_z`` is the pull needed to extract
    (``mu (N_A + N_B) - theta N_A + f3`` to first order).
    """
    Kx, Kt, Lc = _f(springs.K_x), _f(springs.K_theta), _f(springs.L_C)
    xm, tm, mu, f3, s = _f(springs.x_m), _f(springs.theta_m), _f(mu), _f(f3), _f(s)
    aA, aB, XB = _f(pair.a_A), _f(pair.a_B), _f(pair.X_B)
    if exact:
        t = exact_tilt(pair, s)
        ct, st = np.cos(t), np.sin(t)
        x_C = XB - aB * ct - Lc * st
        kA = ct + mu * st
        tauA = -(s - Lc) - mu * aA
        tauB = aB * st - mu * aB * ct - Lc * ct - mu * Lc * st
        tau3 = f3 * (0.5 * s - Lc) * st
        zA = st - mu * ct
    else:
        t = _f(pair.two_c) / s
        x_C = XB - aB - Lc * t
        kA = 1.0
        tauA = -(s - Lc) - mu * aA
        tauB = -Lc - mu * aB + aB * t
        tau3 = f3 * (0.5 * s - Lc) * t
        zA = t - mu
    Fx = -Kx * (x_C - xm)
    M = -Kt * (t - tm)
    # [kA, -1; tauA, tauB] [N_A, N_B] = [-Fx, -M - tau3]
    det = kA * tauB + tauA
    rhs = -M - tau3
    N_A = (-Fx * tauB + rhs) / det
    N_B = (kA * rhs + tauA * Fx) / det
    F_z = -(N_A * zA - mu * N_B) + f3
    return TwoPointForces(theta=t, x_C=x_C, N_A=N_A, N_B=N_B, F_x=Fx, M=M, F_z=F_z)


@dataclass(frozen=True)
class OnePointState:
    """One-point contact state (small angle): tilt, compliance-centre position, normal force
    and extraction force."""

    theta: np.ndarray
    x_C: np.ndarray
    N: np.ndarray
    F_z: np.ndarray


def one_point_tip(pair: ContactPair, springs: Springs, mu: ArrayLike) -> OnePointState:
    """One-point contact at the tip corner B only (thesis eqs 2.17-2.18 and 2.21 re-derived).

    ``theta = (K_t t_m - K_x D l_B) / (K_t + K_x L_C l_B)``, ``N_B = K_x (D + L_C theta)``,
    ``F_z = mu N_B``. Independent of depth (the tip corner slides up the wall).
    """
    Kx, Kt, Lc = _f(springs.K_x), _f(springs.K_theta), _f(springs.L_C)
    mu = _f(mu)
    D = _f(springs.x_m) - (_f(pair.X_B) - _f(pair.a_B))
    lB = Lc + mu * _f(pair.a_B)
    t = (Kt * _f(springs.theta_m) - Kx * D * lB) / (Kt + Kx * Lc * lB)
    N = Kx * (D + Lc * t)
    x_C = _f(pair.X_B) - _f(pair.a_B) - Lc * t
    return OnePointState(theta=t, x_C=x_C, N=N, F_z=mu * N)


def one_point_mouth(
    pair: ContactPair, springs: Springs, mu: ArrayLike, s: ArrayLike
) -> OnePointState:
    """One-point contact at the mouth corner A only, at axial distance ``s`` (small angle).

    ``theta = [K_t t_m + K_x E (s - l_A)] / [K_t + K_x (s - L_C)(s - l_A)]`` with
    ``E = x_m - (X_A - a_A)``; ``N_A = -K_x (E - (s - L_C) theta)``; ``F_z = N_A (mu - theta)``.
    """
    Kx, Kt, Lc = _f(springs.K_x), _f(springs.K_theta), _f(springs.L_C)
    mu, s = _f(mu), _f(s)
    E = _f(springs.x_m) - (_f(pair.X_A) - _f(pair.a_A))
    lA = Lc - mu * _f(pair.a_A)
    t = (Kt * _f(springs.theta_m) + Kx * E * (s - lA)) / (Kt + Kx * (s - Lc) * (s - lA))
    x_C = _f(pair.X_A) - _f(pair.a_A) + (s - Lc) * t
    N = Kx * (x_C - _f(springs.x_m))
    return OnePointState(theta=t, x_C=x_C, N=N, F_z=N * (mu - t))
