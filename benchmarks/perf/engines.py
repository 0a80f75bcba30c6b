"""The throughput engines: one measured row per (engine, scene, worlds), run in a worker.

``run_mjx`` (MJX-JAX or MuJoCo Warp: ``jit(vmap(env.step))`` in a ``lax.scan`` chunk),
``run_mujoco_c`` (MuJoCo C + the NumPy impedance law, :class:`CWorlds`), ``run_rollout``
(``mujoco.rollout``, open loop: an upper bound) and ``run_pybullet`` (the PyBullet baseline,
one process per core). :mod:`benchmarks.perf.throughput` (the runner) describes each engine and
starts every row in a fresh process.
"""

from __future__ import annotations

import copy
import math
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
from peghole_mjx.control import ImpedanceController
from peghole_mjx.control.reference import impedance_torque_c, rot_from_rotvec
from peghole_mjx.envs.engine_mujoco import available_threads
from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S, scripted_policy
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
from peghole_mjx.geometry.specs import MM
from peghole_mjx.provenance import device


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
    overrides = {"impl": impl, **SCENE_OVERRIDES.get(scene, {}), **(engine_overrides or {})}
    if representation:  # the env's default otherwise (dual: capsule)
        overrides["representation"] = representation
    if env is None:
        env = envs.load(SCENES[scene], config_overrides=overrides)
    action = scripted_policy(env)(None, None)
    n_reset = worlds if (gpu or impl == "warp") else min(worlds, 8)
    t0 = time.perf_counter()
    base = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n_reset))
    jax.block_until_ready(base.obs)
    reset_s = time.perf_counter() - t0
    reps = -(-worlds // n_reset)
    init = jax.tree.map(lambda x: jnp.concatenate([x] * reps)[:worlds], base)

    def run(states, init):
        def body(s, _):
            new = jax.vmap(env.step, in_axes=(0, None))(s, action)
            done = new.done > 0

            def pick(n, i):
                return jnp.where(done.reshape((-1,) + (1,) * (n.ndim - 1)), i, n)

            return jax.tree.map(pick, new, init), None

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
class CWorlds:
    """The env's control step in MuJoCo C + the NumPy impedance law, one MjData per world.

    Mirrors ``PegHoleEnv._decode_action`` / ``_physics`` / the done test of ``step`` (hole at
    its nominal pose; commanded lateral and angular errors and the friction scale drawn per
    world as in the env's reset). Finished worlds (success, jamming, time limit, NaN) restart.
    """

    def __init__(self, env, worlds: int, seed: int = 0, record: bool = False):
        self.mujoco, self.MM = mujoco, MM
        self.c = env.config
        self.m = env.mj_model
        m = self.m
        self.ctl = ImpedanceController.from_model(m)
        self.body = self.ctl.body_id
        self.n_sub = env.n_substeps
        s = self.c.stiffness
        self.L_C = float(s.compliance_centre_mm) * MM
        self.stiff = np.array(
            [s.k_xy_N_m, s.k_xy_N_m, s.k_z_N_m, s.k_rot_Nm_rad, s.k_rot_Nm_rad, s.k_rot_Nm_rad]
        )
        self.zeta = float(s.damping_ratio)
        self.null_gains = (s.null_stiffness_Nm_rad, s.null_damping_Nms_rad)
        key = m.key("inserted")
        self.key_id = key.id
        self.q_null = np.array(key.qpos)[self.ctl.qadr]
        self.fric0 = np.array(m.pair_friction)
        self.tool_down = TOOL_DOWN_MAT
        self.hole_body = m.body("hole").id
        self.rng = np.random.default_rng(seed)
        self.datas = [mujoco.MjData(m) for _ in range(worlds)]
        self.info = [None] * worlds
        for w in range(worlds):
            self.reset(w)
        self.record = record
        self.ctrl_log: list[np.ndarray] = []
        self.resets = 0
        self.last_outcome: str | None = None

    def tip(self, d) -> np.ndarray:
        return d.xpos[self.body] + d.xmat[self.body].reshape(3, 3) @ self.ctl.tip_local

    def depth_mm(self, d, info) -> float:
        return float(-(info["hole_mat"].T @ (self.tip(d) - info["hole_pos"]))[2] / self.MM)

    def reset(self, w: int) -> None:
        mj, m, d, r = self.mujoco, self.m, self.datas[w], self.c.randomization
        mj.mj_resetDataKeyframe(m, d, self.key_id)
        mj.mj_forward(m, d)
        rad = r.lateral_error_mm * self.MM * math.sqrt(self.rng.uniform())
        ang = self.rng.uniform(0.0, 2 * math.pi)
        tilt = self.rng.uniform(-1.0, 1.0, 2) * math.radians(r.angular_error_deg)
        H = np.eye(3)
        info = {
            "hole_pos": d.xpos[self.hole_body].copy(),
            "hole_mat": H,
            "cmd_tip": self.tip(d) + np.array([rad * math.cos(ang), rad * math.sin(ang), 0.0]),
            "cmd_mat": H @ rot_from_rotvec(np.array([tilt[0], tilt[1], 0.0])) @ self.tool_down,
            "wrench_ff": np.zeros(3),
            "fric": self.rng.uniform(*r.friction_scale),
            "jam_time": 0.0,
            "step": 0,
        }
        info["depth_mm"] = self.depth_mm(d, info)
        self.info[w] = info

    def law(self, d, target_pos, target_mat, target_vel, ff) -> np.ndarray:
        """Joint torques of the NumPy reference law with the env config's gains and caps."""
        tau, _ = impedance_torque_c(
            self.ctl,
            self.m,
            d,
            self.L_C,
            target_pos,
            target_mat,
            target_vel,
            self.stiff,
            self.zeta,
            ff,
            self.q_null,
            self.null_gains,
            max_wrench=(*self.c.limits.max_force_N, *self.c.limits.max_torque_Nm),
        )
        return tau

    def step(self, w: int, action: np.ndarray) -> bool:
        """One env step of world ``w``; returns True when its episode ended (and restarts it)."""
        mj, m, d, c, info = self.mujoco, self.m, self.datas[w], self.c, self.info[w]
        a = np.clip(action, -1.0, 1.0)
        H = info["hole_mat"]
        prev = info["cmd_tip"]
        dxy = a[:2] * c.action.max_step_offset_mm * self.MM
        cmd_tip = prev + H @ np.array([dxy[0], dxy[1], a[2] * c.action.max_speed_m_s * c.ctrl_dt])
        fx, fy, fz = c.limits.max_force_N  # the env's feed-forward caps (envs/extraction.py)
        cap = np.asarray((min(fx, c.action.max_ff_xy_N), min(fy, c.action.max_ff_xy_N), fz))
        wff = np.clip(info["wrench_ff"] + a[3:6] * c.action.max_force_step_N, -cap, cap)
        cmd_mat = info["cmd_mat"]
        axis = cmd_mat[:, 2]
        vel = (cmd_tip - prev) / c.ctrl_dt
        ff = np.concatenate([cmd_mat.T @ (H @ wff), np.zeros(3)])
        m.pair_friction[:] = self.fric0 * info["fric"]
        for i in range(self.n_sub):
            tip = prev + (i + 1.0) / self.n_sub * (cmd_tip - prev)
            tau = self.law(d, tip - self.L_C * axis, cmd_mat, vel, ff)
            d.ctrl[self.ctl.act] = tau
            if self.record:
                self.ctrl_log.append(d.ctrl.copy())
            mj.mj_step(m, d)
        info.update(cmd_tip=cmd_tip, wrench_ff=wff, step=info["step"] + 1)
        finite = bool(np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))
        depth = self.depth_mm(d, info) if finite else math.nan
        success = finite and depth < -c.success_margin_mm
        done = success or (not finite) or info["step"] >= c.episode_length
        if done:
            self.last_outcome = "success" if success else "failure"
            self.reset(w)
            self.resets += 1
        return done


def scripted_action(env) -> np.ndarray:
    """The scripted pull as an env action (SCRIPTED_SPEED_M_S straight out)."""
    a = np.zeros(env.action_size)
    a[2] = SCRIPTED_SPEED_M_S / env.config.action.max_speed_m_s
    return a


def load_env_quiet(scene: str):
    """The env of a throughput scene (its collision representation's overrides applied)."""
    return envs.load(SCENES[scene], config_overrides=SCENE_OVERRIDES.get(scene))


def run_mujoco_c(scene: str, worlds: int, min_time: float) -> dict:
    """One throughput row of MuJoCo C + the NumPy law (:class:`CWorlds`), one thread."""
    env = load_env_quiet(scene)
    cw = CWorlds(env, worlds)
    a = scripted_action(env)
    steps, t0 = 0, time.perf_counter()
    while True:
        for w in range(worlds):
            cw.step(w, a)
        steps += worlds
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time:
            break
    return {
        "device": cpu_device(),
        "physics_steps_per_s": steps * env.n_substeps / elapsed,
        "env_steps_per_s": steps / elapsed,
        "compile_s": None,
        "peak_mem_mb": max_rss_mb(),
        "extra": {"threads": 1, "episode_restarts": cw.resets, "timed_s": round(elapsed, 2)},
    }


def run_rollout(scene: str, worlds: int, min_time: float, nstep: int = 200) -> dict:
    """One throughput row of ``mujoco.rollout`` replaying recorded torques open loop on all
    cores (an upper bound of MuJoCo C's rate)."""
    env = load_env_quiet(scene)
    rec = CWorlds(env, 1, record=True)
    a = scripted_action(env)
    for _ in range(-(-nstep // env.n_substeps)):
        rec.step(0, a)
    control = np.asarray(rec.ctrl_log[:nstep])[None]  # (1, nstep, nu), tiled over worlds
    cw = CWorlds(env, min(worlds, 8), seed=1)
    m0 = env.mj_model
    models = []
    for w in range(min(worlds, 8)):  # per-world friction: up to 8 distinct model copies
        mw = copy.copy(m0)
        mw.pair_friction[:] = cw.fric0 * cw.info[w]["fric"]
        models.append(mw)
    models = [models[w % len(models)] for w in range(worlds)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    size = mujoco.mj_stateSize(m0, spec)
    init = np.empty((worlds, size))
    for w in range(worlds):
        d = cw.datas[w % len(cw.datas)]
        mujoco.mj_getState(m0, d, init[w], spec)
    nthread = os.cpu_count() or 1
    datas = [mujoco.MjData(m0) for _ in range(nthread)]
    state = np.empty((worlds, nstep, size))
    sens = np.empty((worlds, nstep, m0.nsensordata))
    calls, t0 = 0, None
    with rollout.Rollout(nthread=nthread) as r:
        r.rollout(models, datas, init, control, state=state, sensordata=sens)  # warm-up
        t0 = time.perf_counter()
        while True:
            r.rollout(models, datas, init, control, state=state, sensordata=sens)
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
