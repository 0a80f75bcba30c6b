"""MuJoCo Warp (``impl="warp"``) runs the envs on a CPU and agrees with MJX-JAX.

For RectExtract and DualExtract: one reset from the same key and ``N_STEPS`` control steps of
the scripted pull, as one jitted graph per implementation (one compile per env and
implementation; warp's CPU device, no CUDA needed). Both implementations start from the same
draw and IK (the start joint angles agree to 1e-6 rad), then the contact count, the deepest
penetration, the F/T wrench of every control step and the peg depth are compared.

Tolerances, and why: both run float32 with the same solver options; they differ in the
collision routines (MJX-JAX's capsule-box and box-box against MuJoCo Warp's primitive
narrowphase with ``nativeccd`` off) and in summation order. Measured on 2026-12-04 (2-core CPU,
mujoco-mjx 3.17.0, warp-lang 1.18.0) after 4 steps: RectExtract, the same 12 contacts,
deepest penetration 1.779 vs 1.769 um, wrench within 0.005 N / N m of 1-4 N, depth within
1e-4 mm; DualExtract, the same 6 contacts, penetration 10.23 vs 10.59 um, wrench within
0.014 N of up to 2 N, depth within 2e-4 mm; start joints within 1e-6 rad. The bounds are a
few times the largest measured difference and well below the signal: ``WRENCH_ATOL`` 0.1 N
(N m), ``PEN_ATOL`` 1 um (10 % of the dual's penetration), ``DEPTH_ATOL`` 0.01 mm,
``Q0_ATOL`` 1e-5 rad, contact counts equal.

Skipped, with the reason, only where warp-lang is not installed (``.ci/run`` installs it for
this file).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

pytest.importorskip("warp", reason="warp-lang is not installed (pip install 'peghole_mjx[warp]')")

from peghole_mjx import envs
from peghole_mjx._mjx import WARP_AVAILABLE
from peghole_mjx.envs.rollout import scripted_policy

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
    env = envs.load(name, config_overrides={"impl": impl})
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
    np.testing.assert_allclose(warp["wrench"], ref["wrench"], atol=WRENCH_ATOL)
    np.testing.assert_allclose(warp["depth"], ref["depth"], atol=DEPTH_ATOL)
