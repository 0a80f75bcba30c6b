"""Training as a pure function, PureJaxRL's pattern: ``train = make_train(env, cfg)``.

``jax.jit(train)(key)`` runs a whole SAC run (learner init, replay prefill, learning) in one
compiled call and returns a :class:`TrainOutput`: the final carry and the per-call training
statistics. Several seeds in one call: ``train = make_train(env, cfg, seed_axis=SEED_AXIS)``
and ``jax.jit(jax.vmap(train, axis_name=SEED_AXIS))(keys)`` train one run per key (their
worlds and learners never mix); the named axis keeps the learner's reset a true ``lax.cond``
that runs only on steps where some world finished (:mod:`peghole_mjx.training.sac`).
The pieces are those of :class:`peghole_mjx.training.sac.SACTrainer` (Brax's losses,
networks, replay buffer), on one device: SAC's device averages (``pmean``/``psum`` over the
axis ``"i"``) run on a one-wide ``vmap`` axis of that name, where they are identities.

``train.init(key)`` and ``train.call(carry, learn)`` (one call of ``steps_per_call`` env
steps, learning or only filling the replay) are its pieces, for a driver that checkpoints
between calls (:mod:`peghole_mjx.training.seeds`, ``peghole train --seeds N``); the run is
``train.learn_flags()``'s calls. Env steps follow
:class:`peghole_mjx.training.run.TrainingRun`: prefill calls until ``min_replay_size`` rows,
then learning calls until ``num_timesteps``.
"""

from __future__ import annotations

from typing import Any

import flax
import jax
import jax.numpy as jnp

from peghole_mjx.envs.extraction import PegHoleEnv
from peghole_mjx.sim import engines
from peghole_mjx.training.config import TrainConfig
from peghole_mjx.training.sac import AXIS, Carry, SACTrainer

#: the name of the ``vmap`` axis over seeds (``peghole train --seeds N``); one of the batch
#: axes a reset sizes MuJoCo Warp's contact pool from (:data:`engines.BATCH_AXES`)
SEED_AXIS = engines.SEED_AXIS


@flax.struct.dataclass
class TrainOutput:
    """A finished run: its carry and, per call (the ``prefill_calls`` first), the finished
    training episodes' totals (``TOTAL_KEYS``, summed over the call) and the mean losses
    (zero in prefill calls)."""

    carry: Carry
    history: dict[str, jax.Array]


def _one_wide(fn):
    """``fn`` under a one-wide ``vmap`` named :data:`AXIS` (the SAC collectives' axis)."""

    def wrapped(*args):
        out = jax.vmap(fn, axis_name=AXIS)(*jax.tree.map(lambda x: x[None], args))
        return jax.tree.map(lambda x: x[0], out)

    return wrapped


class Train:
    """``train(key) -> TrainOutput``: a pure, jittable, vmappable SAC run (see the module)."""

    def __init__(self, env: PegHoleEnv, cfg: TrainConfig, seed_axis: str | None = None):
        self.env, self.cfg, self.seed_axis = env, cfg, seed_axis
        self.trainer = SACTrainer(env, cfg, single_device=True, seed_axis=seed_axis)
        self.steps_per_call = cfg.num_envs * cfg.steps_per_call
        self.prefill_calls = -(-cfg.min_replay_size // self.steps_per_call)
        rest = cfg.num_timesteps - self.prefill_calls * self.steps_per_call
        self.learn_calls = max(0, -(-rest // self.steps_per_call))

    @property
    def network(self) -> dict[str, Any]:
        return self.trainer.network

    def init(self, key: jax.Array) -> Carry:
        """Learner and worlds from ``key``, as ``SACTrainer.init_carry`` on one device."""
        learner_key, local_key = jax.random.split(key)
        local_key = jax.random.split(local_key, 1)[0]
        return _one_wide(self.trainer._init)(learner_key, local_key)

    def call(self, carry: Carry, learn: jax.Array) -> tuple[Carry, dict[str, jax.Array]]:
        """One call: ``steps_per_call`` batched env steps, each followed by
        ``grad_updates_per_step`` SGD steps when ``learn`` (else a replay prefill call)."""

        def one(c):
            c, tot, losses = self.trainer._train_call(c, learn)
            return c, {**tot, **losses}

        return _one_wide(one)(carry)

    def learn_flags(self) -> jax.Array:
        """``learn`` of every call of a run: the prefill calls, then the learning calls."""
        n = self.prefill_calls + self.learn_calls
        return jnp.arange(n) >= self.prefill_calls

    def __call__(self, key: jax.Array) -> TrainOutput:
        carry, history = jax.lax.scan(self.call, self.init(key), self.learn_flags())
        return TrainOutput(carry=carry, history=history)

    @staticmethod
    def policy_params(carry: Carry) -> tuple[Any, Any]:
        """(normaliser, policy params) of one run's carry (what ``save_policy`` stores)."""
        return carry.ts.normalizer, carry.ts.policy_params


def make_train(env: PegHoleEnv, cfg: TrainConfig, seed_axis: str | None = None) -> Train:
    """``train(key)``: the whole SAC run of ``cfg`` on ``env`` as one pure function;
    ``seed_axis``: the ``axis_name`` of the ``vmap`` over seeds it will run under (None: not
    vmapped over seeds)."""
    return Train(env, cfg, seed_axis)
