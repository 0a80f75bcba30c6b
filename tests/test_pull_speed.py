"""The MuJoCo C replica of the compliance experiment and the pull-speed check's bookkeeping."""

import json

import numpy as np
import pytest

from benchmarks.studies import pull_speed as ps
from benchmarks.studies.c_replica import COLUMNS, ENGINE, pull_c
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.experiments import sweep as sw


def test_c_replica_holds_the_standard_case_at_the_oracle_force():
    """The standard tilted case (K_theta 300 N m/rad, L_C at the tip) in MuJoCo C, float64:
    sustained two-point contact and the late peak F_z within 10 % of the quasi-static oracle."""
    trace, settle, dt = pull_c("rect-2", cc.STANDARD_MU, cc.STANDARD_CASE, 0.02)
    assert trace.shape[1] == len(COLUMNS) and np.all(np.isfinite(trace))
    row = ps.summarise(trace, settle, dt, cx.EARLY_MM["rect"])
    tab = {k: np.array([v]) for k, v in cc.STANDARD_CASE.items()}
    h0 = sw.h0_mm("rect-2", cx.ExperimentConfig())
    oracle = cx.quasi_static_peaks(cx.quasi_static("rect-2", cc.STANDARD_MU, tab, h0), h0, 5.0)
    assert row["peak_fz_late_N"] == pytest.approx(float(oracle[0]), rel=0.10)
    assert row["both_walls_frac_in_two_point"] >= 0.9
    assert row["penetration_um"] < 12.5  # 25 % of rect-2's radial clearance


def test_c_replica_meets_the_oracle_on_the_dual_meshes_when_slow():
    """The dual-2 mesh scene, K_theta 3 N m/rad, beta0 -0.2 deg, L_C = top, 0.5 mm/s: the late
    peak within 5 % of the oracle's (0.168 vs 0.167 N; MJX float64 0.167 N). With MuJoCo C's
    multi-point CCD on (its default) the replica read 0.121 N."""
    c = ps.cell(3.0, -0.2, "dual")
    tab = ps.worlds_at(c, 1)
    cfg = ps.experiment_config("dual", 0.5, None)
    trace, settle, dt = pull_c(c["preset"], ps.MU, ps.world(tab, 0), 0.5e-3, cfg)
    row = ps.summarise(trace, settle, dt, cx.EARLY_MM["dual"])
    oracle = float(ps.oracle_late_peaks(c, tab)[0])
    assert row["peak_fz_late_N"] == pytest.approx(oracle, rel=0.05)


def _rows(repeats: int, peaks: dict[float, float]) -> dict[str, dict]:
    c = ps.cell(3.0, -0.2)
    out = {}
    for lc_mm, p in peaks.items():
        for r in range(repeats):
            key = json.dumps([3.0, -0.2, 2.0, lc_mm * 1e-3, r])
            out[key] = {
                "peak_fz_late_N": p * (1 + 0.1 * r),
                "oracle_peak_fz_late_N": 2 * p,
                "both_walls_frac_in_two_point": 0.5,
                "two_point_windows": 10 * r,
            }
    return c, out


def test_reductions_pair_the_same_draws_across_l_c():
    c, rows = _rows(4, {0.0: 1.0, 75.0: 2.0, 150.0: 4.0})
    red = ps.reductions(rows, c, 2.0, 4)
    assert red["n_repeats"] == 4
    assert red["reduction_tip_vs_top_pct"]["value"] == pytest.approx(75.0)
    assert red["reduction_tip_vs_centre_pct"]["value"] == pytest.approx(50.0)
    assert red["reduction_centre_vs_top_pct"]["value"] == pytest.approx(50.0)
    # every repeat scales tip and top alike: the paired interval collapses on the value
    lo, hi = red["reduction_tip_vs_top_pct"]["ci95"]
    assert lo == pytest.approx(75.0) and hi == pytest.approx(75.0)
    assert red["reduction_tip_vs_top_pct"]["oracle"] == pytest.approx(75.0)
    # 10 r windows of 20 ms at 2 mm/s: 0.4 r mm of pull, mean over r = 0..3 is 0.6 mm
    assert red["two_point_mm"]["tip"] == pytest.approx(0.6)
    assert set(red["oracle_two_point_mm"]) == {"tip", "centre", "top"}


def test_reductions_wait_for_every_world_of_the_cell():
    c, rows = _rows(4, {0.0: 1.0, 75.0: 2.0, 150.0: 4.0})
    rows.pop(next(iter(rows)))
    assert ps.reductions(rows, c, 2.0, 4) is None


def test_the_summary_covers_every_cell_and_speed_in_the_store():
    """A rerun of one cell at a new speed keeps every other cell in the written summary: the
    plan's cells first, in its order, then the others, each fast to slow."""
    keys = [[30.0, -0.2, 2.0], [7.0, 0.2, 1.0], [3.0, 0.2, 1.0], [3.0, -0.2, 2.0],
            [3.0, 0.2, 20.0], [3.0, -0.2, 20.0]]  # fmt: skip
    rows = {json.dumps([*k, 0.0, 0]): {} for k in keys}
    got = ps.summarised(rows, ps.PLANS["rect"])
    assert got == [(3.0, -0.2, 20.0), (3.0, -0.2, 2.0), (3.0, 0.2, 20.0), (3.0, 0.2, 1.0),
                   (30.0, -0.2, 2.0), (7.0, 0.2, 1.0)]  # fmt: skip


def test_jobs_cover_every_cell_speed_l_c_and_repeat_once():
    jobs = ps.jobs([ps.cell(3.0, -0.2)], (20.0, 2.0), 2, 0)
    keys = [j[0] for j in jobs]
    assert len(keys) == len(set(keys)) == 2 * 3 * 2
    assert all(np.isfinite(j[4]) for j in jobs)  # the oracle's late peak of each world


def test_the_tilt_plan_commands_the_thesis_tilt_in_every_world():
    """The dual_tilt plan is the thesis's dual experiment (theta0 -0.9 deg, K_x 300 N/m) with
    beta0 0: every world it pulls carries the commanded tilt, at every L_C."""
    plan = ps.PLANS["dual_tilt"]
    jobs = ps.jobs([ps.cell(k, b, "dual_tilt") for k, b in plan.cells], (0.5,), 2, 0)
    assert len(jobs) == len(plan.cells) * 3 * 2
    for _, c, _, w, _, coulomb in jobs:
        assert not coulomb
        assert c["preset"] == "dual-2" and c["k_lat_N_m"] == 300.0
        assert w["theta0"] == pytest.approx(np.radians(-0.9)) and w["beta0"] == 0.0
    assert ps.cell(3.0, -0.2, "dual")["theta0_deg"] == 0.0
    # the printed-friction plan carries its mu into every cell, hence into the pulls and oracle
    assert ps.cell(30.0, 0.0, "dual_tilt_mu001")["mu"] == 0.01
    assert ps.cell(30.0, 0.0, "dual_tilt")["mu"] == ps.MU
    # the dual-3 plan pulls the tighter preset; each tilted plan has its own store name
    assert ps.cell(10.0, 0.0, "dual3_tilt_mu001")["preset"] == "dual-3"
    tilted = [n for n, p in ps.PLANS.items() if p.theta0_deg]
    assert all(ps.PLANS[n].theta0_deg == -0.9 for n in tilted) and len(set(tilted)) >= 5


def test_the_speed_figure_draws_from_the_committed_results(tmp_path):
    rect = json.loads((ps.STUDIES_RESULTS / "pull_speed_rect.json").read_text())
    out = ps.write_figure(rect, None, tmp_path / "f.png")
    assert out.stat().st_size > 10_000


def test_every_mjx_check_has_its_committed_row_and_c_twin():
    doc = json.loads((ps.STUDIES_RESULTS / "pull_speed_mjx.json").read_text())
    keys = [ps.check_key(r) for r in doc["rows"]]
    assert sorted(keys) == sorted(ps.check_key(c) for c in ps.MJX_CHECKS)
    for r in doc["rows"]:
        c = ps.cell(r["k_rot_Nm_rad"], r["beta0_deg"], ps.plan_of(r))
        assert r["preset"] == c["preset"]
        assert len(r["c_float64_peak_fz_late_N"]) == len(r["peak_fz_late_N"]) == ps.MJX_REPEATS
        assert r["c_engine"] == ENGINE  # the twin of the replica as it is now
        # the oracle column is the oracle of the very worlds the check pulls
        np.testing.assert_allclose(
            ps.oracle_late_peaks(c, ps.worlds_at(c, ps.MJX_REPEATS, ps.at_of(r))),
            r["oracle_peak_fz_late_N"],
        )
