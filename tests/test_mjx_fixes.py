"""The opt-in MJX cone-Hessian fix (peghole_mjx/sim/mjx_fixes.py): same physics where MJX's clamp
is inactive, and a clear error where it does not apply."""

import jax
import mujoco
import numpy as np
import pytest

from peghole_mjx.core._mjx import mjx
from peghole_mjx.sim import mjx_fixes

SLIDING_BOX = """
<mujoco>
  <option timestep="0.002" cone="elliptic" solver="Newton" iterations="20"/>
  <worldbody>
    <geom type="plane" size="1 1 0.1" friction="0.5"/>
    <body pos="0 0 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.05" mass="1"/></body>
  </worldbody>
</mujoco>
"""


def _roll(m, d, n):
    step = jax.jit(lambda m, d: mjx.step(m, d))  # a new trace: picks up the current solver
    out = []
    for _ in range(n):
        d = step(m, d)
        out.append(np.asarray(d.qvel))
    return np.array(out)


def test_fix_keeps_the_physics_of_a_sliding_contact():
    m = mujoco.MjModel.from_xml_string(SLIDING_BOX)
    d = mujoco.MjData(m)
    d.qvel[0] = 0.5  # sliding: the tangential residual is far above the clamp
    mujoco.mj_forward(m, d)
    mx, dx = mjx.put_model(m, impl="jax"), mjx.put_data(m, d, impl="jax")
    try:
        shipped = _roll(mx, dx, 20)
        mjx_fixes.apply_cone_hessian_fix()
        mjx_fixes.apply_cone_hessian_fix()  # idempotent
        assert mjx_fixes.cone_hessian_fix_applied()
        fixed = _roll(mx, dx, 20)
    finally:
        mjx_fixes.remove_cone_hessian_fix()
    assert not mjx_fixes.cone_hessian_fix_applied()
    # friction decelerates the box at about mu g in both
    assert shipped[-1, 0] < 0.5 - 0.5 * 9.81 * 0.03
    np.testing.assert_allclose(fixed, shipped, atol=1e-4)


def test_fix_refuses_another_mjx_source(monkeypatch):
    monkeypatch.setattr(mjx_fixes, "_OLD", "a line that is not in the solver")
    with pytest.raises(RuntimeError, match="does not apply to this mujoco-mjx version"):
        mjx_fixes.apply_cone_hessian_fix()
    assert not mjx_fixes.cone_hessian_fix_applied()


def test_context_restores_the_shipped_solver():
    from mujoco.mjx._src import solver

    shipped = solver._update_constraint
    with mjx_fixes.cone_hessian_fix():
        assert solver._update_constraint is not shipped
    assert solver._update_constraint is shipped
    with mjx_fixes.cone_hessian_fix(enabled=False):
        assert solver._update_constraint is shipped
