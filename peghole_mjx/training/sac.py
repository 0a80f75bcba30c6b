"""Soft actor-critic on the MJX envs, built from Brax's SAC (``brax.training.agents.sac``).

The networks (:func:`brax.training.agents.sac.networks.make_sac_networks`), the three losses
(:func:`brax.training.agents.sac.losses.make_losses`), the gradient updates, the replay buffer
(:class:`brax.training.replay_buffers.UniformSamplingQueue`) and the observation normaliser
are Brax's own. What this module adds around them, and why Brax's ``sac.train`` is not called
directly:

* **Full resume.** ``sac.train(restore_checkpoint_path=...)`` restores the policy and the
  normaliser only. Here the whole carry is checkpointed: actor, both critics and their
  targets, the temperature, all optimiser states, the normaliser, the replay buffer, every
  world's simulator state and the PRNG key. A resumed run continues bit-for-bit as if it had
  never stopped (tested).
* **Full resets.** Brax's AutoResetWrapper restores each world's first start state, so the
  randomised initial errors would be drawn once. Here a finished world gets a fresh
  :meth:`PegHoleEnv.reset` with a new key (tested).
* **Fixed or learned temperature.** Brax always learns alpha (from 1); the thesis fixed it at
  0.2. ``alpha`` may be ``"auto"`` (learned, from ``alpha_init``) or a number.
* **Entropy in the critics' target, and the learning-rate schedule** (``entropy_backup``,
  ``lr_schedule``, :mod:`peghole_mjx.training.config`): Brax's critic loss with alpha 0 is a
  target without the entropy bonus; the actor and critics take an optax schedule.
* **Critic targets within the reward's return bounds** (``q_target_clip``,
  :mod:`peghole_mjx.training.losses`): Brax's critic loss with its target clipped.
* **Episode statistics during training** (force, |F_xy|, discounted return of every finished
  training episode) for the thesis's Figs 4.5-4.7.

Like Brax, the step is ``pmap``-ed over all local devices, and on several processes
(``jax.distributed``, ``peghole train --distributed``) over every process's devices:
``num_envs``, ``max_replay_size`` and the batch are totals split across all devices
(``jax.device_count()``), each process's worlds start from its own keys, and gradients and
normaliser statistics are averaged across all devices with ``pmean``/``psum``, so every
process holds the same learner (tested with two CPU processes: tests/test_distributed.py).

Time limits. Under the thesis's reward an episode that reaches ``episode_length`` is a failure
with reward -1 (the thesis's rule) and a terminal transition. Under the ``outcome`` reward
(training's default, :mod:`peghole_mjx.envs.reward`) a time-out alone is a truncation
(``State.info["truncation"]``): the transition keeps its discount and the critic bootstraps it
from the true next observation, which the replay stores before the world's reset. Brax's own
loss instead drops truncated transitions (``1 - truncation`` mask), because its auto-reset
wrapper has already replaced their next observation; here that mask stays 0.

Resets only where needed. A finished world restarts from a fresh reset; the reset (an IK
solve, and on the ``mujoco`` engine a host call) runs only on steps where some world finished,
through a ``lax.cond`` whose predicate is one flag for the whole call. Under ``vmap`` (the pure
learner's one-wide axis, and the seeds' named axis ``seed_axis`` of ``peghole train --seeds``)
the predicate is reduced over the named axes, so it stays one flag and the cond is not turned
into a select that would run both branches at every step (tested).
"""

from __future__ import annotations

import functools
import itertools
from typing import Any

import flax
import jax
import jax.numpy as jnp
import optax
from brax.training import gradients, replay_buffers
from brax.training.acme import running_statistics, specs
from brax.training.agents.sac import losses as sac_losses
from brax.training.types import Transition
from jax._src import distributed  # private (jax 0.10.2): the coordination client's barrier

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.extraction import PegHoleEnv
from peghole_mjx.envs.metrics import accumulate_return, episode_totals, zero_returns
from peghole_mjx.envs.reward import return_bounds
from peghole_mjx.policies import make_networks
from peghole_mjx.sim.engines import batch_reset, select_worlds
from peghole_mjx.training.config import TrainConfig, check_discount, learning_rate
from peghole_mjx.training.critics import with_critic
from peghole_mjx.training.losses import make_clipped_critic_loss

AXIS = "i"


def zero_action_mean(policy_params, action_size: int):
    """Policy parameters whose action mean is 0 for every observation: the last layer's
    weights and bias of the mean (``loc``, the first ``action_size`` outputs of Brax's
    ``NormalTanhDistribution``) set to zero, its scale left as drawn. A residual policy
    (env ``action.residual``) then starts at the zero action (the scripted pull's speed,
    mid-range gains), with exploration noise about it, as residual RL does (Silver et al.
    2018, "Residual Policy Learning"); drawn weights would bias each action by 0.1-1."""
    layers = dict(policy_params["params"])
    last = max(layers, key=lambda name: int(name.rsplit("_", 1)[1]))
    w, b = layers[last]["kernel"], layers[last]["bias"]
    layers[last] = {
        "kernel": w.at[:, :action_size].set(0.0),
        "bias": b.at[:action_size].set(0.0),
    }
    return {**policy_params, "params": layers}


@flax.struct.dataclass
class TrainingState:
    """Learner state (replicated on every device)."""

    policy_params: Any
    policy_opt: Any
    q_params: Any
    q_opt: Any
    target_q_params: Any
    log_alpha: jax.Array
    alpha_opt: Any
    normalizer: running_statistics.RunningStatisticsState
    gradient_steps: jax.Array


@flax.struct.dataclass
class Carry:
    """Everything a run needs to continue (one slice per device along axis 0)."""

    ts: TrainingState
    env_state: Any  # batched envs.State of this device's worlds
    ep_acc: dict[str, jax.Array]  # per-world running return, discounted return, gamma^t
    buffer: Any
    key: jax.Array


def network_description(env: PegHoleEnv, cfg: TrainConfig) -> dict[str, Any]:
    """What :mod:`peghole_mjx.policies` needs to rebuild the networks."""
    return {
        "observation_size": int(env.observation_size),
        "action_size": int(env.action_size),
        "hidden_layer_sizes": list(cfg.hidden_layer_sizes),
        "normalize_observations": bool(cfg.normalize_observations),
    }


#: numbers the barriers of :meth:`SACTrainer._run` (a barrier's name is used once)
_BARRIERS = itertools.count()


class SACTrainer:
    """Jitted (pmapped) pieces of a SAC run: ``init``, ``prefill``, ``train_call``."""

    def __init__(
        self,
        env: PegHoleEnv,
        cfg: TrainConfig,
        single_device: bool = False,
        seed_axis: str | None = None,
    ):
        """``single_device``: one learner on one device, whatever the device count (the
        pure :func:`peghole_mjx.training.functional.make_train`; ``init``/``train_call``
        are then not for use). ``seed_axis``: the name of a ``vmap`` axis over seeds that
        the pieces run under (the reset predicate is reduced over it)."""
        rc = env.config.reward_config
        check_discount(rc.kind, rc.discount, cfg.discounting)
        if cfg.q_target_clip and rc.kind != "outcome":
            raise UserInputError(
                "q_target_clip needs the outcome reward (its return bounds); "
                f"env.reward_config.kind is {rc.kind!r}"
            )
        self.env, self.cfg, self.seed_axis = env, cfg, seed_axis
        # the vmapped axes the acting step runs under (none under pmap: there each device's
        # flag is its own): the one-wide axis of the pure learner and the seeds' axis
        axes = (AXIS,) if single_device else ()
        self._vmap_axes = axes + ((seed_axis,) if seed_axis else ())
        # the pmap's width in this process, and every process's devices
        self.n_dev = 1 if single_device else jax.local_device_count()
        n_all = 1 if single_device else jax.device_count()
        if cfg.num_envs % n_all:
            raise UserInputError(
                f"num_envs ({cfg.num_envs}) must be divisible by the device count ({n_all})"
            )
        self.envs_per_dev = cfg.num_envs // n_all
        self.network = network_description(env, cfg)
        self.nets = with_critic(make_networks(self.network), cfg.critic, self.network)
        obs_size, act_size = self.network["observation_size"], self.network["action_size"]
        self.obs_size, self.act_size = obs_size, act_size
        self.fixed_alpha = cfg.alpha != "auto"
        lr = learning_rate(cfg)  # a number, or one schedule for the actor and the critics
        self.policy_opt = optax.adam(lr)
        self.q_opt = optax.adam(lr)
        self.alpha_opt = optax.adam(3e-4)
        dummy_obs = jnp.zeros((obs_size,))
        self.buffer = replay_buffers.UniformSamplingQueue(
            max_replay_size=cfg.max_replay_size // n_all,
            dummy_data_sample=Transition(
                observation=dummy_obs,
                action=jnp.zeros((act_size,)),
                reward=0.0,
                discount=0.0,
                next_observation=dummy_obs,
                extras={"state_extras": {"truncation": 0.0}, "policy_extras": {}},
            ),
            sample_batch_size=cfg.batch_size * cfg.grad_updates_per_step // n_all,
        )
        alpha_loss, critic_loss, actor_loss = sac_losses.make_losses(
            sac_network=self.nets,
            reward_scaling=cfg.reward_scaling,
            discounting=cfg.discounting,
            action_size=act_size,
        )
        if cfg.q_target_clip:  # the same loss, its target clipped to the reward's bounds
            critic_loss = make_clipped_critic_loss(
                self.nets, cfg.reward_scaling, cfg.discounting, return_bounds(rc)
            )
        self._alpha_update = gradients.gradient_update_fn(alpha_loss, self.alpha_opt, AXIS)
        self._critic_update = gradients.gradient_update_fn(critic_loss, self.q_opt, AXIS)
        self._actor_update = gradients.gradient_update_fn(actor_loss, self.policy_opt, AXIS)
        self._dist = self.nets.parametric_action_distribution
        self.init = jax.pmap(self._init, axis_name=AXIS)
        self._train_call_p = jax.pmap(self._train_call, axis_name=AXIS)
        self._compiled: dict[str, bool] = {}  # several processes: compiled ahead (_run)

    # ------------------------------------------------------------------ init
    def init_carry(self, seed: int) -> Carry:
        """A fresh carry: same learner on every device, different worlds per device."""
        key = jax.random.PRNGKey(seed)
        learner_key, local_key = jax.random.split(key)
        if jax.process_count() > 1:  # each process's worlds and replay draws its own
            local_key = jax.random.fold_in(local_key, jax.process_index())
        local_keys = jax.random.split(local_key, self.n_dev)
        learner_keys = jnp.stack([learner_key] * self.n_dev)
        return self._run("init", self.init, learner_keys, local_keys)

    def _run(self, name: str, fn, *args):
        """``fn(*args)``; with several processes, compiled first and then started together.

        JAX's CPU collectives (gloo) give up when the processes reach a collective more than
        30 s apart (seen 2026-11-29: ``Gloo context initialization failed: DEADLINE_EXCEEDED``
        while the other process was still compiling), so each pmapped function is compiled
        ahead (into the compilation cache its call then uses) and the processes meet at a
        barrier of the coordination service before its first run."""
        if jax.process_count() > 1 and name not in self._compiled:
            fn.lower(*args).compile()  # fills the compilation cache that fn(*args) then uses
            barrier = f"peghole_{name}_{next(_BARRIERS)}"  # the same sequence in every process
            distributed.global_state.client.wait_at_barrier(barrier, 3_600_000)
            self._compiled[name] = True
        return fn(*args)

    def _init(self, learner_key, local_key) -> Carry:
        ts = self.learner_state(learner_key)
        k_env, k_buf, k_run = jax.random.split(local_key, 3)
        env_state = batch_reset(self.env, jax.random.split(k_env, self.envs_per_dev))
        n = self.envs_per_dev
        ep_acc = zero_returns(n)
        carry = Carry(ts, env_state, ep_acc, self.buffer.init(k_buf), k_run)
        # no weak types: a carry reloaded from disk then has exactly the same avals (no
        # recompile on resume)
        return jax.tree.map(_strong, carry)

    def learner_state(self, learner_key) -> TrainingState:
        """A fresh learner: networks drawn from ``learner_key`` (a residual policy's mean
        zeroed: :func:`zero_action_mean`), optimisers and normaliser at their start."""
        cfg = self.cfg
        kp, kq = jax.random.split(learner_key)
        policy_params = self.nets.policy_network.init(kp)
        if self.env.config.action.residual:
            policy_params = zero_action_mean(policy_params, self.env.action_size)
        q_params = self.nets.q_network.init(kq)
        alpha0 = cfg.alpha_init if cfg.alpha == "auto" else float(cfg.alpha)
        log_alpha = jnp.asarray(jnp.log(alpha0), jnp.float32)
        ts = TrainingState(
            policy_params=policy_params,
            policy_opt=self.policy_opt.init(policy_params),
            q_params=q_params,
            q_opt=self.q_opt.init(q_params),
            target_q_params=q_params,
            log_alpha=log_alpha,
            alpha_opt=self.alpha_opt.init(log_alpha),
            normalizer=running_statistics.init_state(
                specs.Array((self.obs_size,), jnp.dtype("float32"))
            ),
            gradient_steps=jnp.zeros((), jnp.int32),
        )
        return ts

    # ------------------------------------------------------------------ acting
    def _step_and_reset(self, states, actions, key):
        """One batched env step; finished worlds restart from a fresh randomised reset.

        The resets (an IK solve each) run only on steps where some world finished: under
        ``vmap`` a per-world branch would compute them for every world at every step.
        """
        nxt = jax.vmap(self.env.step)(states, actions)
        done = nxt.done > 0

        def with_resets(_):
            fresh = batch_reset(self.env, jax.random.split(key, self.envs_per_dev))
            return select_worlds(done, fresh, nxt)

        any_done = jnp.any(done)
        if self._vmap_axes:  # one flag for the call's vmapped axes: a true cond
            any_done = jax.lax.pmax(any_done.astype(jnp.int32), self._vmap_axes) > 0
        return nxt, jax.lax.cond(any_done, with_resets, lambda _: nxt, None)

    def _actor_step(self, ts: TrainingState, carry: Carry, key, deterministic=False):
        """Act in every world, store the transitions, track finished episodes."""
        k_act, k_reset = jax.random.split(key)
        es = carry.env_state
        logits = self.nets.policy_network.apply(ts.normalizer, ts.policy_params, es.obs)
        if deterministic:
            actions = self._dist.mode(logits)
        else:
            actions = self._dist.sample(logits, k_act)
        nxt, new_state = self._step_and_reset(es, actions, k_reset)
        trans = Transition(
            observation=es.obs,
            action=actions,
            reward=nxt.reward,
            # a truncated step (time-out under the outcome reward) is bootstrapped
            discount=1.0 - nxt.done + nxt.info["truncation"],
            next_observation=nxt.obs,
            extras={
                "state_extras": {"truncation": jnp.zeros_like(nxt.done)},
                "policy_extras": {},
            },
        )
        acc = accumulate_return(carry.ep_acc, nxt.reward, self.cfg.discounting)
        done = nxt.done > 0
        totals = episode_totals({**nxt.metrics, **acc}, done)
        fresh = zero_returns()
        ep_acc = {k: jnp.where(done, fresh[k], v) for k, v in acc.items()}
        normalizer = ts.normalizer
        if self.cfg.normalize_observations:
            normalizer = running_statistics.update(normalizer, es.obs, pmap_axis_name=AXIS)
        ts = ts.replace(normalizer=normalizer)
        buffer = self.buffer.insert(carry.buffer, trans)
        carry = carry.replace(env_state=new_state, ep_acc=ep_acc, buffer=buffer)
        return ts, carry, {k: v.astype(jnp.float32) for k, v in totals.items()}

    # ------------------------------------------------------------------ learning
    def _sgd_step(self, ts_key, transitions):
        ts, key = ts_key
        key, k_alpha, k_critic, k_actor = jax.random.split(key, 4)
        if self.fixed_alpha:
            alpha_loss, log_alpha, alpha_opt = jnp.zeros(()), ts.log_alpha, ts.alpha_opt
        else:
            alpha_loss, log_alpha, alpha_opt = self._alpha_update(
                ts.log_alpha,
                ts.policy_params,
                ts.normalizer,
                transitions,
                k_alpha,
                optimizer_state=ts.alpha_opt,
            )
        alpha = jnp.exp(ts.log_alpha)
        # Brax's critic target is r + gamma (min Q' - alpha log pi'): alpha 0 drops the entropy
        # bonus from it (``entropy_backup`` false), the actor's loss keeps alpha
        critic_alpha = alpha if self.cfg.entropy_backup else jnp.zeros_like(alpha)
        critic_loss, q_params, q_opt = self._critic_update(
            ts.q_params,
            ts.policy_params,
            ts.normalizer,
            ts.target_q_params,
            critic_alpha,
            transitions,
            k_critic,
            optimizer_state=ts.q_opt,
        )
        actor_loss, policy_params, policy_opt = self._actor_update(
            ts.policy_params,
            ts.normalizer,
            ts.q_params,
            alpha,
            transitions,
            k_actor,
            optimizer_state=ts.policy_opt,
        )
        if self.cfg.actor_delay_updates:  # critic burn-in: actor and temperature held
            learn = ts.gradient_steps >= self.cfg.actor_delay_updates
            keep = functools.partial(jax.tree.map, lambda new, old: jnp.where(learn, new, old))
            policy_params = keep(policy_params, ts.policy_params)
            policy_opt = keep(policy_opt, ts.policy_opt)
            log_alpha, alpha_opt = keep((log_alpha, alpha_opt), (ts.log_alpha, ts.alpha_opt))
        tau = self.cfg.tau
        target = jax.tree.map(lambda t, q: t * (1 - tau) + q * tau, ts.target_q_params, q_params)
        ts = ts.replace(
            policy_params=policy_params,
            policy_opt=policy_opt,
            q_params=q_params,
            q_opt=q_opt,
            target_q_params=target,
            log_alpha=log_alpha,
            alpha_opt=alpha_opt,
            gradient_steps=ts.gradient_steps + 1,
        )
        metrics = {
            "loss/critic": critic_loss,
            "loss/actor": actor_loss,
            "loss/alpha": alpha_loss,
            "alpha": jnp.exp(log_alpha),
        }
        return (ts, key), metrics

    def _train_call(self, carry: Carry, learn: jax.Array) -> tuple[Carry, dict, dict]:
        """``steps_per_call`` x (one batched env step, ``grad_updates_per_step`` SGD steps).

        With ``learn`` False only experience is collected (the replay prefill): one compiled
        function serves both, which saves a compile of the env step.
        """
        g = self.cfg.grad_updates_per_step

        def sgd(ts, buffer, key):
            buffer, trans = self.buffer.sample(buffer)
            trans = jax.tree.map(lambda x: x.reshape((g, -1, *x.shape[1:])), trans)
            (ts, _), m = jax.lax.scan(self._sgd_step, (ts, key), trans)
            return ts, buffer, jax.tree.map(jnp.mean, m)

        def no_sgd(ts, buffer, key):
            m = jax.eval_shape(sgd, ts, buffer, key)[2]
            return ts, buffer, jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), m)

        def body(c, _):
            c, key = _split_carry_key(c)
            k_act, k_sgd = jax.random.split(key)
            ts, c, tot = self._actor_step(c.ts, c, k_act)
            ts, buffer, m = jax.lax.cond(learn, sgd, no_sgd, ts, c.buffer, k_sgd)
            return c.replace(ts=ts, buffer=buffer), (tot, m)

        carry, (tots, ms) = jax.lax.scan(body, carry, None, length=self.cfg.steps_per_call)
        return carry, jax.tree.map(jnp.sum, tots), jax.tree.map(jnp.mean, ms)

    def train_call(self, carry: Carry) -> tuple[Carry, dict, dict]:
        """One call of env steps with learning."""
        return self._run("train_call", self._train_call_p, carry, jnp.ones(self.n_dev, bool))

    def prefill(self, carry: Carry) -> tuple[Carry, dict]:
        """One call of env steps with the current policy, no learning (replay prefill)."""
        learn = jnp.zeros(self.n_dev, bool)
        carry, tot, _ = self._run("train_call", self._train_call_p, carry, learn)
        return carry, tot

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def policy_params(carry: Carry):
        """(normaliser, policy params) of device 0, on the host."""
        ts = jax.tree.map(lambda x: x[0], carry.ts)
        return jax.device_get((ts.normalizer, ts.policy_params))


def _split_carry_key(c: Carry):
    key, sub = jax.random.split(c.key)
    return c.replace(key=key), sub


def _strong(x):
    """``x`` as an array without JAX's weak type."""
    x = jnp.asarray(x)
    return jax.lax.convert_element_type(x, x.dtype)
