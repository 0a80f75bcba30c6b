"""Per-world model fields reach the MJX physics (issue 51).

MuJoCo Playground's domain-randomisation wrapper (``BraxDomainRandomizationVmapWrapper``)
``vmap``s the env's step over a batched ``mjx.Model`` and, inside, sets the env's
``_mjx_model`` to the world's model before calling ``step``. The engine must read that model
at every step (``MjxEngine`` takes ``lambda: env._mjx_model``, never a copy). This test uses
the same mechanism without Playground (not installed in the main suite): three worlds from one
start state, worlds 0 and 1 with the nominal joint damping, world 2 with 30x the damping.
Worlds 0 and 1 must stay identical bit for bit, world 2 must move apart. One compile of the
vmapped steps (MJX-JAX, CPU).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx import envs
from peghole_mjx.envs.rollout import scripted_policy

N_STEPS = 3
FACTORS = (1.0, 1.0, 30.0)


def test_per_world_joint_damping_changes_the_trajectory():
    env = envs.load("RectExtract", config_overrides={"engine": "mjx"})  # swaps the mjx.Model
    nominal = env.mjx_model
    assert float(np.max(np.asarray(nominal.dof_damping))) > 0.0  # the arm's joints are damped
    factors = jnp.asarray(FACTORS)
    model_v = nominal.tree_replace(
        {"dof_damping": factors[:, None] * jnp.asarray(nominal.dof_damping)[None, :]}
    )
    in_axes = jax.tree.map(lambda _: None, nominal).tree_replace({"dof_damping": 0})
    action = scripted_policy(env)(None, None)

    def world(model, state):
        """One world's steps with ``model`` swapped in, as Playground's wrapper does."""
        env._mjx_model = model
        try:

            def body(s, _):
                s = env.step(s, action)
                return s, s.data.qpos

            return jax.lax.scan(body, state, None, length=N_STEPS)[1]
        finally:
            env._mjx_model = nominal

    s0 = jax.jit(env.reset)(jax.random.PRNGKey(0))
    batch = jax.tree.map(lambda x: jnp.stack([x] * len(FACTORS)), s0)
    qpos = np.asarray(jax.jit(jax.vmap(world, in_axes=(in_axes, 0)))(model_v, batch))
    assert env._mjx_model is nominal
    assert np.all(np.isfinite(qpos))
    np.testing.assert_array_equal(qpos[0], qpos[1])  # the same model: the same trajectory
    moved = np.max(np.abs(qpos[2, -1] - qpos[0, -1]))
    assert moved > 1e-6, f"30x joint damping moved the arm by {moved} rad only"
