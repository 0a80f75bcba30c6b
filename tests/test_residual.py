"""Residual actions (``action.residual``): the pull is the scripted 20 mm/s plus
``action.residual_scale`` x its action, the compliance gains are the action's own, the lateral
offset and feed-forward increments are held at 0. The decoding, a MuJoCo C rollout and an
exported policy's deployment all equal the plain env driven by the mapped action."""

from __future__ import annotations

import json
import shutil

import jax
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
A = np.array([1.0, -0.5, 0.8, 1.0, 0.3, -1.0, -0.6, 0.4], np.float32)


def _load(overrides):
    return envs.load("RectExtract", config_overrides=overrides)


def _mapped(a, scale=0.25):
    """The plain env's action that a residual env applies for ``a``."""
    out = np.zeros_like(a)
    out[2] = min(0.8 + scale * a[2], 1.0)  # the scripted 20 mm/s is 0.8 of 25 mm/s
    out[6:] = a[6:]
    return out


def _info():
    return {
        "hole_mat": jnp.eye(3),
        "cmd_tip": jnp.array([1e-4, -2e-4, -0.03]),
        "wrench_ff": jnp.array([0.5, -0.5, 2.0]),
        "k_xy": 111.0,
        "k_rot": 22.0,
        "L_C": 0.01,
    }


@pytest.mark.parametrize("a", [np.zeros(8, np.float32), A, -A])
def test_a_residual_env_decodes_as_the_plain_env_of_the_mapped_action(a):
    plain, res = _load(CS), _load(RESIDUAL)
    ca = res.compliance_actions
    want = extraction.decode_action(jnp.asarray(_mapped(a)), _info(), plain.config, ca)
    got = extraction.decode_action(jnp.asarray(a), _info(), res.config, ca)
    for w, g in zip(want, got, strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    # the integrators are held: the commanded tip moves along the hole axis only, the
    # feed-forward stays where it was
    np.testing.assert_array_equal(np.asarray(got[0][:2]), np.asarray(_info()["cmd_tip"][:2]))
    np.testing.assert_array_equal(np.asarray(got[1]), np.asarray(_info()["wrench_ff"]))


def test_the_scripted_policy_of_a_residual_env_applies_the_scripted_pull():
    plain, res = _load(CS), _load(RESIDUAL)
    a = np.asarray(scripted_policy(res)(None, None))
    np.testing.assert_array_equal(a[:6], 0.0)  # the pull's residual is 0 at 20 mm/s
    np.testing.assert_array_equal(a[6:], np.asarray(scripted_policy(plain)(None, None))[6:])
    slower = np.asarray(scripted_policy(res, 0.018)(None, None))
    np.testing.assert_allclose(slower[2], -0.32, rtol=1e-5)  # (0.72 - 0.8) / 0.25
    with pytest.raises(UserInputError, match="0.005 m/s is beyond this residual env's reach"):
        scripted_policy(res, 0.005)


def test_a_residual_scale_out_of_range_is_refused_naming_the_entry():
    with pytest.raises(UserInputError, match="action.residual_scale must be > 0"):
        _load({**RESIDUAL, "action.residual_scale": 0.0})
    with pytest.raises(UserInputError, match="action.residual must be true or false"):
        _load({**RESIDUAL, "action.residual": "yes"})


def test_a_residual_rollout_on_mujoco_c_equals_the_plain_env_of_the_mapped_action():
    """4 episodes (same keys) of the scripted pull and of a constant residual: every
    per-episode record equal, bit for bit."""
    plain, res = _load(CS), _load(RESIDUAL)
    for plain_policy, res_policy in (
        (scripted_policy(plain), scripted_policy(res)),
        (lambda o, r: jnp.asarray(_mapped(A)), lambda o, r: jnp.asarray(A)),
    ):
        a = rollout(plain, plain_policy, 4, seed=3, progress=False, chunk=50)
        b = rollout(res, res_policy, 4, seed=3, progress=False, chunk=50)
        assert a.per_episode["success"].sum() == 4  # both pulls extract these episodes
        for key, value in a.per_episode.items():
            np.testing.assert_array_equal(b.per_episode[key], value, err_msg=key)


def test_a_deployed_residual_policy_decodes_as_the_env(tmp_path):
    """The export's ``decode.residual`` makes the deployment apply the env's affine map: the
    published rect policy (a residual one since 2026-12-06) against a copy of its export with
    the entry removed (the plain decoding) driven by the mapped action."""
    res = DeployedPolicy(export_policy("rect", tmp_path / "residual")["out"])
    folder = tmp_path / "plain"
    shutil.copytree(res.folder, folder)
    spec = json.loads((folder / "action.json").read_text())
    assert spec["decode"]["residual"] == _residual_spec(_load(RESIDUAL))
    assert spec["decode"]["residual"]["gain"] == [0, 0, 0.25, 0, 0, 0, 1, 1]
    residual = spec["decode"]["residual"]
    spec["decode"]["residual"] = None
    (folder / "action.json").write_text(json.dumps(spec))
    plain = DeployedPolicy(folder)
    for p in (plain, res):
        p.reset(commanded_tip_m=(0.001, -0.002, -0.03))
    got, want = res.decode(A), plain.decode(_mapped(A))
    np.testing.assert_array_equal(got.tip_target_m, want.tip_target_m)
    np.testing.assert_array_equal(got.force_ff_hole_N, want.force_ff_hole_N)
    assert (got.k_xy_N_m, got.k_rot_Nm_rad) == (want.k_xy_N_m, want.k_rot_Nm_rad)
    spec["decode"]["residual"] = {**residual, "offset": [2.0] * len(A)}
    (folder / "action.json").write_text(json.dumps(spec))
    with pytest.raises(CorruptFileError, match=r"residual.offset must be 8 numbers in \[-1"):
        DeployedPolicy(folder)


def test_a_residual_policy_starts_at_a_zero_action():
    """zero_action_mean: the deterministic action is 0 on any observation (the scripted
    pull's speed, mid-range gains), the exploration scale as drawn."""
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
