"""Physics without the impedance law: MuJoCo stepped outside the task engines.

The engines (:mod:`.engines`, :mod:`.engine_mujoco`) step a task's scene under the impedance
law; this module steps the rest, so that ``sim/`` is the one place of the package that steps
physics (``mujoco.mj_step``, ``mjx.step``):

* :func:`run_passive` - MuJoCo C steps with no controller (the task folders' drop test:
  :func:`peghole_mjx.geometry.task_check.place_and_check` takes it as an argument);
* :func:`replay_ctrl` - MuJoCo C steps with recorded controls, a callback after each
  (:class:`peghole_mjx.envs.contacts.ContactReplay`);
* the free peg's drop test, in MuJoCo C (:func:`drop_gap_mujoco`) and MJX-JAX
  (:func:`drop_gap_mjx`), both in :func:`drop_test`, and :func:`check_spec`, one row of
  ``peghole models check``. The model, the clearance measurement, the drop's duration and
  tolerance and the report classes are :mod:`peghole_mjx.geometry.check`'s.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable

import jax
import mujoco
import numpy as np

from peghole_mjx.core._mjx import mjx
from peghole_mjx.geometry import mjcf
from peghole_mjx.geometry.check import (
    CLEARANCE_TOLERANCE,
    DROP_TOLERANCE_MM,
    DropResult,
    PresetReport,
    drop_duration_s,
    effective_clearance_range_mm,
    free_peg_model,
    mjx_buffer_sizes,
    n_collision_geoms,
    numeric,
)
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec


def run_passive(m: mujoco.MjModel, d: mujoco.MjData, n_steps: int) -> None:
    """Step ``d`` ``n_steps`` times in MuJoCo C, its controls as they are (none: passive)."""
    for _ in range(n_steps):
        mujoco.mj_step(m, d)


def replay_ctrl(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    ctrl_rows: Iterable[np.ndarray],
    observe: Callable[[mujoco.MjData], object],
) -> None:
    """One MuJoCo C step of ``d`` per row of ``ctrl_rows`` (``d.ctrl`` set to the row), then
    ``observe(d)``."""
    for row in ctrl_rows:
        d.ctrl[:] = row
        mujoco.mj_step(m, d)
        observe(d)


def drop_gap_mujoco(m: mujoco.MjModel, depth_m: float) -> float:
    """Drop in MuJoCo C; returns tip-to-bottom gap in mm at the end."""
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("mouth").id)
    run_passive(m, d, round(drop_duration_s(depth_m) / m.opt.timestep))
    mujoco.mj_kinematics(m, d)
    return float(d.site("peg_tip").xpos[2] - d.site("hole_bottom").xpos[2]) / MM


@functools.partial(jax.jit, static_argnames=("n", "tip", "bottom"))
def _mjx_drop(mx, dx, n: int, tip: int, bottom: int):
    """Scan ``n`` MJX steps and return the tip height above the hole bottom (m).

    Module-level and taking the model as an argument, so presets of the same shape share one
    compiled function.
    """

    def body(dx, _):
        return mjx.step(mx, dx), None

    dx, _ = jax.lax.scan(body, dx, None, length=n)
    dx = mjx.kinematics(mx, dx)
    return dx.site_xpos[tip, 2] - dx.site_xpos[bottom, 2]


def drop_gap_mjx(m: mujoco.MjModel, depth_m: float) -> float:
    """Drop in MJX (impl jax); returns tip-to-bottom gap in mm (NaN if the state blew up)."""
    mx = mjx.put_model(m, impl="jax")
    d0 = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d0, m.key("mouth").id)
    dx = mjx.put_data(m, d0, impl="jax")
    n = round(drop_duration_s(depth_m) / m.opt.timestep)
    gap = _mjx_drop(mx, dx, n, m.site("peg_tip").id, m.site("hole_bottom").id)
    return float(gap) / MM


def drop_test(
    spec: PegHoleSpec, m: mujoco.MjModel | None = None, mjx_too: bool = True
) -> DropResult:
    """Drop the free peg into the hole in MuJoCo C and (optionally) MJX-JAX: released centred
    and aligned with its tip at the hole mouth, it falls under gravity (a hole filled by its
    convex hull would stop it at the mouth)."""
    m = m or free_peg_model(spec)
    depth = spec.hole_depth_mm * MM
    gap_c = drop_gap_mujoco(m, depth)
    if not mjx_too:
        return DropResult(gap_c, None, "not run")
    if (m.geom_type == mujoco.mjtGeom.mjGEOM_CYLINDER).any():
        return DropResult(gap_c, None, "not run: cylinder-box is MuJoCo Warp only")
    try:
        gap_x = drop_gap_mjx(m, depth)
        err = None if math.isfinite(gap_x) else "NaN state"
    except NotImplementedError as exc:  # an unsupported collision pair
        gap_x, err = None, f"mjx.put_model: {exc}"
    return DropResult(gap_c, gap_x, err)


def check_spec(
    name: str, spec: PegHoleSpec, mjx_too: bool = True, representation: str | None = None
) -> PresetReport:
    """Run the clearance measurement and drop tests for one spec in one representation."""
    rep = resolve_representation(spec, representation)
    m = free_peg_model(spec, representation=rep)
    nominal = spec.clearance_mm
    eff, eff_max = effective_clearance_range_mm(spec, m)
    err_pct = 100.0 * (eff - nominal) / nominal
    err_max_pct = 100.0 * (eff_max - nominal) / nominal
    drop = drop_test(spec, m, mjx_too=mjx_too)
    scene = mjcf.build_scene(spec, representation=rep).compile()
    sizes = mjx_buffer_sizes(scene)
    failures = []
    # a round hole's nominal clearance holds in every direction; a rectangular one's only
    # along the axes (its diagonal travel is longer by design): the min is checked there
    worst = max(err_pct, err_max_pct, key=abs) if isinstance(spec, DualSpec) else err_pct
    if abs(worst) > 100 * CLEARANCE_TOLERANCE:
        failures.append(f"effective clearance off by {worst:+.2f} % in some direction")
    if drop.gap_mm > DROP_TOLERANCE_MM:
        failures.append(f"drop test: tip stopped {drop.gap_mm:.2f} mm above the bottom")
    mjx_applies = rep != "cylinder"
    if mjx_too and mjx_applies and not drop.mjx_ok:
        failures.append(f"MJX-JAX: {drop.mjx_error}")
    return PresetReport(
        preset=name,
        representation=rep,
        nominal_clearance_mm=round(nominal, 6),
        effective_clearance_mm=round(eff, 6),
        effective_clearance_max_mm=round(eff_max, 6),
        clearance_error_pct=round(err_pct, 3),
        clearance_error_max_pct=round(err_max_pct, 3),
        drop_test_gap_mm=round(drop.gap_mm, 4),
        drop_test_gap_mujoco_mm=round(drop.gap_mujoco_mm, 4),
        drop_test_gap_mjx_mm=None if drop.gap_mjx_mm is None else round(drop.gap_mjx_mm, 4),
        mjx_jax_ok=drop.mjx_ok,
        n_convex_geoms=n_collision_geoms(m),
        n_geoms=int(scene.ngeom),
        n_pairs=int(scene.npair),
        contacts_allocated=None if sizes is None else sizes[0],
        constraint_rows=None if sizes is None else sizes[1],
        contact_cap=numeric(scene, "max_contact_points"),
        passed=not failures,
        failures=failures,
    )
