"""Two-point detection, the regime sweep (grid, pairing, resume) and the contact check."""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pytest

from peghole_mjx.cli.main import main
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.experiments import sweep


# ---- the detector, on constructed per-step traces (no physics) ---------------------------
def _windows(plus, minus, k=20):
    return cx.two_point_windows(cx.window_means(plus, k), cx.window_means(minus, k))


def test_detector_finds_sustained_two_point_contact():
    n = 400
    plus, minus = np.full(n, 3.0), np.full(n, 2.0)
    assert _windows(plus, minus).all()


def test_detector_finds_chattering_two_point_contact():
    # the contact alternates between the walls as single-step impulses: never both in one
    # step, but both walls carry force on average in every 20-step window
    n = 400
    plus, minus = np.zeros(n), np.zeros(n)
    plus[::7] = 60.0
    minus[3::7] = 55.0
    assert not np.any((plus > 0) & (minus > 0))  # a same-step detector finds nothing
    assert _windows(plus, minus).all()


def test_detector_rejects_one_sided_and_free_traces():
    n = 400
    assert not _windows(np.full(n, 5.0), np.zeros(n)).any()
    assert not _windows(np.zeros(n), np.zeros(n)).any()
    # a single impulse on the second wall in one window only
    minus = np.zeros(n)
    minus[5] = 10.0
    got = _windows(np.full(n, 1.0), minus)
    assert got[0] and not got[1:].any()


def test_chatter_stats_reads_steady_and_impulsive_windows():
    k = 20
    res = {
        "two_point": np.array([[True, True]]),
        "f_plus": np.array([[2.0, 2.0]]),
        "f_minus": np.array([[1.0, 1.0]]),
        "f_plus_max": np.array([[2.1, 40.0]]),  # window 2: one step carries it all
        "f_minus_max": np.array([[1.05, 1.0]]),
        "both_frac": np.array([[1.0, 0.05]]),
    }
    st = cx.chatter_stats(res, 0)
    assert st["windows"] == 2 and st["both_frac"] == pytest.approx(0.525)
    assert st["peak_ratio_max"] == pytest.approx(20.0) and st["peak_ratio_median"] > 1.0
    assert k == 20


def test_two_point_penetration_ignores_samples_outside_the_windows():
    # world 0: deep contact at the exit (no window there), shallow inside the windows;
    # world 1: never in two-point contact
    two_point = np.array([[True, True, False], [False, False, False]])
    pen = np.array([[0.002, 0.003, 0.144], [0.001, 0.2, 0.0]])
    got = cx.two_point_penetration(two_point, pen)
    assert got[0] == pytest.approx(0.003) and np.isnan(got[1])
    with pytest.raises(ValueError, match="differ"):
        cx.two_point_penetration(two_point, pen[:, :2])


# ---- the grid and the pairing -----------------------------------------------------------
def test_grid_cells_and_pairing():
    g = sweep.Grid(("rect-2",), (300.0, 3.0), (-0.2, 0.2), (0.266,), theta0_arm_deg=-0.9)
    cells = g.cells()
    # 2 K_theta x (2 beta0 + 1 theta0 arm)
    assert len(cells) == 6
    arm = [c for c in cells if c["theta0_deg"] == -0.9]
    assert len(arm) == 2 and all(c["beta0_deg"] == 0.0 for c in arm)
    t1 = sweep.cell_table(cells[0], 4, seed=3)
    t2 = sweep.cell_table(cells[3], 4, seed=3)
    # paired: the same draws for every L_C of a cell, and across cells
    d = t1["delta0"].reshape(3, 4)
    assert np.all(d == d[0]) and np.array_equal(t1["delta0"], t2["delta0"])
    # the sign of beta0 is fixed per cell
    assert np.all(np.sign(t1["beta0"]) == np.sign(cells[0]["beta0_deg"]))
    assert sorted(set(t1["L_C"].round(6))) == [0.0, 0.075, 0.15]


def test_a_tilted_grid_commands_the_tilt_and_untilted_keys_stay():
    """``theta0_deg`` tilts every beta0 cell (thesis Table 2.2); a grid without it keeps the
    resume key it had before the field existed, so committed slices are found again."""
    g = sweep.Grid(("dual-2",), (30.0,), (0.0,), (0.266,), theta0_deg=-0.9)
    (c,) = g.cells()
    assert c["theta0_deg"] == -0.9 and c["beta0_deg"] == 0.0
    assert np.allclose(sweep.cell_table(c, 2, 0)["theta0"], np.radians(-0.9))
    flat = sweep.SweepConfig(grid=sweep.GRIDS["dual"]["cpu"]).settings()["grid"]
    assert "theta0_deg" not in flat
    assert sweep.SweepConfig(grid=g).settings()["grid"]["theta0_deg"] == -0.9


def test_paired_bootstrap_interval_contains_the_estimate():
    rng = np.random.default_rng(0)
    top = rng.uniform(4, 6, 16)
    tip = 0.3 * top + rng.normal(0, 0.05, 16)
    est = sweep.reduction_pct(tip, top)
    lo, hi = sweep.paired_bootstrap(tip, top)
    assert lo < est < hi and 60 < est < 80
    assert sweep.paired_bootstrap(tip, top) == [lo, hi]  # fixed seed


@pytest.mark.parametrize(
    "args, message",
    [
        (["--geometry", "rect", "--k-rot", "0,30"], "K_theta must be > 0"),
        (["--geometry", "rect", "--k-rot", "-3"], "K_theta must be > 0"),
        (["--geometry", "rect", "--k-rot", ","], "grid is empty"),
        (["--geometry", "rect", "--presets", "rect-9"], "unknown preset"),
        (["--geometry", "rect", "--presets", "dual-2"], "not rect presets"),
        (["--geometry", "round"], "rect or dual"),
        (["--geometry", "rect", "--mu", "nan"], "must be finite"),
        (["--geometry", "rect", "--k-rot", "abc"], "comma-separated numbers"),
        (["--geometry", "rect", "--speed-mm-s", "0"], "--speed-mm-s must be > 0"),
        (["--geometry", "dual", "--theta0", "-52"], "|theta0| must be <= 5 deg"),
    ],
)
def test_sweep_bad_input_is_one_line(args, message, capsys, tmp_path):
    rc = main(["experiment", "sweep", *args, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and len(err.splitlines()) == 1


def test_contact_check_bad_input_is_one_line(capsys):
    assert main(["experiment", "contact-check", "--preset", "dual-2"]) == 2
    assert "rect preset" in capsys.readouterr().err
    assert main(["experiment", "contact-check", "--variant", "nope"]) == 2
    assert "unknown variant" in capsys.readouterr().err


# ---- a real tiny sweep: runs, writes, resumes -------------------------------------------
#: the sweep and the contact check run on the experiment's ``mujoco`` engine (float64 MuJoCo C,
#: seconds; the MJX experiment compiles for minutes and is tested in test_experiment.py): the
#: sweep's grid, pairing, files and resume sit above the engine
FAST = cx.ExperimentConfig(speed_m_s=0.1, settle_s=0.1, chunk_steps=400, engine="mujoco")


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    cfg = sweep.SweepConfig(grid=sweep.GRIDS["rect"]["tiny"], batch_worlds=4, experiment=FAST)
    return cfg, out, sweep.run_sweep(cfg, out, progress=False)


def test_tiny_sweep_writes_the_documented_keys(tiny_sweep):
    _, out, _ = tiny_sweep
    doc = json.loads((out / "compliance_sweep_rect.json").read_text())
    assert {"cells", "best_match_R1", "device", "versions", "date"} <= set(doc)
    (cell,) = doc["cells"]
    assert cell["n_worlds"] == 6 and cell["nan_worlds"] == 0
    assert set(cell["peak_fz_N"]) == {"0", "75", "150"}
    tp_pen = cell["max_penetration_two_point_um"]
    assert tp_pen is None or tp_pen <= cell["max_penetration_um"]
    for k in (
        "reduction_tip_vs_top_pct",
        "reduction_tip_vs_centre_pct",
        "reduction_centre_vs_top_pct",
    ):
        lo, hi = cell[k]["ci95"]
        assert lo <= cell[k]["value"] <= hi
        assert k in cell["quasi_static"]
    assert "NaN" not in (out / "compliance_sweep_rect.json").read_text()
    assert (out / "compliance_sweep_rect.csv").read_text().count("\n") == 2
    assert len(list((out / "parts").glob("*.npz"))) == 2  # 6 worlds in slices of 4


def test_tiny_sweep_resumes_from_its_parts(tiny_sweep, monkeypatch):
    cfg, out, res = tiny_sweep

    def no_physics(*a, **k):
        raise AssertionError("a saved slice was recomputed")

    monkeypatch.setattr(cx.Extraction, "run", no_physics)
    again = sweep.run_sweep(cfg, out, progress=False)
    assert again["cells"] == res["cells"]
    # another seed is another sweep: refused into these results without force, and with
    # force its slices are not taken from this one
    other = dataclasses.replace(cfg, seed=1)
    with pytest.raises(UserInputError, match="seed"):
        sweep.run_sweep(other, out, progress=False)
    with pytest.raises(AssertionError, match="recomputed"):
        sweep.run_sweep(other, out, progress=False, force=True)


def test_widening_a_grid_reuses_the_slices_already_run(tiny_sweep):
    cfg, out, _ = tiny_sweep
    (preset,), (mu,) = cfg.grid.presets, cfg.grid.mu
    wider = dataclasses.replace(cfg, grid=dataclasses.replace(cfg.grid, mu=(0.01, mu)))
    key = sweep.group_key(wider, preset, mu)
    assert key == sweep.group_key(cfg, preset, mu)
    assert len(list((out / "parts").glob(f"{preset}_mu{mu:g}_{key}_*.npz"))) == 2
    assert sweep.group_key(wider, preset, 0.01) != key
    # a float64 sweep is another sweep; a float32 one keeps the keys of older folders
    assert sweep.group_key(dataclasses.replace(cfg, x64=True), preset, mu) != key
    assert "precision" not in cfg.settings()


def test_contact_check_runs_one_world():
    run = cc.run_variant(
        "rect-2", cc.VARIANTS["experiment"], worlds=1, progress=False, engine="mujoco"
    )
    (w,) = run["worlds"]
    assert not w["nan"] and math.isfinite(w["penetration_um"])
    assert set(run["summary"]["pass"]) == {
        "both_frac",
        "peak_ratio",
        "penetration",
        "oracle",
        "all",
    }
    assert cc.table_row(run).startswith("| rect-2 | experiment |")


def test_slice_claims_share_a_sweep_folder_between_processes(tmp_path):
    part = tmp_path / "rect-2_mu0.266_key_000000.npz"
    assert sweep._claim(part)  # free: taken
    assert sweep._claim(part)  # ours already
    claim = part.with_suffix(".claim")
    claim.write_text("1")  # held by a live process (init)
    assert not sweep._claim(part)
    claim.write_text("4194303")  # held by a process that is gone: taken over
    assert sweep._claim(part) and json.loads(claim.read_text())["pid"] == os.getpid()
