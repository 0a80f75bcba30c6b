"""Residual actions (``action.residual``): the step applies the scripted pull plus
``action.residual_scale`` x the policy's action. A zero residual is the scripted baseline,
bit for bit, in the decoding, in a MuJoCo C rollout and in an exported policy's deployment."""

from __future__ import annotations

import json
import shutil

import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.deploy import DeployedPolicy
from peghole_mjx.envs import extraction
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.policies.export import _residual_spec, export_policy

#: the learning benchmark's RectExtract settings (its ``cpu`` profile's env overrides)
CS = {"compliance_strategy": True, "action.max_speed_m_s": 0.025, "engine": "mujoco"}
RESIDUAL = {**CS, "action.residual": True}


def _info():
    return {
        "hole_mat": jnp.eye(3),
        "cmd_tip": jnp.array([1e-4, -2e-4, -0.03]),
        "wrench_ff": jnp.array([0.5, -0.5, 2.0]),
        "k_xy": 111.0,
        "k_rot": 22.0,
        "L_C": 0.01,
    }


def test_a_zero_residual_decodes_to_the_scripted_pull():
    plain, res = (
        envs.load("RectExtract", config_overrides=CS),
        envs.load("RectExtract", config_overrides=RESIDUAL),
    )
    ca = res.compliance_actions
    want = extraction.decode_action(
        jnp.asarray(extraction.scripted_action(plain.config, ca)), _info(), plain.config, ca
    )
    got = extraction.decode_action(jnp.zeros(res.action_size), _info(), res.config, ca)
    for w, g in zip(want, got, strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    # a residual moves the command by residual_scale of the plain action's step
    a = jnp.array([1.0, -1.0, 1.0, 0.5, 0.0, -0.5, 0.0, 0.0])
    tip = extraction.decode_action(a, _info(), res.config, ca)[0]
    step_xy = res.config.action.max_step_offset_mm * 1e-3 * 0.25
    np.testing.assert_allclose(np.asarray(tip - want[0])[:2], [step_xy, -step_xy], rtol=1e-5)
    # the pull's residual is clipped at the plain action's bound: 0.8 + 0.25 -> 1, not more
    dz_full = res.config.action.max_speed_m_s * res.config.ctrl_dt
    assert float(tip[2] - _info()["cmd_tip"][2]) == pytest.approx(dz_full, rel=1e-5)


def test_the_scripted_policy_of_a_residual_env_is_its_zero_residual():
    res = envs.load("RectExtract", config_overrides=RESIDUAL)
    np.testing.assert_array_equal(np.asarray(scripted_policy(res)(None, None)), 0.0)
    slower = np.asarray(scripted_policy(res, 0.018)(None, None))
    np.testing.assert_allclose(slower[2], -0.32, rtol=1e-5)  # (0.72 - 0.8) / 0.25
    with pytest.raises(UserInputError, match="0.005 m/s is beyond this residual env's reach"):
        scripted_policy(res, 0.005)


def test_a_residual_scale_of_zero_is_refused_naming_the_entry():
    with pytest.raises(UserInputError, match="action.residual_scale must be > 0"):
        envs.load("RectExtract", config_overrides={**RESIDUAL, "action.residual_scale": 0.0})
    with pytest.raises(UserInputError, match="action.residual must be true or false"):
        envs.load("RectExtract", config_overrides={**RESIDUAL, "action.residual": "yes"})


def test_a_zero_residual_rolls_out_the_scripted_baseline_on_mujoco_c():
    """4 episodes (same keys): every per-episode record equal, bit for bit."""
    plain, res = (
        envs.load("RectExtract", config_overrides=CS),
        envs.load("RectExtract", config_overrides=RESIDUAL),
    )
    a = rollout(plain, scripted_policy(plain), 4, seed=3, progress=False, chunk=50)
    b = rollout(res, scripted_policy(res), 4, seed=3, progress=False, chunk=50)
    assert a.per_episode.keys() == b.per_episode.keys()
    assert a.per_episode["success"].sum() == 4  # the scripted pull extracts these
    for key, value in a.per_episode.items():
        np.testing.assert_array_equal(b.per_episode[key], value, err_msg=key)


def test_a_deployed_residual_policy_decodes_as_the_env(tmp_path):
    """The export's ``decode.residual`` makes the deployment apply base + scale x action."""
    plain = DeployedPolicy(export_policy("rect", tmp_path / "plain")["out"])
    spec_env = envs.load(
        "RectExtract", config_overrides={**RESIDUAL, "action.residual_scale": 0.25}
    )
    folder = tmp_path / "residual"
    shutil.copytree(plain.folder, folder)
    spec = json.loads((folder / "action.json").read_text())
    assert spec["decode"]["residual"] is None  # the published policy is not residual
    spec["decode"]["residual"] = _residual_spec(spec_env)
    (folder / "action.json").write_text(json.dumps(spec))
    res = DeployedPolicy(folder)
    a = np.array([1.0, -0.5, 0.8, 1.0, 0.0, -1.0, -1.0, 1.0])
    applied = np.clip(np.asarray(spec["decode"]["residual"]["base"]) + 0.25 * a, -1, 1)
    for p in (plain, res):
        p.reset(commanded_tip_m=(0.001, -0.002, -0.03))
    got, want = res.decode(a), plain.decode(applied)
    np.testing.assert_array_equal(got.tip_target_m, want.tip_target_m)
    np.testing.assert_array_equal(got.force_ff_hole_N, want.force_ff_hole_N)
    assert (got.k_xy_N_m, got.k_rot_Nm_rad) == (want.k_xy_N_m, want.k_rot_Nm_rad)
    spec["decode"]["residual"]["base"] = [2.0] * len(a)
    (folder / "action.json").write_text(json.dumps(spec))
    with pytest.raises(CorruptFileError, match=r"decode.residual.base must be 8 numbers in \[-1"):
        DeployedPolicy(folder)


def test_a_residual_policy_starts_as_the_scripted_pull():
    """zero_action_mean: the deterministic action is 0 on any observation, the exploration
    scale as drawn."""
    import jax
    from brax.training.acme import running_statistics, specs
    from brax.training.agents.sac import networks as sac_networks

    from peghole_mjx.training.sac import zero_action_mean

    nets = sac_networks.make_sac_networks(9, 8, hidden_layer_sizes=(32, 32))
    params = nets.policy_network.init(jax.random.PRNGKey(0))
    norm = running_statistics.init_state(specs.Array((9,), jnp.float32))
    obs = jax.random.normal(jax.random.PRNGKey(1), (64, 9)) * 3.0
    before = nets.policy_network.apply(norm, params, obs)
    after = nets.policy_network.apply(norm, zero_action_mean(params, 8), obs)
    assert float(jnp.abs(before[:, :8]).max()) > 0.1  # drawn weights: a bias of order 0.1-1
    np.testing.assert_array_equal(np.asarray(after[:, :8]), 0.0)
    np.testing.assert_array_equal(np.asarray(after[:, 8:]), np.asarray(before[:, 8:]))
    mode = nets.parametric_action_distribution.mode(after)
    np.testing.assert_array_equal(np.asarray(mode), 0.0)
