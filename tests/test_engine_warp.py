"""MuJoCo Warp (``impl="warp"``) runs the envs on a CPU and agrees with MJX-JAX.

For RectExtract and DualExtract: one reset from the same key and ``N_STEPS`` control steps of
the scripted pull, as one jitted graph per implementation (one compile per env and
implementation; warp's CPU device, no CUDA needed). Both implementations start from the same
draw and IK (the start joint angles agree to 1e-6 rad), then the contact count, the deepest
penetration, the F/T wrench of every control step and the peg depth are compared.

Tolerances, and why: both run float32 with the same solver options; they differ in the
collision routines (MJX-JAX's capsule-box and box-box against MuJoCo Warp's primitive
narrowphase with ``nativeccd`` off) and in summation order. The wrench of the first step agrees
to 1e-3 N; from the second step on, RectExtract's 12 contacts share the load differently with
any change of float order: MJX-JAX against ITSELF, with and without XLA's
``--xla_cpu_use_fusion_emitters=false`` (core/runtime.py), differs by up to 0.85 N per step,
as much as Warp does (0.84 N), while the mean wrench over the steps moves by at most 0.025 N
(Warp vs MJX-JAX: 0.025 N). So the per-step wrench is compared at the first step only and the
steps' mean wrench (the impulse the peg receives) over all of them. Measured on 2026-12-06
(2-core CPU, mujoco-mjx 3.17.0, warp-lang 1.18.0, jax 0.10.2, the suite's XLA flags) after 4
steps: RectExtract, the same 12 contacts, deepest penetration 2.25 vs 1.76 um, first-step
wrench within 0.001 N, mean wrench within 0.025 N / N m of 1-2 N, depth within 0.004 mm;
DualExtract, the same 6 contacts, penetration 10.1 vs 10.6 um, wrench within 0.013 N per step,
depth within 2e-4 mm; start joints within 1e-6 rad. The bounds are a few times the largest
measured difference and well below the signal: ``WRENCH_ATOL`` 0.1 N (N m), ``PEN_ATOL`` 1 um
(10 % of the dual's penetration), ``DEPTH_ATOL`` 0.01 mm, ``Q0_ATOL`` 1e-5 rad, contact
counts equal.

Skipped, with the reason, only where warp-lang is not installed (``.ci/run`` installs it for
this file).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("warp", reason="warp-lang is not installed (pip install 'peghole_mjx[warp]')")

from peghole_mjx import envs
from peghole_mjx.core._mjx import WARP_AVAILABLE
from peghole_mjx.envs.rollout import make_runner, scripted_policy
from peghole_mjx.envs.task_make import ContactRun, make_builtin
from peghole_mjx.sim.engines import batch_reset, select_worlds

pytestmark = pytest.mark.skipif(not WARP_AVAILABLE, reason="MJX cannot import MuJoCo Warp")

N_STEPS = 4
WRENCH_ATOL = 0.1  # N and N m
DEPTH_ATOL = 0.01  # mm
PEN_ATOL = 1e-6  # m
Q0_ATOL = 1e-5  # rad


def _contacts(data, impl: str) -> tuple[int, float]:
    """(penetrating contacts, deepest penetration in m) of one world's MJX data."""
    if impl == "warp":
        n = int(np.asarray(data._impl.nacon).reshape(-1)[0])
        dist = np.asarray(data._impl.contact__dist)[:n]
    else:
        dist = np.asarray(data._impl.contact.dist)
    pen = dist[dist < 0]
    return len(pen), float(-pen.min()) if len(pen) else 0.0


def _run(name: str, impl: str) -> dict:
    env = envs.load(name, config_overrides={"engine": "mjx", "impl": impl})
    action = scripted_policy(env)(None, None)

    def run(key):
        s0 = env.reset(key)

        def body(s, _):
            s = env.step(s, action)
            return s, (s.info["wrench"], s.info["depth_mm"])

        s, (wrench, depth) = jax.lax.scan(body, s0, None, length=N_STEPS)
        return s0, s, wrench, depth

    s0, s, wrench, depth = jax.jit(run)(jax.random.PRNGKey(0))
    count, pen = _contacts(s.data, impl)
    return {
        "q0": np.asarray(s0.data.qpos),
        "wrench": np.asarray(wrench),
        "depth": np.asarray(depth),
        "contacts": count,
        "pen": pen,
        "overflow": float(s.metrics["overflow"]),
        "finite": bool(np.all(np.isfinite(np.asarray(s.obs)))),
    }


@pytest.mark.parametrize("name", ["RectExtract", "DualExtract"])
def test_warp_on_the_cpu_matches_mjx_jax(name):
    ref = _run(name, "jax")
    warp = _run(name, "warp")
    assert warp["finite"] and warp["overflow"] == 0.0
    np.testing.assert_allclose(warp["q0"], ref["q0"], atol=Q0_ATOL)
    assert ref["contacts"] > 0, "the pull must be in contact to compare contacts"
    assert warp["contacts"] == ref["contacts"]
    assert warp["pen"] == pytest.approx(ref["pen"], abs=PEN_ATOL)
    np.testing.assert_allclose(warp["wrench"][0], ref["wrench"][0], atol=WRENCH_ATOL)
    np.testing.assert_allclose(
        warp["wrench"].mean(axis=0), ref["wrench"].mean(axis=0), atol=WRENCH_ATOL
    )
    np.testing.assert_allclose(warp["depth"], ref["depth"], atol=DEPTH_ATOL)


#: the worlds of the batched test: MuJoCo Warp's contact pool is shared by a batch's worlds
#: (``naconmax`` per world times the worlds: sim/engines.py ``batch_worlds``)
BATCH = 3


@pytest.fixture(scope="module")
def hex_task(tmp_path_factory):
    """A built-in part's task folder (MeshExtract's parts)."""
    out = tmp_path_factory.mktemp("warp_task") / "hex"
    make_builtin("hex", 0.2, out, contacts=ContactRun(worlds=2, env_steps=40))
    return out


@pytest.mark.parametrize("name", [*envs.ALL_ENVS, "MeshExtract"])
def test_warp_runs_a_batch_of_worlds(name, request):
    """Every registered env runs a batch of worlds on MuJoCo Warp (what ``peghole envs
    rollout --engine mjx-warp`` runs): the contact pool fits the batch, finished worlds are
    frozen by ``select_worlds`` and the states stay finite."""
    over = {"impl": "warp"}
    if name in envs.TASK_ENVS:
        over["task"] = str(request.getfixturevalue("hex_task"))
    env = envs.load(name, config_overrides=over)
    reset, run = make_runner(env, scripted_policy(env), 2, False, 0.99)
    states, rec, fin = reset(jax.random.split(jax.random.PRNGKey(0), BATCH))
    pool = np.asarray(states.data._impl.contact__dist)
    assert pool.shape == (env._config.naconmax * BATCH,)
    depth0 = np.asarray(states.info["depth_mm"])
    states, rec, fin, _ = run(states, rec, fin, jax.random.PRNGKey(1), None)
    assert np.asarray(states.data.qpos).shape[0] == BATCH
    assert np.all(np.isfinite(np.asarray(states.obs)))
    assert float(np.sum(states.metrics["overflow"])) == 0.0
    assert np.all(np.asarray(states.info["depth_mm"]) < depth0), "the scripted pull moves out"


def test_select_worlds_keeps_the_shared_pool():
    """``select_worlds`` picks per-world fields by the mask and takes MuJoCo Warp's shared
    contact pool from ``on_false`` whole (mjx.Data.where's rule), whatever its length."""
    env = envs.load("RectExtract", config_overrides={"impl": "warp"})
    reset = jax.jit(lambda k: batch_reset(env, k))
    s1 = reset(jax.random.split(jax.random.PRNGKey(1), BATCH))
    s2 = reset(jax.random.split(jax.random.PRNGKey(2), BATCH))
    mask = jnp.array([True, False, True])
    out = select_worlds(mask, s1, s2)
    q1, q2, q = (np.asarray(s.data.qpos) for s in (s1, s2, out))
    np.testing.assert_array_equal(q[[0, 2]], q1[[0, 2]])
    np.testing.assert_array_equal(q[1], q2[1])
    np.testing.assert_array_equal(
        np.asarray(out.data._impl.contact__pos), np.asarray(s2.data._impl.contact__pos)
    )
    np.testing.assert_array_equal(np.asarray(out.obs)[1], np.asarray(s2.obs)[1])
