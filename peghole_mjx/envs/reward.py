"""The extraction rewards, as named terms: the thesis's eq (4.4) and the ``outcome`` reward.

``reward_config.kind`` picks one (the env config's ``reward_config`` group holds the weights
of both; :data:`REWARD_WEIGHTS` and :data:`OUTCOME_WEIGHTS` are their one source):

* ``thesis`` (the env config's default): eq (4.4) with the Table 4.1 weights, exactly as the
  thesis wrote it. Progress is
  paid every step and the outcome only +-1 at the end, several hundred steps later: at a
  discount of 0.99 a success 300 steps away is worth 0.05 of its face value, so the return
  cannot tell an extraction from a peg left 1 mm in. The reproduction studies (R3-R5, C4.1 /
  C4.2) keep it, stated in their files. A time-out is a terminal failure (the thesis's rule).
* ``outcome`` (training's default with residual actions,
  :data:`peghole_mjx.training.config.TRAINING_ENV_DEFAULTS`; on plain actions it did not learn
  RectExtract within the ``cpu`` budget, docs/research/learning.md): a reward whose optimum is
  a clean extraction. Per step a time cost ``time_cost`` plus a contact cost
  ``time_cost * w_contact * min(|f| / force_scale_N, 1)`` (|f| the contact force, F_z and
  F_xy together); a progress term that is potential-based shaping (Ng, Harada and Russell
  1999), ``gamma Phi(s') - Phi(s)`` with ``Phi = -w_progress * (distance left to success) /
  (distance at the start)`` and ``Phi = 0`` after a terminal step, so it shifts every
  episode's discounted return by the same ``-Phi(s_0)`` and changes no ordering; a terminal
  failure (jamming, NaN, contact overflow) costs ``P = c_max / (1 - gamma)`` with ``c_max =
  time_cost (1 + w_contact)``, the return of staying in the hole for ever at the largest step
  cost. A time-out is a truncation, not an outcome (``State.info["truncation"]``): the learner
  bootstraps it (:mod:`peghole_mjx.training.sac`). With ``reward_config.time_limit``
  ``failure`` a time-out is a terminal failure like a jam (costs ``P``) and the observation
  must carry ``obs.time_left`` (the config is refused otherwise); the ordering below covers it,
  since it bounds a terminal failure at any ``T_f <= L``.

  Why the ordering holds (tested: tests/test_reward.py). With ``L = episode_length`` and
  ``gamma`` the reward's discount: a success after T <= L steps returns at least
  ``-c_max (1 - gamma^T) / (1 - gamma) >= -c_max (1 - gamma^L) / (1 - gamma)``; a terminal
  failure at T_f <= L returns at most ``-gamma^(T_f - 1) P <= -gamma^(L - 1) c_max /
  (1 - gamma)``, lower when ``gamma^(L - 1) >= 1 - gamma^L``; a peg never extracted pays at
  least ``time_cost`` per step for ever, ``-time_cost / (1 - gamma)``, lower when
  ``1 / (1 + w_contact) >= 1 - gamma^L``. Among extractions, less contact force and fewer
  steps cost less. :func:`outcome_ordering_problem` checks both conditions whenever a config
  is built. The defaults (``gamma`` 0.9995, ``w_contact`` 1) meet them up to L = 1386 steps
  (RectExtract's 750: 0.688 >= 0.313 and 0.5 >= 0.313); a discount of 0.99 cannot meet the
  first at L = 750 (0.0005 < 0.9995). Hence the reward carries its own discount and training
  uses it (``TrainConfig.discounting``). The conditions fix no scale; the scale is the
  thesis's (a full pull earns 30 of progress, about 1 per mm as eq (4.4)'s ``w_d``; a step
  costs 0.05 to 0.1; a failure 200). Chosen 2026-12-04 on one probe of seed 0 (RectExtract,
  ``cpu`` profile): at a step cost of 1 (a failure 4000) the critic's loss stayed near 1e5 and
  every training episode of the first 20k env steps jammed (Adam grows the critic's output
  layer to thousands slowly); the learning benchmark's seeds (100-104) were not run with
  either setting before it was chosen.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from ml_collections import config_dict

#: the reward kinds of ``reward_config.kind``
REWARD_KINDS = ("thesis", "outcome")
#: what a time-out is under the outcome reward (``reward_config.time_limit``): a truncation the
#: learner bootstraps, or a terminal failure (then ``obs.time_left`` must be on)
TIME_LIMITS = ("truncation", "failure")
#: Table 4.1 reward weights (one source of truth; configs copy them into reward_config)
REWARD_WEIGHTS = {"w_d": 1.0, "w_f": 1.0, "w_stf": 0.1, "r_success": 1.0, "r_failure": -1.0}
#: the ``outcome`` reward's settings (one source of truth; configs copy them into
#: reward_config): its discount, the cost of a step, the contact cost's weight at
#: ``force_scale_N`` (relative to the time cost) and the progress potential's depth
OUTCOME_WEIGHTS = {"discount": 0.9995, "time_cost": 0.05, "w_contact": 1.0, "w_progress": 30.0}


def reward_terms(
    dz_mm, fxy_N, k_xy_N_m, success, failure, rc: config_dict.ConfigDict, k_rot_Nm_rad=0.0, fz_N=0.0
) -> dict[str, jax.Array]:
    """The named reward terms of eq (4.4) (Table 4.1 weights in ``rc``, the ``reward_config``).

    ``dz_mm``: change of tip depth this step (negative when the peg comes out);
    ``fxy_N``: lateral contact force; ``k_xy_N_m``: lateral stiffness (both axes equal, so
    ``||k_xy|| = sqrt(2) k``); ``success``/``failure``: 0 or 1. Two terms are not in
    eq (4.4) and are zero at their default weights: ``rot_stiffness``
    ``-w_stf_rot K_theta / 300 N m/rad`` and ``extraction_force`` ``-w_fz |f_z| / fz_scale_N``.
    ``time`` is the outcome reward's and 0 here. The names are
    :data:`peghole_mjx.envs.metrics.REWARD_TERMS`.
    """
    return {
        "progress": -rc.w_d * dz_mm,
        "force": -rc.w_f * fxy_N / rc.force_scale_N,
        "stiffness": -rc.w_stf * jnp.sqrt(2.0) * jnp.abs(k_xy_N_m) / rc.stiffness_scale_N_m,
        "rot_stiffness": -rc.w_stf_rot * jnp.abs(k_rot_Nm_rad) / rc.rot_stiffness_scale_Nm_rad,
        "extraction_force": -rc.w_fz * jnp.abs(fz_N) / rc.fz_scale_N,
        "end": rc.r_success * success + rc.r_failure * failure,
        "time": jnp.zeros_like(jnp.asarray(dz_mm, jnp.float32)),
    }


def failure_cost(rc: config_dict.ConfigDict) -> float:
    """``P = c_max / (1 - gamma)``: the outcome reward's cost of a terminal failure."""
    return rc.time_cost * (1.0 + rc.w_contact) / (1.0 - rc.discount)


def return_bounds(rc: config_dict.ConfigDict) -> tuple[float, float]:
    """``(lo, hi)``: bounds on the discounted return from any state under the ``outcome``
    reward (time-outs bootstrapped, so the horizon is unbounded). Every step's time and contact
    cost lies in ``[-c_max, 0]``, summing to at least ``-c_max / (1 - gamma) = -P``; a terminal
    failure costs ``P`` once; the progress shaping telescopes to ``gamma^T Phi(s_T) - Phi(s_0)``,
    within ``[-w_progress, w_progress]`` since ``Phi`` lies in ``[-w_progress, 0]``. So
    ``hi = w_progress`` and ``lo = -(2 P + w_progress)``. A critic's estimate outside them is
    an error, whatever the policy."""
    if rc.kind != "outcome":
        raise ValueError(f"return bounds are derived for the outcome reward, not {rc.kind!r}")
    return -(2.0 * failure_cost(rc) + rc.w_progress), float(rc.w_progress)


def progress_potential(left_mm, left0_mm: float, rc: config_dict.ConfigDict) -> jax.Array:
    """``Phi = -w_progress * left / left0`` (clipped to [0, 1]): ``left_mm`` the distance the
    tip still has to rise to count as extracted, ``left0_mm`` that distance at the start."""
    return -rc.w_progress * jnp.clip(left_mm / left0_mm, 0.0, 1.0)


def outcome_terms(
    left_prev_mm, left_mm, left0_mm: float, f_N, success, terminal_failure, rc
) -> dict[str, jax.Array]:
    """The named terms of the ``outcome`` reward of one step (module text).

    ``left_prev_mm`` / ``left_mm``: the distance to success before / after the step;
    ``left0_mm``: at the start; ``f_N``: the contact force's magnitude (N);
    ``success``, ``terminal_failure`` (jamming, NaN, overflow; not the time-out): 0 or 1.
    """
    gamma = rc.discount
    terminal = jnp.maximum(success, terminal_failure)
    phi_next = (1.0 - terminal) * progress_potential(left_mm, left0_mm, rc)
    phi = progress_potential(left_prev_mm, left0_mm, rc)
    contact = jnp.minimum(jnp.abs(f_N) / rc.force_scale_N, 1.0)
    zero = jnp.zeros_like(jnp.asarray(f_N, jnp.float32))
    return {
        "progress": gamma * phi_next - phi,
        "force": -rc.time_cost * rc.w_contact * contact,
        "stiffness": zero,
        "rot_stiffness": zero,
        "extraction_force": zero,
        "end": -failure_cost(rc) * terminal_failure,
        "time": -rc.time_cost + zero,
    }


def outcome_ordering_problem(rc: config_dict.ConfigDict, episode_length: int) -> str | None:
    """Why the ``outcome`` reward of ``rc`` would not rank every extraction above every
    failure within ``episode_length`` steps (module text), or None when it does."""
    g, L = rc.discount, episode_length
    tail = 1.0 - g**L  # the share of a never-ending cost paid within L steps
    if g ** (L - 1) < tail:
        need = 0.5 ** (1.0 / L)  # g^L >= 1/2 is about enough: g^(L-1) >= 1 - g^L
        return (
            f"reward_config.discount {g:g} is too short for episode_length {L}: a failure "
            f"at the last step would cost less than a slow extraction (needs discount^(L-1) "
            f">= 1 - discount^L, about discount >= {math.ceil(need * 1e5) / 1e5:g})"
        )
    if 1.0 / (1.0 + rc.w_contact) < tail:
        most = 1.0 / tail - 1.0
        return (
            f"reward_config.w_contact {rc.w_contact:g} is too large for discount {g:g} and "
            f"episode_length {L}: a peg never extracted at no force would return more than a "
            f"slow extraction at full force (needs w_contact <= {math.floor(most * 1e3) / 1e3:g})"
        )
    return None
