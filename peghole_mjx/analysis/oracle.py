"""Independent numerical oracle: exact quasi-static solver for a compliant rigid body in 2D.

This solver shares no formula with the closed forms in :mod:`.planar`. It knows only

* the exact rigid-body kinematics of a planar body (no small-angle approximation),
* a list of candidate contacts (a hole corner at the mouth against a straight side of the
  body, or a tip corner of the body against a hole wall), each with its exact gap function,
* the spring wrench of the compliance centre (``K_x``, ``K_theta`` at ``L_C``; vertical
  motion prescribed, so the extraction force ``F_z`` is the vertical reaction at ``C``),
* Coulomb sliding friction opposing extraction (along the body side for corner-on-side
  contacts, vertical for corner-on-wall contacts),

and solves the contact complementarity problem at each depth ``h`` (depth of the body origin,
the middle of the tip line): find the pose ``(x_O, theta)`` and multipliers ``lambda_i`` with

    gap_i >= 0,  lambda_i >= 0,  lambda_i * gap_i = 0,  spring + sum_i lambda_i w_i = 0.

The active set is found by enumeration (every subset of at most two contacts; a planar body
at prescribed depth has two free coordinates), each subset solved with a vectorised Newton
iteration on its exact equations, then filtered by feasibility. Three-point contacts exist
only at isolated depths (thesis Sec 2.3) and are reported as unresolved points.

Units: mm, N, N mm, rad (any consistent system works; the equations are homogeneous).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

ON_SIDE = "corner_on_side"
ON_WALL = "corner_on_wall"


@dataclass(frozen=True)
class Contact:
    """A candidate contact.

    ``kind == ON_SIDE``: the hole corner ``(X, 0)`` against the body side ``a = a_body``;
    ``sigma = +1`` if the body lies at ``a > a_body`` (the side faces ``-x``), else ``-1``.
    ``kind == ON_WALL``: the body tip corner ``(a_body, 0)`` against the wall ``x = X``;
    ``sigma = +1`` if the body lies at ``x < X`` (a right-hand wall), else ``-1``.
    """

    kind: str
    X: float | np.ndarray
    a_body: float | np.ndarray
    sigma: int
    name: str


@dataclass(frozen=True)
class PlanarBody:
    """A compliant rigid body and its candidate contacts. Array fields broadcast together."""

    contacts: tuple[Contact, ...]
    K_x: float | np.ndarray
    K_theta: float | np.ndarray
    L_C: float | np.ndarray
    x_m: float | np.ndarray
    theta_m: float | np.ndarray
    mu: float | np.ndarray
    length: float | np.ndarray
    plane_friction: float | np.ndarray = 0.0  # extra vertical friction (rect case 3), N


@dataclass
class OracleSolution:
    """Solution at each depth: ``active[..., k]`` flags contact k, ``lam[..., k]`` its normal
    force (N); ``valid`` is False where no subset of <= 2 contacts is consistent (isolated
    three-point depths); ``ambiguous`` where two different poses are both consistent."""

    h: np.ndarray
    x_O: np.ndarray
    theta: np.ndarray
    active: np.ndarray
    lam: np.ndarray
    F_z: np.ndarray
    valid: np.ndarray
    ambiguous: np.ndarray
    names: tuple[str, ...] = field(default=())

    def state_code(self) -> np.ndarray:
        """Bit mask of active contacts (bit k = contact k); -1 where unresolved."""
        bits = (self.active * (1 << np.arange(self.active.shape[-1]))).sum(axis=-1)
        return np.where(self.valid, bits, -1)


def _geometry(body: PlanarBody, c: Contact, h, x_O, th):
    """Gap, applicability, world force direction (per unit normal force) and moment about C."""
    ct, st = np.cos(th), np.sin(th)
    Lc, mu = body.L_C, body.mu
    if c.kind == ON_SIDE:
        dx, dz = c.X - x_O, h  # corner relative to O (corner at z = 0, O at z = -h)
        a_p = dx * ct + dz * st
        s_p = -dx * st + dz * ct
        gap = c.sigma * (c.a_body - a_p)
        ok = (s_p >= 0.0) & (s_p <= body.length)
        fx = c.sigma * ct + mu * st
        fz = c.sigma * st - mu * ct
        tau = a_p * (-mu) - (s_p - Lc) * c.sigma
    else:
        x_c = x_O + c.a_body * ct
        z_c = -h + c.a_body * st
        gap = c.sigma * (c.X - x_c)
        ok = z_c < 0.0
        fx = -c.sigma * np.ones_like(x_c)
        fz = -mu * np.ones_like(x_c)
        rx = c.a_body * ct + Lc * st
        rz = c.a_body * st - Lc * ct
        tau = rx * fz - rz * fx
    return gap, ok, fx, fz, tau


def _x_from_contact(body: PlanarBody, c: Contact, h, th):
    """Body-origin lateral position that closes the gap of contact ``c`` at tilt ``th``."""
    ct, st = np.cos(th), np.sin(th)
    if c.kind == ON_SIDE:
        return c.X - (c.a_body - h * st) / ct
    return c.X - c.a_body * ct


def _spring(body: PlanarBody, h, x_O, th):
    x_C = x_O - body.L_C * np.sin(th)
    Fx = -body.K_x * (x_C - body.x_m)
    M = -body.K_theta * (th - body.theta_m)
    # plane-contact friction (vertical, on the body axis at mid insertion)
    s_mid = 0.5 * h / np.cos(th)
    tau3 = body.plane_friction * (s_mid - body.L_C) * np.sin(th)
    return Fx, M + tau3


def _newton(fun, t0, iters: int = 40, tol: float = 1e-12):
    """Vectorised secant-Newton on a scalar residual of ``theta``; returns (theta, converged)."""
    t = np.array(t0, dtype=float, copy=True)
    for _ in range(iters):
        r = fun(t)
        d = 1e-7 * (1.0 + np.abs(t))
        dr = (fun(t + d) - fun(t - d)) / (2 * d)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(np.abs(dr) > 0, r / dr, 0.0)
        step = np.clip(np.nan_to_num(step), -0.05, 0.05)
        t = t - step
        if np.all(np.abs(step) < tol):
            break
    r = fun(t)
    return t, np.isfinite(r)


def _solve_subset(body: PlanarBody, subset: tuple[int, ...], h, shape):
    """Pose and multipliers for the active set ``subset`` (exact equations)."""
    cs = body.contacts
    n = len(cs)
    lam = np.zeros((*shape, n))
    if len(subset) == 0:
        th = np.broadcast_to(np.asarray(body.theta_m, float), shape).copy()
        x_O = np.broadcast_to(body.x_m + body.L_C * np.sin(th), shape).copy()
        res = np.zeros(shape)
    elif len(subset) == 1:
        (i,) = subset
        c = cs[i]

        def resid(th):
            x_O = _x_from_contact(body, c, h, th)
            Fx, M = _spring(body, h, x_O, th)
            _, _, fx, _, tau = _geometry(body, c, h, x_O, th)
            lam_i = -Fx / fx
            return M + lam_i * tau

        th0 = np.broadcast_to(np.asarray(body.theta_m, float), shape)
        th, _ = _newton(resid, th0)
        x_O = _x_from_contact(body, c, h, th)
        Fx, M = _spring(body, h, x_O, th)
        _, _, fx, _, tau = _geometry(body, c, h, x_O, th)
        lam[..., i] = -Fx / fx
        res = np.abs(M + lam[..., i] * tau)
    else:
        i, j = subset
        ci, cj = cs[i], cs[j]

        def resid(th):
            return _x_from_contact(body, ci, h, th) - _x_from_contact(body, cj, h, th)

        th, _ = _newton(resid, np.zeros(shape))
        x_O = _x_from_contact(body, ci, h, th)
        Fx, M = _spring(body, h, x_O, th)
        _, _, fxi, _, ti = _geometry(body, ci, h, x_O, th)
        _, _, fxj, _, tj = _geometry(body, cj, h, x_O, th)
        det = fxi * tj - fxj * ti
        with np.errstate(divide="ignore", invalid="ignore"):
            lam[..., i] = (-Fx * tj + M * fxj) / det
            lam[..., j] = (-M * fxi + Fx * ti) / det
        res = np.abs(resid(th)) / (1.0 + np.abs(h))
        res = np.where(np.isfinite(det) & (np.abs(det) > 1e-12), res, np.inf)
    return x_O, th, lam, res


def solve(
    body: PlanarBody,
    h: np.ndarray,
    gap_tol: float = 1e-9,
    lam_tol: float = 1e-9,
    max_tilt: float = 0.3,
) -> OracleSolution:
    """Quasi-static contact state of ``body`` at depths ``h`` (array; broadcast with the body's
    array fields). Returns the state with the fewest contacts among the consistent ones."""
    h = np.asarray(h, dtype=float)
    fields = [
        body.K_x,
        body.K_theta,
        body.L_C,
        body.x_m,
        body.theta_m,
        body.mu,
        body.length,
        body.plane_friction,
    ]
    for c in body.contacts:
        fields += [c.X, c.a_body]
    shape = np.broadcast_shapes(h.shape, *(np.shape(f) for f in fields))
    h = np.broadcast_to(h, shape)
    n = len(body.contacts)
    best = None
    count = np.zeros(shape, dtype=int)
    subsets = [(), *((i,) for i in range(n)), *itertools.combinations(range(n), 2)]
    for subset in subsets:
        x_O, th, lam, res = _solve_subset(body, subset, h, shape)
        ok = (res < 1e-8) & (np.abs(th) < max_tilt) & np.isfinite(th)
        geo = [_geometry(body, c, h, x_O, th) for c in body.contacts]
        for k, (gap, app, _, _, _) in enumerate(geo):
            if k in subset:
                ok &= app & (lam[..., k] >= -lam_tol)
            else:
                ok &= (gap >= -gap_tol) | ~app
        fz = np.zeros(shape)
        # a subset with no solution (e.g. frictional contacts at mu 0) holds inf/NaN entries:
        # masked by ``ok`` below, so their arithmetic warnings are not the user's
        with np.errstate(invalid="ignore", over="ignore"):
            for k in subset:
                fz -= lam[..., k] * geo[k][3]
        active = np.zeros((*shape, n), dtype=bool)
        for k in subset:
            active[..., k] = True
        if best is None:
            best = dict(
                x_O=np.where(ok, x_O, np.nan),
                theta=np.where(ok, th, np.nan),
                active=active & ok[..., None],
                lam=np.where(ok[..., None], lam, 0.0),
                F_z=np.where(ok, fz + body.plane_friction, np.nan),
                valid=ok.copy(),
                ambiguous=np.zeros(shape, dtype=bool),
            )
        else:
            new = ok & ~best["valid"]
            # two consistent states with different poses: friction-induced non-uniqueness
            differ = ok & best["valid"] & (np.abs(th - best["theta"]) > 1e-7)
            strict = differ & np.all((lam >= 1e-6) | ~active, axis=-1)
            best["ambiguous"] |= strict
            best["x_O"] = np.where(new, x_O, best["x_O"])
            best["theta"] = np.where(new, th, best["theta"])
            best["active"] = np.where(new[..., None], active, best["active"])
            best["lam"] = np.where(new[..., None], lam, best["lam"])
            best["F_z"] = np.where(new, fz + body.plane_friction, best["F_z"])
            best["valid"] |= ok
        count += ok
    assert best is not None
    return OracleSolution(h=h, names=tuple(c.name for c in body.contacts), **best)


def region_of_state(
    body: PlanarBody,
    target: tuple[frozenset[int], ...],
    h_lo: float | np.ndarray,
    h_hi: float | np.ndarray,
    n_grid: int = 161,
    n_bisect: int = 30,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth region where the oracle's state is one of ``target`` (sets of contact indices).

    Scans ``n_grid`` depths in ``[h_lo, h_hi]`` (broadcast over the body's parameter arrays,
    which must have the leading shape ``P``), then bisects every transition to ``1e-9``
    relative accuracy. Returns ``(lo, hi, length)`` per parameter combination (outer bounds and
    total length; NaN bounds when empty).
    """
    h_lo = np.asarray(h_lo, float)
    h_hi = np.asarray(h_hi, float)
    frac = np.linspace(0.0, 1.0, n_grid)
    grid = h_lo[..., None] + (h_hi - h_lo)[..., None] * frac  # (P, G)
    body_g = _expand(body, -1)
    codes = {sum(1 << k for k in t) for t in target}

    def inside(hh, b):
        sol = solve(b, hh)
        code = sol.state_code()
        return np.isin(code, list(codes))

    ins = inside(grid, body_g)
    # bisect each transition between neighbouring grid points
    a, b = grid[..., :-1], grid[..., 1:]
    ia, ib = ins[..., :-1], ins[..., 1:]
    trans = ia != ib
    lo_b, hi_b = a.copy(), b.copy()
    for _ in range(n_bisect):
        mid = 0.5 * (lo_b + hi_b)
        im = inside(mid, body_g)
        go_right = im == ia  # the switch lies in [mid, hi]
        lo_b = np.where(trans & go_right, mid, lo_b)
        hi_b = np.where(trans & ~go_right, mid, hi_b)
    xt = 0.5 * (lo_b + hi_b)
    # measure: each grid cell contributes its inside part
    cell = np.where(ia & ib, b - a, 0.0)
    cell = np.where(trans & ia, xt - a, cell)
    cell = np.where(trans & ib, b - xt, cell)
    length = cell.sum(axis=-1)
    starts = np.where(ia & ib, a, np.where(trans & ia, a, np.where(trans & ib, xt, np.inf)))
    ends = np.where(ia & ib, b, np.where(trans & ia, xt, np.where(trans & ib, b, -np.inf)))
    lo = starts.min(axis=-1)
    hi = ends.max(axis=-1)
    lo = np.where(length > 0, lo, np.nan)
    hi = np.where(length > 0, hi, np.nan)
    return lo, hi, length


def _expand(body: PlanarBody, axis: int) -> PlanarBody:
    """Add a trailing axis to every array field so that it broadcasts against depth grids."""

    def ex(v):
        v = np.asarray(v, float)
        return v[..., None] if v.ndim else v

    contacts = tuple(Contact(c.kind, ex(c.X), ex(c.a_body), c.sigma, c.name) for c in body.contacts)
    return PlanarBody(
        contacts=contacts,
        K_x=ex(body.K_x),
        K_theta=ex(body.K_theta),
        L_C=ex(body.L_C),
        x_m=ex(body.x_m),
        theta_m=ex(body.theta_m),
        mu=ex(body.mu),
        length=ex(body.length),
        plane_friction=ex(body.plane_friction),
    )


def category_contacts(plus, minus, prefix: str = "") -> tuple[Contact, ...]:
    """The four candidate contacts of a two-point category, from its "+" configuration and its
    "-" configuration, both given in world coordinates as :class:`.planar.ContactPair`.

    Order: ``A+`` (mouth corner pushing ``+x``), ``B+`` (tip corner against a wall on its
    right), ``A-`` (mouth corner pushing ``-x``), ``B-`` (tip corner against a wall on its left).
    """
    return (
        Contact(ON_SIDE, plus.X_A, plus.a_A, +1, prefix + "A+"),
        Contact(ON_WALL, plus.X_B, plus.a_B, +1, prefix + "B+"),
        Contact(ON_SIDE, minus.X_A, minus.a_A, -1, prefix + "A-"),
        Contact(ON_WALL, minus.X_B, minus.a_B, -1, prefix + "B-"),
    )
