"""Property tests (hypothesis) of the analytic model's invariants."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from peghole_mjx.analysis import dual, oracle, planar, rect
from peghole_mjx.geometry.specs import dual_spec, get_preset

SETTINGS = settings(max_examples=40, deadline=None)

peg_r = st.floats(5.6, 6.09)
L_C = st.floats(0.0, 50.0)
K_x = st.floats(0.05, 2.0)
K_t = st.floats(5e2, 1e6)
delta = st.floats(-3.0, 3.0)
angle = st.floats(-0.03, 0.03)


@SETTINGS
@given(r=peg_r, lc=L_C, kx=K_x, kt=K_t, d0=delta, b0=angle, t0=angle, cat=st.sampled_from("5"))
# found by hypothesis: 0.01 mm clearance, the small-angle depth map went below the mouth
@example(r=6.08984375, lc=0.0, kx=1.0, kt=500.0, d0=0.0, b0=0.015625, t0=0.015625, cat="5")
def test_boundaries_within_zero_and_peg_length(r, lc, kx, kt, d0, b0, t0, cat):
    spec = dual_spec(6.1, r, 40.0, 50.0)
    for refine in (False, True):
        reg = dual.two_point_region(spec, cat, lc, kx, kt, d0, b0, t0, refine=refine)
        if reg.length > 0:
            assert 0.0 <= reg.h_lo <= reg.h_hi <= spec.length_mm + 1e-9
            assert reg.length <= reg.h_hi - reg.h_lo + 1e-9
        else:
            assert math.isnan(float(reg.h_lo))


@SETTINGS
@given(r=peg_r, lc=L_C, kx=K_x, d0=delta, t0=angle, cat=st.sampled_from(["5", "10", "9"]))
def test_no_two_point_when_clearance_exceeds_worst_case_tilt(r, lc, kx, d0, t0, cat):
    """A rotationally rigid compliance keeps the tilt at its rest value; two-point contact
    needs the tilt 2c/s, so no two-point contact if 2c/h0 exceeds it. The oracle agrees."""
    spec = dual_spec(6.1, r, 40.0, 50.0)
    plus, _ = dual.category_pairs(spec, cat)
    two_c = float(plus.two_c)
    h0 = 45.0
    worst_tilt = abs(t0)
    kt = 1e12
    reg = dual.two_point_region(spec, cat, lc, kx, kt, d0, 0.0, t0, h0_mm=h0)
    if two_c / h0 > worst_tilt * 1.02:
        assert reg.length == 0.0
        body, _target = dual.oracle_body(
            spec, cat, lc, K_x_N_per_mm=kx, K_theta_Nmm_per_rad=kt, delta0_mm=d0, theta0_rad=t0
        )
        sol = oracle.solve(body, np.linspace(2.0, h0, 12))
        codes = sol.state_code()
        assert not np.isin(codes, [3, 12]).any()
    elif worst_tilt > 0 and two_c / worst_tilt < 0.9 * h0 and abs(worst_tilt) > 1e-3:
        assert reg.length > 0.0


@SETTINGS
@given(lc=L_C, kx=K_x, kt=K_t, d0=delta, b0=angle, t0=angle, cat=st.sampled_from(["5", "10", "9"]))
def test_mirror_symmetry_of_lateral_error(lc, kx, kt, d0, b0, t0, cat):
    """Mirroring the errors (delta0, beta0, theta0) -> -(...) swaps the "+" and "-" regions of
    a symmetric dual peg-hole and leaves the category's region unchanged."""
    spec = get_preset("dual-2")
    a = dual.two_point_region(spec, cat, lc, kx, kt, d0, b0, t0)
    b = dual.two_point_region(spec, cat, lc, kx, kt, -d0, -b0, -t0)
    assert np.isclose(a.length, b.length, atol=1e-9)
    assert np.isclose(a.plus.length, b.minus.length, atol=1e-9)


@SETTINGS
@given(lc=st.floats(0.0, 150.0), d=delta, t0=angle, case=st.sampled_from([1, 2, 3]))
def test_rect_mirror_symmetry(lc, d, t0, case):
    kw = dict(delta_x_mm=d, delta_y_mm=d, theta0_rad=t0)
    a = rect.two_contact_region("rect-1", case, lc, **kw)
    kw = dict(delta_x_mm=-d, delta_y_mm=-d, theta0_rad=-t0)
    b = rect.two_contact_region("rect-1", case, lc, **kw)
    assert np.isclose(a.length, b.length, atol=1e-9)


@SETTINGS
@given(lc=L_C, kx=K_x, kt=K_t, xm=delta, tm=angle, refine=st.booleans())
def test_units_are_consistent_mm_N_versus_SI(lc, kx, kt, xm, tm, refine):
    """The model is dimensionally homogeneous: lengths in m, K_x in N/m and K_theta in N m/rad
    (0.4 N/mm = 400 N/m, 30e4 N mm/rad = 300 N m/rad; erratum E8) give the same region in m."""
    mm = 1e-3
    pair = planar.ContactPair(-6.1, -6.0, 6.1, 6.0)
    pair_si = planar.ContactPair(-6.1 * mm, -6.0 * mm, 6.1 * mm, 6.0 * mm)
    a = planar.two_point_region(
        pair, planar.Springs(kx, kt, lc, xm, tm), 0.05, 45.0, 50.0, refine=refine
    )
    b = planar.two_point_region(
        pair_si,
        planar.Springs(kx / mm, kt * mm, lc * mm, xm * mm, tm),
        0.05,
        45.0 * mm,
        50.0 * mm,
        refine=refine,
    )
    assert np.isclose(a.length * mm, b.length, rtol=1e-6, atol=1e-12)
    fa = planar.two_point_forces(pair, planar.Springs(kx, kt, lc, xm, tm), 0.05, 30.0)
    fb = planar.two_point_forces(
        pair_si, planar.Springs(kx / mm, kt * mm, lc * mm, xm * mm, tm), 0.05, 30.0 * mm
    )
    assert np.isclose(fa.N_A, fb.N_A, rtol=1e-9, atol=1e-12)  # N in both systems
    assert np.isclose(fa.M * mm, fb.M, rtol=1e-9, atol=1e-15)  # N mm -> N m


def test_vectorised_evaluation_matches_scalar_calls():
    Lc = np.linspace(0, 50, 7)[:, None]
    d0 = np.array([0.5, 2.0, 3.0])[None, :]
    reg = dual.two_point_region("dual-2", "5", Lc, delta0_mm=d0, K_theta_Nmm_per_rad=2e3)
    assert reg.length.shape == (7, 3)
    for i in range(7):
        for j in range(3):
            one = dual.two_point_region(
                "dual-2", "5", float(Lc[i, 0]), delta0_mm=float(d0[0, j]), K_theta_Nmm_per_rad=2e3
            )
            assert np.isclose(one.length, reg.length[i, j])
