"""Batched evaluation rollouts: N episodes side by side, each run until its first ``done``.

Policies are functions ``policy(obs, rng) -> action`` (batched over worlds by ``vmap``):

* :func:`scripted_policy` - the thesis's Ch 2-3 method and the baseline of every RL
  comparison: fixed compliance with the compliance centre at the peg tip, straight pull at a
  constant speed, no lateral correction, no force feed-forward;
* :func:`random_policy` - uniform actions in [-1, 1].
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx.envs.base import PegHoleEnv

Policy = Callable[[jax.Array, jax.Array], jax.Array]

#: the scripted baseline's constant pulling speed (thesis: 150 mm in about 7.6 s)
SCRIPTED_SPEED_M_S = 0.02


def scripted_policy(env: PegHoleEnv, speed_m_s: float = SCRIPTED_SPEED_M_S) -> Policy:
    """Straight pull at ``speed_m_s`` with the env's fixed stiffness and compliance centre."""
    c = env.config
    a = np.zeros(env.action_size, np.float32)
    a[2] = speed_m_s / c.action.max_speed_m_s
    if c.compliance_strategy:  # hold k_xy at the fixed value, L_C at the configured one
        s = c.stiffness
        a[6] = 2 * (s.k_xy_N_m - s.k_xy_min_N_m) / (s.k_xy_max_N_m - s.k_xy_min_N_m) - 1
        if c.learn_compliance_centre:
            a[7] = 2 * s.compliance_centre_mm / env.spec.length_mm - 1
    action = jnp.asarray(np.clip(a, -1, 1))
    return lambda obs, rng: action


def random_policy(env: PegHoleEnv) -> Policy:
    n = env.action_size
    return lambda obs, rng: jax.random.uniform(rng, (n,), minval=-1.0, maxval=1.0)


@dataclass
class RolloutSummary:
    """The keys of ``peghole envs rollout --json``."""

    success_rate: float
    mean_time_s: float  # mean extraction time of the successful episodes
    mean_fz_N: float  # mean over episodes of the per-episode mean |F_z|
    peak_fz_N: float  # mean over episodes of the per-episode peak |F_z|
    mean_fxy_N: float  # mean over episodes of the per-episode mean |F_xy|
    episodes: int
    nan_worlds: int
    jammed: int
    timeouts: int

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class RolloutResult:
    """Per-episode arrays and timing of a batched rollout."""

    per_episode: dict[str, np.ndarray]
    compile_s: float
    run_s: float
    env_steps: int
    physics_steps: int

    @property
    def env_steps_per_s(self) -> float:
        return self.env_steps / max(self.run_s, 1e-9)

    @property
    def physics_steps_per_s(self) -> float:
        return self.physics_steps / max(self.run_s, 1e-9)

    def summary(self) -> RolloutSummary:
        e = self.per_episode
        ok = e["success"] > 0
        return RolloutSummary(
            success_rate=float(ok.mean()),
            mean_time_s=float(e["extraction_time_s"][ok].mean()) if ok.any() else float("nan"),
            mean_fz_N=float(e["mean_fz_N"].mean()),
            peak_fz_N=float(e["peak_fz_N"].mean()),
            mean_fxy_N=float(e["mean_fxy_N"].mean()),
            episodes=len(ok),
            nan_worlds=int((e["nan"] > 0).sum()),
            jammed=int((e["jammed"] > 0).sum()),
            timeouts=int(((e["failure"] > 0) & (e["jammed"] == 0) & (e["nan"] == 0)).sum()),
        )


_KEYS = (
    "success",
    "failure",
    "jammed",
    "nan",
    "extraction_time_s",
    "mean_fz_N",
    "peak_fz_N",
    "mean_fxy_N",
)


def _make_runner(env: PegHoleEnv, policy: Policy, chunk: int):
    """Jitted (reset, run-chunk) over a batch of worlds; finished worlds are frozen."""

    def reset(rngs):
        states = jax.vmap(env.reset)(rngs)
        record = {k: jnp.zeros(rngs.shape[0]) for k in _KEYS}
        finished = jnp.zeros(rngs.shape[0], bool)
        return states, record, finished

    def one_step(carry, _):
        states, record, finished, rng = carry
        rng, key = jax.random.split(rng)
        keys = jax.random.split(key, finished.shape[0])
        actions = jax.vmap(policy)(states.obs, keys)
        new = jax.vmap(env.step)(states, actions)
        done_now = (new.done > 0) & ~finished

        def keep(n, o):
            mask = finished.reshape((-1,) + (1,) * (n.ndim - 1))
            return jnp.where(mask, o, n)

        states = jax.tree.map(keep, new, states)
        record = {k: jnp.where(done_now, new.metrics[k], record[k]) for k in _KEYS}
        return (states, record, finished | done_now, rng), None

    def run(states, record, finished, rng):
        (states, record, finished, rng), _ = jax.lax.scan(
            one_step, (states, record, finished, rng), None, length=chunk
        )
        return states, record, finished, rng

    return jax.jit(reset), jax.jit(run)


def rollout(
    env: PegHoleEnv,
    policy: Policy,
    episodes: int,
    seed: int = 0,
    chunk: int = 25,
    progress: bool = True,
) -> RolloutResult:
    """Run ``episodes`` episodes in one batch until each is done (success or failure)."""
    reset, run = _make_runner(env, policy, chunk)
    rng = jax.random.PRNGKey(seed)
    rng, key = jax.random.split(rng)
    t0 = time.perf_counter()
    states, record, finished = reset(jax.random.split(key, episodes))
    states, record, finished, rng = run(states, record, finished, rng)
    jax.block_until_ready(finished)
    compile_s = time.perf_counter() - t0  # first chunk: compile + chunk steps
    n_chunks = -(-env.config.episode_length // chunk)
    from tqdm import tqdm

    bar = tqdm(
        total=n_chunks * chunk,
        initial=chunk,
        unit="step",
        desc="rollout",
        file=sys.stderr,
        disable=not progress,
    )
    t1 = time.perf_counter()
    steps = chunk
    for _ in range(n_chunks - 1):
        if bool(finished.all()):
            break
        states, record, finished, rng = run(states, record, finished, rng)
        jax.block_until_ready(finished)
        steps += chunk
        bar.update(chunk)
        bar.set_postfix(done=f"{int(finished.sum())}/{episodes}")
    bar.close()
    run_s = time.perf_counter() - t1
    per_episode = {k: np.asarray(v) for k, v in record.items()}
    timed = steps - chunk  # steps after the compiled first chunk
    return RolloutResult(
        per_episode=per_episode,
        compile_s=compile_s,
        run_s=run_s,
        env_steps=timed * episodes,
        physics_steps=timed * episodes * env.n_substeps,
    )
