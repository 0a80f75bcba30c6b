"""The quasi-static oracle's R2 map over the full dual grid (benchmarks/studies/r2_map.py)."""

import json

import pytest

from benchmarks.studies import pull_speed as ps
from benchmarks.studies import r2_map as rm


def test_classes_follow_the_intervals():
    assert rm.classify([5, 9], [1, 3], [2, 4]) == "ordered"
    assert rm.classify([5, 9], [-1, 3], [2, 4]) == "tip_below_top"
    assert rm.classify([-9, -5], [-1, 3], [2, 4]) == "reversed"
    assert rm.classify([-1, 5], [1, 3], [-2, 4]) == "unresolved"


def test_the_thesis_tilt_orders_the_peaks_and_300_n_m_rad_is_over_the_torque_cap():
    """At the thesis's commanded tilt (theta0 -0.9 deg) and K_x 300 N/m, K_theta 30 N m/rad:
    tip < centre < top, resolved by the oracle's own intervals; at 300 N m/rad the tilt's
    spring torque (4.7 N m) is over the law's 3 N m cap."""
    row = rm.map_cell(ps.cell(30.0, 0.0, "dual_tilt"), 16)
    assert row["r2_class"] == "ordered"
    assert not row["over_force_cap"] and not row["over_torque_cap"]
    pk = row["oracle_peak_fz_N"]
    assert pk["tip"] < pk["centre"] < pk["top"]
    assert rm.map_cell(ps.cell(300.0, 0.0, "dual_tilt"), 2)["over_torque_cap"]


def test_the_committed_map_backs_the_tilt_plan():
    """The dual_tilt plan was chosen from the map: at dual-2, mu 0.266, K_x 300 N/m, every cell
    where the oracle resolves R2's ordering within the caps is on the tilt arm, and the plan
    holds those of them at delta0 2 mm."""
    doc = json.loads((ps.STUDIES_RESULTS / "r2_map.json").read_text())
    assert len(doc["cells"]) == len(rm.GRID.cells())
    ordered = [
        c
        for c in doc["cells"]
        if (c["preset"], c["mu"], c["k_lat_N_m"]) == ("dual-2", 0.266, 300.0)
        and c["r2_class"] == "ordered"
        and not (c["over_force_cap"] or c["over_torque_cap"])
    ]
    assert ordered and all(c["theta0_deg"] == -0.9 and c["beta0_deg"] == 0 for c in ordered)
    planned = {k for k, _ in ps.PLANS["dual_tilt"].cells}
    assert {c["k_rot_Nm_rad"] for c in ordered if c["delta0_mm"] == 2.0} <= planned
    assert doc["summary"] and doc["device"] and doc["date"]


def test_too_few_repeats_is_one_clear_line(monkeypatch):
    monkeypatch.setattr("sys.argv", ["r2_map", "--repeats", "1"])
    with pytest.raises(SystemExit, match="repeats must be >= 2"):
        rm.main()
