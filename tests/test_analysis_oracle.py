"""Closed forms versus the independent numerical oracle (acceptance grid) and Whitney's
single-peg jamming diagram."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from peghole_mjx.analysis import dual, jamming, oracle, planar, rect
from peghole_mjx.geometry.specs import get_preset, with_changes

H_TOP = 48.0  # below the full-insertion sliver h > L - 0.1 mm, where the peg's top corners act


def _grid():
    base = get_preset("dual-2")
    specs = (
        ("5", base),
        ("5", get_preset("dual-3")),
        ("10", with_changes(base, peg_distance_mm=40.02)),
        ("9", with_changes(base, peg_distance_mm=39.98)),
    )
    combos = list(
        itertools.product(
            [0.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0],
            [3e3, 3e4, 3e5],
            [0.5, 2.0],
            [-0.9, -0.6, -0.3],
        )
    )
    out = []
    for cat, spec in specs:
        Lc, Kt, d0, th0 = (np.array(v) for v in zip(*combos, strict=True))
        kw = dict(K_theta_Nmm_per_rad=Kt, delta0_mm=d0, theta0_rad=np.deg2rad(th0))
        cf = dual.two_point_region(spec, cat, Lc, h0_mm=H_TOP, **kw)
        ref = dual.two_point_region(spec, cat, Lc, h0_mm=H_TOP, refine=True, **kw)
        body, target = dual.oracle_body(spec, cat, Lc, **kw)
        lo, hi, ln = oracle.region_of_state(
            body, target, np.full(Lc.shape, 1.0), np.full(Lc.shape, H_TOP), n_grid=121
        )
        plus, _ = dual.category_pairs(spec, cat)
        # small-angle indicator: relative error of theta = 2c/s at the shallow boundary
        eps = np.abs(float(plus.w_peg)) * 0.5 * float(plus.two_c) / np.where(ln > 0, lo, 1) ** 2
        # largest two-point contact force min(N_A, N_B) inside the closed-form region: tells a
        # genuine region from a near-tangent one that carries no force
        pr = dual.params(spec, Lc, **kw)
        nmax = np.zeros(Lc.shape)
        for pair, mir in (
            (plus, False),
            (dual.planar.mirror_pair(dual.category_pairs(spec, cat)[1]), True),
        ):
            s = cf.h_lo + (cf.h_hi - cf.h_lo) * np.linspace(0.0, 1.0, 50)[:, None]
            f = dual.planar.two_point_forces(pair, dual._springs(pr, mir), pr.mu, s)
            nmax = np.fmax(
                nmax, np.nanmax(np.where(np.isfinite(s), np.minimum(f.N_A, f.N_B), -np.inf), axis=0)
            )
        out.append(dict(cf=cf, ref=ref, lo=lo, hi=hi, ln=ln, eps=eps, nmax=nmax))
    return {
        k: np.concatenate(
            [
                np.broadcast_to(
                    np.asarray(
                        getattr(o["cf"], k, None) if k in ("length", "h_lo", "h_hi") else o[k]
                    ),
                    o["ln"].shape,
                )
                for o in out
            ]
        )
        for k in ("length", "h_lo", "h_hi", "lo", "hi", "ln", "eps", "nmax")
    } | {"ref": np.concatenate([o["ref"].length for o in out])}


@pytest.fixture(scope="module")
def grid():
    return _grid()


def test_grid_has_enough_small_angle_combinations(grid):
    small = (grid["eps"] <= 0.01) & (grid["ln"] >= 8.0)
    assert grid["ln"].size == 504
    assert small.sum() >= 200, small.sum()


def test_closed_form_agrees_with_oracle_within_two_percent(grid):
    ln, cf = grid["ln"], grid["length"]
    # emptiness agrees everywhere, except near-tangent regions whose contact forces stay
    # below 1 mN (small-angle error decides the sign of a vanishing force;
    # docs/research/analysis.md)
    mismatch = (ln > 0) != (cf > 0)
    assert mismatch.sum() <= 3
    assert np.all(grid["nmax"][mismatch] < 1e-3)
    small = (grid["eps"] <= 0.01) & (ln >= 8.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        err_len = np.abs(cf - ln) / ln
        err_lo = np.abs(grid["h_lo"] - grid["lo"]) / ln
        err_hi = np.abs(grid["h_hi"] - grid["hi"]) / ln
    worst = np.max(np.maximum.reduce([err_len, err_lo, err_hi])[small])
    assert worst <= 0.02, worst
    # short regions: the boundary error stays within a few times the small-angle error eps*h
    short = (grid["eps"] <= 0.01) & (ln > 0) & (ln < 8.0)
    bnd = np.fmax(np.abs(grid["h_lo"] - grid["lo"]), np.abs(grid["h_hi"] - grid["hi"]))
    assert np.all(bnd[short] <= 5 * grid["eps"][short] * grid["lo"][short] + 0.02)


def test_refined_closed_form_matches_oracle_to_solver_tolerance(grid):
    ln = grid["ln"]
    assert np.max(np.abs(grid["ref"] - ln)) < 1e-5


def test_small_angle_error_outside_regime_is_geometric():
    """Outside the small-angle regime (wide effective peg, shallow boundary) the quadratic is
    off by the neglected w_p theta^2 / 2 term; the refined form is exact there too."""
    spec = with_changes(get_preset("dual-2"), peg_distance_mm=40.1)
    kw = dict(K_theta_Nmm_per_rad=1e3, delta0_mm=2.0)
    cf = dual.two_point_region(spec, "10", 10.0, h0_mm=H_TOP, **kw)
    ref = dual.two_point_region(spec, "10", 10.0, h0_mm=H_TOP, refine=True, **kw)
    body, target = dual.oracle_body(spec, "10", 10.0, **kw)
    lo, _hi, _ln = oracle.region_of_state(body, target, 1.0, H_TOP)
    assert abs(float(ref.h_lo) - float(lo[()])) < 1e-5
    plus, _ = dual.category_pairs(spec, "10")
    predicted = abs(float(plus.w_peg)) * 0.5 * float(plus.two_c) / float(lo[()]) ** 2
    assert predicted > 0.05  # theta off by > 5 %: not the small-angle regime
    assert abs(float(cf.h_lo) - float(lo[()])) < 2 * predicted * float(lo[()])


def test_rect_cases_agree_with_planar_oracle():
    for case in (1, 2, 3):
        Lc = np.array([0.0, 75.0, 150.0])
        kw = dict(K_theta_Nmm_per_rad=5e3, K_phi_Nmm_per_rad=5e3, delta_x_mm=2.0)
        ref = rect.two_contact_region("rect-1", case, Lc, h0_mm=145.0, refine=True, **kw)
        body, target = rect.oracle_body("rect-1", case, Lc, **kw)
        _lo, _hi, ln = oracle.region_of_state(body, target, np.full(3, 1.0), np.full(3, 145.0))
        assert np.allclose(ref.length, ln, atol=1e-5), (case, ref.length, ln)


def test_oracle_two_point_forces_equal_exact_template():
    spec = get_preset("dual-2")
    body, _ = dual.oracle_body(spec, "5", 25.0, delta0_mm=2.0)
    h = np.array([20.0, 30.0, 40.0])
    _x_O, th, lam, _res = oracle._solve_subset(body, (2, 3), h, h.shape)
    _, _minus = dual.category_pairs(spec, "5")
    f = dual.forces(spec, "5", h, 25.0, configuration="-", exact=True, delta0_mm=2.0)
    assert np.allclose(lam[:, 2], f.two_point.N_A, rtol=1e-9)
    assert np.allclose(lam[:, 3], f.two_point.N_B, rtol=1e-9)
    assert np.allclose(-th, f.two_point.theta, rtol=1e-9)


def test_oracle_one_point_tip_matches_closed_form():
    """At a depth where only the tip touches, oracle and eqs (2.17)/(2.21) agree."""
    spec = get_preset("dual-2")
    kw = dict(delta0_mm=0.5, theta0_rad=0.0, K_theta_Nmm_per_rad=2e3)
    body, _ = dual.oracle_body(spec, "5", 0.0, **kw)
    sol = oracle.solve(body, np.array([20.0]))
    active = [n for n, a in zip(sol.names, sol.active[0], strict=True) if a]
    assert active == ["B+"]
    f = dual.forces(spec, "5", 20.0, 0.0, configuration="+", **kw)
    assert np.isclose(sol.lam[0, 1], f.tip_only.N, rtol=2e-3)
    assert np.isclose(sol.theta[0], f.tip_only.theta, rtol=2e-2)
    assert np.isclose(sol.F_z[0], f.tip_only.F_z, rtol=2e-3)


def test_oracle_solution_is_unique_on_the_figure_sweep():
    spec = get_preset("dual-2")
    body, _ = dual.oracle_body(spec, "5", np.linspace(0, 50, 11)[:, None])
    sol = oracle.solve(body, np.linspace(2, 48, 40)[None, :])
    assert sol.valid.mean() > 0.99
    assert not sol.ambiguous.any()


@pytest.mark.parametrize("depth", [10.0, 20.0, 45.0])
def test_single_peg_limit_matches_whitney_jamming_diagram(depth):
    """Whitney (1982): two-point sliding lines M/(rF_z) = +-lambda - f mu (lambda - 1) and
    |F_x/F_z| = 1/mu. Points clearly inside never admit static equilibrium; points clearly
    beyond a two-point line do (the peg jams)."""
    r, mu, two_c = 6.0, 0.2, 0.2
    d = jamming.diagram(depth, r, mu)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(600):
        f = rng.uniform(-0.97 / mu, 0.97 / mu)
        m = rng.uniform(-2.5 * d.lam, 2.5 * d.lam)
        line = -f * mu * (d.lam - 1)
        margin = min(abs(m - (line + d.lam)), abs(m - (line - d.lam)))
        if margin < 0.1 * d.lam + 0.1:
            continue
        checked += 1
        inside = bool(jamming.extracts(f, 1.0, m * r, depth, r, mu))
        jam_p = jamming.jams_exact(f, 1.0, m * r, depth, r, mu, two_c, "+")
        jam_m = jamming.jams_exact(f, 1.0, m * r, depth, r, mu, two_c, "-")
        assert inside == (not jam_p and not jam_m)
        assert jam_p == (m > line + d.lam)
        assert jam_m == (m < line - d.lam)
    assert checked > 300
    # corners (re-derived eq 2.52)
    assert np.allclose(
        d.corners, [[1 / mu, 1], [-1 / mu, 2 * d.lam - 1], [-1 / mu, -1], [1 / mu, 1 - 2 * d.lam]]
    )


def test_planar_template_sign_of_quadratics_matches_forces():
    """N_B and Q_B (N_A and Q_A) share their sign: the boundaries are the quadratics' roots."""
    pair = planar.ContactPair(-6.1, -6.0, 6.1, 6.0)
    rng = np.random.default_rng(3)
    for _ in range(50):
        sp = planar.Springs(
            rng.uniform(0.1, 1),
            rng.uniform(1e2, 1e5),
            rng.uniform(0, 50),
            rng.uniform(-3, 3),
            rng.uniform(-0.03, 0.03),
        )
        s = rng.uniform(5, 50, 20)
        f = planar.two_point_forces(pair, sp, 0.05, s)
        qb, qa = planar.boundary_quadratics(pair, sp, 0.05)
        ok = np.abs(f.N_B) > 1e-9 * (1 + np.abs(f.N_A))
        assert np.all(np.sign(f.N_B[ok]) == np.sign(planar.poly2(qb, s)[ok]))
        ok = np.abs(f.N_A) > 1e-9 * (1 + np.abs(f.N_B))
        assert np.all(np.sign(f.N_A[ok]) == np.sign(planar.poly2(qa, s)[ok]))


@pytest.mark.parametrize("mu", [0.0, -0.0])
def test_oracle_at_zero_friction_raises_no_arithmetic_warning(mu):
    """At mu 0 some contact subsets have no solution (inf/NaN entries); they are masked, and
    their arithmetic must not leak a RuntimeWarning to the user (seen at --mu -0.0)."""
    import warnings

    spec = with_changes(get_preset("dual-2"), friction=abs(mu))
    body, _ = dual.oracle_body(spec, "5", np.linspace(0, 50, 6)[:, None])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        sol = oracle.solve(body, np.linspace(2, 48, 12)[None, :])
    assert sol.valid.mean() > 0.5
