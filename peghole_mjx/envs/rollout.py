"""Batched evaluation rollouts: N episodes side by side, each run until its first ``done``.

Policies are functions ``policy(obs, rng) -> action`` (batched over worlds by ``vmap``), or,
for learned policies whose parameters change between calls without recompiling,
``policy(params, obs, rng) -> action`` passed with ``params=...``:

* :func:`scripted_policy` - the thesis's Ch 2-3 method and the baseline of every RL
  comparison: fixed compliance with the compliance centre at the peg tip, straight pull at a
  constant speed, no lateral correction, no force feed-forward;
* :func:`random_policy` - uniform actions in [-1, 1].
"""

from __future__ import annotations

import functools
import sys
import time
import weakref
from collections.abc import Callable
from dataclasses import asdict, dataclass, make_dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from peghole_mjx import envs
from peghole_mjx.core import memory
from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.config import leaves
from peghole_mjx.envs.extraction import (
    SCRIPTED_SPEED_M_S,
    PegHoleEnv,
    residual_affine,
    scripted_action,
)
from peghole_mjx.envs.metrics import (
    STATS,
    accumulate_return,
    record_keys,
    summarize,
    zero_returns,
)
from peghole_mjx.files import fileio
from peghole_mjx.sim.engines import batch_reset, select_worlds

Policy = Callable[[jax.Array, jax.Array], jax.Array]


@functools.lru_cache(maxsize=16)
def scripted_policy(env: PegHoleEnv, speed_m_s: float = SCRIPTED_SPEED_M_S) -> Policy:
    """Straight pull at ``speed_m_s`` with the env's fixed stiffness and compliance centre
    (:func:`~peghole_mjx.envs.extraction.scripted_action`); on a residual env
    (``action.residual``) the action that makes the step apply it (the pull's residual zero at
    the default speed, the gains' own encoding).

    Cached per env, so rollouts of the baseline reuse their compiled runner.
    """
    c = env.config
    a = scripted_action(c, env.compliance_actions, speed_m_s)
    affine = residual_affine(c, env.compliance_actions)
    if affine is not None:  # held entries: the scripted pull's 0 is their only value
        offset, gain = affine
        a = np.divide(a - offset, gain, out=np.zeros_like(a), where=gain != 0)
        if np.any(np.abs(a) > 1.0 + 1e-6):
            raise UserInputError(
                f"a scripted pull at {speed_m_s:g} m/s is beyond this residual env's reach "
                f"(action.residual_scale {c.action.residual_scale:g} about the "
                f"{SCRIPTED_SPEED_M_S:g} m/s pull)"
            )
    action = jnp.asarray(np.clip(a, -1, 1))
    return lambda obs, rng: action


@functools.lru_cache(maxsize=16)
def random_policy(env: PegHoleEnv) -> Policy:
    n = env.action_size
    return lambda obs, rng: jax.random.uniform(rng, (n,), minval=-1.0, maxval=1.0)


#: the keys of ``peghole envs rollout --json`` and of an evaluation's ``policy`` / ``baseline``:
#: the episode statistics of :data:`peghole_mjx.envs.metrics.STATS` (their docs there)
RolloutSummary = make_dataclass(
    "RolloutSummary",
    [(s.name, int if s.kind in ("episodes", "count") else float) for s in STATS],
    namespace={"as_dict": lambda self: asdict(self)},
)
RolloutSummary.__doc__ = "The episode statistics of a rollout (peghole_mjx.envs.metrics.STATS)."


@dataclass
class RolloutResult:
    """Per-episode arrays and timing of a batched rollout."""

    #: one array per key of the env's record (:func:`~peghole_mjx.envs.metrics.record_keys`)
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
        return RolloutSummary(**summarize(self.per_episode))


@functools.lru_cache(maxsize=16)
def _batch_reset(env: PegHoleEnv) -> Callable:
    """The start of a batch of worlds: one per env, shared by every policy run on it (the
    baseline and the policy of an evaluation trace and load it once).

    On an engine with host callbacks (the ``mujoco`` engine), two compiled graphs:
    :meth:`~peghole_mjx.envs.extraction.PegHoleEnv.reset_start` (pure JAX, most of the
    compile time, kept by the persistent compilation cache) and ``reset_finish`` (the
    engine's first state through a host callback: JAX does not cache such a graph, so it
    compiles in each process, but it is small). The start states are the same as from one
    graph (tests/test_engine_mujoco.py). On MJX, one graph: split, XLA's float32 rounding at the
    boundary moves the start states by an ulp, and the committed MJX results would not
    reproduce bit for bit."""
    if not env.engine.host_callbacks:

        @jax.jit
        def reset(rngs):
            return _batch_start(batch_reset(env, rngs))

        return reset
    start = jax.jit(jax.vmap(env.reset_start))
    finish = jax.jit(lambda starts: _batch_start(jax.vmap(env.reset_finish)(starts)))
    return lambda rngs: finish(start(rngs))


def _batch_start(states):
    """``(states, (record, returns), finished)``: a batch's carry at its reset."""
    n = states.reward.shape[0]
    record = {k: jnp.zeros(n) for k in record_keys(states.metrics)}
    return states, (record, zero_returns(n)), jnp.zeros(n, bool)


@functools.lru_cache(maxsize=16)
def make_runner(env: PegHoleEnv, policy: Callable, chunk: int, with_params: bool, gamma: float):
    """Jitted (reset, run-chunk) over a batch of worlds; finished worlds are frozen.

    Cached per (env, policy, chunk): a trainer that evaluates the same policy function with
    new parameters compiles once. The reset is shared by all policies on ``env``.
    """

    def one_step(carry, _):
        states, (record, acc), finished, rng, params = carry
        rng, key = jax.random.split(rng)
        keys = jax.random.split(key, finished.shape[0])
        if with_params:
            actions = jax.vmap(policy, in_axes=(None, 0, 0))(params, states.obs, keys)
        else:
            actions = jax.vmap(policy)(states.obs, keys)
        new = jax.vmap(env.step)(states, actions)
        done_now = (new.done > 0) & ~finished

        states = select_worlds(finished, states, new)
        r = jnp.where(finished, 0.0, new.reward)
        acc = accumulate_return(acc, r, gamma)
        ended = {**new.metrics, **acc}
        record = {k: jnp.where(done_now, ended[k], record[k]) for k in record}
        return (states, (record, acc), finished | done_now, rng, params), None

    def run(states, record, finished, rng, params):
        (states, record, finished, rng, _), _ = jax.lax.scan(
            one_step, (states, record, finished, rng, params), None, length=chunk
        )
        return states, record, finished, rng

    return _batch_reset(env), jax.jit(run)


def episode_keys(seed: int, episodes: int) -> tuple[jax.Array, jax.Array]:
    """``(rng, reset_keys)`` of a rollout with ``seed``: the key its policy draws from and the
    ``episodes`` reset keys (episode i starts from ``reset_keys[i]`` in every rollout of this
    seed, whatever the episode count or batch)."""
    rng, key = jax.random.split(jax.random.PRNGKey(seed))
    return rng, jax.random.split(key, episodes)


def rollout(
    env: PegHoleEnv,
    policy: Policy,
    episodes: int,
    seed: int = 0,
    chunk: int = 25,
    progress: bool = True,
    params: Any = None,
    gamma: float = 0.99,
    batch: int | None = None,
    parts_dir: str | Path | None = None,
    refuse_all_nan: bool = True,
    label: str = "rollout",
) -> RolloutResult:
    """Run ``episodes`` episodes until each is done (success or failure).

    The episodes' start states depend only on ``seed``: two policies run with the same seed
    meet the same randomised episodes, and the first n of a longer run are the n of a shorter
    one (keys split from one seed are prefix-stable with JAX's partitionable threefry). With
    ``params``, ``policy`` is called as ``policy(params, obs, rng)``.

    A rollout in which every episode ended in a non-finite (NaN) world has no result to report:
    with ``refuse_all_nan`` (the default) it raises :class:`UserInputError` naming the likely
    cause (:func:`check_not_all_nan`).

    ``batch``: run at most this many worlds at once (slices of the same start states; one
    compiled shape). ``parts_dir``: save each finished slice there and load the slices already
    saved, so an interrupted long evaluation continues where it stopped or is extended (the
    caller keys the folder to the policy, env, seed and batch; slice files are named by their
    first episode and size).

    ``label`` names the progress bar (``policy rollout``, ``baseline rollout``); with
    ``progress`` the first chunk of a runner not compiled yet in this process is shown as
    ``compiling the env step and policy of the <label>`` (:mod:`peghole_mjx.core.progress`).
    """
    if not jax.config.jax_threefry_partitionable:
        raise RuntimeError("rollout needs jax_threefry_partitionable=True (prefix-stable keys)")
    batch = episodes if batch is None else max(1, min(batch, episodes))
    check_policy_actions(env, policy, params)  # traced for shapes only: nothing compiled
    # before anything is allocated or compiled: the worlds of one batch must fit in memory
    memory.check_worlds(env, batch, "a rollout batch", "run fewer episodes at once (--batch)")
    rng, reset_keys = episode_keys(seed, episodes)
    parts = Path(parts_dir) if parts_dir is not None else None
    if parts is not None:
        parts.mkdir(parents=True, exist_ok=True)
    records, compile_s, run_s, env_steps = [], 0.0, 0.0, 0
    for start in range(0, episodes, batch):
        n = min(batch, episodes - start)
        saved = parts / f"episodes_{start:07d}_{n:07d}.npz" if parts is not None else None
        if saved is not None and saved.exists():
            with np.load(saved) as z:
                records.append({k: z[k] for k in z.files})
            continue
        slice_rng = rng if start == 0 else jax.random.fold_in(rng, start)
        keys = reset_keys[start : start + n]
        if n < batch:  # a short last slice is padded to the compiled shape, extras dropped
            keys = jnp.concatenate([keys, reset_keys[: batch - n]])
        rec, c_s, r_s, steps = _rollout_slice(
            env,
            policy,
            keys,
            slice_rng,
            chunk,
            params,
            gamma,
            progress=progress,
            desc=f"{label} {start + n}/{episodes}" if n < episodes else label,
        )
        rec = {k: v[:n] for k, v in rec.items()}
        records.append(rec)
        compile_s, run_s, env_steps = compile_s + c_s, run_s + r_s, env_steps + steps
        if saved is not None:  # atomic and flushed: a kill or power cut leaves no torn slice
            fileio.write_bytes_with(saved, lambda f, rec=rec: np.savez(f, **rec))
    per_episode = {k: np.concatenate([r[k] for r in records]) for k in records[0]}
    result = RolloutResult(
        per_episode=per_episode,
        compile_s=compile_s,
        run_s=run_s,
        env_steps=env_steps,
        physics_steps=env_steps * env.n_substeps,
    )
    if refuse_all_nan:
        check_not_all_nan(result, env, params)
    return result


def check_policy_actions(env: PegHoleEnv, policy: Callable, params: Any = None) -> None:
    """Refuse (one line) a policy whose action is not one vector of ``env.action_size`` real
    numbers (a 4- or 9-action policy on a 6-action env): its output is traced with
    ``jax.eval_shape`` (shapes only, nothing compiled or run) before any rollout."""
    obs = jax.ShapeDtypeStruct((env.observation_size,), jnp.float32)
    key = jax.eval_shape(lambda: jax.random.PRNGKey(0))
    if params is None:
        out = jax.eval_shape(policy, obs, key)
    else:
        out = jax.eval_shape(policy, params, obs, key)
    want, name = (env.action_size,), getattr(env, "env_name", type(env).__name__)
    if not hasattr(out, "shape") or tuple(out.shape) != want:
        got = tuple(out.shape) if hasattr(out, "shape") else type(out).__name__
        raise UserInputError(
            f"the policy gives actions of shape {got}; {name} takes one action "
            f"vector of shape {want} (its action_size)"
        )
    if not jnp.issubdtype(out.dtype, jnp.floating):
        raise UserInputError(
            f"the policy gives actions of dtype {out.dtype}; {name} takes float actions in [-1, 1]"
        )


def check_not_all_nan(result: RolloutResult, env: PegHoleEnv, params: Any = None) -> None:
    """:class:`UserInputError` when every episode of ``result`` ended in a non-finite world
    (a NaN action or a diverged simulation): a failure with its likely cause, not a result.

    The cause named: policy ``params`` that are not finite, else the entries of the env config
    that differ from the env's defaults, else the policy's actions (a NaN action ends its
    episode as a NaN world)."""
    nan = np.asarray(result.per_episode["nan"]) > 0
    if nan.size == 0 or not nan.all():
        return
    leaves = jax.tree.leaves(params) if params is not None else []
    if any(not np.isfinite(np.asarray(x, np.float64)).all() for x in leaves):
        cause = "the policy's parameters are not finite (NaN or inf)"
    else:
        changed = _config_changes(env)
        if changed:
            shown = ", ".join(f"{k}={v!r}" for k, v in changed[:6])
            more = f" and {len(changed) - 6} more" if len(changed) > 6 else ""
            cause = (
                f"the simulation diverged under the env config's changes from the "
                f"{env.env_name} defaults ({shown}{more})"
            )
        else:
            cause = (
                f"the policy's actions (a NaN action ends its episode) or the physics at the "
                f"{env.env_name} defaults"
            )
    raise UserInputError(
        f"all {nan.size} episodes ended in a non-finite (NaN) world: no result to report; "
        f"likely cause: {cause}"
    )


def _config_changes(env: PegHoleEnv) -> list[tuple[str, Any]]:
    """``(flat key, value)`` of the env config's entries that differ from its env's defaults
    (the engine choice left out: it is set per machine)."""
    if env.env_name not in envs.ENV_NAMES:
        return []
    default = dict(leaves(envs.get_default_config(env.env_name)))
    return [
        (k, v)
        for k, v in leaves(env.config)
        if k not in ("engine", "impl", "mujoco_threads") and default.get(k) != v
    ]


#: the runners (:func:`make_runner`'s jitted run) that have compiled in this process: their
#: first chunk is not labelled as a compile again
_COMPILED: weakref.WeakSet = weakref.WeakSet()


def _rollout_slice(env, policy, reset_keys, rng, chunk, params, gamma, progress, desc):
    """One batch of worlds until all are done: (per-episode record, compile s, run s, steps)."""
    episodes = reset_keys.shape[0]
    reset, run = make_runner(env, policy, chunk, params is not None, gamma)
    t0 = time.perf_counter()
    fresh = run not in _COMPILED
    with prog.compiling(f"the env step and policy of the {desc}", enabled=progress and fresh):
        states, record, finished = reset(reset_keys)
        states, record, finished, rng = run(states, record, finished, rng, params)
        jax.block_until_ready(finished)
    _COMPILED.add(run)
    compile_s = time.perf_counter() - t0  # first chunk: compile + chunk steps
    n_chunks = -(-env.config.episode_length // chunk)

    bar = tqdm(
        total=n_chunks * chunk,
        initial=chunk,
        unit="step",
        desc=desc,
        file=sys.stderr,
        disable=not progress,
        dynamic_ncols=True,
    )
    t1 = time.perf_counter()
    steps = chunk
    for _ in range(n_chunks - 1):
        if bool(finished.all()):
            break
        states, record, finished, rng = run(states, record, finished, rng, params)
        jax.block_until_ready(finished)
        steps += chunk
        bar.update(chunk)
        bar.set_postfix(done=f"{int(finished.sum())}/{episodes}")
    bar.close()
    run_s = time.perf_counter() - t1
    per_episode = {k: np.asarray(v) for k, v in record[0].items()}
    timed = steps - chunk  # steps after the compiled first chunk
    return per_episode, compile_s, run_s, timed * episodes
