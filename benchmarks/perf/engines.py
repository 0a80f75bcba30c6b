"""The throughput engines: one measured row per (engine, scene, worlds), run in a worker.

``run_mjx`` (MJX-JAX or MuJoCo Warp: ``jit(vmap(env.step))`` in a ``lax.scan`` chunk),
``run_env_mujoco`` (the same on the env's ``mujoco`` engine), ``run_rollout``
(``mujoco.rollout``, open loop, torques recorded on the env's ``mujoco`` engine: an upper
bound) and ``run_pybullet`` (the PyBullet baseline, one process per core). Every MuJoCo row
runs the env itself: the task (action decoding, law, termination) has one implementation,
``peghole_mjx/envs/extraction.py`` (the one-thread ``mujoco-c`` engine, a second copy of the
env's step in this module, was retired on 2026-12-02). :mod:`benchmarks.perf.throughput` (the
runner) describes each engine and starts every row in a fresh process.
"""

from __future__ import annotations

import copy
import functools
import multiprocessing as mp
import os
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import rollout

from benchmarks.baselines.pybullet_peghole import PegHoleSim
from benchmarks.common import SCENE_OVERRIDES, SCENES, cpu_device, max_rss_mb
from peghole_mjx import envs
from peghole_mjx.envs.iiwa_constants import HOLE_BODY
from peghole_mjx.envs.rollout import scripted_policy
from peghole_mjx.files.provenance import device
from peghole_mjx.sim.engine_mujoco import available_threads
from peghole_mjx.sim.engines import batch_reset, select_worlds


# ----------------------------------------------------------------------------- device
def gpu_kind() -> str | None:
    """The CUDA device kind JAX sees (e.g. ``NVIDIA H100 80GB HBM3``), else None."""
    try:
        dev = jax.devices()[0]
        return None if dev.platform == "cpu" else str(getattr(dev, "device_kind", dev.platform))
    except Exception:
        return None


def jax_device_str() -> str:
    """The device JAX runs on, in words (provenance's ``device``)."""
    return device()


# ----------------------------------------------------------------------------- MJX engines
def run_mjx(
    scene: str,
    worlds: int,
    impl: str,
    chunk: int,
    min_time: float,
    representation: str | None = None,
    engine_overrides: dict | None = None,
    env=None,
) -> dict:
    """One throughput row of the env on MJX (``impl`` jax or warp): a jitted, scanned chunk
    of ``vmap(env.step)`` over ``worlds`` worlds, timed for at least ``min_time`` s."""
    gpu = gpu_kind()
    overrides = {"engine": "mjx", "impl": impl, **SCENE_OVERRIDES.get(scene, {})}
    overrides |= engine_overrides or {}
    if representation:  # the env's default otherwise (dual: capsule)
        overrides["representation"] = representation
    if env is None:
        env = envs.load(SCENES[scene], config_overrides=overrides)
        if env.engine.name != "mjx":  # an MJX row must never measure the auto default
            raise RuntimeError(f"an mjx-{impl} row built a {env.engine.name} env")
    action = scripted_policy(env)(None, None)
    n_reset = worlds if (gpu or impl == "warp") else min(worlds, 8)
    t0 = time.perf_counter()
    base = jax.jit(functools.partial(batch_reset, env))(
        jax.random.split(jax.random.PRNGKey(0), n_reset)
    )
    jax.block_until_ready(base.obs)
    reset_s = time.perf_counter() - t0
    reps = -(-worlds // n_reset)
    init = base  # MuJoCo Warp: every world reset (its contact pool is sized for the batch)
    if n_reset < worlds:
        init = jax.tree.map(lambda x: jnp.concatenate([x] * reps)[:worlds], base)

    def run(states, init):
        def body(s, _):
            new = jax.vmap(env.step, in_axes=(0, None))(s, action)
            return select_worlds(new.done > 0, init, new), None

        states, _ = jax.lax.scan(body, states, None, length=chunk)
        return states

    t0 = time.perf_counter()
    compiled = jax.jit(run).lower(init, init).compile()
    compile_s = time.perf_counter() - t0
    states = compiled(init, init)  # warm-up
    jax.block_until_ready(states.obs)
    calls, t0 = 0, time.perf_counter()
    while True:
        states = compiled(states, init)
        jax.block_until_ready(states.obs)
        calls += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time and calls >= 2:
            break
    env_steps = calls * chunk * worlds
    nan = float(jnp.mean(states.metrics["nan"]))
    if gpu:
        stats = jax.devices()[0].memory_stats() or {}
        peak = stats.get("peak_bytes_in_use", float("nan")) / 2**20
    else:
        peak = max_rss_mb()
    return {
        "device": jax_device_str(),
        "physics_steps_per_s": env_steps * env.n_substeps / elapsed,
        "env_steps_per_s": env_steps / elapsed,
        "compile_s": compile_s,
        "peak_mem_mb": peak,
        "extra": {
            "reset_compile_and_run_s": round(reset_s, 1),
            "chunk_env_steps": chunk,
            "timed_s": round(elapsed, 2),
            "nan_world_share": nan,
            "distinct_start_states": n_reset,
        },
    }


def run_env_mujoco(
    scene: str, worlds: int, chunk: int, min_time: float, threads: int, ceiling: bool = False
) -> dict:
    """The env on the ``mujoco`` engine (MuJoCo C via mujoco.batch, ``threads`` threads, 0 =
    all): the same jitted, scanned ``vmap(env.step)`` as :func:`run_mjx`.

    ``ceiling``: the row's rates are those of ``Batch.step`` alone in the same run (the
    physics of the env's own states with the law's cost taken out: what the engine would
    reach if its host law and callback cost nothing)."""
    over = {**SCENE_OVERRIDES.get(scene, {}), "engine": "mujoco", "mujoco_threads": threads}
    env = envs.load(SCENES[scene], config_overrides=over)
    row = run_mjx(scene, worlds, "jax", chunk, min_time, env=env)
    t = env.engine.timing
    row["device"] = cpu_device()
    share = t["batch_step_s"] / max(t["callback_s"], 1e-12)
    row["extra"].update(
        threads=threads or available_threads(),
        batch_step_share_of_callback=round(share, 3),
        callback_s=round(t["callback_s"], 2),
        batch_step_s=round(t["batch_step_s"], 2),
    )
    if ceiling:
        # every call of the run (warm-up and reset included) is timed alike: the rates scale by
        # the callbacks' time over Batch.step's
        row["physics_steps_per_s"] /= share
        row["env_steps_per_s"] /= share
        row["compile_s"] = None
        row["extra"]["law"] = "none: Batch.step time alone, same run and states"
    return row


# ----------------------------------------------------------------------------- MuJoCo C
def record_starts(scene: str, starts: int, nstep: int, seed: int = 1) -> dict:
    """Closed-loop torques of ``starts`` randomised episode starts of a throughput scene, on the
    env's own ``mujoco`` engine under the scripted pull, ``nstep`` physics steps each.

    The env is stepped as any caller steps it (``jit(vmap(env.step))`` from
    ``jit(vmap(env.reset))``) with the engine's torque record on
    (:attr:`~peghole_mjx.sim.engine_mujoco.MujocoEngine.ctrl_log`). Returns ``control``
    ``(starts, nstep, nu)``; per start, for ``mujoco.rollout``: ``state`` (mjSTATE_FULLPHYSICS
    rows, written from the reset state by ``env.engine.to_mjdata``), ``warmstart``
    (``qacc_warmstart``) and ``models`` (copies of the engine's model with that start's hole
    pose on the hole's mocap body, which ``mujoco.rollout`` resets its data from, and its
    friction scale, ``State.info["friction_scale"]``, on ``pair_friction``)."""
    over = {**SCENE_OVERRIDES.get(scene, {}), "engine": "mujoco"}
    env = envs.load(SCENES[scene], config_overrides=over)
    with jax.default_device(jax.devices("cpu")[0]):  # a CPU engine, also on a GPU machine
        s = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), starts))
        step = jax.jit(jax.vmap(env.step, in_axes=(0, None)))
        action = scripted_policy(env)(None, None)
    m0 = env.engine.model
    d = mujoco.MjData(m0)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty((starts, mujoco.mj_stateSize(m0, spec)))
    warmstart = np.empty((starts, m0.nv))
    hole = m0.body(HOLE_BODY).id
    mocap = int(m0.body_mocapid[hole])
    fscale = np.asarray(s.info["friction_scale"], float)
    data0 = jax.tree.map(np.asarray, s.data)
    models = []
    for w in range(starts):
        env.engine.to_mjdata(jax.tree.map(lambda x, w=w: x[w], data0), m0, d)
        mujoco.mj_getState(m0, d, state[w], spec)
        warmstart[w] = d.qacc_warmstart
        mw = copy.copy(m0)
        mw.pair_friction[:] = m0.pair_friction * fscale[w]
        mw.body_pos[hole], mw.body_quat[hole] = d.mocap_pos[mocap], d.mocap_quat[mocap]
        models.append(mw)
    log: list[np.ndarray] = []
    env.engine.ctrl_log = log
    try:
        with jax.default_device(jax.devices("cpu")[0]):
            for _ in range(-(-nstep // env.n_substeps)):
                s = step(s, action)
            jax.block_until_ready(s.obs)
    finally:
        env.engine.ctrl_log = None
    control = np.stack(log[:nstep], axis=1)  # (starts, nstep, nu)
    return {
        "env": env,
        "control": control,
        "state": state,
        "warmstart": warmstart,
        "models": models,
        "episodes_ended": int(np.sum(np.asarray(s.done) > 0)),
    }


def run_rollout(scene: str, worlds: int, min_time: float, nstep: int = 200) -> dict:
    """One throughput row of ``mujoco.rollout`` replaying recorded torques open loop on all
    cores (an upper bound of MuJoCo C's rate): world ``w`` replays start ``w mod 8`` of
    :func:`record_starts` (the env's ``mujoco`` engine, closed loop) from that start's state."""
    rec = record_starts(scene, min(worlds, 8), nstep)
    env, n_rec = rec["env"], len(rec["models"])
    pick = np.arange(worlds) % n_rec
    models = [rec["models"][i] for i in pick]
    init, warm, control = rec["state"][pick], rec["warmstart"][pick], rec["control"][pick]
    m0 = models[0]
    nthread = os.cpu_count() or 1
    datas = [mujoco.MjData(m0) for _ in range(nthread)]
    state = np.empty((worlds, nstep, init.shape[1]))
    sens = np.empty((worlds, nstep, m0.nsensordata))
    calls, t0 = 0, None
    kw = {"initial_warmstart": warm, "state": state, "sensordata": sens}
    with rollout.Rollout(nthread=nthread) as r:
        r.rollout(models, datas, init, control, **kw)  # warm-up
        t0 = time.perf_counter()
        while True:
            r.rollout(models, datas, init, control, **kw)
            calls += 1
            elapsed = time.perf_counter() - t0
            if elapsed >= min_time and calls >= 2:
                break
    nan = float(np.mean(~np.isfinite(state[:, -1]).all(axis=1)))
    phys = calls * worlds * nstep
    return {
        "device": cpu_device(),
        "physics_steps_per_s": phys / elapsed,
        "env_steps_per_s": phys / env.n_substeps / elapsed,
        "compile_s": None,
        "peak_mem_mb": max_rss_mb(),
        "extra": {
            "threads": nthread,
            "nstep_per_rollout": nstep,
            "controls": "open loop: recorded closed-loop torques replayed (upper bound)",
            "recorded": f"the env's mujoco engine (MujocoEngine.ctrl_log), {n_rec} starts",
            "recorded_episodes_ended": rec["episodes_ended"],
            "nan_world_share": nan,
            "timed_s": round(elapsed, 2),
        },
    }


# ----------------------------------------------------------------------------- PyBullet
def _pybullet_worker(args) -> dict:
    n_sims, min_time, seed, barrier = args
    sims = [PegHoleSim(seed=seed + i) for i in range(n_sims)]
    for s in sims:
        s.reset()
    a = np.zeros(6)
    a[2] = 0.02 / sims[0].c.action.max_speed_m_s  # the scripted pull (20 mm/s)
    barrier.wait()  # all processes have built their worlds: the clocks start together
    steps, resets, t0 = 0, 0, time.perf_counter()
    while True:
        for s in sims:
            r = s.step(a)
            if r.success or r.failure:
                s.reset()
                resets += 1
        steps += n_sims
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time:
            break
    for s in sims:
        s.close()
    return {"env_steps": steps, "elapsed": elapsed, "rss_mb": max_rss_mb(), "resets": resets}


def run_pybullet(worlds: int, min_time: float) -> dict:
    """One throughput row of the PyBullet baseline env, one process per core."""
    nproc = min(worlds, os.cpu_count() or 1)
    split = [worlds // nproc + (1 if i < worlds % nproc else 0) for i in range(nproc)]
    ctx = mp.get_context("spawn")
    with ctx.Manager() as mgr:
        barrier = mgr.Barrier(nproc)
        with ctx.Pool(nproc) as pool:
            out = pool.map(
                _pybullet_worker, [(n, min_time, 100 * i, barrier) for i, n in enumerate(split)]
            )
    rate = sum(o["env_steps"] / o["elapsed"] for o in out)
    n_sub = 10
    return {
        "device": cpu_device(),
        "physics_steps_per_s": rate * n_sub,
        "env_steps_per_s": rate,
        "compile_s": None,
        "peak_mem_mb": sum(o["rss_mb"] for o in out) + max_rss_mb(),
        "extra": {
            "processes": nproc,
            "worlds_per_process": split,
            "episode_restarts": sum(o["resets"] for o in out),
        },
    }
