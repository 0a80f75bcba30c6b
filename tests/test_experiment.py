"""The compliance-centre extraction experiment: a short real MJX run and the CLI's errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from peghole_mjx.cli.main import main
from peghole_mjx.experiments.compliance import (
    ExperimentConfig,
    Extraction,
    analytic_two_point_hook,
    peak_forces,
)
from peghole_mjx.experiments.report import summarise, write_outputs

KEYS = {
    "peak_force_N",
    "reduction_tip_vs_top_pct",
    "reduction_tip_vs_centre_pct",
    "thesis",
    "max_penetration_mm",
    "nan_worlds",
    "device",
    "versions",
    "date",
    "two_point_depth_mm",
    "analytic_two_point_depth_mm",
    "two_point_cross_check",
}


@pytest.mark.slow
def test_short_extraction_writes_complete_outputs(tmp_path):
    # rect-1, one repeat, fast pull (0.1 m/s, the thesis's speed limit): about 1 s of sim
    cfg = ExperimentConfig(
        geometry="rect",
        presets=("rect-1",),
        repeats=1,
        speed_m_s=0.1,
        settle_s=0.1,
        chunk_steps=800,
    )
    ex = Extraction("rect-1", cfg)
    res = ex.run(progress=False)
    assert res["depth_mm"].shape[0] == 3  # three L_C
    assert not res["nan"].any()
    assert np.all(res["depth_mm"][:, -1] < 0.0)  # every tip ended above the mouth
    assert np.all(res["wrench_ratio"] <= 1.0 + 1e-5)  # commanded wrench within its caps
    pk = peak_forces(res)
    assert np.all(np.isfinite(pk)) and np.all(pk >= 0)
    summary = summarise({"rect-1": res}, cfg, 1.0)
    assert KEYS <= set(summary)
    assert set(summary["peak_force_N"]["rect-1"]) == {"0", "75", "150"}
    files = write_outputs({"rect-1": res}, summary, tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text())["nan_worlds"] == 0
    for f in files:
        assert f.stat().st_size > 0
    assert (tmp_path / "force_depth.png").stat().st_size < 200_000


def test_cli_rejects_bad_geometry(capsys, tmp_path):
    assert main(["experiment", "compliance", "--geometry", "round", "--out", str(tmp_path)]) == 2
    assert "rect or dual" in capsys.readouterr().err


def test_cli_rejects_unknown_preset(capsys, tmp_path):
    rc = main(
        [
            "experiment",
            "compliance",
            "--geometry",
            "rect",
            "--presets",
            "dual-1",
            "--out",
            str(tmp_path),
        ]
    )
    assert rc == 2


def test_config_is_frozen():
    cfg = ExperimentConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.repeats = 3  # type: ignore[misc]


def test_analytic_hook_uses_the_quasi_static_model():
    cfg = ExperimentConfig()
    # rect-2 (2c = 0.1 mm), tilt error 0.2 deg: two-point from s ~ 2c/beta = 29 mm to h0
    out = analytic_two_point_hook(
        "rect-2", 75.0, cfg, delta0_mm=[2.0, 2.0], beta0_rad=np.radians([0.2, 0.0]), h0_mm=149.5
    )
    lo, hi = out["interval_mm"]
    assert 25.0 < lo < 35.0 and hi == pytest.approx(149.5, abs=0.01)
    assert out["worlds_with_two_point"] == 1 and out["per_world"][1] is None
    # the tilt sign does not matter for the symmetric rect hole (mirror configurations)
    neg = analytic_two_point_hook(
        "rect-2", 75.0, cfg, delta0_mm=[2.0], beta0_rad=np.radians([-0.2]), h0_mm=149.5
    )
    assert neg["interval_mm"][0] == pytest.approx(lo, abs=3.0)
    # dual-2 (2c = 0.2 mm over a 50 mm peg): 0.2 deg cannot make two-point contact
    dual = analytic_two_point_hook("dual-2", 25.0, cfg, beta0_rad=np.radians([0.2]), h0_mm=49.5)
    assert dual["interval_mm"] is None and set(dual["per_category"]) == {"5", "10", "9"}


def test_quick_experiment_is_one_definition(tmp_path, monkeypatch):
    """`peghole experiment compliance --quick` and `peghole demo` run ExperimentConfig.quick."""
    from peghole_mjx.experiments import report

    quick = ExperimentConfig.quick("dual", seed=3)
    assert quick.preset_names() == ("dual-2",) and quick.repeats == 2 and quick.seed == 3
    seen = []

    def fake_run(cfg, out):
        seen.append(cfg)
        return {"peak_force_N": {}}, []

    monkeypatch.setattr(report, "run_experiment", fake_run)
    argv = ["experiment", "compliance", "--geometry", "dual", "--quick", "--seed", "3"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    assert seen == [quick]
