"""Throughput of the extraction scenes vs the number of worlds, per engine.

Measures physics steps/s and env (control) steps/s (one env step = ``env.n_substeps`` = 10
physics steps of 2 ms) of the ``rect`` (RectExtract, rect-2) and ``dual`` (DualExtract,
dual-2) scenes, with the iiwa and the impedance law, for these engines:

``mjx-jax``
    ``jit(vmap(env.step))`` inside a ``lax.scan`` chunk (the pattern of
    ``peghole_mjx/envs/rollout.py``), the scripted action (``scripted_policy``: straight pull
    at 20 mm/s), finished worlds reset in place to their start state (as Brax's auto-reset).
    Worlds are the start states of 8 randomised resets, tiled (all worlds cost the same in
    MJX-JAX). ``compile_s``: lowering + XLA compilation of the chunk (ahead of time); the
    reset's compile is logged in the side JSON, not in the CSV. CPU or GPU: JAX's default.
``mjx-warp``
    the same with ``impl="warp"`` (MuJoCo Warp); CUDA GPU only, skipped with a message
    otherwise.
``mujoco-c``
    MuJoCo C (``mj_step``) in ONE thread, worlds stepped one after the other, with the
    impedance law ported to NumPy and run in closed loop at every physics step
    (:func:`bench_common.impedance_torque`, tested against the JAX law): the same control
    work per step as the MJX env, paid in Python (so this row is C physics + NumPy control).
``mujoco-c-rollout``
    ``mujoco.rollout`` over all cores (one ``MjData`` per thread). Its controls are OPEN LOOP:
    the joint torques of one closed-loop ``mujoco-c`` episode start (recorded), replayed in
    every world. No control law runs, so this is an UPPER BOUND on what MuJoCo C can do for
    this task on this machine (the law's cost and the Python round trip are left out).
``pybullet``
    PyBullet (the thesis's simulator), its bundled ``kuka_iiwa/model.urdf`` with the peg and
    the hole as boxes, the same impedance law in joint-torque control
    (``benchmarks/pybullet_peghole.py``), one process per core (worlds split over them).
    Rect only: the dual peg-hole is the task PyBullet could not run (convex hull, thesis
    Sec 1.6), so no PyBullet dual rows.

The C engines start from the ``inserted`` keyframe at the nominal hole pose with the env's
randomised commanded errors and friction (the hole pose itself is not moved: that needs an IK
per world and does not change the cost of a step); PyBullet also moves the hole, as the env's
reset does (Newton IK per reset). All engines restart finished episodes, and the restarts are
timed with the steps.

Peak memory: on a GPU, ``peak_bytes_in_use`` of the JAX device (XLA buffers; MuJoCo Warp's own
scratch allocations are not counted); on the CPU, the worker process's max RSS (PyBullet: the
sum over its processes). Every row runs in a fresh subprocess, so RSS and threads do not leak
between rows.

Files: ``benchmarks/results/throughput_<device>.csv`` (columns ``bench_common.COLUMNS``) and a
side JSON ``throughput_<device>.json`` (note, load average, command, per-row details).
``--roofline`` prints and writes ``roofline.json``: the per-world state size (bytes of the
``mjx.Data`` leaves) and the memory-bandwidth roofline on an H100 (3.35 TB/s) and H200
(4.8 TB/s), with the arithmetic.

Run ``python benchmarks/throughput.py --quick`` (under 5 minutes on 2 CPU cores: mjx-jax rect
at 1 and 8 worlds, the C engines on both scenes, PyBullet rect; the dual MJX scene compiles for
3-4 minutes on a CPU, so quick leaves it out) or the full sweep without ``--quick``.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from bench_common import (  # noqa: E402
    COLUMNS,
    ENGINES,
    RESULTS,
    SCENE_OVERRIDES,
    SCENES,
    cpu_device,
    device_label,
    impedance_torque,
    load_average,
    max_rss_mb,
    read_csv,
    rot_from_rotvec,
    utc_now,
    versions_str,
    write_csv,
)

#: memory bandwidth of the target GPUs (data-sheet HBM bandwidth), bytes/s
GPU_BANDWIDTH = {"H100 SXM (HBM3)": 3.35e12, "H200 (HBM3e)": 4.8e12}

#: default sweeps (worlds) per engine; GPU sweeps go to 16384
SWEEP_CPU = {
    "mjx-jax": {"rect": [1, 8, 64, 256], "dual": [1, 8]},
    "mujoco-c": {"rect": [1, 16], "dual": [1, 16]},
    "mujoco-c-rollout": {"rect": [1, 16, 256, 1024], "dual": [1, 16, 256, 1024]},
    "pybullet": {"rect": [1, 2, 8, 16]},
}
SWEEP_GPU = {
    "mjx-jax": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mjx-warp": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mujoco-c": {s: [1, 16] for s in SCENES},
    "mujoco-c-rollout": {s: [1, 16, 256, 1024, 4096] for s in SCENES},
    "pybullet": {"rect": [1, 16, 64]},
}
SWEEP_QUICK = {
    "mjx-jax": {"rect": [1, 8]},
    "mujoco-c": {"rect": [1], "dual": [1]},
    "mujoco-c-rollout": {"rect": [1, 64], "dual": [1, 64]},
    "pybullet": {"rect": [1, 2]},
}


# ----------------------------------------------------------------------------- device
def gpu_kind() -> str | None:
    """The CUDA device kind JAX sees (e.g. ``NVIDIA H100 80GB HBM3``), else None."""
    try:
        import jax

        dev = jax.devices()[0]
        return None if dev.platform == "cpu" else str(getattr(dev, "device_kind", dev.platform))
    except Exception:
        return None


def jax_device_str() -> str:
    from peghole_mjx.provenance import device

    return device()


# ----------------------------------------------------------------------------- roofline
def roofline_estimate(data_bytes: int, bandwidth: float, n_substeps: int = 10) -> dict:
    """Memory-bandwidth roofline for a per-world state of ``data_bytes`` bytes.

    Every physics step must at least read and write each world's ``mjx.Data`` once, so it
    moves >= ``2 * data_bytes``; at ``bandwidth`` bytes/s no engine can exceed
    ``bandwidth / (2 * data_bytes)`` physics steps/s (env steps: that / ``n_substeps``).
    The real traffic is larger (contacts, constraint Jacobians, solver iterations): an upper
    bound on throughput, not a prediction.
    """
    per_step = 2 * int(data_bytes)
    rate = bandwidth / per_step
    return {
        "bytes_per_physics_step": per_step,
        "bandwidth_B_per_s": bandwidth,
        "max_physics_steps_per_s": rate,
        "max_env_steps_per_s": rate / n_substeps,
        "arithmetic": (
            f"{bandwidth:.3g} B/s / (2 x {int(data_bytes)} B read+write per world-step) "
            f"= {rate:.4g} physics steps/s"
        ),
    }


def roofline_fraction(physics_steps_per_s: float, data_bytes: int, bandwidth: float) -> float:
    """Share of the state-traffic roofline a measured rate reaches."""
    return physics_steps_per_s * 2 * data_bytes / bandwidth


def tree_bytes(tree) -> int:
    import jax

    return int(sum(x.size * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree)))


def roofline(scenes: list[str], hlo: bool = True) -> dict:
    """Per-world state size of each scene and the H100/H200 rooflines (printed + returned)."""
    import jax

    import peghole_mjx  # noqa: F401  (XLA CPU flag)
    from peghole_mjx import envs

    out: dict = {"gpus": GPU_BANDWIDTH, "scenes": {}}
    for scene in scenes:
        env = envs.load(SCENES[scene], config_overrides=SCENE_OVERRIDES.get(scene))
        shape = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
        data_b = tree_bytes(shape.data)
        state_b = tree_bytes(shape)
        entry: dict = {
            "env": SCENES[scene],
            "mjx_data_bytes_per_world": data_b,
            "env_state_bytes_per_world": state_b,
            "n_substeps": env.n_substeps,
            "roofline": {
                g: roofline_estimate(data_b, bw, env.n_substeps) for g, bw in GPU_BANDWIDTH.items()
            },
        }
        if hlo:
            entry.update(hlo_traffic(env, shape))
        out["scenes"][scene] = entry
    return out


def hlo_traffic(env, shape, n: int = 9) -> dict:
    """XLA's own count of the bytes one env step touches, per world (un-optimised HLO).

    ``jit(vmap(env.step))`` is lowered for 1 and ``n`` worlds; the difference / (n - 1) is
    the per-world part (the model's arrays, read once per batch, cancel). XLA counts every
    loop body once (one of the 10 substeps, one solver iteration) and the HLO is not yet
    fused, so this is an order-of-magnitude traffic figure for about one physics step, far
    above what fused GPU kernels move: a pessimistic roofline, next to the state-only one.
    """
    import jax

    t0 = time.perf_counter()
    counts = {}
    for w in (1, n):
        a = jax.ShapeDtypeStruct((w, env.action_size), np.float32)
        batched = jax.tree.map(lambda x, w=w: jax.ShapeDtypeStruct((w, *x.shape), x.dtype), shape)
        ca = jax.jit(jax.vmap(env.step)).lower(batched, a).cost_analysis()
        ca = ca[0] if isinstance(ca, list | tuple) else ca
        counts[w] = float((ca or {}).get("bytes accessed", float("nan")))
    per_world = (counts[n] - counts[1]) / (n - 1)
    out: dict = {
        "xla_hlo_bytes": {f"{w}_worlds": b for w, b in counts.items()},
        "xla_hlo_bytes_per_world_step": per_world,
        "xla_hlo_note": (
            f"bytes accessed by XLA's cost analysis of jit(vmap(env.step)), un-optimised HLO, "
            f"(B({n} worlds) - B(1 world)) / {n - 1}: loop bodies (substeps, solver "
            "iterations) counted once, no fusion: order of magnitude only, pessimistic"
        ),
        "lower_s": round(time.perf_counter() - t0, 1),
    }
    if per_world == per_world and per_world > 0:
        out["xla_hlo_roofline"] = {
            g: {
                "max_physics_steps_per_s": bw / per_world,
                "arithmetic": (
                    f"{bw:.3g} B/s / {per_world:.4g} B per world-step = "
                    f"{bw / per_world:.4g} physics steps/s"
                ),
            }
            for g, bw in GPU_BANDWIDTH.items()
        }
    return out


def print_roofline(r: dict) -> None:
    for scene, e in r["scenes"].items():
        print(
            f"[roofline] {scene}: mjx.Data {e['mjx_data_bytes_per_world']} B/world, "
            f"env State {e['env_state_bytes_per_world']} B/world"
        )
        for g, est in e["roofline"].items():
            print(f"  {g}: {est['arithmetic']} ({est['max_env_steps_per_s']:.4g} env steps/s)")
        for g, est in e.get("xla_hlo_roofline", {}).items():
            print(f"  {g} (XLA HLO bytes): {est['arithmetic']}")


# ----------------------------------------------------------------------------- MJX engines
def run_mjx(
    scene: str,
    worlds: int,
    impl: str,
    chunk: int,
    min_time: float,
    representation: str | None = None,
) -> dict:
    import jax
    import jax.numpy as jnp

    import peghole_mjx  # noqa: F401  (XLA CPU flag before JAX starts)
    from peghole_mjx import envs
    from peghole_mjx.envs.rollout import scripted_policy

    gpu = gpu_kind()
    overrides = {"impl": impl, **SCENE_OVERRIDES.get(scene, {})}
    if representation:  # the env's default otherwise (dual: capsule)
        overrides["representation"] = representation
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


# ----------------------------------------------------------------------------- MuJoCo C
class CWorlds:
    """The env's control step in MuJoCo C + the NumPy impedance law, one MjData per world.

    Mirrors ``PegHoleEnv._decode_action`` / ``_physics`` / the done test of ``step`` (hole at
    its nominal pose; commanded lateral and angular errors and the friction scale drawn per
    world as in the env's reset). Finished worlds (success, jamming, time limit, NaN) restart.
    """

    def __init__(self, env, worlds: int, seed: int = 0, record: bool = False):
        import mujoco

        from peghole_mjx.control import ImpedanceController
        from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
        from peghole_mjx.geometry.specs import MM

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
        self.jacp, self.jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        self.M = np.zeros((m.nv, m.nv))
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
        mj, m, ctl = self.mujoco, self.m, self.ctl
        R = d.xmat[self.body].reshape(3, 3)
        x_C = d.xpos[self.body] + R @ (ctl.tip_local - np.array([0.0, 0.0, self.L_C]))
        mj.mj_jac(m, d, self.jacp, self.jacr, x_C, self.body)
        J = np.vstack([self.jacp, self.jacr])[:, ctl.dadr]
        mj.mj_fullM(m, d, self.M)
        tau, _ = impedance_torque(
            J,
            self.M[np.ix_(ctl.dadr, ctl.dadr)],
            d.qfrc_bias[ctl.dadr],
            d.qpos[ctl.qadr],
            d.qvel[ctl.dadr],
            x_C,
            R,
            target_pos,
            target_mat,
            target_vel,
            self.stiff,
            self.zeta,
            ff,
            self.q_null,
            self.null_gains,
            (*self.c.limits.max_force_N, *self.c.limits.max_torque_Nm),
            ctl.ctrl_lo,
            ctl.ctrl_hi,
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
    from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S

    a = np.zeros(env.action_size)
    a[2] = SCRIPTED_SPEED_M_S / env.config.action.max_speed_m_s
    return a


def load_env_quiet(scene: str):
    import peghole_mjx._mjx  # noqa: F401
    from peghole_mjx import envs

    return envs.load(SCENES[scene], config_overrides=SCENE_OVERRIDES.get(scene))


def run_mujoco_c(scene: str, worlds: int, min_time: float) -> dict:
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
    import mujoco
    from mujoco import rollout

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
    sys.path.insert(0, str(HERE))
    from pybullet_peghole import PegHoleSim

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
    import multiprocessing as mp

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


# ----------------------------------------------------------------------------- driver
def run_worker(spec: dict) -> dict:
    engine, scene, worlds = spec["engine"], spec["scene"], spec["worlds"]
    if engine in ("mjx-jax", "mjx-warp"):
        return run_mjx(
            scene,
            worlds,
            "jax" if engine == "mjx-jax" else "warp",
            spec["chunk"],
            spec["min_time"],
            spec.get("representation"),
        )
    if engine == "mujoco-c":
        return run_mujoco_c(scene, worlds, spec["min_time"])
    if engine == "mujoco-c-rollout":
        return run_rollout(scene, worlds, spec["min_time"])
    if engine == "pybullet":
        return run_pybullet(worlds, spec["min_time"])
    raise ValueError(engine)


def skip_reason(engine: str, scene: str, gpu: str | None) -> str | None:
    if engine == "mjx-jax" and SCENE_OVERRIDES.get(scene, {}).get("representation") == "cylinder":
        return "MJX-JAX has no cylinder-box collision (MuJoCo Warp and C only)"
    if engine == "pybullet" and scene != "rect":
        return "PyBullet models the rect peg-hole only (the dual is the task it could not run)"
    if engine == "mjx-warp":
        if gpu is None:
            return "mjx-warp needs a CUDA GPU (none here): skipped"
        from peghole_mjx._mjx import WARP_AVAILABLE

        if not WARP_AVAILABLE:
            return "mjx-warp needs warp-lang (pip install '.[warp]'): skipped"
    if engine == "pybullet":
        try:
            import pybullet  # noqa: F401
        except ImportError:
            return "pybullet not installed (pip install '.[bench]'): skipped"
    return None


def plan(args, gpu: str | None) -> list[dict]:
    if args.quick:
        sweep = SWEEP_QUICK
    else:
        sweep = SWEEP_GPU if gpu else SWEEP_CPU
    jobs = []
    for engine in args.engines:
        for scene in args.scenes:
            worlds = args.worlds or sweep.get(engine, {}).get(scene, [])
            reason = skip_reason(engine, scene, gpu)
            if reason:
                print(f"[skip] {engine} {scene}: {reason}", flush=True)
                continue
            if not worlds:
                print(f"[skip] {engine} {scene}: not in this sweep", flush=True)
            for w in worlds:
                jobs.append(
                    {
                        "engine": engine,
                        "scene": scene,
                        "worlds": int(w),
                        "chunk": args.chunk or (20 if gpu else 5),
                        "min_time": args.min_time,
                    }
                )
    return jobs


#: environment variables the driver set for itself only (not passed on to the workers)
_DRIVER_ONLY_ENV: set[str] = set()


def run_job(job: dict, timeout: float) -> dict | None:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--_worker", json.dumps(job)]
    env = {k: v for k, v in os.environ.items() if k not in _DRIVER_ONLY_ENV}
    t0 = time.perf_counter()
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        print(f"[fail] {job['engine']} {job['scene']} x{job['worlds']}: timeout", flush=True)
        return None
    for line in res.stdout.splitlines():
        if line.startswith("ROW "):
            out = json.loads(line[4:])
            out["wall_s"] = round(time.perf_counter() - t0, 1)
            return out
    print(
        f"[fail] {job['engine']} {job['scene']} x{job['worlds']}: rc={res.returncode}\n"
        + res.stderr[-2000:],
        flush=True,
    )
    return None


def _fmt(x, nd=1):
    return "" if x is None else round(float(x), nd)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="small sweep, < 5 min on 2 CPU cores")
    ap.add_argument("--engines", default=",".join(ENGINES), help="comma list of " + str(ENGINES))
    ap.add_argument("--scenes", default="rect,dual", help="comma list: rect, dual")
    ap.add_argument("--worlds", default=None, help="comma list overriding the default sweep")
    ap.add_argument("--out", type=Path, default=None, help="CSV path (default per device)")
    ap.add_argument("--min-time", type=float, default=None, help="timed seconds per row")
    ap.add_argument("--chunk", type=int, default=None, help="env steps per scan chunk (MJX)")
    ap.add_argument("--timeout", type=float, default=900, help="seconds per row")
    ap.add_argument("--merge", action="store_true", help="keep rows of --out not re-measured")
    ap.add_argument("--roofline", action="store_true", help="print/write the roofline JSON")
    ap.add_argument("--roofline-only", action="store_true", help="roofline, no measurements")
    ap.add_argument("--note", default="", help="free text stored in the side JSON's note")
    ap.add_argument("--_worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args._worker:
        spec = json.loads(args._worker)
        row = run_worker(spec)
        print("ROW " + json.dumps(row, default=float), flush=True)
        return 0

    args.engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    args.scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    bad = [e for e in args.engines if e not in ENGINES] + [
        s for s in args.scenes if s not in SCENES
    ]
    if bad:
        ap.error(f"unknown engine/scene {bad}")
    args.worlds = [int(w) for w in args.worlds.split(",")] if args.worlds else None
    if args.min_time is None:
        args.min_time = 2.0 if args.quick else 8.0

    # the driver only asks which device JAX sees: it must not grab GPU memory (the rows run in
    # worker processes, which keep JAX's default allocator)
    if "XLA_PYTHON_CLIENT_PREALLOCATE" not in os.environ:
        os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
        _DRIVER_ONLY_ENV.add("XLA_PYTHON_CLIENT_PREALLOCATE")
    gpu = gpu_kind()
    label = device_label(gpu)
    out = args.out or RESULTS / (
        f"throughput_{label}_quick.csv" if args.quick else f"throughput_{label}.csv"
    )
    side = out.with_suffix(".json")

    if args.roofline or args.roofline_only:
        r = roofline(args.scenes)
        r.update(date=utc_now(), versions=versions_str())
        print_roofline(r)
        rpath = out.parent / "roofline.json"
        rpath.parent.mkdir(parents=True, exist_ok=True)
        rpath.write_text(json.dumps(r, indent=2) + "\n")
        print(f"[roofline] wrote {rpath}")
        if args.roofline_only:
            return 0

    load0 = load_average()
    jobs = plan(args, gpu)
    rows, details, runs = [], [], []
    if args.merge and out.exists():
        keep = {(j["engine"], j["scene"], j["worlds"]) for j in jobs}
        rows = [
            {k: r[k] if r[k] is not None else "" for k in COLUMNS}
            for r in read_csv(out)
            if (r["engine"], r["scene"], r["worlds"]) not in keep
        ]
        if side.exists():
            old = json.loads(side.read_text())
            runs = old.get("runs", [])
            details = [
                d for d in old.get("rows", []) if (d["engine"], d["scene"], d["worlds"]) not in keep
            ]
    vers = versions_str()
    t_start = time.perf_counter()
    for job in jobs:
        res = run_job(job, args.timeout)
        if res is None:
            continue
        row = {
            "engine": job["engine"],
            "device": res["device"],
            "scene": job["scene"],
            "worlds": job["worlds"],
            "physics_steps_per_s": _fmt(res["physics_steps_per_s"]),
            "env_steps_per_s": _fmt(res["env_steps_per_s"]),
            "compile_s": _fmt(res["compile_s"]),
            "peak_mem_mb": _fmt(res["peak_mem_mb"]),
            "versions": vers,
            "date": utc_now(),
        }
        print(
            f"[row] {row['engine']:17s} {row['scene']:4s} worlds={row['worlds']:<6d} "
            f"physics/s={row['physics_steps_per_s']:<10} env/s={row['env_steps_per_s']:<9} "
            f"compile_s={row['compile_s']} peak_mb={row['peak_mem_mb']} "
            f"(row wall {res['wall_s']} s)",
            flush=True,
        )
        rows.append(row)
        details.append({**{k: row[k] for k in ("engine", "scene", "worlds")}, **res["extra"]})
    order = {e: i for i, e in enumerate(ENGINES)}
    rows.sort(key=lambda r: (order[r["engine"]], r["scene"], int(r["worlds"])))
    write_csv(out, rows)
    # the load averages before and after are recorded with each run: say in --note what else ran
    note = args.note
    runs.append(
        {
            "command": "python benchmarks/throughput.py " + " ".join(sys.argv[1:]),
            "date": utc_now(),
            "rows": [f"{j['engine']} {j['scene']} {j['worlds']}" for j in jobs],
            "load_average_before": load0,
            "load_average_after": load_average(),
            "quick": args.quick,
            "min_time_s": args.min_time,
            "total_wall_s": round(time.perf_counter() - t_start, 1),
        }
    )
    meta = {
        "device": jax_device_str(),
        "date": utc_now(),
        "versions": vers,
        "note": note.strip(),
        "runs": runs,
        "gpu_rows": "measured"
        if gpu
        else "unmeasured here (no GPU): run the same command on "
        "a GPU machine (pip install -e '.[bench,warp]'), it writes throughput_gpu-<kind>.csv",
        "rows": details,
    }
    side.write_text(json.dumps(meta, indent=2, default=float) + "\n")
    print(f"wrote {out} ({len(rows)} rows) and {side}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
