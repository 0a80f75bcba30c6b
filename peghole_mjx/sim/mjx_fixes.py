"""Opt-in fix of MJX-JAX's elliptic-cone Newton Hessian (a private MJX function, patched).

MJX's ``solver._update_constraint`` builds the Hessian of each contact in the cone's middle zone
with the rank-one term ``mu N / T^3 * u u^T`` and clamps ``T^3`` on its own to ``mjMINVAL``
(1e-15) while ``T`` and ``N`` stay unclamped. For a nearly sticking contact (tangential residual
``T`` < 1e-5, common in a slow quasi-static pull) the term is then suppressed by up to 1e9 and the
Hessian can lose positive definiteness; the Newton step's Cholesky factor then returns NaN. The
same clamp was found and removed in MuJoCo Warp (google-deepmind/mujoco_warp pull request 1660,
2026-09, "Fix indefinite elliptic cone Hessians near the apex"), whose code notes it follows
MJX. The fix writes the term as ``(mu N / T) * (u / T)(u / T)^T``: the same value wherever
``T^3`` > 1e-15, no separate clamp below it.

Evidence in this project (benchmarks/results/studies/low_stiffness_check.json, rect-2 at
K_theta 3 N m/rad): a world that ended in NaN with MJX as shipped finished with the fix; the
other world of the batch moved by 0.3 %. The compliance experiment traces its
functions inside :func:`cone_hessian_fix` (``ExperimentConfig.fix_cone_hessian``, on by default;
``peghole experiment sweep --no-fix-cone-hessian`` turns it off); nothing else in the package
uses it, so the envs and the committed policies run MJX as shipped.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
from collections.abc import Callable, Iterator

from peghole_mjx.core._mjx import solver  # MJX's private solver module, imported quietly

_OLD = """      ttt = jp.maximum(t * t * t, mujoco.mjMINVAL)
      h = jax.vmap(lambda x, y: x * jp.outer(y, y.T))(mu * n / ttt, u)"""
_NEW = """      h = jax.vmap(lambda x, y: x * jp.outer(y, y.T))(mu * n / t, u / t[:, None])"""

_state: dict[str, object] = {}


def cone_hessian_fix_applied() -> bool:
    """Whether :func:`apply_cone_hessian_fix` has patched this process's MJX."""
    return "original" in _state


@functools.cache
def _fixed(old: str, new: str) -> Callable:
    """MJX's ``_update_constraint`` with ``old`` replaced by ``new`` (built once per process)."""
    src = inspect.getsource(solver._update_constraint)
    if old not in src:
        raise RuntimeError(
            "the cone-Hessian fix does not apply to this mujoco-mjx version "
            "(solver._update_constraint changed); run without it"
        )
    namespace = dict(solver.__dict__)
    exec(compile(src.replace(old, new), solver.__file__, "exec"), namespace)
    return namespace["_update_constraint"]


def apply_cone_hessian_fix() -> None:
    """Patch ``mujoco.mjx._src.solver._update_constraint`` in this process (idempotent).

    Functions jitted before the call keep the shipped solver. Raises ``RuntimeError`` when the
    installed MJX's source does not contain the expected lines (another MJX version).
    """
    if cone_hessian_fix_applied():
        return
    fixed = _fixed(_OLD, _NEW)
    _state["original"] = solver._update_constraint
    solver._update_constraint = fixed


def remove_cone_hessian_fix() -> None:
    """Restore MJX's shipped function."""
    if not cone_hessian_fix_applied():
        return
    solver._update_constraint = _state.pop("original")


@contextlib.contextmanager
def cone_hessian_fix(enabled: bool = True) -> Iterator[None]:
    """Within the block, MJX functions traced for the first time use the fixed Hessian (a jitted
    function keeps the solver it was traced with); the previous state is restored after."""
    if not enabled or cone_hessian_fix_applied():
        yield
        return
    apply_cone_hessian_fix()
    try:
        yield
    finally:
        remove_cone_hessian_fix()
