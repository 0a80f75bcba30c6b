"""The demo's compliance table: simulated reductions beside the quasi-static oracle's for the
same worlds and the thesis's, and one regime sentence per cell that follows the oracle."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from peghole_mjx import demo
from peghole_mjx.training.evaluate import THESIS_RL


def _cell(sim: float | None, oracle: float | None, k_rot: float = 300.0, beta=(0.1, 0.3)):
    """A fabricated cell record with distinct numbers in every column."""
    return {
        "name": "default",
        "preset": "rect-2",
        "mu": 0.266,
        "k_rot_Nm_rad": k_rot,
        "k_lat_N_m": 300.0,
        "beta0_deg": list(beta),
        "delta0_mm": [1.5, 2.5],
        "repeats": 2,
        "regime_KxLc2_over_Ktheta": 300.0 * 0.15**2 / k_rot,
        "early_mm": 5.0,
        "sim": {
            "peak_fz_N": [4.30, 3.91, 3.50],
            "tip_vs_top_pct": sim,
            "tip_vs_centre_pct": -9.75,
            "pairs": 2,
        },
        "oracle": {
            "peak_fz_N": [4.61, 4.22, 3.83],
            "tip_vs_top_pct": oracle,
            "tip_vs_centre_pct": -8.25,
            "pairs": 2,
        },
        "thesis": {"tip_vs_top_pct": 77.1, "tip_vs_centre_pct": 55.6},
        "max_penetration_in_hole_mm": 0.0106,
        "penetration_limit_mm": 0.0125,
        "nan_worlds": 0,
    }


def _row(lines: list[str], n: int = 0) -> list[str]:
    rows = [ln for ln in lines if ln.startswith("| rect-2")]
    return [c.strip() for c in rows[n].strip("|").split("|")]


def test_table_puts_sim_oracle_and_thesis_side_by_side():
    lines = demo.compliance_table([_cell(-23.5, -22.8)])
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    row = _row(lines)
    assert len(row) == len(header) == 12
    col = dict(zip(header, row, strict=True))
    assert col["cell"] == "rect-2, K_theta 300 N m/rad, beta0 +0.1..+0.3 deg"
    # tip vs top: simulated, then the oracle, then the thesis, in adjacent columns
    i = header.index("tip vs top %: sim")
    assert row[i : i + 3] == ["-23.5", "-22.8", "77.1"]
    assert header[i + 1 : i + 3] == ["oracle", "thesis"]
    j = header.index("tip vs centre %: sim")
    assert row[j : j + 3] == ["-9.8", "-8.2", "55.6"]
    k = header.index("mean peak F_z N, tip / centre / top: sim")
    assert row[k : k + 2] == ["4.3 / 3.91 / 3.5", "4.61 / 4.22 / 3.83"]
    assert col["max penetration mm, tip in the hole (limit)"] == "0.0106 (0.0125)"
    # the regime sentence follows the table, one per cell
    bullets = [ln for ln in lines if ln.startswith("- ")]
    assert len(bullets) == 1 and "R1 is reversed" in bullets[0]


@pytest.mark.parametrize(
    ("oracle", "kind", "words"),
    [
        (69.9, "holds", "R1 holds: the oracle puts the tip's peak 69.9 % below the top's"),
        (13.0, "weaker", "R1's ordering, weaker than the thesis's"),
        (-4.0, "small", "the effect is small: the oracle gives -4.0 %"),
        (9.9, "small", "the effect is small: the oracle gives +9.9 %"),
        (-19.4, "reversed", "R1 is reversed: the oracle puts the tip's peak 19.4 % above"),
        (None, "unknown", "no oracle value for this cell"),
    ],
)
def test_regime_sentence_follows_the_oracles_sign_and_size(oracle, kind, words):
    assert demo.regime(oracle) == kind
    text = demo.regime_sentence(_cell(-21.0, oracle))
    assert words in text
    assert text.startswith("rect-2, K_theta 300 N m/rad, beta0 +0.1..+0.3 deg: ")
    assert text.count(".") >= 1 and text.endswith(".")
    # the simulated value says nothing about the regime: only the oracle's does
    assert demo.regime_sentence(_cell(80.0, oracle)).split(";")[0] == text.split(";")[0]


def test_regime_sentence_says_whether_the_simulation_agrees_with_the_oracle():
    assert "the simulation agrees within 10 points (-21.0 %)" in demo.regime_sentence(
        _cell(-21.0, -19.4)
    )
    assert "the simulation does not agree within 10 points (+20.0 %)" in (
        demo.regime_sentence(_cell(20.0, -19.4))
    )
    assert "simulation" not in demo.regime_sentence(_cell(None, -19.4))


def test_reductions_pair_the_repeats_and_drop_a_nan_world():
    tip, ctr, top = np.array([1.0, np.nan, 2.0]), np.array([2.0, 5.0, 2.0]), np.array([4.0] * 3)
    r = demo._reductions([tip, ctr, top])
    assert r["pairs"] == 2
    assert r["peak_fz_N"] == [1.5, 2.0, 4.0]  # the NaN repeat left out at every L_C
    assert math.isclose(r["tip_vs_top_pct"], 100 * (1 - 1.5 / 4.0))
    assert math.isclose(r["tip_vs_centre_pct"], 100 * (1 - 1.5 / 2.0))
    none = demo._reductions([np.full(2, np.nan)] * 3)
    assert none["tip_vs_top_pct"] is None and none["pairs"] == 0


def test_the_real_oracle_puts_the_demo_cells_in_their_regimes():
    """The quasi-static oracle for the demo's own worlds: the default stiffness reverses R1
    (the tip's peak above the top's, as the sweep's K_theta 300 N m/rad, beta0 +0.2 deg cell:
    oracle -19.4 %), the cell nearest R1 holds it (sweep: oracle 69.9 %)."""
    default = demo.cell_oracle(demo._cell_config(demo.DEMO_CELLS[""]))
    r1 = demo.cell_oracle(demo._cell_config(demo.DEMO_CELLS["r1_regime"]))
    assert demo.regime(default["tip_vs_top_pct"]) == "reversed"
    assert demo.regime(r1["tip_vs_top_pct"]) == "holds"
    tip, ctr, top = default["peak_fz_N"]
    assert tip > ctr > top > 0  # reversed: the top loads the peg least
    tip, ctr, top = r1["peak_fz_N"]
    assert 0 < tip < ctr < top  # R1's ordering
    assert default["pairs"] == r1["pairs"] == demo.cx.ExperimentConfig.quick("rect").repeats


def test_report_shows_both_cells_with_their_figures_table_and_regimes(tmp_path):
    """The demo's report from the stage outputs: section 2 links each cell's figure and holds
    the side-by-side table and one regime sentence per cell (``cells.json`` as written by the
    compliance stage)."""
    cells = [_cell(-21.8, -22.8), _cell(70.1, 70.1, k_rot=30.0, beta=(-0.3, -0.1))]
    (tmp_path / "compliance").mkdir()
    (tmp_path / "compliance" / demo.CELLS_FILE).write_text(json.dumps(cells))
    metrics = {"success_rate": 1.0, "mean_time_s": 5.6, "mean_fz_N": 2.8, "peak_fz_N": 15.5}
    ev = {
        "policy": {**metrics, "mean_fxy_N": 3.3},
        "baseline": {**metrics, "mean_fxy_N": 3.4},
        "thesis": THESIS_RL,
        "episodes": 32,
        "force_reduction_pct": 62.3,
    }
    tr = {
        "env_steps": 100,
        "wall_s": 10.0,
        "untrained_eval_return": -1.0,
        "final_eval": {"mean_return": 2.0, "success_rate": 1.0},
        "demo_eval": ev,
        "engine": "mujoco",
        "task": "RL, compliance strategy off",
    }
    text = demo._report(tmp_path, tr, ev, {"models": 1.0}, "quick")
    assert "## 3. Training (RectExtract, RL, compliance strategy off, profile quick" in text
    section = text.split("## 2.")[1].split("## 3.")[0]
    assert "(compliance/force_depth.png)" in section
    assert "(compliance/r1_regime/force_depth.png)" in section
    rows = [ln for ln in section.splitlines() if ln.startswith("| rect-2")]
    assert len(rows) == 2 and "| -21.8 | -22.8 | 77.1 |" in rows[0]
    assert "| 70.1 | 70.1 | 77.1 |" in rows[1]
    bullets = [ln for ln in section.splitlines() if ln.startswith("- ")]
    assert "R1 is reversed" in bullets[0] and "R1 holds" in bullets[1]


def test_the_demo_trains_trainings_default_reward_and_learner_for_the_whole_budget(monkeypatch):
    """The demo trains training's defaults (RL + compliance strategy, the outcome reward,
    residual actions) and the profile's learner on every profile, for the profile's whole
    budget (no early stop: its report states the final policy)."""
    from peghole_mjx.training import config as tc

    engine = {"env.engine": "mujoco"}
    cpu = demo._train_config("cpu", engine)
    for key, value in tc.TRAINING_ENV_DEFAULTS.items():
        assert cpu.env_overrides[key] == value, key
    assert cpu.env_overrides["reward_config.kind"] == "outcome"
    assert cpu.env_overrides["action.residual"] is True
    assert cpu.actor_delay_updates == 0 and cpu.num_timesteps == 256_000
    assert cpu.discounting == tc.reward_discount("RectExtract", cpu.env_overrides)
    task = "RL + compliance strategy, outcome reward, residual actions"
    assert demo.training_task(cpu) == f"{task}, time-out a failure"
    full = demo._train_config("full", {"env.engine": "mjx"})
    assert full.env_overrides["action.max_speed_m_s"] == 0.025
    assert demo.training_task(full) == task  # GPU sizes: time-outs truncations
    seen = {}

    class Run:
        def __init__(self, cfg, out, **kw):
            seen.update(kw)

        def run(self):
            return {}

    monkeypatch.setattr(demo.run_mod, "TrainingRun", Run)
    demo._train(Path("unused"), cpu)
    assert "stop_at_success" not in seen
