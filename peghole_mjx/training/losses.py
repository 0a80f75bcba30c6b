"""The critics' loss with targets clipped to the reward's return bounds, beside Brax's.

Brax's SAC critic loss (:func:`brax.training.agents.sac.losses.make_losses`, brax 0.14.2)
regresses both critics on ``r + gamma (min Q'(s', a') - alpha log pi(a'|s'))``. With one
gradient update per env step the critics' estimates in our Hard-task runs grew far beyond any
return the ``outcome`` reward can pay (docs/research/learner_settings.md), which bounds its
returns (:func:`peghole_mjx.envs.reward.return_bounds`). :func:`make_clipped_critic_loss` is
Brax's loss, term for term, with the target clipped to those bounds (scaled by
``reward_scaling``), as Andrychowicz et al. (2017, Hindsight Experience Replay) clip targets
to the range of returns a reward allows. ``TrainConfig.q_target_clip`` selects it.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from brax.training.agents.sac import networks as sac_networks
from brax.training.types import Params, PRNGKey, Transition


def make_clipped_critic_loss(
    sac_network: sac_networks.SACNetworks,
    reward_scaling: float,
    discounting: float,
    bounds: tuple[float, float],
):
    """Brax's critic loss with its target clipped to ``bounds`` (the discounted return's range
    in reward units; scaled here by ``reward_scaling``)."""
    lo, hi = (float(b) * reward_scaling for b in bounds)
    if not lo < hi:
        raise ValueError(f"return bounds must be increasing, got {bounds}")
    policy_network = sac_network.policy_network
    q_network = sac_network.q_network
    dist = sac_network.parametric_action_distribution

    def critic_loss(
        q_params: Params,
        policy_params: Params,
        normalizer_params: Any,
        target_q_params: Params,
        alpha: jnp.ndarray,
        transitions: Transition,
        key: PRNGKey,
    ) -> jnp.ndarray:
        q_old_action = q_network.apply(
            normalizer_params, q_params, transitions.observation, transitions.action
        )
        next_dist_params = policy_network.apply(
            normalizer_params, policy_params, transitions.next_observation
        )
        next_action = dist.sample_no_postprocessing(next_dist_params, key)
        next_log_prob = dist.log_prob(next_dist_params, next_action)
        next_action = dist.postprocess(next_action)
        next_q = q_network.apply(
            normalizer_params, target_q_params, transitions.next_observation, next_action
        )
        next_v = jnp.min(next_q, axis=-1) - alpha * next_log_prob
        target_q = transitions.reward * reward_scaling + transitions.discount * discounting * next_v
        target_q = jax.lax.stop_gradient(jnp.clip(target_q, lo, hi))
        q_error = q_old_action - jnp.expand_dims(target_q, -1)
        truncation = transitions.extras["state_extras"]["truncation"]
        q_error *= jnp.expand_dims(1 - truncation, -1)
        return 0.5 * jnp.mean(jnp.square(q_error))

    return critic_loss
