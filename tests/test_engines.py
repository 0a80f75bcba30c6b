"""The compliance experiment's two engines (``compliance.Extraction``'s ``engine``): MJX-JAX and
MuJoCo C float64 run one experiment (one scene, schedule, law, F/T tare and contact rule), give
the same record, and agree on the standard case; the commands and the pull-speed study take
``--engine``."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from benchmarks.studies import pull_speed as ps
from benchmarks.studies.c_replica import pull_c
from peghole_mjx.cli.main import main
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.experiments import sweep

#: the peak F_z of the two engines on the standard case may differ by this fraction (MJX float32
#: against MuJoCo C float64, each its own contact solver; measured 2026-12-02: 4.655 N on mjx,
#: 4.640 N on mujoco, 0.3 %; the oracle 5.21 N)
PEAK_REL_TOL = 0.05


@pytest.fixture(scope="module")
def both_engines():
    """The standard tilted case (contact-check's, rect-2, K_theta 300 N m/rad, L_C at the
    tip, 20 mm/s) on one world, the same table on each engine (the mjx graph is the one
    ``test_sweep.test_contact_check_runs_one_world`` compiles)."""
    tab = cc.world_table(1, 0)
    return {
        e: cx.Extraction(
            "rect-2", cc.variant_config(cc.VARIANTS["experiment"], e), mu=cc.STANDARD_MU
        ).run(progress=False, table=tab)
        for e in cx.ENGINES
    }


@pytest.mark.slow
def test_the_mujoco_engine_gives_the_mjx_engines_record(both_engines):
    mjx, c = both_engines["mjx"], both_engines["mujoco"]
    assert set(c) == set(mjx)
    for k in mjx:
        assert np.shape(c[k]) == np.shape(mjx[k]), k
    # the shared scene, keyframe, step count and sampling
    np.testing.assert_array_equal(c["time_s"], mjx["time_s"])
    assert c["h0_mm"] == mjx["h0_mm"] and c["settle_s"] == mjx["settle_s"]
    assert not c["nan"].any() and not mjx["nan"].any()


@pytest.mark.slow
def test_the_engines_agree_on_the_standard_case(both_engines):
    """Peak extraction force (F/T F_z, filtered, late and whole pull) within PEAK_REL_TOL,
    the same share of two-point samples (0.72 on both, 2026-12-02) and the tip's path. Short
    events differ: in one 20 ms sample MuJoCo C's peg strikes the -x wall at up to 88 N where
    MJX's does not (the unfiltered |F| peaks 20.1 N against 4.8 N; the tip's depth then departs
    by up to 0.13 mm)."""
    mjx, c = both_engines["mjx"], both_engines["mujoco"]
    for skip in (0.0, cx.EARLY_MM["rect"]):
        pm, pc = cx.peaks(mjx, skip)["fz"][0], cx.peaks(c, skip)["fz"][0]
        assert pc == pytest.approx(pm, rel=PEAK_REL_TOL), (skip, pm, pc)
    tp_m, tp_c = mjx["two_point"][0].mean(), c["two_point"][0].mean()
    assert tp_m > 0.3 and abs(tp_c - tp_m) < 0.05
    np.testing.assert_allclose(c["depth_mm"], mjx["depth_mm"], atol=0.5)
    # the commanded wrench within its caps on both
    assert c["wrench_ratio"].max() <= 1.0 + 1e-9 and mjx["wrench_ratio"].max() <= 1.0 + 1e-5


def test_the_mujoco_run_records_its_own_trace():
    """``run`` on the mujoco engine samples the very steps ``trace`` returns: the 20 ms means of
    the trace's side forces and depth are the record's, the record's deepest contact the
    trace's."""
    cfg = cx.ExperimentConfig(geometry="rect", speed_m_s=0.1, settle_s=0.1, chunk_steps=400)
    ex = cx.Extraction("rect-1", cfg, mu=cc.STANDARD_MU, engine="mujoco")
    world = dict(cc.STANDARD_CASE)
    res = ex.run(progress=False, table={k: np.array([v]) for k, v in world.items()})
    trace, settle, dt = ex.trace(world)
    assert (settle, dt) == (ex.n_settle, ex.dt) and len(trace) == ex.n_pull <= ex.n_steps
    col = {c: i for i, c in enumerate(cx.TRACE_COLUMNS)}
    k = ex.record_every
    n = len(trace) // k
    for name, rec in (("f_plus", "f_plus"), ("f_minus", "f_minus"), ("depth", "depth_mm")):
        means = cx.window_means(trace[:, col[name]], k)
        scale = 1e3 if rec == "depth_mm" else 1.0
        np.testing.assert_allclose(res[rec][0, :n], means * scale, rtol=1e-12, atol=1e-15)
    assert res["penetration_mm"][0] == pytest.approx(trace[:, col["penetration"]].max() * 1e3)
    assert res["f_plus"][0].max() > 1.0  # the peg does load a wall (not a trivial comparison)
    loaded = (trace[:, col["f_plus"]] > cx.LOADED_N) | (trace[:, col["f_minus"]] > cx.LOADED_N)
    np.testing.assert_array_equal(res["any_frac"][0, :n], cx.window_means(loaded, k))


def test_the_replica_is_the_mujoco_engines_trace():
    """``pull_c`` (the studies' name) is ``Extraction.trace`` on the mujoco engine, its
    speed and law damping ratio taking the place of the config's."""
    cfg = cx.ExperimentConfig(geometry="rect", speed_m_s=0.05, settle_s=0.1)
    world = dict(cc.STANDARD_CASE)
    a, settle, dt = pull_c("rect-1", cc.STANDARD_MU, world, 0.1, cfg, damping_ratio=0.5)
    ex = cx.Extraction(
        "rect-1",
        cx.ExperimentConfig(geometry="rect", speed_m_s=0.1, settle_s=0.1, damping_ratio=0.5),
        mu=cc.STANDARD_MU,
        engine="mujoco",
    )
    b, *rest = ex.trace(world)
    np.testing.assert_array_equal(a, b)
    assert (settle, dt) == tuple(rest) == (ex.n_settle, ex.dt)


def test_an_unknown_engine_is_one_line(capsys, tmp_path):
    with pytest.raises(UserInputError, match="engine must be auto, mjx or mujoco, not 'bullet'"):
        cx.Extraction("rect-1", cx.ExperimentConfig(), engine="bullet")
    for argv in (
        ["experiment", "sweep", "--geometry", "rect", "--grid", "tiny", "--engine", "bullet"],
        ["experiment", "contact-check", "--engine", "bullet"],
    ):
        assert main([*argv, "--out", str(tmp_path / "o.json")]) == 2
        err = capsys.readouterr().err.strip()
        assert (
            "engine must be auto, mjx or mujoco, not 'bullet'" in err and len(err.splitlines()) == 1
        )
    # float64 is MuJoCo C's own precision: --x64 is MJX's option
    argv = ["experiment", "contact-check", "--engine", "mujoco", "--x64"]
    assert main(argv) == 2
    assert "always runs in float64" in capsys.readouterr().err


def test_a_trace_comes_from_the_mujoco_engine_only():
    ex = cx.Extraction("rect-1", cx.ExperimentConfig(), engine="mjx")
    with pytest.raises(UserInputError, match="mujoco engine"):
        ex.trace(dict(cc.STANDARD_CASE))


def test_the_tiny_sweep_runs_on_the_mujoco_engine(tmp_path, capsys):
    """``peghole experiment sweep --engine mujoco`` at the tiny grid (rect-1, 2 repeats) and
    the fastest pull: the result records its engine, which keys its slices apart from mjx's."""
    out = tmp_path / "sweep"
    argv = ["experiment", "sweep", "--geometry", "rect", "--grid", "tiny", "--engine", "mujoco"]
    assert main([*argv, "--speed-mm-s", "100", "--batch-worlds", "4", "--out", str(out)]) == 0
    doc = json.loads((out / "compliance_sweep_rect.json").read_text())
    assert doc["engine"] == "mujoco"
    assert doc["settings"]["experiment"]["engine"] == "mujoco"
    (cell,) = doc["cells"]
    assert cell["n_worlds"] == 6 and cell["nan_worlds"] == 0
    assert all(v > 0 for v in cell["peak_fz_N"].values())
    assert len(list((out / "parts").glob("*.npz"))) == 2  # 6 worlds in slices of 4
    mjx = sweep.SweepConfig(grid=sweep.GRIDS["rect"]["tiny"], batch_worlds=4)
    assert "engine" not in mjx.settings()["experiment"]  # mjx keeps the keys it had
    c = sweep.SweepConfig(
        grid=mjx.grid, batch_worlds=4, experiment=cx.ExperimentConfig(engine="mujoco")
    )
    assert sweep.group_key(c, "rect-1", 0.266) != sweep.group_key(mjx, "rect-1", 0.266)


def test_the_pull_speed_rows_on_the_mjx_path_match_the_trace_rows(tmp_path, monkeypatch):
    """The pull-speed study's ``--engine mjx`` rows come from the experiment's record
    (``run_mjx_rows``, ``summarise_run``); run here on the mujoco engine (the path is the same,
    the engine is swapped in) beside the trace rows of the same world, at K_theta 300 N m/rad
    where the pull is quasi-static: the F/T peak within 5 % of the contact forces' peak."""
    real = cx.Extraction

    def on_mujoco(preset, cfg, mu=None, engine=None, opt=None):
        return real(preset, cfg, mu=mu, engine="mujoco", opt=opt)

    monkeypatch.setattr(cx, "Extraction", on_mujoco)
    todo = [j for j in ps.jobs([ps.cell(300.0, -0.2)], (20.0,), 1, 0) if j[3]["L_C"] == 0.0]
    parts, rows = tmp_path / "p.parts.jsonl", {}
    ps.run_mjx_rows(todo, parts, rows)
    (key,) = rows
    assert json.loads(parts.read_text())["key"] == key == todo[0][0]
    row = rows[key]
    assert row["engine"] == ps.MJX_ENGINE and row["mu_eff"] is None
    trace_row = ps.world_row(todo[0])
    assert row["peak_fz_late_N"] == pytest.approx(trace_row["peak_fz_late_N"], rel=0.05)
    assert row["both_walls_frac_in_two_point"] == pytest.approx(
        trace_row["both_walls_frac_in_two_point"], abs=0.05
    )


def test_the_pull_speed_engine_option_is_for_the_plans_rows(monkeypatch):
    for extra in (["--mechanism"], ["--mjx"]):
        monkeypatch.setattr(sys, "argv", ["pull_speed", "--engine", "mjx", *extra])
        with pytest.raises(SystemExit, match="--engine chooses the engine of the plan's rows"):
            ps.main()
    assert ps.engine_of(False) == ps.ENGINE and ps.ENGINES[0] == "mujoco"
