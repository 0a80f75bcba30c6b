"""The seed-stack comparison: the env option reaching the PyBullet sim, its config check, the
time-to-success threshold and ratio, and the dual peg's convex-hull collision in PyBullet."""

import json

import numpy as np
import pytest

from benchmarks.baselines import seed_stack, time_to_success
from benchmarks.baselines.pybullet_peghole import check_config, make_gym_env
from benchmarks.baselines.time_to_success import compare
from benchmarks.studies.seed_stack_dual_hull import run_both
from peghole_mjx.control.reference import rotvec_from_mat
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs import get_default_config
from peghole_mjx.envs.rect_extract import HARD_ANGULAR_ERROR_DEG
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
from peghole_mjx.geometry.specs import get_preset


# ----------------------------------------------------------------------------- compare
def _seed(points):
    return {"curve": [{"train_s": t, "eval": {"success_rate": s}} for t, s in points]}


def _ours(points):
    return {"curve": [{"train_wall_s": t, "eval_success_rate": s} for t, s in points]}


def test_compare_seed_stack_reaches_095():
    r = compare(_seed([(15, 0.2), (30, 0.95), (45, 1.0)]), _ours([(5, 0.0), (10, 1.0)]))
    assert r["threshold"] == 0.95 and "reached by the seed stack" in r["rule"]
    assert (r["seed_time_s"], r["ours_time_s"]) == (30, 10)
    assert r["ratio_seed_over_ours"] == pytest.approx(3.0)


def test_compare_seed_stack_never_reaches_095_uses_its_best():
    seed = _seed([(60, 0.1), (120, 0.6), (180, 0.4)])
    r = compare(seed, _ours([(20, 0.5), (40, 0.65), (60, 0.9)]))
    assert r["threshold"] == 0.6 and "never reached 0.95" in r["rule"]
    assert (r["seed_time_s"], r["ours_time_s"]) == (120, 40)
    assert r["ratio_seed_over_ours"] == pytest.approx(3.0)
    assert r["verdict"] == "both reached 0.6"


def test_compare_ours_never_reaches():
    r = compare(_seed([(60, 0.3)]), _ours([(50, 0.1), (100, 0.2)]))
    assert r["threshold"] == 0.3 and r["seed_time_s"] == 60
    assert r["ours_time_s"] is None and r["ratio_seed_over_ours"] is None
    assert "ours never reached 0.3" in r["verdict"]


def test_compare_seed_stack_never_succeeds():
    r = compare(_seed([(60, 0.0)]), _ours([(50, 1.0)]))
    assert r["threshold"] is None and r["ratio_seed_over_ours"] is None


def test_result_names_keep_the_default_env_files():
    assert seed_stack.result_path("RectExtract", "cpu-2core").name == "seed_stack_cpu-2core.json"
    assert (
        seed_stack.result_path("RectExtractHard", "cpu-2core").name
        == "seed_stack_RectExtractHard_cpu-2core.json"
    )
    assert (
        time_to_success.result_path("RectExtract", "cpu-2core").name == "train_rect_cpu-2core.json"
    )
    assert (
        time_to_success.result_path("RectExtractHard", "gpu-h200").name
        == "train_RectExtractHard_gpu-h200.json"
    )


def test_result_files_take_each_envs_training_results_only(tmp_path):
    """Files are told apart by their own fields: a pre-``--env`` file is RectExtract's, and the
    dual-hull result (no ``stack``) is never a training result."""
    files = {
        "seed_stack_cpu-2core.json": {"stack": "sb3"},
        "seed_stack_gpu-h100.json": {"stack": "sb3", "env": "RectExtract"},
        "seed_stack_RectExtractHard_cpu-2core.json": {"stack": "sb3", "env": "RectExtractHard"},
        "seed_stack_dual_hull.json": {"benchmark": "hull", "env": "DualExtract"},
    }
    for name, d in files.items():
        (tmp_path / name).write_text(json.dumps(d))
    names = [p.name for p in seed_stack.result_files(results=tmp_path)]
    assert names == ["seed_stack_cpu-2core.json", "seed_stack_gpu-h100.json"]
    hard = seed_stack.result_files("RectExtractHard", tmp_path)
    assert [p.name for p in hard] == ["seed_stack_RectExtractHard_cpu-2core.json"]
    assert seed_stack.result_files("DualExtract", tmp_path) == []


# ----------------------------------------------------------------------------- PyBullet
def test_unknown_env_is_one_clear_line(capsys):
    pytest.importorskip("pybullet")
    assert seed_stack.main(["--env", "NoSuchEnv"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "NoSuchEnv" in err and "RectExtractHard" in err
    assert seed_stack.main(["--env", "DualExtract"]) == 2  # a registered env it cannot rebuild
    assert "DualExtract" in capsys.readouterr().err
    assert time_to_success.main(["--env", "NoSuchEnv"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "NoSuchEnv" in err


def test_config_entries_the_sim_cannot_honour_are_refused():
    pytest.importorskip("pybullet")
    check_config(get_default_config("RectExtractHard"))  # every entry accounted for
    c = get_default_config("RectExtract")
    c.compliance_strategy = True
    with pytest.raises(UserInputError, match="compliance_strategy=True") as exc:
        check_config(c)
    assert "\n" not in str(exc.value)
    c = get_default_config("RectExtract")
    with c.unlocked():
        c.randomization.new_knob = 1.0
    with pytest.raises(UserInputError, match="randomization.new_knob"):
        check_config(c)


def _tilt_deg(sim) -> float:
    """Commanded tilt error of the last reset: the angle of cmd_mat from the hole's axis."""
    H, cmd = sim.info["hole_mat"], sim.info["cmd_mat"]
    return float(np.rad2deg(np.linalg.norm(rotvec_from_mat(H.T @ cmd @ TOOL_DOWN_MAT.T))))


def test_env_option_reaches_the_pybullet_sim():
    """RectExtractHard: rect-3 and its +-4 deg tilt error drive the sim (RectExtract: rect-2)."""
    pytest.importorskip("pybullet")
    pytest.importorskip("gymnasium")
    tilts = {}
    for env_name, preset in (("RectExtract", "rect-2"), ("RectExtractHard", "rect-3")):
        env = make_gym_env(env_name, seed=0)
        try:
            sim = env.sim
            assert sim.spec == get_preset(preset)
            assert sim.c.episode_length == get_default_config(env_name).episode_length
            tilt = []
            for seed in range(6):
                env.reset(seed=seed)
                tilt.append(_tilt_deg(sim))
            tilts[env_name] = max(tilt)
        finally:
            env.close()
    bound = get_default_config("RectExtract").randomization.angular_error_deg
    assert tilts["RectExtract"] <= bound * np.sqrt(2) + 1e-6
    assert bound * np.sqrt(2) < tilts["RectExtractHard"] <= HARD_ANGULAR_ERROR_DEG * np.sqrt(2)


def test_dual_hull_penetrates_where_the_compound_fits():
    """One short run each: the hull overlaps the hole block at the start pose, the pieces fit."""
    pytest.importorskip("pybullet")
    hull, compound = run_both(hold_s=0.2, pull_s=0.05)
    assert hull["peg_model"] == "hull" and compound["peg_model"] == "compound"
    assert hull["start_penetration_mm"] > compound["start_penetration_mm"] + 1.0
    assert hull["first_step_normal_force_N"] > compound["first_step_normal_force_N"] + 100.0
    assert compound["placed_inserted"] and not hull["placed_inserted"]
    assert hull["peg_collision_volume_cm3"] > compound["peg_collision_volume_cm3"]
