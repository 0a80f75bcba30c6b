"""The transfer matrix (benchmarks/evals/transfer.py): its cells for every published policy, and
a tiny run end to end with its resume."""

from __future__ import annotations

import csv
import json

import pytest

from benchmarks.evals import transfer
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.config import env_spec
from peghole_mjx.policies import PRETRAINED, load_policy
from peghole_mjx.training.evaluate import requested_config


@pytest.mark.parametrize("name", sorted(PRETRAINED))
def test_every_cell_is_a_valid_env_of_the_policy(name):
    """Every cell's overrides pass the env config's checks on the policy's training config;
    friction and clearance are relative to the policy's own (DualExtractHard's mu 0.266)."""
    bundle = load_policy(name)
    trained = requested_config(bundle)
    cells = transfer.cells(trained, trained.engine)
    assert next(iter(cells)) == "nominal" and list(cells)[-1] == "realistic"
    assert set(cells) == set(transfer.CELL_SOURCES)
    assert cells["engine"].overrides["engine"] != trained.engine
    spec = env_spec(trained)
    for cell in cells.values():
        config = requested_config(bundle, cell.overrides)  # the checks of the env config
        if cell.name.startswith("clearance"):
            f = 0.5 if "-50" in cell.name else 1.5
            assert env_spec(config).clearance_mm == pytest.approx(f * spec.clearance_mm)
    centre = sum(trained.randomization.friction_scale) / 2
    for f in transfer.FRICTION_FACTORS:
        got = cells[f"friction_x{f:g}"].overrides["randomization.friction_scale"]
        assert got == pytest.approx((f * centre, f * centre))


def test_cells_on_the_other_engine_swap_the_engine_cell():
    trained = requested_config(load_policy("rect"))
    cells = transfer.cells(trained, "mujoco")
    assert cells["nominal"].overrides == {"engine": "mujoco"}
    assert cells["engine"].overrides == {"engine": "mjx"}
    assert all(c.overrides["engine"] == "mujoco" for n, c in cells.items() if n != "engine")


@pytest.mark.slow
def test_transfer_command_runs_cells_and_resumes(tmp_path, capsys):
    """Three cells of two episodes on the mujoco engine: policy and scripted on the same
    episodes, paired against the nominal cell; JSON, CSV and heat map written; a rerun loads
    every cell from the partial file instead of running it."""
    out = tmp_path / "t.json"
    argv = ["--policy", "rect", "--episodes", "2", "--engine", "mujoco", "--no-progress"]
    argv += ["--cells", "obs_latency_1,ft_noise", "--parts", str(tmp_path / "parts")]
    argv += ["--out", str(out)]
    assert transfer.main(argv) == 0
    doc = json.loads(out.read_text())
    assert {"device", "versions", "date", "episodes_per_cell", "seed", "engine"} <= set(doc)
    assert doc["complete"] and doc["cells_planned"] == ["nominal", "ft_noise", "obs_latency_1"]
    nominal, noise, latency = doc["cells"]
    for c in doc["cells"]:
        for who in transfer.METHODS:
            assert c[who]["episodes"] == 2 and len(c[who]["success_ci95"]) == 2
    assert nominal["policy"]["vs_nominal"]["mean_fz_N"] == {"mean": 0.0, "ci95": [0.0, 0.0]}
    # the scripted pull's action is constant: the observation shifts change none of its episodes
    for c in (noise, latency):
        assert abs(c["scripted"]["vs_nominal"]["mean_fz_N"]["mean"]) < 1e-3
        # the engine is provenance, not the task: never a difference
        assert "engine" not in c["differs_from_training"]
    assert "randomization.ft_noise_force_N" in noise["overrides"]
    rows = list(csv.DictReader(out.with_suffix(".csv").open()))
    assert [(r["cell"], r["method"]) for r in rows][:2] == [
        ("nominal", "policy"),
        ("nominal", "scripted"),
    ]
    assert all(r["device"] and r["versions"] and r["date"] for r in rows)
    assert out.with_suffix(".png").stat().st_size > 1000
    capsys.readouterr()
    assert transfer.main(argv) == 0  # every finished cell is loaded, none run again
    err = capsys.readouterr().err
    assert all(f"{c}: loaded from" in err for c in ("nominal", "ft_noise", "obs_latency_1"))
    assert json.loads(out.read_text())["cells"] == doc["cells"]


def test_an_unknown_cell_is_refused_in_one_line(tmp_path, capsys):
    argv = ["--policy", "rect", "--cells", "gravity_x2", "--out", str(tmp_path / "x.json")]
    with pytest.raises(SystemExit):
        transfer.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert "unknown cells ['gravity_x2']" in err[-1]


def test_reference_puts_a_robust_variant_into_the_reference_env():
    """--reference: the robust variant's randomisation entries are reset to the reference's
    (every one that differs, nothing else); any other difference is refused in one line."""
    from peghole_mjx.envs.config import apply_overrides

    ref = requested_config(load_policy("rect_hard"))
    robust = apply_overrides(
        ref,
        {
            "engine": "mujoco",
            "randomization.obs_latency_steps": 1,
            "randomization.friction_scale": (0.5, 2.0),
            "randomization.ft_noise_force_N": 0.0625,
        },
    )
    back = transfer.reference_overrides(robust, ref)
    assert back == {
        "randomization.friction_scale": tuple(ref.randomization.friction_scale),
        "randomization.ft_noise_force_N": 0.0,
        "randomization.obs_latency_steps": 0,
    }
    assert transfer.reference_overrides(ref, ref) == {}
    other = apply_overrides(robust, {"action.max_ff_xy_N": 1.0})
    with pytest.raises(UserInputError, match="differ beyond the randomisation.*max_ff_xy_N"):
        transfer.reference_overrides(other, ref)


def test_newcombe_interval_meets_the_published_examples():
    """Newcombe (1998), Table II: 56/70 - 48/80 -> [0.0524, 0.3339]; 9/10 - 3/10 -> [0.1705,
    0.8090]."""
    from benchmarks.common import newcombe

    assert newcombe(56, 70, 48, 80) == [0.0524, 0.3339]
    assert newcombe(9, 10, 3, 10) == [0.1705, 0.809]


def test_robust_rule_takes_the_worst_cells_and_publishes_only_above_zero():
    def doc(name, rates, fz=1.0):
        cells = [
            {"cell": f"c{i}", "policy": {"success_rate": r, "mean_fz_N": fz}}
            for i, r in enumerate(rates)
        ]
        return {"policy_name": name, "complete": True, "episodes_per_cell": 128, "cells": cells}

    ref = doc("ref", [1.0, 122 / 128, 1.0])
    v = transfer.robust_verdict(doc("rob", [1.0, 1.0]), ref)
    assert v["reference_worst"]["cell"] == "c1" and v["publish"]  # 128/128 vs 122/128
    v = transfer.robust_verdict(doc("rob", [1.0, 127 / 128]), ref)
    assert v["robust_worst"]["successes"] == 127 and not v["publish"]  # interval holds 0
    tie = doc("t", [0.5, 0.5])
    tie["cells"][1]["policy"]["mean_fz_N"] = 9.0
    assert transfer.worst_cell(tie)["cell"] == "c1"  # ties: the higher force
    with pytest.raises(UserInputError, match="incomplete"):
        transfer.robust_verdict({**ref, "complete": False}, ref)
