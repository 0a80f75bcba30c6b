"""MuJoCo Playground interop: Playground's Brax training wrapper around the extraction envs.

:class:`~peghole_mjx.envs.extraction.PegHoleEnv` already has the interface that Playground's
wrappers (``mujoco_playground._src.wrapper``, playground 0.2.0) read: ``reset(rng)``,
``step(state, action)``, ``observation_size``, ``action_size``, ``mj_model``, ``mjx_model``,
``unwrapped``, a :class:`~peghole_mjx.envs.base.State` with ``data, obs, reward, done, metrics,
info``, and the ``_mjx_model`` attribute that Playground's domain-randomisation wrapper swaps
for each world's model. So no adapter class is needed: :func:`wrap_for_brax_training` hands
an env to Playground's own function, and :func:`joint_damping_randomization` is an example of
the model-level hook Playground vmaps over.

Two randomisations then compose. The env's own per-episode draw
(:func:`peghole_mjx.envs.randomization.randomization_fn`: hole pose, commanded error,
friction scale, k_xy) runs inside ``reset`` for every world; Playground's hook varies fields of
the compiled model per world, and the MJX engine steps with the env's current ``_mjx_model``
(:class:`peghole_mjx.sim.engines.MjxEngine` reads it at every trace), so every field a hook
varies (``dof_damping``, ``body_mass``, ``pair_friction``, ...) reaches the physics
(``tests/test_model_swap.py``). A hook's ``pair_friction`` is multiplied by the env's own
friction-scale draw at every step. The scene's contacts are explicit ``<pair>`` elements: a hook on
``geom_friction`` has no effect on them. The ``mujoco`` engine (MuJoCo C) does not read an
``mjx.Model``: Playground's hooks need ``engine=mjx``.

:func:`load` builds an env for Playground with the package's one default, engine ``auto``
(2026-12-05), with one difference: where ``auto`` stands for MuJoCo C (a machine
without a GPU) it picks ``mjx`` (MJX-JAX) instead, because Playground's whole point is an
``mjx.Model`` its hooks vary per world; on a CUDA GPU ``auto`` is MJX-Warp or MJX-JAX as for
every env. An engine named in the overrides is kept.

Needs the ``playground`` extra (``pip install -e ".[playground]"``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from peghole_mjx import envs
from peghole_mjx.core._mjx import mjx
from peghole_mjx.core._optional import optional_import
from peghole_mjx.sim.engines import default_engine, engine_overrides

__all__ = ["joint_damping_randomization", "load", "playground_engine", "wrap_for_brax_training"]

#: Playground's hook: mjx.Model -> (model batched over worlds, its vmap in_axes)
ModelRandomization = Callable[[mjx.Model], tuple[mjx.Model, mjx.Model]]


def playground_engine() -> dict[str, str]:
    """The env config entries of engine ``auto`` for Playground: :func:`default_engine`'s
    engine, ``mjx`` (MJX-JAX) where that is ``mujoco`` (MuJoCo C has no ``mjx.Model``)."""
    choice = default_engine()
    return engine_overrides("mjx" if choice == "mujoco" else choice)


def load(name: str = "RectExtract", config_overrides: dict | None = None) -> Any:
    """Env ``name`` (:func:`peghole_mjx.envs.load`) for Playground: engine ``auto`` as
    :func:`playground_engine` resolves it, unless ``config_overrides`` names an engine
    other than ``auto``."""
    over = dict(config_overrides or {})
    if over.get("engine", "auto") == "auto":
        over = {**over, **playground_engine()}
    return envs.load(name, config_overrides=over)


def wrap_for_brax_training(
    env: Any,
    episode_length: int | None = None,
    action_repeat: int = 1,
    randomization_fn: ModelRandomization | None = None,
    full_reset: bool = False,
) -> Any:
    """``mujoco_playground``'s ``wrap_for_brax_training`` applied to a peg-hole env.

    ``episode_length`` defaults to the env config's (env steps). With ``randomization_fn``
    the result is batched over that function's worlds (Playground's
    ``BraxDomainRandomizationVmapWrapper``), otherwise over the leading axis of the keys.
    """
    wrapper = optional_import("mujoco_playground._src.wrapper", "Playground's training wrapper")
    return wrapper.wrap_for_brax_training(
        env,
        episode_length=env.config.episode_length if episode_length is None else episode_length,
        action_repeat=action_repeat,
        randomization_fn=randomization_fn,
        full_reset=full_reset,
    )


def joint_damping_randomization(
    mjx_model: mjx.Model, rng: jax.Array, scale: tuple[float, float] = (0.8, 1.2)
) -> tuple[mjx.Model, mjx.Model]:
    """A Playground-style model randomisation: the robot's joint damping scaled per world.

    ``rng`` holds one key per world, shape (n_worlds, 2); each world's ``dof_damping`` (N m s/rad)
    is the model's times a factor uniform in ``scale``. Returns the batched model and the
    ``in_axes`` tree (0 on ``dof_damping``, None elsewhere) that Playground's wrapper vmaps with.
    Bind ``rng`` (``functools.partial``) before passing it as ``randomization_fn``.
    """
    factor = jax.vmap(lambda k: jax.random.uniform(k, (), minval=scale[0], maxval=scale[1]))(rng)
    damping = factor[:, None] * jnp.asarray(mjx_model.dof_damping)[None, :]
    in_axes = jax.tree.map(lambda _: None, mjx_model)
    in_axes = in_axes.tree_replace({"dof_damping": 0})
    return mjx_model.tree_replace({"dof_damping": damping}), in_axes
