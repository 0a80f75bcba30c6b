"""Env config values, rollouts and the Gymnasium adapter: bad input ends in one clear line
(exit 2) before any model is built or compiled, and a rollout with nothing but NaN worlds is
a failure with its likely cause, not a result (docs/guide/reliability.md).

Cheap by design: the refusals happen when the env config is built (no scene, no JAX
compilation); the all-NaN rollout is injected by replacing the batched run with one whose
worlds all went NaN; the Gymnasium adapters are driven by a stand-in env of a few lines (the
adapters' logic, not the physics; tests/test_gym.py runs them on the real env).
"""

from __future__ import annotations

import json
import math
import types
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import RANGES
from peghole_mjx.envs import base as env_base
from peghole_mjx.envs import rollout as rollout_mod
from peghole_mjx.envs.config import FLAGS, OPTIONAL, TEXT, TUPLES, apply_overrides, leaves
from peghole_mjx.envs.metrics import EPISODE_RECORD
from peghole_mjx.geometry.specs import PRESETS, get_preset

ROLLOUT = ["envs", "rollout", "--env", "RectExtract", "--policy", "scripted", "--episodes", 4]


@pytest.fixture
def no_model(monkeypatch):
    """Building a scene (the step before any compilation) fails the test."""

    def built(*a, **k):
        raise AssertionError("a model was built for a refused env config")

    monkeypatch.setattr(env_base, "build_scene", built)


# ---------------------------------------------------------------------- 1. config values
@pytest.mark.parametrize(
    "override, needles",
    [
        # the cases
        ("success_margin_mm=-1000", ["success_margin_mm", "> 0"]),
        ("jam_force_N=-1", ["jam_force_N", "> 0"]),
        ("stiffness.k_z_N_m=-100", ["stiffness.k_z_N_m", "> 0"]),
        ("randomization.hole_xy_mm=1e6", ["randomization.hole_xy_mm", "<= 100", "IK reach"]),
        ("obs.force_scale_N=0", ["obs.force_scale_N", "> 0"]),
        ("stiffness.damping_ratio=-1", ["stiffness.damping_ratio", ">= 0.1"]),
        ("contact_cap=1e9", ["contact_cap", "<= 10000"]),
        ("limits=1e30", ["limits is a group", "limits.max_force_N"]),
        ("limits.max_force_N=[1e30, 20, 60]", ["limits.max_force_N", "<= 500"]),
        ("episode_length=true", ["episode_length", "not true or false"]),
        # more of the same kinds
        ("success_margin_mm=true", ["success_margin_mm", "not true or false"]),
        ("episode_length=0", ["episode_length", ">= 1"]),
        ("episode_length=2.5", ["episode_length"]),
        ("jam_time_s=0", ["jam_time_s", "> 0"]),
        ("stiffness.k_xy_N_m=1e5", ["stiffness.k_xy_N_m", "<= 5000", "iiwa"]),
        ("stiffness.k_rot_Nm_rad=301", ["stiffness.k_rot_Nm_rad", "<= 300"]),
        ("stiffness.compliance_centre_mm=200", ["compliance_centre_mm", "150 mm"]),
        ("stiffness.k_xy_min_N_m=1200", ["min <= max"]),
        ('stiffness={"k_z_N_m": 5}', ["stiffness is a group"]),
        ("contact_cap=100", ["contact_cap", "at most 80", "measured maximum of 20"]),
        ("contact_cap=10", ["below the measured maximum of 20"]),
        ("reward_config.w_d=-1", ["reward_config.w_d", ">= 0"]),
        ("reward_config.r_failure=1", ["reward_config.r_failure", "<= 0"]),
        ("reward_config.force_scale_N=0", ["reward_config.force_scale_N", "> 0"]),
        ("action.max_speed_m_s=0", ["action.max_speed_m_s", "never move"]),
        ("ctrl_dt=0.005", ["whole multiple of sim_dt"]),
        ("sim_dt=1", ["sim_dt", "<= 0.01"]),
        ("randomization.friction_scale=[1.2, 0.8]", ["friction_scale", "lo <= hi"]),
        ("randomization.stiffness_N_m=[0, 1e9]", ["randomization.stiffness_N_m", "<= 5000"]),
        ("randomization.angular_error_deg=90", ["angular_error_deg", "<= 30"]),
        ("obs.torques=1", ["obs.torques", "true or false"]),
        ("representation=5", ["representation", "text"]),
        ('geometry={"peg_w_mm": true}', ["geometry", "peg_w_mm must be a number"]),
        ('geometry={"peg_w_mm": [59]}', ["geometry", "peg_w_mm must be a number"]),
        ("geometry=5", ["geometry"]),
        ("mujoco_threads=-1", ["mujoco_threads", ">= 0"]),
        ("naconmax=0", ["naconmax", ">= 1"]),
    ],
)
def test_nonsense_env_config_is_refused_naming_the_key_before_any_model(
    capsys, no_model, override, needles
):
    rc, out, err = peghole([*ROLLOUT, "--set", override], capsys)
    assert rc == 2, err
    assert_one_line(err, *needles)
    assert out == "" and "internal error" not in err


def test_dual_geometry_radii_are_lists_of_two_numbers(no_model):
    dual = envs.get_default_config("DualExtract")
    for bad in ([6.0], [6.0, True], 6.0):
        with pytest.raises(UserInputError, match="peg_radii_mm must be a list of 2 numbers"):
            apply_overrides(dual, {"geometry": {"peg_radii_mm": bad}})
    good = apply_overrides(dual, {"geometry": {"peg_radii_mm": [5.9, 5.9]}})
    assert json.loads(good.geometry) == {"peg_radii_mm": [5.9, 5.9]}


def _numeric_leaves(name: str):
    for key, value in leaves(envs.get_default_config(name)):
        if key not in FLAGS and key not in TEXT:
            yield key, value


@pytest.mark.parametrize("name", envs.ALL_ENVS)
def test_every_numeric_env_config_entry_has_a_range_that_holds_its_default(name):
    """Walk the whole env config: every entry is a flag, text, or a number (or numbers) with
    its range in validation.RANGES ("env.<key>"), and the default lies in it."""
    config = envs.get_default_config(name)
    for key, value in leaves(config):
        if key in FLAGS:
            assert isinstance(value, bool), key
            continue
        if key in TEXT:
            assert (value is None and key in OPTIONAL) or isinstance(value, str), key
            continue
        assert f"env.{key}" in RANGES, f"env config entry {key} has no range in RANGES"
        if value is None:
            assert key in OPTIONAL, key
            continue
        rng = RANGES[f"env.{key}"]
        values = value if key in TUPLES else (value,)
        assert key not in TUPLES or len(value) == TUPLES[key], key
        for v in values:
            assert rng.problem(v) is None, (key, v)
    # and no range of an entry that is not there (a renamed entry would lose its check)
    keys = {k for k, _ in leaves(config)}
    stale = {k[4:] for k in RANGES if k.startswith("env.")} - keys
    assert not stale, stale


def _outside(rng):
    """Values just outside ``rng`` on each bounded side."""
    out = []
    if rng.lo is not None:
        out.append(rng.lo - 1 if rng.integer else rng.lo - max(1e-3, abs(rng.lo) * 0.01))
    if rng.hi is not None:
        out.append(rng.hi + 1 if rng.integer else rng.hi * 1.01 + 1e-3)
    return out


@pytest.mark.parametrize("key", sorted(dict(_numeric_leaves("RectExtract"))))
def test_every_numeric_entry_refuses_values_outside_its_range(key, no_model):
    """Each bound of each entry is enforced when the config is built, naming the entry."""
    rng = RANGES[f"env.{key}"]
    default = envs.get_default_config("RectExtract")
    for v in _outside(rng):
        value = (v,) * TUPLES[key] if key in TUPLES else v
        with pytest.raises(UserInputError, match=key.replace(".", r"\.")) as err:
            apply_overrides(default, {key: value})
        assert "\n" not in str(err.value)
    for bad in (math.nan, True):
        value = (bad,) * TUPLES[key] if key in TUPLES else bad
        with pytest.raises(UserInputError):
            apply_overrides(default, {key: value})


def test_shipped_configs_profiles_presets_and_policies_pass_the_ranges():
    """The defaults of every env, every preset of its kind, every training profile's env
    overrides (train/configs) and every published policy's env (peghole_mjx/policies)."""
    from peghole_mjx.training.config import CONFIG_DIR, PROFILES, load_train_config

    for name in envs.ALL_ENVS:
        default = envs.get_default_config(name)
        apply_overrides(default, None)
        kind = get_preset(default.preset).kind
        for preset in (p for p, s in PRESETS.items() if s.kind == kind):
            apply_overrides(default, {"preset": preset})
        for representation in ("box", "edges") if kind == "rect" else ("capsule", "mesh"):
            apply_overrides(default, {"representation": representation})
    profiles = 0
    for path in sorted(Path(CONFIG_DIR).glob("*.json")):
        for profile in PROFILES:
            if profile not in json.loads(path.read_text())["profiles"]:
                continue
            tc = load_train_config(path.stem, profile)
            if tc.env in envs.TASK_ENVS:  # its parts come from --set env.task=DIR
                with pytest.raises(UserInputError, match="needs a task folder"):
                    apply_overrides(envs.get_default_config(tc.env), tc.env_overrides)
                continue
            apply_overrides(envs.get_default_config(tc.env), tc.env_overrides)
            profiles += 1
    assert profiles >= 12
    policies = sorted(Path(envs.__file__).parents[1].glob("policies/*/policy.json"))
    assert len(policies) == 4
    for path in policies:
        meta = json.loads(path.read_text())
        apply_overrides(envs.get_default_config(meta["env"]), meta["env_overrides"])


def test_overrides_leave_the_given_config_as_it_was():
    """apply_overrides returns a changed copy: the config passed in (e.g. a built env's) is
    not changed through shared groups, also when an override is refused half-way."""
    config = envs.get_default_config("RectExtract")
    before = config.to_dict()
    changed = apply_overrides(config, {"stiffness.k_z_N_m": 3000.0, "episode_length": 1e3})
    assert changed.stiffness.k_z_N_m == 3000.0 and changed.episode_length == 1000
    with pytest.raises(UserInputError):
        apply_overrides(config, {"stiffness.k_z_N_m": 100.0, "stiffness.damping_ratio": -1.0})
    assert config.to_dict() == before


def test_overrides_must_be_a_mapping():
    with pytest.raises(UserInputError, match="must be a mapping"):
        envs.load("RectExtract", config_overrides=[("episode_length", 10)])


# ---------------------------------------------------------------------- 2. all-NaN rollouts
def _nan_slice(calls):
    def fake(env, policy, reset_keys, rng, chunk, params, gamma, progress, desc):
        calls.append(reset_keys.shape[0])
        n = reset_keys.shape[0]
        rec = {k: np.zeros(n, np.float32) for k in EPISODE_RECORD}
        rec["nan"][:] = 1.0
        rec["failure"][:] = 1.0
        return rec, 0.0, 0.0, 0

    return fake


def test_a_rollout_with_every_world_nan_is_a_failure_naming_the_likely_cause(capsys, monkeypatch):
    calls = []
    monkeypatch.setattr(rollout_mod, "_rollout_slice", _nan_slice(calls))
    rc, out, err = peghole([*ROLLOUT, "--set", "stiffness.k_z_N_m=4000", "--json"], capsys)
    assert calls == [4]  # the run happened (injected), then was refused
    assert rc == 2
    assert_one_line(err, "all 4 episodes ended in a non-finite (NaN) world", "likely cause")
    assert "stiffness.k_z_N_m=4000.0" in err and "engine" not in err
    assert out == ""  # no result printed, no success rate of NaN worlds


def test_all_nan_rollout_names_nan_parameters_and_a_partial_nan_is_a_result(monkeypatch):
    env = envs.load("RectExtract", config_overrides={"representation": "box"})
    monkeypatch.setattr(rollout_mod, "_rollout_slice", _nan_slice([]))
    policy = lambda params, obs, rng: obs[..., : env.action_size]  # noqa: E731
    with pytest.raises(UserInputError, match="policy's parameters are not finite"):
        rollout_mod.rollout(env, policy, 3, params={"w": jnp.array([1.0, jnp.nan])})
    # at the env's defaults (representation aside) the policy's actions are named
    with pytest.raises(UserInputError, match="representation='box'"):
        rollout_mod.rollout(env, policy, 3, params={"w": jnp.ones(2)})
    default_env = envs.load("RectExtract")
    with pytest.raises(UserInputError, match="the policy's actions"):
        rollout_mod.rollout(default_env, policy, 3, params={"w": jnp.ones(2)})
    # callers that want the NaN worlds themselves
    res = rollout_mod.rollout(env, policy, 3, params={"w": jnp.ones(2)}, refuse_all_nan=False)
    assert res.summary().nan_worlds == 3

    def some_nan(*a, **k):
        rec, *rest = _nan_slice([])(*a, **k)
        rec["nan"][0] = 0.0
        return rec, *rest

    monkeypatch.setattr(rollout_mod, "_rollout_slice", some_nan)
    assert rollout_mod.rollout(env, policy, 3, params={"w": jnp.ones(2)}).summary().nan_worlds == 2


# ---------------------------------------------------------------------- 3. Gymnasium adapter
class _StandIn:
    """A stand-in env (no physics): obs = [step, sum of actions, 0]; the episode terminates
    when action[0] > 0.5 (a success) and is truncated at ``episode_length``; the reward is the
    native env's end term (+1 / -1) on the last step, else 0.5."""

    observation_size = 3
    action_size = 6

    def __init__(self, episode_length=3):
        self.config = types.SimpleNamespace(episode_length=episode_length)
        self.steps_simulated = 0

    def _state(self, step, total, success, done, reward):
        from peghole_mjx.gym import INFO_KEYS

        metrics = {k: jnp.zeros(()) for k in (*INFO_KEYS, "overflow")}
        metrics["success"] = success
        obs = jnp.stack([step.astype(jnp.float32), total, jnp.zeros(())])
        return envs.State(total, obs, reward, done, metrics, {"step": step})

    def reset(self, rng):
        z = jnp.zeros(())
        return self._state(jnp.zeros((), jnp.int32), z, z, z, z)

    def step(self, state, action):
        step = state.info["step"] + 1
        success = (action[0] > 0.5).astype(jnp.float32)
        timeout = (step >= self.config.episode_length).astype(jnp.float32)
        done = jnp.maximum(success, timeout)
        reward = jnp.where(success > 0, 1.0, jnp.where(timeout > 0, -1.0, 0.5))
        return self._state(step, state.data + action.sum(), success, done, reward)


@pytest.fixture
def stand_in(monkeypatch):
    made = []

    def load(name, config_overrides=None):
        made.append(name)
        return _StandIn()

    monkeypatch.setattr(envs, "load", load)
    return made


def test_single_env_refuses_to_step_an_ended_episode(stand_in):
    from peghole_mjx.gym import PegHoleGymEnv

    env = PegHoleGymEnv("RectExtract")
    zero = np.zeros(6, np.float32)
    with pytest.raises(UserInputError, match="call reset"):
        env.step(zero)
    env.reset(seed=0)
    rewards = []
    for _ in range(3):
        obs, reward, terminated, truncated, _ = env.step(zero)
        rewards.append(reward)
    assert (terminated, truncated) == (False, True) and rewards == [0.5, 0.5, -1.0]
    # truncated: no more simulation, no second terminal reward
    for _ in range(2):
        with pytest.raises(UserInputError, match=r"episode has ended \(truncated\)"):
            env.step(zero)
    assert obs[0] == 3.0 and float(env._state.info["step"]) == 3
    # terminated likewise; reset starts a new episode
    env.reset(seed=1)
    success = np.array([1, 0, 0, 0, 0, 0], np.float32)
    _, reward, terminated, truncated, _ = env.step(success)
    assert (reward, terminated, truncated) == (1.0, True, False)
    with pytest.raises(UserInputError, match=r"episode has ended \(terminated\)"):
        env.step(zero)
    obs, _ = env.reset(seed=2)
    assert obs[0] == 0.0
    assert env.step(zero)[1] == 0.5


@pytest.mark.parametrize(
    "action, needle",
    [
        (np.array([1j, 0, 0, 0, 0, 0]), "dtype complex128"),
        (np.ones(6, np.complex64), "dtype complex64"),
        (np.ones(6, bool), "dtype bool"),
        (["a"] * 6, "dtype <U1"),
        ([0.1, None, 0, 0, 0, 0], "dtype object"),
        ([[0.1, 0.2], [0.3]], "shape"),
        (np.zeros(5, np.float32), r"shape \(6,\)"),
        (np.zeros((1, 6), np.float32), r"shape \(6,\)"),
        (0.5, r"shape \(6,\)"),
    ],
)
def test_single_env_checks_action_dtype_and_shape(stand_in, action, needle):
    from peghole_mjx.gym import PegHoleGymEnv

    env = PegHoleGymEnv("RectExtract")
    env.reset(seed=0)
    with pytest.raises(UserInputError, match=needle):
        env.step(action)
    assert float(env._state.info["step"]) == 0  # nothing was simulated
    # real numbers of other dtypes are fine (integers, float64)
    env.step(np.zeros(6, np.int64))
    env.step(np.zeros(6, np.float64))
    assert float(env._state.info["step"]) == 2


def test_vector_env_checks_actions_and_autoresets_as_documented(stand_in):
    from peghole_mjx.gym import PegHoleVectorEnv

    env = PegHoleVectorEnv("RectExtract", num_envs=2)
    env.reset(seed=0)
    for bad, needle in (
        (np.ones((2, 6), np.complex128), "dtype complex128"),
        (np.zeros((6,), np.float32), r"shape \(2, 6\)"),
        (np.zeros((2, 6), object), "dtype object"),
    ):
        with pytest.raises(UserInputError, match=needle):
            env.step(bad)
    zero = np.zeros((2, 6), np.float32)
    for _ in range(3):
        _, reward, terminated, truncated, _ = env.step(zero)
    assert truncated.all() and not terminated.any() and np.all(reward == -1.0)
    # NEXT_STEP autoreset: the step after the end starts a new episode, reward 0
    obs, reward, terminated, truncated, _ = env.step(zero)
    np.testing.assert_array_equal(reward, 0.0)
    assert not truncated.any() and np.all(obs[:, 0] == 0.0)
    _, reward, _, truncated, _ = env.step(zero)
    np.testing.assert_array_equal(reward, 0.5)


@pytest.mark.parametrize("num_envs", [True, False, 2.7, 0, -1, "2", None, 1 << 21])
def test_vector_env_num_envs_must_be_a_whole_number_of_worlds(stand_in, num_envs):
    from peghole_mjx.gym import PegHoleVectorEnv

    with pytest.raises(UserInputError, match="num_envs must be an integer"):
        PegHoleVectorEnv("RectExtract", num_envs=num_envs)
    assert stand_in == []  # refused before the env is built
    assert PegHoleVectorEnv("RectExtract", num_envs=2.0).num_envs == 2


def test_a_rollout_batch_beyond_memory_is_refused_before_it_runs(capsys, monkeypatch):
    from peghole_mjx.core import memory

    calls = []
    monkeypatch.setattr(rollout_mod, "_rollout_slice", _nan_slice(calls))
    monkeypatch.setattr(memory, "host_available_bytes", lambda: 10_000)  # 10 kB free
    rc, out, err = peghole([*ROLLOUT, "--json"], capsys)
    assert rc == 2 and calls == [] and out == ""  # refused before the first slice
    assert_one_line(err, "a rollout batch (4 worlds of", "more than the host memory", "--batch")


@pytest.mark.parametrize(
    "name, overrides",
    [
        ("RectExtract", {"engine": "mjx"}),
        ("DualExtract", {"engine": "mjx", "representation": "mesh"}),
    ],
)
def test_the_world_ceiling_bounds_the_built_in_worlds(name, overrides):
    """The shortcut of ``memory.check_worlds`` is sound only while every built-in world is
    well below its ceiling (rect's box scene and dual's mesh scene are the largest)."""
    from peghole_mjx.core import memory

    env = envs.load(name, config_overrides=overrides)
    assert 0 < memory.world_bytes(env) < memory.WORLD_CEILING_BYTES / 10
