"""Physics of the impedance law: the robot holds a free-space peg (contact pairs removed).

All worlds of the compliance tests run in ONE jitted MJX rollout (the JAX law inside
``mjx.step``), shared by the tests through a module-scoped fixture.
"""

from __future__ import annotations

import functools
import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from peghole_mjx.control import (
    LIMITS,
    ImpedanceController,
    Target,
    force_at_point,
    make_params,
    rate_limit,
    rotvec_from_mat,
)
from peghole_mjx.core._mjx import mjx
from peghole_mjx.geometry.mjcf import build_scene
from peghole_mjx.geometry.specs import PRESETS

L_C = 0.075  # compliance centre at mid-peg (rect peg, 150 mm)
N_STEPS = 2500  # 5 s: the K = 50 N/m case settles to about 1 %

# (K_t N/m, K_r N m/rad, force N (world), lever arm above C along the peg axis, m)
CASES = [
    (50.0, 300.0, (1.5, 0.0, 0.0), 0.0),
    (300.0, 300.0, (0.0, 6.0, 0.0), 0.0),
    (1000.0, 300.0, (10.0, 0.0, 0.0), 0.0),
    (300.0, 100.0, (10.0, 0.0, 0.0), 0.1),
    (300.0, 300.0, (0.0, 0.0, 5.0), 0.0),
]


def _free_space_model() -> mujoco.MjModel:
    s = build_scene(PRESETS["rect-2"])
    for p in list(s.pairs):  # free space: the peg touches nothing
        s.delete(p)
    # MJX 3.17's elliptic-cone solver fails to trace with no contact at all (empty float
    # index array in solver._update_constraint); without contacts the cone type is moot
    s.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    return s.compile()


@pytest.fixture(scope="module")
def rig():
    m = _free_space_model()
    ctl = ImpedanceController(m)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    return m, ctl, mjx.put_model(m, impl="jax"), mjx.put_data(m, d, impl="jax"), d.qpos.copy()


def _rollout(ctl, mx, dx, params, force, arm, target, n):
    bid = ctl.body_id

    def body(dx, _):
        dx, out = ctl.apply(mx, dx, target, params)
        x_C, R = ctl.centre_pose(dx, params.L_C)
        point = x_C - R[:, 2] * arm  # peg z points to the tip: -z is up the axis
        dx = dx.replace(
            xfrc_applied=dx.xfrc_applied.at[bid].set(force_at_point(dx, bid, force, point))
        )
        dx = mjx.step(mx, dx)
        return dx, (out.x_C, out.err, out.tau, out.wrench)

    _, tr = jax.lax.scan(body, dx, None, length=n)
    return tr


@pytest.fixture(scope="module")
def compliance_runs(rig):
    _m, ctl, mx, dx0, q0 = rig
    x0, R0 = ctl.centre_pose(dx0, jnp.asarray(L_C))
    target = Target(x0, R0, jnp.zeros(3))
    run = jax.jit(functools.partial(_rollout, ctl, mx, n=N_STEPS))
    res = []
    for k, kr, f, arm in CASES:  # sequential: vmap of mjx.step is slow on this CPU
        params = make_params(L_C, q0, stiffness=[k, k, k, kr, kr, kr])
        tr = run(dx0, params, jnp.asarray(f), jnp.asarray(arm), target=target)
        res.append([np.asarray(a) for a in tr])
    return res, np.asarray(R0)


@pytest.mark.slow
def test_force_at_centre_translates_by_F_over_K(compliance_runs):
    res, _R0 = compliance_runs
    for (k, _, f, arm), (x_C, err, _, _) in zip(CASES, res, strict=True):
        if arm != 0.0:
            continue
        f = np.asarray(f)
        disp = x_C[-1] - x_C[0]
        expected = f / k
        assert np.linalg.norm(disp - expected) <= 0.05 * np.linalg.norm(expected), (k, disp)
        rot = np.linalg.norm(err[-1, 3:])
        assert rot < 1e-3 * np.linalg.norm(f) / 10.0, (k, rot)


@pytest.mark.slow
def test_measured_stiffness_matches_command(compliance_runs):
    res, _ = compliance_runs
    measured = {}
    for (k, _, f, arm), (x_C, *_) in zip(CASES, res, strict=True):
        if arm == 0.0:
            f = np.asarray(f)
            u = f / np.linalg.norm(f)
            measured.setdefault(k, np.linalg.norm(f) / float((x_C[-1] - x_C[0]) @ u))
    assert {50.0, 300.0, 1000.0} <= set(measured)
    for k, km in measured.items():
        assert abs(km / k - 1.0) < 0.05, (k, km)


@pytest.mark.slow
def test_force_off_centre_rotates_by_Fd_over_Krot(compliance_runs):
    res, _ = compliance_runs
    (_k, kr, f, arm), (_, err, _, _) = next(
        (c, r) for c, r in zip(CASES, res, strict=True) if c[3] != 0.0
    )
    rot = np.linalg.norm(err[-1, 3:])
    expected = np.linalg.norm(f) * arm / kr
    assert abs(rot / expected - 1.0) < 0.05, (rot, expected)


@pytest.mark.slow
def test_limits_hold_under_large_errors(rig):
    m, ctl, mx, dx0, q0 = rig
    x0, R0 = ctl.centre_pose(dx0, jnp.asarray(L_C))
    # 0.3 m and 60 degrees away: the raw law asks for far more than the limits allow
    Rt = (
        jnp.asarray(R0)
        @ jnp.asarray([[0.5, -0.866, 0.0], [0.866, 0.5, 0.0], [0.0, 0.0, 1.0]])
        @ jnp.asarray([[1.0, 0.0, 0.0], [0.0, 0.5, -0.866], [0.0, 0.866, 0.5]])
    )
    target = Target(x0 + jnp.array([0.3, -0.2, 0.1]), Rt, jnp.zeros(3))
    params = make_params(L_C, q0, stiffness=[1000.0] * 3 + [300.0] * 3)
    run = jax.jit(functools.partial(_rollout, ctl, mx, n=100))
    _, _, tau, w = (
        np.asarray(a) for a in run(dx0, params, jnp.zeros(3), jnp.asarray(0.0), target=target)
    )
    cap = np.asarray(LIMITS.max_wrench)
    assert np.all(np.abs(w) <= cap + 1e-5)
    assert np.any(np.abs(w) >= cap - 1e-5)  # the clip was active
    assert np.all(tau >= ctl.ctrl_lo - 1e-5) and np.all(tau <= ctl.ctrl_hi + 1e-5)
    assert np.allclose(ctl.ctrl_hi, m.actuator_ctrlrange[ctl.act, 1])


def test_law_vmaps_and_stiffness_changes_per_call(rig):
    _, ctl, mx, dx0, q0 = rig
    x0, R0 = ctl.centre_pose(dx0, jnp.asarray(L_C))
    target = Target(x0 + jnp.array([0.01, 0.0, 0.0]), R0, jnp.zeros(3))
    ks = jnp.array([50.0, 300.0, 1000.0])
    params = jax.vmap(lambda k: make_params(L_C, q0, stiffness=jnp.array([k, k, k, 1, 1, 1.0])))(ks)
    out = jax.jit(jax.vmap(lambda p: ctl(mx, dx0, target, p)))(params)
    fx = np.asarray(out.wrench[:, 0])  # compliance frame x = world -x for the hanging peg
    assert np.allclose(np.abs(fx), np.asarray(ks) * 0.01, rtol=1e-3)


def test_rate_limit_caps_speed():
    new = rate_limit(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), dt=0.002)
    assert np.isclose(float(jnp.linalg.norm(new)), LIMITS.max_speed_m_s * 0.002)
    small = rate_limit(jnp.zeros(3), jnp.array([1e-5, 0.0, 0.0]), dt=0.002)
    assert np.allclose(small, [1e-5, 0, 0])


def test_rotvec_small_and_large_angles():
    for a in (1e-6, 0.3, 2.5):
        c, s = np.cos(a), np.sin(a)
        R = jnp.asarray([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        assert np.allclose(rotvec_from_mat(R), [0, 0, a], rtol=1e-4, atol=1e-9)


def test_compensate_passive_cancels_the_joint_damping(rig):
    """With ``compensate_passive`` the law adds exactly ``dof_damping * qvel`` per arm joint (the
    model's passive joint force), so the arm's damping no longer loads a soft spring."""
    m, ctl, mx, dx0, q0 = rig
    comp = ImpedanceController(m, compensate_passive=True)
    qvel = np.zeros(m.nv)
    qvel[ctl.dadr] = np.linspace(-0.05, 0.05, len(ctl.dadr))
    dx = mjx.forward(mx, dx0.replace(qvel=jnp.asarray(qvel, dx0.qvel.dtype)))
    x0, R0 = ctl.centre_pose(dx, jnp.asarray(L_C))
    params = make_params(L_C, q0, stiffness=[300.0] * 3 + [3.0] * 3)
    target = Target(x0, R0, jnp.zeros(3))
    tau0, tau1 = (np.asarray(c(mx, dx, target, params).tau) for c in (ctl, comp))
    expected = m.dof_damping[ctl.dadr] * qvel[ctl.dadr]
    assert np.abs(expected).max() > 1e-3  # the model has joint damping to cancel
    np.testing.assert_allclose(tau1 - tau0, expected, atol=1e-5)


def test_numpy_reference_law_equals_the_jax_law_on_random_states():
    """peghole_mjx.control.reference (NumPy on MuJoCo C arrays) gives the JAX law's torques and
    wrench on random joint states, targets and gains: inside the wrench limits and clipped."""
    from peghole_mjx.control.reference import impedance_torque_c, rot_from_rotvec

    m = build_scene(PRESETS["rect-2"]).compile()
    ctl = ImpedanceController(m)
    mx = mjx.put_model(m, impl="jax")
    law = jax.jit(lambda dx, target, p: ctl(mx, dx, target, p))
    rng = np.random.default_rng(7)
    d = mujoco.MjData(m)
    q_null = np.array(m.key("inserted").qpos)[ctl.qadr]
    clipped = 0
    for scale in (1.0, 1.0, 30.0, 30.0):
        mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
        d.qpos[ctl.qadr] += 0.02 * rng.standard_normal(len(ctl.qadr))
        d.qvel[ctl.dadr] = 0.1 * rng.standard_normal(len(ctl.dadr))
        mujoco.mj_forward(m, d)
        L_C = rng.uniform(0.0, 0.15)
        R = d.xmat[ctl.body_id].reshape(3, 3)
        x_C = d.xpos[ctl.body_id] + R @ (ctl.tip_local - np.array([0.0, 0.0, L_C]))
        t_mat = rot_from_rotvec(1e-3 * scale * rng.standard_normal(3)) @ R
        t_pos = x_C + 1e-3 * scale * rng.standard_normal(3)
        t_vel = 0.02 * rng.standard_normal(3)
        stiff = np.concatenate([rng.uniform(50, 1000, 3), rng.uniform(20, 300, 3)])
        zeta, ff = rng.uniform(0.5, 1.0), rng.standard_normal(6)
        null = (rng.uniform(1, 20), rng.uniform(0.1, 2))
        tau_np, w_np = impedance_torque_c(
            ctl, m, d, L_C, t_pos, t_mat, t_vel, stiff, zeta, ff, q_null, null
        )
        out = law(
            mjx.put_data(m, d, impl="jax"),
            Target(jnp.asarray(t_pos), jnp.asarray(t_mat), jnp.asarray(t_vel)),
            make_params(L_C, q_null, stiff, zeta, ff, null),
        )
        np.testing.assert_allclose(w_np, np.asarray(out.wrench), rtol=2e-3, atol=2e-3)
        np.testing.assert_allclose(tau_np, np.asarray(out.tau), rtol=2e-3, atol=2e-3)
        clipped += bool(np.any(np.abs(np.asarray(out.wrench_raw)) > np.abs(w_np) + 1e-6))
    assert clipped >= 1  # the large-error states exercise the wrench clip


def test_numpy_rotvec_roundtrip():
    from peghole_mjx.control import reference as ref

    v = np.array([0.3, -0.2, 0.1])
    np.testing.assert_allclose(ref.rotvec_from_mat(ref.rot_from_rotvec(v)), v, atol=1e-12)
    np.testing.assert_allclose(ref.rotvec_from_mat(np.eye(3)), 0.0)
    # the NumPy twins equal the JAX helpers of control/kinematics.py
    from peghole_mjx.control import kinematics as kin

    for w in (v, np.array([0.0, 0.0, 2.5]), np.array([1e-7, 0.0, 0.0])):
        np.testing.assert_allclose(ref.rot_from_rotvec(w), kin.rot_from_rotvec(w), atol=1e-6)
        R = ref.rot_from_rotvec(w)
        np.testing.assert_allclose(ref.rotvec_from_mat(R), kin.rotvec_from_mat(R), atol=1e-6)
    np.testing.assert_allclose(ref.rot_z(0.7), kin.rot_z(0.7), atol=1e-6)


@pytest.fixture(scope="module")
def twin_rig():
    """The rect-2 scene with its controller, MJX model and the jitted JAX law."""
    m = build_scene(PRESETS["rect-2"]).compile()
    ctl = ImpedanceController(m)
    mx = mjx.put_model(m, impl="jax")
    return m, ctl, mx, jax.jit(lambda dx, target, p: ctl(mx, dx, target, p))


def _random_state(m, ctl, rng):
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    d.qpos[ctl.qadr] += 0.02 * rng.standard_normal(len(ctl.qadr))
    d.qvel[ctl.dadr] = 0.1 * rng.standard_normal(len(ctl.dadr))
    mujoco.mj_forward(m, d)
    return d


def test_numpy_law_equals_the_jax_law_with_a_tool_frame_and_a_load_error(twin_rig):
    """Both twins with a believed tool frame off the true one (offset and tilt) and a payload
    the gravity compensation leaves out: the same torques and wrench, and not those of the law
    without the errors."""
    from peghole_mjx.control.reference import impedance_torque_c, rot_from_rotvec

    m, ctl, _mx, law = twin_rig
    rng = np.random.default_rng(11)
    q_null = np.array(m.key("inserted").qpos)[ctl.qadr]
    for _ in range(3):
        d = _random_state(m, ctl, rng)
        L_C = rng.uniform(0.0, 0.15)
        R = d.xmat[ctl.body_id].reshape(3, 3)
        x_C = d.xpos[ctl.body_id] + R @ (ctl.tip_local - np.array([0.0, 0.0, L_C]))
        t_mat = rot_from_rotvec(2e-3 * rng.standard_normal(3)) @ R
        t_pos, t_vel = x_C + 1e-3 * rng.standard_normal(3), 0.02 * rng.standard_normal(3)
        stiff = np.concatenate([rng.uniform(50, 1000, 3), rng.uniform(20, 300, 3)])
        args = (stiff, 1.0, 0.1 * rng.standard_normal(6), q_null, (10.0, 2.0))
        errors = dict(
            tool_offset=2e-3 * rng.standard_normal(3),
            tool_mat=rot_from_rotvec(np.radians(0.5) * np.array([*rng.standard_normal(2), 0])),
            load_error=np.array([0.0, 0.0, -rng.uniform(0.5, 1.5)]),
        )
        tau_np, w_np = impedance_torque_c(ctl, m, d, L_C, t_pos, t_mat, t_vel, *args, **errors)
        target = Target(jnp.asarray(t_pos), jnp.asarray(t_mat), jnp.asarray(t_vel))
        stiff_, zeta, ff, _, null = args
        params = make_params(L_C, q_null, stiff_, zeta, ff, null, **errors)
        out = law(mjx.put_data(m, d, impl="jax"), target, params)
        np.testing.assert_allclose(w_np, np.asarray(out.wrench), rtol=2e-3, atol=2e-3)
        np.testing.assert_allclose(tau_np, np.asarray(out.tau), rtol=2e-3, atol=2e-3)
        plain, _ = impedance_torque_c(ctl, m, d, L_C, t_pos, t_mat, t_vel, *args)
        assert np.abs(plain - tau_np).max() > 0.05  # the errors change the torques


def test_a_tool_offset_along_the_axis_is_an_L_C_change_in_the_law(twin_rig):
    """The believed tip d above the true one (tool_offset (0, 0, -d), peg frame: z towards
    the tip) puts the compliance centre where L_C + d puts it: the same torques in both
    twins."""
    from peghole_mjx.control.reference import impedance_torque_c

    m, ctl, _mx, law = twin_rig
    rng = np.random.default_rng(5)
    d_ = _random_state(m, ctl, rng)
    q_null = np.array(m.key("inserted").qpos)[ctl.qadr]
    R = d_.xmat[ctl.body_id].reshape(3, 3)
    t_pos = d_.xpos[ctl.body_id] + R @ ctl.tip_local + 1e-3 * rng.standard_normal(3)
    t_mat, t_vel = R, np.zeros(3)
    stiff = np.array([300.0, 300.0, 2000.0, 30.0, 30.0, 30.0])
    L_C, off = 0.01, 0.002
    args = (stiff, 1.0, np.zeros(6), q_null, (10.0, 2.0))
    shifted, _ = impedance_torque_c(
        ctl, m, d_, L_C, t_pos, t_mat, t_vel, *args, tool_offset=np.array([0.0, 0.0, -off])
    )
    moved, _ = impedance_torque_c(ctl, m, d_, L_C + off, t_pos, t_mat, t_vel, *args)
    np.testing.assert_allclose(shifted, moved, rtol=1e-9, atol=1e-9)
    target = Target(jnp.asarray(t_pos), jnp.asarray(t_mat), jnp.asarray(t_vel))
    dx = mjx.put_data(m, d_, impl="jax")
    p_tool = make_params(
        L_C,
        q_null,
        stiff,
        1.0,
        np.zeros(6),
        (10.0, 2.0),
        tool_offset=np.array([0.0, 0.0, -off]),
        tool_mat=np.eye(3),
    )
    p_lc = make_params(L_C + off, q_null, stiff, 1.0, np.zeros(6), (10.0, 2.0))
    a, b = law(dx, target, p_tool), law(dx, target, p_lc)
    np.testing.assert_allclose(np.asarray(a.tau), np.asarray(b.tau), rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(np.asarray(a.x_C), np.asarray(b.x_C), atol=1e-6)


def test_one_rotation_helper_per_array_library():
    """``rotvec_from_mat`` / ``rot_from_rotvec`` are defined once in JAX (control/kinematics.py)
    and once in NumPy (core/rotations.py), and the robot-side runner imports the NumPy
    module without loading JAX or MuJoCo."""
    pkg = Path(__file__).resolve().parents[1] / "peghole_mjx"
    for name in ("rotvec_from_mat", "rot_from_rotvec"):
        defs = sorted(
            str(p.relative_to(pkg))
            for p in pkg.rglob("*.py")
            if re.search(rf"^def {name}\(", p.read_text(), re.M)
        )
        assert defs == ["control/kinematics.py", "core/rotations.py"], (name, defs)
    code = "import sys, peghole_mjx.deploy; print('jax' in sys.modules, 'mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"], out
