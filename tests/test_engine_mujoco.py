"""The ``mujoco`` engine (MuJoCo C through mujoco.batch, sim/engine_mujoco.py): its array
kinematics against MuJoCo's own, its substeps against a loop over one MjData per world, per-world
model fields, NaN worlds, and its bad-input errors."""

import json
import types

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from benchmarks.common import PERF_RESULTS
from benchmarks.studies import engine_contacts
from peghole_mjx import envs
from peghole_mjx.control.reference import impedance_torque, impedance_torque_c
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.rollout import _batch_reset, scripted_policy
from peghole_mjx.sim.engine_mujoco import STATE_SPEC, MujocoEngine

N = 4


@pytest.fixture(scope="module")
def env():
    return envs.load("RectExtract", config_overrides={"engine": "mujoco", "mujoco_threads": 2})


@pytest.fixture(scope="module")
def fns(env):
    return jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))


def _random_pool(env, seed=0):
    """The engine's pool for N worlds at random arm states, derived fields computed."""
    e = env.engine
    p = e._pool(N)
    rng = np.random.default_rng(seed)
    p.batch.reset()
    p.qpos[:] = np.array(env.mj_model.key("inserted").qpos) + 0.05 * rng.standard_normal((N, 7))
    p.qvel[:] = 0.2 * rng.standard_normal((N, 7))
    p.batch.forward()
    return p


def test_array_jacobian_and_inertia_equal_mujocos_own(env):
    """The per-substep Jacobian (joint axes x anchors) and the inertia scattered from the sparse
    M equal mj_jac and mj_fullM on random states."""
    e, m = env.engine, env.engine.model
    p = _random_pool(env)
    pts = p.xpos[:, e.ctrl.body_id] + 0.01 * np.arange(3 * N).reshape(N, 3)
    J = e.centre_jacobian(p, pts)
    M = e.full_inertia(p.M)
    d = mujoco.MjData(m)
    for w in range(N):
        d.qpos[:], d.qvel[:] = p.qpos[w], p.qvel[w]
        mujoco.mj_forward(m, d)
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, jacr, pts[w], e.ctrl.body_id)
        np.testing.assert_allclose(J[w], np.vstack([jacp, jacr]), atol=1e-12)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        np.testing.assert_allclose(M[w], full, atol=1e-12)


def test_batched_law_equals_the_law_world_by_world(env):
    """impedance_torque over a batch of worlds gives each world's single-world result."""
    rng = np.random.default_rng(3)
    n = 5
    J = rng.standard_normal((n, 6, 7))
    A = rng.standard_normal((n, 7, 7))
    M = A @ np.swapaxes(A, 1, 2) + 7 * np.eye(7)
    R = np.stack([np.linalg.qr(rng.standard_normal((3, 3)))[0] for _ in range(n)])
    R *= np.sign(np.linalg.det(R))[:, None, None]
    args = dict(
        bias=rng.standard_normal((n, 7)),
        q=rng.standard_normal((n, 7)),
        qvel=rng.standard_normal((n, 7)),
        x_C=rng.standard_normal((n, 3)),
        target_pos=rng.standard_normal((n, 3)),
        target_vel=rng.standard_normal((n, 3)),
        stiffness=rng.uniform(10, 1000, (n, 6)),
        damping_ratio=rng.uniform(0.5, 1, n),
        wrench_ff=rng.standard_normal((n, 6)),
        q_null=rng.standard_normal((n, 7)),
        null_gains=rng.uniform(0.1, 10, (n, 2)),
    )
    caps, lo, hi = (20, 20, 60, 3, 3, 1), -np.full(7, 100.0), np.full(7, 100.0)
    tau, w = impedance_torque(J, M, R=R, target_mat=R[::-1], max_wrench=caps, ctrl_lo=lo,
                              ctrl_hi=hi, **args)  # fmt: skip
    for i in range(n):
        one = {k: v[i] for k, v in args.items()}
        t1, w1 = impedance_torque(J[i], M[i], R=R[i], target_mat=R[::-1][i], max_wrench=caps,
                                  ctrl_lo=lo, ctrl_hi=hi, **one)  # fmt: skip
        np.testing.assert_allclose(tau[i], t1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(w[i], w1, rtol=1e-12, atol=1e-12)


def test_substeps_equal_a_loop_over_one_mjdata_per_world(env, fns):
    """One env step on the engine = mj_setState, then per substep the NumPy law on that MjData
    (impedance_torque_c, mj_jac + mj_fullM) and mj_step, world by world."""
    reset, step = fns
    s = reset(jax.random.split(jax.random.PRNGKey(0), N))
    a = np.zeros((N, env.action_size), np.float32)
    a[:, 2], a[:, 0] = 0.5, 0.7
    s1 = step(s, jnp.asarray(a))
    e, m = env.engine, env.engine.model
    c = env.config
    d = mujoco.MjData(m)
    for w in range(N):
        info = {k: np.asarray(v[w]) for k, v in s1.info.items()}
        prev = np.asarray(s.info["cmd_tip"][w], float)
        cmd, mat = info["cmd_tip"].astype(float), info["cmd_mat"].astype(float)
        H = info["hole_mat"].astype(float)
        L_C = float(info["L_C"])
        ff = np.concatenate([mat.T @ (H @ info["wrench_ff"]), np.zeros(3)])
        mujoco.mj_setState(m, d, np.asarray(s.data.state[w]).view(np.float64), STATE_SPEC)
        m.pair_friction[:] = e._pair_friction0 * float(info["friction_scale"])
        mujoco.mj_forward(m, d)
        s_ = c.stiffness
        stiff = np.array([info["k_xy"]] * 2 + [s_.k_z_N_m] + [info["k_rot"]] * 3, float)
        for k in range(env.n_substeps):
            tip = prev + np.float32((k + 1) / env.n_substeps) * (cmd - prev)
            tau, _ = impedance_torque_c(
                e.ctrl, m, d, L_C, tip - L_C * mat[:, 2], mat, (cmd - prev) / c.ctrl_dt,
                stiff, s_.damping_ratio, ff, np.asarray(env._init_q)[e.ctrl.qadr],
                (s_.null_stiffness_Nm_rad, s_.null_damping_Nms_rad),
            )  # fmt: skip
            d.ctrl[e.ctrl.act] = tau
            mujoco.mj_step(m, d)
        row = np.zeros(e.nstate)
        mujoco.mj_getState(m, d, row, STATE_SPEC)
        got = np.asarray(s1.data.state[w]).view(np.float64)
        # the engine takes the law's parameters as float32 (from the jitted task): equal to
        # that rounding, not bit for bit; the solver's warm start (row 15-21) is the most
        # sensitive entry
        nq = m.nq
        np.testing.assert_allclose(got[1 : 1 + 2 * nq], row[1 : 1 + 2 * nq], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(got, row, rtol=1e-4, atol=1e-7)
    m.pair_friction[:] = e._pair_friction0


def test_a_rollouts_two_graph_reset_equals_the_env_reset(env, fns):
    """The rollout starts mujoco-engine worlds through two compiled graphs (reset_start, which
    the persistent cache keeps, then the host-callback half): the same start states, bit for
    bit, as the env's own one-graph reset."""
    keys = jax.random.split(jax.random.PRNGKey(3), N)
    one = fns[0](keys)
    two, _, finished = _batch_reset(env)(keys)
    assert not np.asarray(finished).any()
    for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(two), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_the_reset_ik_runs_in_mujoco_c_and_meets_the_mjx_ik(env, monkeypatch):
    """The mujoco engine's reset solves the start pose in MuJoCo C on the host: tracing its
    reset traces none of MJX's kinematics, and its joint angles put the peg tip where the MJX
    engine's IK does (to float32 rounding: 2e-6 rad; measured 7e-7 on 2026-12-05) at the
    preset's insertion depth."""
    from peghole_mjx.control import kinematics

    traced = []
    counting = types.SimpleNamespace(
        kinematics=lambda m, d: traced.append(1), com_pos=kinematics.mjx.com_pos
    )
    keys = jax.random.split(jax.random.PRNGKey(5), N)
    with monkeypatch.context() as mp:
        mp.setattr(kinematics, "mjx", counting)
        kinematics._newton_ik.clear_cache()
        calls = env.engine.timing["ik_calls"]
        q_c = np.asarray(jax.jit(jax.vmap(env.reset_start))(keys)["q"])
        assert not traced and env.engine.timing["ik_calls"] == calls + 1
    kinematics._newton_ik.clear_cache()
    mjx_env = envs.load("RectExtract", config_overrides={"engine": "mjx"})
    q_mjx = np.asarray(jax.jit(jax.vmap(mjx_env.reset_start))(keys)["q"])
    assert np.abs(q_c - q_mjx).max() < 2e-6
    assert np.abs(q_c - q_c[:1]).max() > 1e-3  # four moved holes, four starts
    depth = np.asarray(jax.jit(jax.vmap(env.reset))(keys).info["depth_mm"])
    np.testing.assert_allclose(depth, env._depth0_mm, atol=1e-3)
    assert env._mjx_model is None  # the C engine's env never put an MJX model


def test_a_scene_mjx_cannot_load_runs_on_the_c_engine():
    """The dual scene's cylinder representation (cylinder-box pairs: MJX-JAX has no collision
    function for them) builds, resets and steps on the mujoco engine, which never loads MJX."""
    over = {"engine": "mujoco", "representation": "cylinder"}
    env = envs.load("DualExtract", config_overrides=over)
    with pytest.raises(NotImplementedError, match="CYLINDER"):  # MJX-JAX cannot load it
        _ = env.mjx_model
    s = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), 2))
    s = jax.vmap(env.step)(s, jnp.zeros((2, env.action_size)))
    assert np.isfinite(np.asarray(s.obs)).all()


def test_per_world_friction_reaches_the_c_engine(env, fns):
    """Two worlds from one start state differ only by their friction draw: a sideways push
    gives different states; with equal friction, bit-identical ones."""
    reset, step = fns
    key = jax.random.PRNGKey(5)
    s = reset(jnp.stack([key] * N))
    scale = jnp.array([0.8, 1.2, 0.8, 0.8], jnp.float32)
    s = s.replace(info={**s.info, "friction_scale": scale})
    push = jnp.tile(jnp.array([1.0, 0.0, -1.0, 1.0, 0.0, 0.0]), (N, 1))
    for _ in range(5):
        s = step(s, push)
    st = np.asarray(s.data.state)
    assert not np.array_equal(st[0], st[1])
    np.testing.assert_array_equal(st[0], st[2])
    np.testing.assert_array_equal(st[0], st[3])


def test_a_nan_world_ends_its_episode_and_the_batch_goes_on(env, fns):
    reset, step = fns
    s = reset(jax.random.split(jax.random.PRNGKey(1), N))
    a = jnp.zeros((N, env.action_size))
    clean = step(s, a)
    row = np.asarray(s.data.state).copy()
    f64 = row.view(np.float64)
    f64[0, 1 + env.mj_model.nq] = np.nan  # world 0: qvel[0] NaN (after the time entry, qpos)
    bad = s.replace(data=s.data.replace(state=jnp.asarray(f64.view(np.uint32))))
    out = step(bad, a)
    assert float(out.metrics["nan"][0]) == 1.0 and float(out.done[0]) == 1.0
    np.testing.assert_array_equal(np.asarray(out.metrics["nan"][1:]), 0.0)
    # the NaN world keeps its last state; the others are those of the clean batch
    np.testing.assert_array_equal(np.asarray(out.data.state[0]), np.asarray(bad.data.state[0]))
    np.testing.assert_array_equal(np.asarray(out.data.state[1:]), np.asarray(clean.data.state[1:]))
    assert np.isfinite(np.asarray(out.obs)).all()


def test_the_scripted_pull_extracts_as_on_mjx(env, fns):
    """The scripted pull on the mujoco engine succeeds in the time the committed MJX rollouts
    take (benchmarks/results/perf/env_rollouts.json, RectExtract, scripted: mean over 64
    episodes): within 0.2 s in each of N worlds (with the engine's own done test)."""
    committed = json.loads((PERF_RESULTS / "env_rollouts.json").read_text())
    mjx_time = next(
        r["mean_time_s"]
        for r in committed["rows"]
        if r["env"] == "RectExtract" and r["policy"] == "scripted"
    )
    reset, step = fns
    s = reset(jax.random.split(jax.random.PRNGKey(5), N))
    a = jnp.broadcast_to(scripted_policy(env)(None, None), (N, env.action_size))
    steps = np.zeros(N, int)
    success = np.zeros(N, bool)
    for t in range(1, env.config.episode_length + 1):
        s = step(s, a)
        done = (np.asarray(s.done) > 0) & (steps == 0)
        steps[done] = t
        success[done] = np.asarray(s.metrics["success"])[done] > 0
        if (steps > 0).all():
            break
    assert success.all(), steps
    np.testing.assert_allclose(steps * env.dt, mjx_time, atol=0.2)


def test_state_renders_through_mjdata(env, fns):
    reset, _ = fns
    s = reset(jax.random.split(jax.random.PRNGKey(2), N))
    d = mujoco.MjData(env.mj_model)
    one = jax.tree.map(lambda x: x[1], s.data)
    env.engine.to_mjdata(one, env.mj_model, d)
    np.testing.assert_allclose(d.qpos, np.asarray(one.qpos), atol=1e-6)


def test_a_policy_on_another_engine_is_evaluated_as_trained():
    """The published rect policy was trained on MuJoCo C (since 2026-12-06): on MJX it is the
    same task (the engine is provenance, issue 51, 2026-12-05), while a task entry is still a
    difference."""
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training.evaluate import check_requested_env, requested_config

    bundle = load_policy("rect")
    assert bundle.trained_engine() == {"engine": "mujoco"}
    on_mjx = requested_config(bundle, {"engine": "mjx", "impl": "jax"})
    assert check_requested_env(bundle, on_mjx, cross=False) == {}
    on_c = requested_config(bundle, {"engine": "mujoco", "mujoco_threads": 2})
    assert check_requested_env(bundle, on_c, cross=False) == {}
    with pytest.raises(UserInputError, match="episode_length"):
        check_requested_env(bundle, requested_config(bundle, {"episode_length": 7}), False)


def test_engine_choices_map_to_config_entries():
    from peghole_mjx.sim.engines import default_engine, engine_overrides

    assert engine_overrides("mjx-warp") == {"engine": "mjx", "impl": "warp"}
    assert engine_overrides("mujoco") == {"engine": "mujoco"}
    assert engine_overrides("auto") == {"engine": default_engine()}
    assert default_engine() == ("mujoco" if jax.default_backend() == "cpu" else "mjx")
    with pytest.raises(UserInputError, match="unknown engine 'gpu'"):
        engine_overrides("gpu")


def test_engine_bad_input_is_one_line():
    with pytest.raises(UserInputError, match="unknown engine 'bullet'"):
        envs.load("RectExtract", config_overrides={"engine": "bullet"})
    with pytest.raises(UserInputError, match="mujoco_threads must be an integer >= 0"):
        envs.load("RectExtract", config_overrides={"engine": "mujoco", "mujoco_threads": -1})
    with pytest.raises(UserInputError, match="engine 'mujoco' needs impl jax"):
        envs.load("RectExtract", config_overrides={"engine": "mujoco", "impl": "warp"})
    env = envs.load("RectExtract")
    with pytest.raises(UserInputError, match="only joints are the arm's 7 hinges"):
        spec = mujoco.MjSpec.from_string(
            "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
        )
        MujocoEngine(spec.compile(), env._ctrl, None, 10)


def test_mjx_in_float64_meets_mujoco_c_at_the_same_box_scene_states():
    """benchmarks/studies/engine_contacts.py: at the same states of a scripted pull on the box
    scene, MJX's forward pass in float64 reads MuJoCo C's F/T force with the same active
    contacts (so the engines' F_z difference there is MJX's float32), and the study switches
    JAX back to float32 after it."""
    rows = engine_contacts.record_states("RectExtract", 2, [20])
    r = engine_contacts.compare("RectExtract", rows, "float64")
    assert r["states"] == 2 and r["mean_abs_fz_N_mujoco"] > 1.0  # in contact
    assert r["mean_abs_dfz_N"] < 0.01 and r["contact_count_differs_share"] == 0
    assert not jax.config.jax_enable_x64
    assert jnp.zeros(1).dtype == jnp.float32
