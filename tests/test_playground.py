"""MuJoCo Playground's Brax training wrapper runs the extraction env (the ``playground`` extra).

Playground's ``wrap_for_brax_training`` with its domain-randomisation vmap hook
(:func:`peghole_mjx.envs.playground.joint_damping_randomization`) over 2 worlds: a reset and a
few steps, finite, batched, each world with its own model and its own episode draw.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip(
    "mujoco_playground",
    reason='MuJoCo Playground is not installed (pip install -e ".[playground]")',
)

from peghole_mjx.envs import playground
from peghole_mjx.envs.playground import (
    joint_damping_randomization,
    wrap_for_brax_training,
)

N_WORLDS = 2


def test_playground_training_wrapper_runs_the_env_with_domain_randomisation():
    env = playground.load("RectExtract")  # engine auto: never MuJoCo C for Playground
    assert env.config.engine == "mjx"
    dr_keys = jax.random.split(jax.random.PRNGKey(1), N_WORLDS)
    wrapped = wrap_for_brax_training(
        env,
        episode_length=3,
        randomization_fn=functools.partial(joint_damping_randomization, rng=dr_keys),
    )
    assert wrapped.unwrapped is env
    assert (wrapped.observation_size, wrapped.action_size) == (
        env.observation_size,
        env.action_size,
    )
    damping = np.asarray(wrapped.env.env._mjx_model_v.dof_damping)  # the DR wrapper's models
    assert damping.shape == (N_WORLDS, env.mj_model.nv)
    assert not np.allclose(damping[0], damping[1])

    reset = jax.jit(wrapped.reset)
    step = jax.jit(wrapped.step)
    state = reset(jax.random.split(jax.random.PRNGKey(0), N_WORLDS))
    assert state.obs.shape == (N_WORLDS, env.observation_size)
    # the env's own per-episode draw (randomization_fn) still differs between worlds
    assert not np.allclose(state.info["hole_pos"][0], state.info["hole_pos"][1])
    action = jnp.zeros((N_WORLDS, env.action_size))
    for _ in range(4):  # past episode_length=3: the auto-reset path runs too
        state = step(state, action)
        assert np.all(np.isfinite(np.asarray(state.obs)))
        assert state.reward.shape == (N_WORLDS,)
    assert np.all(np.asarray(state.info["AutoResetWrapper_done_count"]) >= 1)
