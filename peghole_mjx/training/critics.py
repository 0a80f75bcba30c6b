"""The critics SAC can learn with, beside Brax's: the twin Q networks of a run (``critic``).

* ``mlp``: Brax's own (:func:`brax.training.networks.make_q_network`), a plain ReLU MLP of
  ``hidden_layer_sizes`` per critic; the default, and what every published policy used.
* ``layernorm``: the same MLP with a LayerNorm after every hidden layer (Brax's
  ``layer_norm=True``). Normalised critics bound the Q-values' growth and are the common
  remedy for the late collapse of off-policy learners (Ball et al. 2023, RLPD; Nauman et al.
  2024, BRO).
* ``simba``: a SimBa critic (Lee et al. 2025, "SimBa: Simplicity Bias for Scaling Up
  Parameters in Deep RL", ICLR): a linear embedding of (observation, action) to width
  ``d = hidden_layer_sizes[0]``, ``len(hidden_layer_sizes)`` residual blocks
  ``x + W2 relu(W1 LN(x))`` with an inner width 4 d, a final LayerNorm, then the Q output.
  The observation is already standardised by the run's running normaliser (SimBa's RSNorm).

Only the critics change: the actor, the losses (Brax's), the target critics and the exported
policy are the same for every choice. Which critic trains best on this project's tasks is
decided by the protocol in ``docs/research/learning.md`` ("Critic choice"), on the tuning
seeds only.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
from brax.training import networks
from brax.training import types as brax_types
from brax.training.acme import running_statistics
from flax import linen

from peghole_mjx.core.errors import UserInputError

#: the ``critic`` choices of :class:`~peghole_mjx.training.config.TrainConfig`
CRITICS = ("mlp", "layernorm", "simba")
#: SimBa's inner width of a residual block, in multiples of the block's width (the paper's 4)
SIMBA_EXPANSION = 4


class SimbaBlock(linen.Module):
    """One pre-LayerNorm residual block: ``x + Dense(relu(Dense(LN(x))))``."""

    width: int

    @linen.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        init = jax.nn.initializers.he_normal()
        h = linen.LayerNorm()(x)
        h = linen.relu(linen.Dense(SIMBA_EXPANSION * self.width, kernel_init=init)(h))
        return x + linen.Dense(self.width, kernel_init=init)(h)


class SimbaQ(linen.Module):
    """``n_critics`` SimBa critics of (observation, action), outputs concatenated."""

    width: int
    blocks: int
    n_critics: int = 2

    @linen.compact
    def __call__(self, obs: jax.Array, actions: jax.Array) -> jax.Array:
        x0 = jnp.concatenate([obs, actions], axis=-1)
        out = []
        for _ in range(self.n_critics):
            x = linen.Dense(self.width, kernel_init=jax.nn.initializers.orthogonal())(x0)
            for _ in range(self.blocks):
                x = SimbaBlock(self.width)(x)
            x = linen.LayerNorm()(x)
            out.append(linen.Dense(1, kernel_init=jax.nn.initializers.orthogonal(1.0))(x))
        return jnp.concatenate(out, axis=-1)


def make_q_network(
    critic: str,
    obs_size: int,
    action_size: int,
    preprocess_observations_fn=brax_types.identity_observation_preprocessor,
    hidden_layer_sizes: Sequence[int] = (256, 256),
) -> networks.FeedForwardNetwork:
    """The twin critics of kind ``critic`` (:data:`CRITICS`) as a Brax ``FeedForwardNetwork``
    (``init(key)``, ``apply(normaliser_params, q_params, obs, actions) -> (..., 2)``)."""
    if critic not in CRITICS:
        raise UserInputError(f"critic must be one of {list(CRITICS)}, got {critic!r}")
    if critic in ("mlp", "layernorm"):
        return networks.make_q_network(
            obs_size,
            action_size,
            preprocess_observations_fn=preprocess_observations_fn,
            hidden_layer_sizes=tuple(hidden_layer_sizes),
            layer_norm=critic == "layernorm",
        )
    module = SimbaQ(width=int(hidden_layer_sizes[0]), blocks=len(hidden_layer_sizes))

    def apply(processor_params, q_params, obs, actions):
        return module.apply(q_params, preprocess_observations_fn(obs, processor_params), actions)

    dummy_obs, dummy_act = jnp.zeros((1, obs_size)), jnp.zeros((1, action_size))
    return networks.FeedForwardNetwork(
        init=lambda key: module.init(key, dummy_obs, dummy_act), apply=apply
    )


def with_critic(nets, critic: str, network: dict):
    """Brax's ``SACNetworks`` ``nets`` with their critics replaced by ``critic``'s (the same
    networks when ``critic`` is ``mlp``). ``network``: the run's network description."""
    if critic == "mlp":
        return nets
    normalize = (
        running_statistics.normalize
        if network["normalize_observations"]
        else brax_types.identity_observation_preprocessor
    )
    q = make_q_network(
        critic,
        int(network["observation_size"]),
        int(network["action_size"]),
        normalize,
        network["hidden_layer_sizes"],
    )
    return nets.replace(q_network=q)
