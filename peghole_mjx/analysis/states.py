"""Enumeration of contact states from the geometry (claims C2.1 and C3.1).

Nothing here is hard-coded from the thesis's tables: the states are found by solving the exact
contact geometry.

* Dual peg-hole (2D, Table 2.1): every subset ``S`` of the eight candidate contacts
  (:func:`.dual.full_contacts`) with ``|S| <= 4`` is tested: is there a pose ``(x, theta)`` at
  some depth ``h`` where exactly the contacts of ``S`` close (gap 0) and every other gap is
  open? Subsets of one or two contacts are solved on a depth grid (a region of depths if
  feasible); larger subsets add one equation per extra contact, so the depth is found by
  bisection on the extra gap (isolated depths) unless that gap vanishes identically (a
  region, e.g. line contact in both pegs of a symmetric pair).
* Rectangular peg-hole (3D, Table 3.1, Fig 3.4): for every sign pattern of the small
  rotations ``(theta, phi, psi)`` and every choice of touched walls (none, +, -, both, per
  lateral axis), the pose is solved (the rotation magnitude fixes the extent when both walls
  of an axis are touched) and the contact feature on each touched wall is read off the
  support set of the inserted part of the peg: one vertex (point), two (line: tip edge,
  mouth line or vertical edge) or four (plane).

States are counted up to the mirror symmetries of the geometry.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from peghole_mjx.analysis import oracle
from peghole_mjx.analysis.dual import full_contacts
from peghole_mjx.geometry.specs import DualSpec, RectSpec

# ----------------------------------------------------------------------------------------
# Dual peg-hole, 2D
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DualState:
    """A feasible contact set: contact names, kind, and whether it exists over a depth region
    (``True``) or only at isolated depths."""

    contacts: tuple[str, ...]
    kind: str
    region: bool


def _mirror_name(name: str) -> str:
    """Mirror ``x -> -x``: peg/hole 1 <-> 2 and left <-> right."""
    table = str.maketrans({"1": "2", "2": "1", "L": "R", "R": "L"})
    return name.translate(table)


def _kind(names: tuple[str, ...]) -> str:
    def peg(n):
        return n.split("/")[1][1] if "corner" in n else n[1]

    def side(n):
        return n[2]

    if len(names) == 1:
        where = "mouth corner on peg side" if "corner" in names[0] else "peg tip on hole wall"
        return f"one-point ({where})"
    pegs = {peg(n) for n in names}
    if len(names) == 2:
        a, b = names
        if len(pegs) == 1:
            return "line contact, one peg" if side(a) == side(b) else "two-point, one peg"
        outer = {("1", "L"), ("2", "R")}
        so = [(peg(n), side(n)) in outer for n in names]
        if side(a) != side(b) and all(so):
            return "two-point, outer surfaces of both pegs"
        if side(a) != side(b) and not any(so):
            return "two-point, inner surfaces of both pegs"
        return "one point on each peg"
    by_peg = {p: [n for n in names if peg(n) == p] for p in pegs}
    if len(names) == 4 and all(len(v) == 2 and side(v[0]) == side(v[1]) for v in by_peg.values()):
        return "line contact, both pegs"
    return f"{len(names)}-point"


def _gaps(body, h, x_O, th):
    out = []
    for c in body.contacts:
        gap, ok, *_ = oracle._geometry(body, c, h, x_O, th)
        out.append(np.where(ok, gap, np.inf))
    return np.stack(out, axis=-1)


def enumerate_dual_states(
    spec: DualSpec, n_depth: int = 20, tol: float = 1e-6, max_contacts: int = 4
) -> list[DualState]:
    """All contact states of the dual peg-hole ``spec`` found from the exact geometry."""
    contacts = _dual_contacts(spec)
    body = oracle.PlanarBody(contacts, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, spec.length_mm)
    n = len(contacts)
    L = spec.length_mm
    hs = np.geomspace(0.01 * L, 0.96 * L, n_depth)
    names = tuple(c.name for c in contacts)
    found: dict[frozenset[int], bool] = {}

    def record(S, region):
        key = frozenset(S)
        found[key] = found.get(key, False) or region

    # one contact: sweep depth and tilt
    thetas = np.linspace(-0.06, 0.06, 121)
    H, T = np.meshgrid(hs, thetas, indexing="ij")
    for i, c in enumerate(contacts):
        x = oracle._x_from_contact(body, c, H, T)
        g = _gaps(body, H, x, T)
        g[..., i] = 0.0
        ok = np.all((g > tol) | (np.arange(n) == i), axis=-1)
        ok &= np.isfinite(g[..., i])
        if ok.sum() >= 2:
            record((i,), True)
    # two or more contacts: solve the first pair for theta at each depth
    for k in range(2, max_contacts + 1):
        for S in itertools.combinations(range(n), k):
            i, j = S[0], S[1]
            ci, cj = contacts[i], contacts[j]
            sols = []
            for seed in (0.0, 0.03, -0.03):
                th, _ = oracle._newton(
                    lambda t, ci=ci, cj=cj: (
                        oracle._x_from_contact(body, ci, hs, t)
                        - oracle._x_from_contact(body, cj, hs, t)
                    ),
                    np.full(hs.shape, seed),
                )
                res = np.abs(
                    oracle._x_from_contact(body, ci, hs, th)
                    - oracle._x_from_contact(body, cj, hs, th)
                )
                sols.append((th, res < 1e-10))
            for th, conv in sols:
                conv = conv & (np.abs(th) < 0.3)
                x = oracle._x_from_contact(body, ci, hs, th)
                g = _gaps(body, hs, x, th)
                rest = [m for m in range(n) if m not in S]
                extra = list(S[2:])
                open_ok = np.all(g[:, rest] > tol, axis=-1) if rest else np.ones_like(conv)
                in_pair = np.all(np.abs(g[:, [i, j]]) <= tol, axis=-1)
                if not extra:
                    ok = conv & open_ok & in_pair
                    if ok.sum() >= 2:
                        record(S, True)
                    continue
                ge = g[:, extra]
                zero = np.all(np.abs(ge) <= tol, axis=-1)
                if (conv & open_ok & in_pair & zero).sum() >= 2:
                    record(S, True)  # extra gaps vanish identically: a region
                    continue
                # isolated: the first extra gap changes sign between neighbouring depths
                g0 = ge[:, 0]
                for a in range(len(hs) - 1):
                    if not (conv[a] and conv[a + 1]) or not np.isfinite(g0[a] * g0[a + 1]):
                        continue
                    if g0[a] * g0[a + 1] > 0:
                        continue
                    hit = _bisect_isolated(body, ci, cj, hs[a], hs[a + 1], extra, th[a], tol)
                    if hit is not None:
                        th_h, h_h = hit
                        xh = oracle._x_from_contact(body, ci, h_h, th_h)
                        gh = _gaps(body, np.array(h_h), np.array(xh), np.array(th_h))
                        others = [m for m in range(n) if m not in S]
                        if np.all(np.abs(gh[list(S)]) <= tol) and np.all(gh[others] > tol):
                            record(S, False)
    states = [
        DualState(
            tuple(names[m] for m in sorted(S)), _kind(tuple(names[m] for m in sorted(S))), reg
        )
        for S, reg in found.items()
    ]
    return states


def _bisect_isolated(body, ci, cj, h_a, h_b, extra, th_seed, tol):
    def solve_pair(h):
        th, _ = oracle._newton(
            lambda t: (
                oracle._x_from_contact(body, ci, h, t) - oracle._x_from_contact(body, cj, h, t)
            ),
            np.array(th_seed),
        )
        x = oracle._x_from_contact(body, ci, h, th)
        g = _gaps(body, np.array(h), np.array(x), np.array(th))
        return th, g[extra[0]]

    _, ga = solve_pair(h_a)
    for _ in range(60):
        hm = 0.5 * (h_a + h_b)
        th, gm = solve_pair(hm)
        if not np.isfinite(gm):
            return None
        if ga * gm <= 0:
            h_b = hm
        else:
            h_a, ga = hm, gm
    return float(th), 0.5 * (h_a + h_b)


def _dual_contacts(spec: DualSpec) -> tuple[oracle.Contact, ...]:
    return full_contacts(spec)


def dual_state_classes(states: list[DualState]) -> dict[tuple[str, ...], DualState]:
    """Distinct states up to the mirror symmetry (canonical contact tuple -> state)."""
    out: dict[tuple[str, ...], DualState] = {}
    for s in states:
        mirrored = tuple(sorted(_mirror_name(n) for n in s.contacts))
        key = min(tuple(sorted(s.contacts)), mirrored)
        prev = out.get(key)
        if prev is None or (s.region and not prev.region):
            out[key] = s
    return out


# ----------------------------------------------------------------------------------------
# Rectangular peg-hole, 3D
# ----------------------------------------------------------------------------------------

WALLS = ("+x", "-x", "+y", "-y")


def _rot(theta: float, phi: float, psi: float) -> np.ndarray:
    cx, sx = np.cos(theta), np.sin(theta)
    cy, sy = np.cos(phi), np.sin(phi)
    cz, sz = np.cos(psi), np.sin(psi)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _inserted_vertices(spec: RectSpec, rot: np.ndarray, h: float) -> tuple[np.ndarray, list[str]]:
    """Vertices of the inserted part (tip corners and mouth points), tip centre at the origin
    laterally and ``h`` below the mouth."""
    vp, wp, L = spec.peg_v_mm, spec.peg_w_mm, spec.length_mm
    verts, tags = [], []
    for sx, sy in itertools.product((-1, 1), (-1, 1)):
        base = np.array([sx * vp / 2, sy * wp / 2, 0.0])
        p0 = rot @ base + np.array([0, 0, -h])
        d = rot @ np.array([0.0, 0.0, 1.0])
        t = -p0[2] / d[2]  # where the vertical edge crosses the mouth plane
        assert 0 < t < L
        verts += [p0, p0 + t * d]
        tags += [f"tip{sx:+d}{sy:+d}", f"mouth{sx:+d}{sy:+d}"]
    return np.array(verts), tags


def _feature(tags: list[str]) -> str:
    n = len(tags)
    if n == 1:
        return "point"
    if n == 2:
        kinds = {t[:3] for t in tags}
        if kinds == {"tip"}:
            return "line(tip edge)"
        if kinds == {"mou"}:
            return "line(mouth edge)"
        return "line(vertical edge)"
    return "plane"


def _rect_pose_features(spec: RectSpec, signs, touch, h: float, alpha: float = 2e-3):
    """Solve one (rotation signs, touched walls) combination; return {wall: feature} or None."""
    v, w = spec.hole_v_mm, spec.hole_w_mm

    def extents(k_x, k_y):
        th = signs[0] * alpha * (k_y if touch[1] == "both" else 1.0)
        ph = signs[1] * alpha * (k_x if touch[0] == "both" else 1.0)
        ps = (
            signs[2]
            * alpha
            * (k_x if touch[0] == "both" else 1.0)
            * (k_y if touch[1] == "both" and touch[0] != "both" else 1.0)
        )
        P, tags = _inserted_vertices(spec, _rot(th, ph, ps), h)
        return P, tags

    k_x = k_y = 1.0
    for axis, idx, width in ((0, 0, v), (1, 1, w)):
        if touch[axis] != "both":
            continue

        def f(k, axis=axis, idx=idx, width=width, kx0=k_x, ky0=k_y):
            P, _ = extents(k if axis == 0 else kx0, k if axis == 1 else ky0)
            return np.ptp(P[:, idx]) - width

        if f(1e-6) >= 0 or f(200.0) <= 0:
            return None
        k = brentq(f, 1e-6, 200.0, xtol=1e-14)
        if axis == 0:
            k_x = k
        else:
            k_y = k
    P, tags = extents(k_x, k_y)
    # translation: touch the chosen walls, centre otherwise
    shift = np.zeros(3)
    for axis, idx, width in ((0, 0, v), (1, 1, w)):
        lo, hi = P[:, idx].min(), P[:, idx].max()
        if hi - lo > width + 1e-9:
            return None
        mode = touch[axis]
        if mode == "+":
            shift[idx] = width / 2 - hi
        elif mode == "-":
            shift[idx] = -width / 2 - lo
        else:
            shift[idx] = -(hi + lo) / 2
    P = P + shift
    out = {}
    tol = 1e-9
    for wall, (idx, sgn, width) in zip(
        WALLS, ((0, 1, v), (0, -1, v), (1, 1, w), (1, -1, w)), strict=True
    ):
        gap = width / 2 - sgn * P[:, idx]
        touching = gap <= tol * max(width, 1.0)
        if touching.any():
            out[wall] = _feature([t for t, z in zip(tags, touching, strict=True) if z])
    # consistency: exactly the requested walls touch
    want = set()
    for axis, (p, m) in enumerate((("+x", "-x"), ("+y", "-y"))):
        mode = touch[axis]
        want |= (
            {p, m} if mode == "both" else ({p} if mode == "+" else {m} if mode == "-" else set())
        )
    if set(out) != want:
        return None
    return out


def _mirror_state(state: tuple[tuple[str, str], ...], mx: bool, my: bool):
    def mw(wall):
        if mx and wall[1] == "x":
            return ("-" if wall[0] == "+" else "+") + "x"
        if my and wall[1] == "y":
            return ("-" if wall[0] == "+" else "+") + "y"
        return wall

    return tuple(sorted((mw(wl), f) for wl, f in state))


@dataclass(frozen=True)
class RectStates:
    """Result of the 3D enumeration: every feasible state (wall -> feature tuples), the
    distinct classes up to the mirror symmetries, and the jamming candidates (contacts on two
    opposite walls of one axis only; four-wall wedging excluded), grouped by feature set."""

    all_states: tuple[tuple[tuple[str, str], ...], ...]
    classes: tuple[tuple[tuple[str, str], ...], ...]
    jamming: tuple[tuple[tuple[str, str], ...], ...]
    jamming_groups: dict[str, int]


def enumerate_rect_states(spec: RectSpec, depth_fraction: float = 0.5) -> RectStates:
    """Contact states of the rectangular peg (no-contact excluded)."""
    h = depth_fraction * spec.hole_depth_mm
    states = set()
    modes = ("none", "+", "-", "both")
    for signs in itertools.product((-1, 0, 1), repeat=3):
        for touch in itertools.product(modes, modes):
            if touch == ("none", "none"):
                continue
            if touch == ("both", "both"):
                continue  # four-wall wedging (Sec 3.2.1), not a jamming state
            feats = _rect_pose_features(spec, signs, touch, h)
            if feats:
                states.add(tuple(sorted(feats.items())))
    all_states = tuple(sorted(states))
    classes = {}
    for s in all_states:
        key = min(_mirror_state(s, mx, my) for mx in (False, True) for my in (False, True))
        classes[key] = s
    jam = []
    groups: dict[str, int] = {}
    for key in sorted(classes):
        walls = {wl for wl, _ in key}
        two_x = {"+x", "-x"} <= walls
        two_y = {"+y", "-y"} <= walls
        if two_x ^ two_y:
            jam.append(key)
            label = " + ".join(sorted(f for _, f in key))
            groups[label] = groups.get(label, 0) + 1
    return RectStates(all_states, tuple(sorted(classes)), tuple(jam), groups)
