"""The Gymnasium adapters (peghole_mjx.gym): env checker, spaces, determinism, autoreset, SB3.

One single-world env and one two-world vector env (RectExtract, the cheap ``box`` parts, short
episodes) are built per module, so each jitted reset/step compiles once for all tests here.
They run on the ``mujoco`` engine: the adapters call the env's ``reset`` and ``step`` and never
the engine below them (an MJX graph compiles for one to two minutes per env on a 2-core CPU).
"""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.gym import INFO_KEYS, PegHoleGymEnv, PegHoleVectorEnv

pytestmark = pytest.mark.slow

N_WORLDS = 2
VECTOR_EPISODE = 4  # env steps: short, so that the autoreset test reaches the time limit
ENGINE = {"engine": "mujoco", "mujoco_threads": 1}


@pytest.fixture(scope="module")
def single():
    env = PegHoleGymEnv(
        "RectExtract", config_overrides={"representation": "box", "episode_length": 16, **ENGINE}
    )
    yield env
    env.close()


@pytest.fixture(scope="module")
def vector():
    env = PegHoleVectorEnv(
        "RectExtract",
        num_envs=N_WORLDS,
        config_overrides={"representation": "box", "episode_length": VECTOR_EPISODE, **ENGINE},
    )
    yield env
    env.close()


# the observations are unbounded in principle (normalised forces); the checker warns about it
@pytest.mark.filterwarnings("ignore:.*Box observation space m:UserWarning")
def test_single_world_env_passes_the_gymnasium_env_checker(single):
    check_env(single, skip_render_check=True)
    obs, info = single.reset(seed=0)
    assert obs.shape == (single.env.observation_size,) and obs.dtype == np.float32
    assert single.action_space.shape == (single.env.action_size,)
    obs, reward, _, _, info = single.step(np.zeros(6, np.float32))
    assert obs in single.observation_space
    assert isinstance(reward, float) and np.isfinite(reward)
    assert set(info) == set(INFO_KEYS)


def test_wrong_action_shape_is_refused(single):
    single.reset(seed=0)
    with pytest.raises(UserInputError, match=r"shape \(6,\)"):
        single.step(np.zeros(5, np.float32))


def test_vector_env_spaces_shapes_and_dtypes(vector):
    n, d = N_WORLDS, vector.env.observation_size
    assert vector.single_observation_space.shape == (d,)
    assert vector.observation_space.shape == (n, d)
    assert vector.action_space.shape == (n, vector.env.action_size)
    assert vector.observation_space.dtype == vector.action_space.dtype == np.float32
    obs, info = vector.reset(seed=1)
    assert obs.shape == (n, d) and obs.dtype == np.float32 and obs in vector.observation_space
    obs, reward, terminated, truncated, info = vector.step(vector.action_space.sample())
    assert obs.shape == (n, d) and obs.dtype == np.float32
    assert reward.shape == (n,) and reward.dtype == np.float64 and np.all(np.isfinite(reward))
    assert terminated.shape == truncated.shape == (n,) and terminated.dtype == bool
    assert all(info[k].shape == (n,) for k in INFO_KEYS)
    # the worlds start from different randomised states
    assert not np.allclose(obs[0], obs[1])


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        out += [obs, reward, terminated, truncated]
    return out


def test_vector_env_is_deterministic_for_a_fixed_seed(vector):
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (VECTOR_EPISODE + 2, *vector.action_space.shape))
    actions = actions.astype(np.float32)
    first = _rollout(vector, 7, actions)  # through an autoreset too
    again = _rollout(vector, 7, actions)
    other = _rollout(vector, 8, actions)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(first[0], other[0])


def test_vector_env_autoresets_on_the_next_step(vector):
    zero = np.zeros(vector.action_space.shape, np.float32)
    first, _ = vector.reset(seed=2)
    for t in range(VECTOR_EPISODE):
        obs, reward, terminated, truncated, _ = vector.step(zero)
        # holding still: no success, no jam, so each episode ends at the time limit only
        assert not terminated.any()
        assert truncated.all() == (t == VECTOR_EPISODE - 1)
    assert np.all(reward < 0)  # the time-limit step keeps eq (4.4)'s failure term
    obs, reward, terminated, truncated, _ = vector.step(zero)  # the reset step
    np.testing.assert_array_equal(reward, 0.0)
    assert not terminated.any() and not truncated.any()
    assert not np.allclose(obs, first)  # a new randomised start, not a cached one
    obs, reward, terminated, truncated, _ = vector.step(zero)
    assert np.all(reward != 0.0) and not truncated.any()


def test_stable_baselines3_sac_trains_on_the_single_world_env(single):
    sb3 = pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)
    model = sb3.SAC(
        "MlpPolicy",
        single,
        learning_starts=16,
        buffer_size=1000,
        batch_size=16,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )
    model.learn(total_timesteps=64)  # four 16-step episodes, 48 gradient steps
    assert model.num_timesteps == 64
    obs, _ = single.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == single.action_space.shape and np.all(np.abs(action) <= 1)
