"""``peghole export`` and :mod:`peghole_mjx.deploy`: ONNX Runtime reproduces the JAX policy,
the deploy module runs without JAX and MuJoCo, bad input is refused in one line, and the
MuJoCo C engine driven through the export reproduces the policy's evaluation.

Recorded observations (``test_onnx_actions_equal_jax_on_10000_observations``): each pretrained
policy's env (engine mujoco) runs 16 episodes for up to 200 control steps driven through its
export (:func:`peghole_mjx.policies.export.run_deployed`), which records the env's
observations of the running worlds (1 800 to 3 200 per policy); the rest of the 10 000 are
resampled around them (a recorded observation plus Gaussian noise of 0.1 x each entry's
spread over the recording), since recording 10 000 real steps of four envs would take minutes
on a 2-core CPU.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.deploy import DeployedPolicy, SensorError
from peghole_mjx.envs import get_default_config
from peghole_mjx.policies import PRETRAINED, load_policy
from peghole_mjx.policies.export import (
    EXPORT_TOLERANCE,
    compare_with_evaluation,
    export_policy,
    jax_actions,
    read_spec,
    run_deployed,
)
from peghole_mjx.sim.engines import engine_overrides

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """``name -> exported folder`` of the pretrained policies, each exported once."""
    root = tmp_path_factory.mktemp("exports")
    made: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in made:
            made[name] = Path(export_policy(name, root / name)["out"])
        return made[name]

    return get


@pytest.fixture(scope="module")
def mujoco_env():
    """``name -> the policy's training env on the mujoco engine``, built once per module, so
    that the recording and the closed loop of rect share its compiled reset."""
    made: dict[str, object] = {}

    def get(name: str):
        if name not in made:
            made[name] = load_policy(name).make_env(engine_overrides("mujoco"))
        return made[name]

    return get


# ---------------------------------------------------------------------- the export
def test_export_writes_a_checked_onnx_model_and_its_action_decoding(exports):
    import onnx

    folder = exports("rect")
    names = sorted(p.name for p in folder.iterdir())
    assert names == [".peghole_manifest.json", "action.json", "policy.json", "policy.onnx"]
    model = onnx.load(str(folder / "policy.onnx"))
    onnx.checker.check_model(model, full_check=True)
    # the normaliser's two ops lead when the policy normalises (rect since 2026-12-06 does not)
    meta = json.loads((PRETRAINED["rect"] / "policy.json").read_text())
    norm = ["Sub", "Div"] if meta["network"]["normalize_observations"] else []
    assert [n.op_type for n in model.graph.node] == [
        *norm,
        "Gemm",
        "Relu",
        "Gemm",
        "Relu",
        "Gemm",
        "Tanh",
        "Clip",
    ]
    assert (folder / "policy.json").read_bytes() == (
        PRETRAINED["rect"] / "policy.json"
    ).read_bytes()
    spec = json.loads((folder / "action.json").read_text())
    assert spec["format_version"] == 1 and spec["peghole_mjx_version"]
    obs = spec["observation"]
    # eq 4.2's nine numbers and the time left (the policy observes it: obs.time_left)
    assert obs["size"] == 10 == len(obs["entries"])
    assert [e["name"] for e in obs["entries"]][:3] == ["flange_x", "flange_y", "flange_height"]
    assert {e["unit"] for e in obs["entries"][6:9]} == {"deg"}
    assert obs["entries"][9]["name"] == "time_left"
    # the decoding's numbers are the training env's config (policy.json's overrides applied)
    meta = load_policy("rect").meta
    cfg = get_default_config("RectExtract")
    dec = spec["decode"]
    assert dec["tip_step_m"][2] == pytest.approx(
        meta["env_overrides"]["action.max_speed_m_s"] * cfg.ctrl_dt
    )
    assert dec["tip_step_m"][0] == pytest.approx(cfg.action.max_step_offset_mm * 1e-3)
    assert dec["learned_gains"]["k_xy"] == {"index": 6, "lo": 50.0, "hi": 1000.0, "unit": "N/m"}
    assert dec["learned_gains"]["k_rot"]["index"] == 7
    assert spec["control"]["period_s"] == cfg.ctrl_dt
    assert spec["action"]["size"] == 8 == len(spec["action"]["entries"])


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(PRETRAINED))
def test_onnx_actions_equal_jax_on_10000_observations(exports, mujoco_env, name):
    """ONNX Runtime's actions equal the JAX policy's within 1e-5 on 10 000 observations
    (recorded from rollouts driven through the export, the rest resampled around them: see the
    module docstring); the deployed observations and commands equal the env's on the way."""
    folder = exports(name)
    run = run_deployed(folder, 16, env=mujoco_env(name), max_steps=200, record=True)
    rec = run.observations
    assert rec.shape[0] >= 1000 and np.all(np.isfinite(rec))
    # what DeployedPolicy computed from the robot-side readings is what the env computed
    assert run.max_obs_diff < 1e-3, run.max_obs_diff
    # float32 rounding of the env's own sums: the world-frame tip over hundreds of steps
    assert run.max_command_diff["tip_m"] < 1e-5, run.max_command_diff
    assert run.max_command_diff["force_ff_N"] < 1e-4, run.max_command_diff
    assert run.max_command_diff["gains"] < 1e-3, run.max_command_diff
    rng = np.random.default_rng(0)
    extra = 10_000 - len(rec)
    pick = rec[rng.integers(0, len(rec), extra)]
    noise = rng.normal(size=pick.shape) * (0.1 * rec.std(axis=0) + 1e-6)
    obs = np.concatenate([rec, pick + noise]).astype(np.float32)
    assert obs.shape[0] == 10_000
    onnx_a = DeployedPolicy(folder).act_obs(obs)
    jax_a = jax_actions(load_policy(name), obs)
    diff = np.abs(onnx_a - jax_a)
    assert diff.max() <= EXPORT_TOLERANCE, (diff.max(), np.unravel_index(diff.argmax(), diff.shape))
    assert np.all(np.abs(onnx_a) <= 1.0)
    assert np.ptp(jax_a, axis=0).min() > 0.01  # the observations do move every action


@pytest.mark.slow
def test_the_time_left_entry_is_exported_and_deployed_as_the_env_computes_it(tmp_path):
    """A policy whose env observes the time left (``obs.time_left``, with the time-out a
    failure; the published ``rect`` since 2026-12-06): the export names the entry (offset the
    episode length, scale its inverse negated) and the deployed observation, counted from its
    own steps, equals the env's."""
    over = load_policy("rect").meta["env_overrides"]
    assert over["obs.time_left"] is True and over["reward_config.time_limit"] == "failure"
    folder = Path(export_policy(PRETRAINED["rect"], tmp_path / "export")["out"])
    entry = read_spec(folder)["observation"]["entries"][-1]
    n = get_default_config("RectExtract").episode_length
    assert entry["name"] == "time_left" and entry["source"] == "step"
    assert entry["offset"] == n and entry["scale"] == pytest.approx(-1.0 / n)
    run = run_deployed(folder, 2, max_steps=30, record=True)
    assert run.observations[:, -1].max() == pytest.approx(1.0)
    assert run.observations[:, -1].min() < 1.0  # the entry moves
    assert run.max_obs_diff < 1e-3, run.max_obs_diff


@pytest.mark.slow
def test_closed_loop_through_the_export_reproduces_the_evaluation(exports, mujoco_env):
    """The MuJoCo C engine driven by DeployedPolicy (one per world, fed the contact wrench and
    the flange pose) on the episodes of the JAX policy's evaluation (16 episodes of rect, seed
    0): success identical episode by episode, mean F_z within 1 %.

    Measured 2026-12-02 (2-core CPU, loaded): 16/16 successes both, mean F_z 3.0058 (JAX) vs
    3.0090 N (0.11 %). Per episode the force moves by up to 6 %: contact amplifies the
    rounding-level differences of the observation (float64 robot side vs the env's float32,
    at most 2e-6); the JAX policy fed the deployed observations gives the ONNX loop's numbers
    exactly, so the spread is not the export's. On 8 episodes the mean moved by 0.59 % (seed
    0) and 1.36 % (seed 1), on 16 by 0.11, 0.93 and 0.20 % (seeds 0, 1, 2): docs/guide/deploy.md.
    """
    res = compare_with_evaluation("rect", exports("rect"), 16, seed=0, env=mujoco_env("rect"))
    assert res["engine"] == "mujoco"
    assert res["success_identical"], res["summary_line"]
    assert res["jax"]["episodes"] == res["deployed"]["episodes"] == 16
    assert res["mean_fz_rel_diff"] <= 0.01, res["summary_line"]
    assert res["max_obs_diff"] < 1e-5
    assert res["agrees"]


# ---------------------------------------------------------------------- the deploy module
def test_deploy_runs_with_jax_and_mujoco_blocked(exports):
    """``peghole_mjx.deploy`` imports and runs with jax, jaxlib, mujoco and the stack above
    them made unimportable: NumPy and ONNX Runtime only."""
    folder = exports("rect")
    code = textwrap.dedent(
        f"""
        import sys
        BLOCKED = ("jax", "jaxlib", "mujoco", "mujoco_mjx", "flax", "brax", "ml_collections")

        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in BLOCKED:
                    raise ImportError(f"{{name}} is blocked")
                return None

        sys.meta_path.insert(0, Block())
        from peghole_mjx.deploy import DeployedPolicy

        p = DeployedPolicy({str(folder)!r})
        p.reset(commanded_tip_m=(0.0, 0.0, -0.03))
        cmd = p.act(wrench_N_Nm=[0.0, 0.5, 3.0, 0, 0, 0], flange_pos_m=[1e-4, 0.0, 0.05],
                    flange_tilt_rad=[0.001, 0.0, 0.0])
        assert cmd.step == 1 and cmd.stiffness.shape == (6,)
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
        assert not loaded, loaded
        print("ok", cmd.tip_target_m[2], cmd.k_xy_N_m)
        """
    )
    res = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.startswith("ok")


def test_deployed_command_follows_the_decoding(exports, tmp_path):
    """One step by hand: the action moves the commanded tip and feed-forward by its steps and
    sets the learned gains on their ranges (action.json's decode), the rotation is held. The
    plain decoding: the exported rect policy is a residual one (``decode.residual``, applied
    before this decoding and tested in tests/test_residual.py), so this copy drops the entry."""
    import shutil

    folder = tmp_path / "plain"
    shutil.copytree(exports("rect"), folder)
    spec = json.loads((folder / "action.json").read_text())
    assert spec["decode"].pop("residual", None) is not None
    (folder / "action.json").write_text(json.dumps(spec))
    p = DeployedPolicy(folder)
    p.reset(commanded_tip_m=(0.001, -0.002, -0.03), commanded_tilt_rad=(0.005, 0.0, 0.0))
    a = np.array([1.0, -0.5, 0.8, 1.0, 0.0, -1.0, -1.0, 1.0])
    cmd = p.decode(a)
    dec = spec["decode"]
    step = np.asarray(dec["tip_step_m"])
    np.testing.assert_allclose(cmd.tip_target_m, np.array([0.001, -0.002, -0.03]) + a[:3] * step)
    np.testing.assert_allclose(cmd.tip_velocity_m_s, a[:3] * step / 0.02)
    np.testing.assert_allclose(cmd.force_ff_hole_N, a[3:6] * dec["force_ff_step_N"])
    assert cmd.k_xy_N_m == 50.0 and cmd.k_rot_Nm_rad == 300.0
    assert cmd.stiffness[2] == dec["k_z_N_m"]
    # feed-forward in the commanded tool frame: tool z points down, so +F_z (out) is -z_tool
    np.testing.assert_allclose(cmd.wrench_ff_tool[:3], cmd.tool_rotation.T @ cmd.force_ff_hole_N)
    np.testing.assert_array_equal(cmd.wrench_ff_tool[3:], 0.0)
    straight = DeployedPolicy(folder)
    straight.reset(commanded_tip_m=(0.0, 0.0, -0.03))
    down = straight.decode(a)
    np.testing.assert_allclose(down.wrench_ff_tool[:3], [-2.0, 0.0, 2.0])  # tool x, z reversed
    np.testing.assert_allclose(down.compliance_centre_target_m, down.tip_target_m)  # L_C = 0
    again = p.decode(a)
    np.testing.assert_array_equal(again.tool_rotation, cmd.tool_rotation)
    assert again.step == 2


def test_a_nan_reading_is_refused_and_changes_nothing(exports):
    folder = exports("rect")
    pos, tilt = [0.0, 1e-4, 0.06], [0.0, 0.0, 0.0]
    wrench = [0.2, 0.1, 2.0, 0.0, 0.0, 0.0]
    p, fresh = DeployedPolicy(folder), DeployedPolicy(folder)
    for q in (p, fresh):
        q.reset(commanded_tip_m=(0.0, 0.0, -0.03))
    with pytest.raises(SensorError, match="wrench_N_Nm holds NaN.*keeps its last command"):
        p.act([0.2, np.nan, 2.0, 0.0, 0.0, 0.0], pos, tilt)
    with pytest.raises(SensorError, match="flange_tilt_rad holds NaN or infinity"):
        p.act(wrench, pos, [0.0, np.inf, 0.0])
    a, b = p.act(wrench, pos, tilt), fresh.act(wrench, pos, tilt)
    assert a.step == b.step == 1  # the refused readings left no trace
    np.testing.assert_array_equal(a.action, b.action)
    np.testing.assert_array_equal(a.tip_target_m, b.tip_target_m)


def test_a_wrong_observation_size_is_refused_in_one_line(exports):
    p = DeployedPolicy(exports("rect"))
    n = load_policy("rect").meta["network"]["observation_size"]
    assert p.observation_size == n != 15
    with pytest.raises(UserInputError, match=rf"shape \(15,\): this policy takes {n} numbers") as e:
        p.act_obs(np.zeros(15, np.float32))
    assert "\n" not in str(e.value)
    with pytest.raises(SensorError, match="NaN"):
        p.act_obs(np.full(n, np.nan, np.float32))
    with pytest.raises(SensorError, match="wrench_N_Nm must be 6 numbers"):
        p.reset(commanded_tip_m=(0, 0, 0))
        p.act(wrench_N_Nm=[1.0, 2.0, 3.0], flange_pos_m=[0, 0, 0], flange_tilt_rad=[0, 0, 0])


def test_act_before_reset_is_refused(exports):
    p = DeployedPolicy(exports("rect"))
    with pytest.raises(UserInputError, match="call reset"):
        p.act(wrench_N_Nm=[0] * 6, flange_pos_m=[0, 0, 0], flange_tilt_rad=[0, 0, 0])


def test_an_export_of_another_format_version_is_refused(exports, tmp_path):
    folder = tmp_path / "old"
    shutil.copytree(exports("rect"), folder)
    spec = json.loads((folder / "action.json").read_text())
    spec["format_version"] = 2
    (folder / "action.json").write_text(json.dumps(spec))
    with pytest.raises(UserInputError, match="export format 2, this peghole_mjx reads format 1"):
        DeployedPolicy(folder)
    with pytest.raises(UserInputError, match="not an exported policy"):
        DeployedPolicy(tmp_path)


def test_a_damaged_export_is_refused_in_one_line(exports, tmp_path):
    folder = tmp_path / "damaged"
    shutil.copytree(exports("rect"), folder)
    spec = json.loads((folder / "action.json").read_text())
    del spec["decode"]["tip_step_m"]
    (folder / "action.json").write_text(json.dumps(spec))
    with pytest.raises(CorruptFileError, match="action.json is damaged.*tip_step_m") as e:
        DeployedPolicy(folder)
    assert "\n" not in str(e.value)
    shutil.copy(exports("rect") / "action.json", folder / "action.json")
    data = (folder / "policy.onnx").read_bytes()
    (folder / "policy.onnx").write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptFileError, match="policy.onnx cannot be loaded"):
        DeployedPolicy(folder)


# ---------------------------------------------------------------------- peghole export refusals
def test_export_refuses_an_unknown_policy(tmp_path, capsys):
    rc, _, err = peghole(["export", "no_such_policy", "--out", tmp_path / "x"], capsys)
    assert rc == 2
    assert_one_line(err, "no policy at no_such_policy")
    assert not (tmp_path / "x").exists()


def test_export_refuses_a_non_empty_out_without_force(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    rc, _, err = peghole(["export", "rect", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, "exists and is not empty", "--force")
    rc, _, err = peghole(["export", "rect", "--out", out, "--force"], capsys)
    assert rc == 2  # --force replaces an earlier export only, never other files
    assert_one_line(err, "not an export")
    assert (out / "notes.txt").read_text() == "mine"


def test_export_refuses_an_unwritable_out(tmp_path, capsys):
    ro = tmp_path / "parent"
    ro.mkdir()
    (ro / "f").write_text("")
    rc, _, err = peghole(["export", "rect", "--out", ro / "f" / "sub"], capsys)
    assert rc == 2
    assert_one_line(err, "--out", "is an existing file, not a folder")
    # a folder that refuses writes even to root (a real write is tried: a probe file)
    rc, _, err = peghole(["export", "rect", "--out", "/proc/peghole_export"], capsys)
    assert rc == 2
    assert_one_line(err, "--out /proc: the folder is not writable")


def test_export_force_replaces_an_earlier_export(exports, tmp_path, capsys):
    out = tmp_path / "again"
    shutil.copytree(exports("rect"), out)
    (out / "stale.txt").write_text("old")  # a file of the user's: --force refuses, keeps it
    rc, stdout, err = peghole(["export", "dual", "--out", out, "--force"], capsys)
    assert rc == 2 and "stale.txt" in err and len(err.strip().splitlines()) == 1
    assert (out / "stale.txt").read_text() == "old"
    (out / "stale.txt").unlink()
    rc, stdout, err = peghole(["export", "dual", "--out", out, "--force"], capsys)
    assert rc == 0, err
    assert "ONNX Runtime vs JAX actions differ by at most" in stdout
    assert json.loads((out / "action.json").read_text())["policy"]["env"] == "DualExtract"
    dual = load_policy("dual").meta["network"]["observation_size"]
    assert DeployedPolicy(out).observation_size == dual
