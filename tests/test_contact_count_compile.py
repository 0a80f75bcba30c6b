"""``max_active_contacts`` (envs/contacts.py) compiles an env's batched step once however many
policies count contacts on it: ``task make`` counts under the scripted and a random policy,
and a fresh ``jax.jit(jax.vmap(env.step))`` per call traced and compiled the step twice."""

from peghole_mjx import envs
from peghole_mjx.envs.contacts import batched_reset_step, max_active_contacts
from peghole_mjx.envs.rollout import random_policy, scripted_policy


def test_two_policies_trace_the_batched_step_once():
    env = envs.load("RectExtract", config_overrides={"engine": "mujoco"})
    traced = []
    step = env.step

    def counting(state, action):
        traced.append(1)  # Python runs once per trace; a compiled call does not come here
        return step(state, action)

    env.step = counting
    for policy in (scripted_policy(env), random_policy(env)):
        out = max_active_contacts(env, policy, worlds=2, env_steps=2)
        assert out["env_steps"] == 2
    assert len(traced) == 1
    assert batched_reset_step(env) is batched_reset_step(env)
