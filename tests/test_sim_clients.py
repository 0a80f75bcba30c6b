"""The sim layer's scripted clients (the compliance experiment): the MuJoCo C engine's per-step
API (``MujocoEngine.pool``, ``law_step``, ``contact_forces``) against MuJoCo's own calls, its NaN
worlds, the law's passive-force option on both array libraries, and a committed result of the
experiment's earlier per-world loop reproduced on the engine."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from benchmarks.studies import pull_speed as ps
from benchmarks.studies import sim_reproduction as sr
from peghole_mjx.control import ImpedanceController, Target, make_params
from peghole_mjx.core._mjx import mjx
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.sim.engine_mujoco import MujocoEngine
from peghole_mjx.sim.engines import SceneIds


@pytest.fixture(scope="module")
def ex():
    """The rect-2 experiment on the ``mujoco`` engine (its scene, law and engine)."""
    cfg = cx.ExperimentConfig(geometry="rect", speed_m_s=0.1, settle_s=0.05, chunk_steps=400)
    return cx.Extraction("rect-2", cfg, mu=0.266, engine="mujoco")


def _table(n: int) -> dict[str, np.ndarray]:
    return {
        "L_C": np.linspace(0.0, 0.15, n),
        "delta0": np.full(n, 2e-3),
        "beta0": np.full(n, np.radians(0.2)),
        "theta0": np.zeros(n),
        "k_lat": np.full(n, 300.0),
        "k_rot": np.full(n, 30.0),
    }


def test_contacts_are_mujocos_contact_forces(ex):
    """After law steps that press the peg on a wall, the engine's per-world contacts are
    ``mj_contactForce`` of that world's MjData (replayed in one MjData with the same torques)."""
    sim, m = ex.sim, ex.sim.model
    tab = _table(2)
    p = sim.pool(np.tile(ex.q0, (2, 1)))
    prm = ex.law_params(tab)
    R0 = np.array(p.xmat[:, ex.ctl.body_id]).reshape(2, 3, 3)
    pos = np.array(p.site_xpos[:, ex.tip_site]) + np.array([3e-3, 0.0, 0.05])
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    sim.ctrl_log = log = []
    try:
        for _ in range(40):
            ok, _ = sim.law_step(p, pos, R0, np.zeros((2, 3)), prm)
            assert ok.all()
            d.ctrl[:] = log[-1][0]
            mujoco.mj_step(m, d)
    finally:
        sim.ctrl_log = None
    c = sim.contact_forces(p, 0, mujoco.MjData(m))
    assert d.ncon == len(c.normal_force) and (c.normal_force > 0).any()
    f6 = np.zeros(6)
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, f6)
        assert c.normal_force[i] == pytest.approx(max(f6[0], 0.0), rel=1e-9, abs=1e-12)
    # a world's state is its own: world 1 (another L_C) differs from world 0
    assert not np.array_equal(p.qpos[0], p.qpos[1])
    np.testing.assert_array_equal(p.qpos[0], d.qpos)


def test_a_diverging_world_keeps_its_last_finite_state_and_the_batch_goes_on(ex):
    sim = ex.sim
    tab = _table(3)
    p = sim.pool(np.tile(ex.q0, (3, 1)))
    prm = ex.law_params(tab)
    R0 = np.array(p.xmat[:, ex.ctl.body_id]).reshape(3, 3, 3)
    pos = np.array(p.site_xpos[:, ex.tip_site])
    sim.law_step(p, pos, R0, np.zeros((3, 3)), prm)
    before = np.array(p.state)
    p.qvel[1] = np.nan  # world 1 diverges in its next step
    bad = np.array(p.state)
    ok, _ = sim.law_step(p, pos, R0, np.zeros((3, 3)), prm)
    assert ok.tolist() == [True, False, True]
    np.testing.assert_array_equal(p.state[1], bad[1])  # its state before the failed step
    assert np.isfinite(p.qpos[[0, 2]]).all() and not np.array_equal(p.state[0], before[0])


def test_the_c_law_cancels_the_passive_forces_as_the_jax_law(ex):
    """With ``compensate_passive`` both laws subtract the joint damping's ``qfrc_passive``; the
    engine's torques on a moving state then equal the JAX law's (float32) to its precision."""
    m = ex.sim.model
    assert ex.ctl.compensate_passive and np.any(m.dof_damping > 0)
    tab = _table(1)
    p = ex.sim.pool(ex.q0[None])
    p.qvel[:] = 0.3
    ex.sim._run(p, p.batch.forward)
    prm = ex.law_params(tab)
    R0 = np.array(p.xmat[:, ex.ctl.body_id]).reshape(1, 3, 3)
    pos = np.array(p.site_xpos[:, ex.tip_site]) + 1e-3
    tau_c, _ = ex.sim._law(p, pos, R0, np.zeros((1, 3)), prm)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = p.qpos[0], p.qvel[0]
    mujoco.mj_forward(m, d)
    mx = mjx.put_model(m, impl="jax")
    dx = mjx.put_data(m, d, impl="jax")
    params = make_params(float(tab["L_C"][0]), ex.q0, stiffness=prm["stiffness"][0])
    target = Target(jnp.asarray(pos[0]), jnp.asarray(R0[0]), jnp.zeros(3))
    out = ex.ctl(mx, dx, target, params)
    passive = np.array(d.qfrc_passive)
    assert np.abs(passive).max() > 0.1
    np.testing.assert_allclose(tau_c[0], np.asarray(out.tau), atol=2e-3 * np.abs(tau_c).max())
    # without the option the C law differs by exactly the passive forces (where not clipped)
    plain = ImpedanceController(m, compensate_passive=False)
    e2 = MujocoEngine(m, plain, SceneIds.from_model(m, plain.qadr), n_substeps=1, threads=1)
    tau_p, _ = e2._law(p, pos, R0, np.zeros((1, 3)), prm)
    free = (np.abs(tau_c[0]) < plain.ctrl_hi - 1e-6) & (np.abs(tau_p[0]) < plain.ctrl_hi - 1e-6)
    np.testing.assert_allclose((tau_p - tau_c)[0][free], passive[free], rtol=1e-9, atol=1e-9)


def test_a_committed_result_of_the_per_world_loop_reproduces_on_the_engine():
    """One dual-2 world of the committed pull-speed study (written by the experiment's earlier
    per-world MuJoCo C loop) rerun through the study's row function: every stored figure within
    the reproduction rule fixed before the study (benchmarks/studies/sim_reproduction.py)."""
    job = sr.todo("dual", 1)[0]
    new, old = ps.world_row(job), sr.committed("dual")[job[0]]
    got = sr.compare(new, old)
    assert got["reproduced"], got
    assert json.loads(job[0])[2] == sr.SPEED_MM_S


def test_the_reproduction_rule_refuses_a_moved_peak():
    row = {"peak_fz_late_N": 1.0, "penetration_um": 3.0, "mu_eff": 0.25, "two_point_windows": 10}
    assert sr.compare(row, row)["reproduced"]
    assert not sr.compare({**row, "peak_fz_late_N": 1.02}, row)["reproduced"]
    assert not sr.compare({**row, "two_point_windows": 13}, row)["reproduced"]
    assert not sr.compare({**row, "peak_fz_late_N": None}, row)["reproduced"]


def test_the_experiments_mjx_path_steps_through_the_engine(monkeypatch):
    """The ``mjx`` experiment's physics step is :meth:`MjxEngine.law_step` (no MJX call of its
    own): counted while its one-world step function is traced."""
    cfg = cx.ExperimentConfig(geometry="rect", speed_m_s=0.1, settle_s=0.05, chunk_steps=400)
    e = cx.Extraction("rect-2", cfg, mu=0.266, engine="mjx")
    calls = []
    real = type(e.sim).law_step

    def counted(self, *a, **k):
        calls.append(1)
        return real(self, *a, **k)

    monkeypatch.setattr(type(e.sim), "law_step", counted)
    carry = e.init_world(*(jnp.asarray(v[0]) for v in _table(1).values()))
    jax.eval_shape(e.step, carry, jnp.asarray(0))
    assert calls == [1]
    # the plain mjx.step inlined in the chunk's graph, as the committed records were computed
    # (the jitted one is fused differently: up to 1.2 N apart in a float32 F_z sample)
    assert e.sim._step is mjx.step
