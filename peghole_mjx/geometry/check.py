"""Model checks: effective clearance by MuJoCo distance queries and the free-peg drop test.

* :func:`effective_clearance_mm` - the diametral free travel of the centred, aligned peg until
  contact, found by bisection on ``mujoco.mj_geomDistance`` over every peg-hole contact pair,
  minimum over several directions in the hole plane (4 for rectangular holes, 8 for round).
* :func:`drop_test` - the free peg, released centred and aligned with its tip at the hole
  mouth, falls under gravity; the gap between its tip and the hole bottom is measured in
  MuJoCo C and in MJX-JAX. A hole filled by its convex hull would stop the peg at the mouth.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import jax
import mujoco
import numpy as np
from mujoco import mjx

from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec

#: the drop test passes if the tip ends within this distance of the hole bottom
DROP_TOLERANCE_MM = 1.0
#: the effective clearance passes if within this fraction of the nominal clearance
CLEARANCE_TOLERANCE = 0.10


def contact_pairs(m: mujoco.MjModel) -> list[tuple[int, int]]:
    """(geom1, geom2) of every explicit contact pair of the model."""
    return [(int(a), int(b)) for a, b in zip(m.pair_geom1, m.pair_geom2, strict=True)]


def min_pair_distance(
    m: mujoco.MjModel, d: mujoco.MjData, pairs: list[tuple[int, int]], distmax: float = 0.01
) -> float:
    """Smallest signed distance (m) over the given geom pairs at the current state."""
    return min(mujoco.mj_geomDistance(m, d, g1, g2, distmax, None) for g1, g2 in pairs)


def _free_travel(
    m: mujoco.MjModel,
    d: mujoco.MjData,
    q0: np.ndarray,
    u: np.ndarray,
    pairs: list[tuple[int, int]],
    t_max: float,
    tol: float,
) -> float:
    """Largest translation t along u from q0 with all pairs still separated (bisection)."""

    def clear(t: float) -> bool:
        d.qpos[:] = q0
        d.qpos[0:3] += t * u
        mujoco.mj_kinematics(m, d)
        return min_pair_distance(m, d, pairs) > 0.0

    if not clear(0.0):
        raise RuntimeError("the centred peg already touches the hole")
    lo, hi = 0.0, t_max
    while clear(hi):  # grow until contact
        lo, hi = hi, 2 * hi
        if hi > 1.0:
            raise RuntimeError("no wall found along the test direction")
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clear(mid) else (lo, mid)
    return 0.5 * (lo + hi)


def free_peg_model(spec: PegHoleSpec, peg_single_hull: bool = False) -> mujoco.MjModel:
    """The free peg above its hole block (keyframe ``mouth``)."""
    from peghole_mjx.geometry.mjcf import build_scene

    return build_scene(spec, robot=False, peg_single_hull=peg_single_hull).compile()


def effective_clearance_mm(
    spec: PegHoleSpec, m: mujoco.MjModel | None = None, n_directions: int | None = None
) -> float:
    """Measured diametral clearance (mm) of the centred, aligned peg at half depth."""
    m = m or free_peg_model(spec)
    m.opt.ccd_tolerance = 1e-12
    m.opt.ccd_iterations = 200
    d = mujoco.MjData(m)
    q0 = m.key("mouth").qpos.copy()
    q0[2] -= 0.5 * spec.hole_depth_mm * MM  # tip at half depth: walls only, not the floor
    pairs = contact_pairs(m)
    if n_directions is None:
        # round holes: 2n directions over a half turn hit both polygon vertices and edges
        n_directions = 2 * spec.n_sides if isinstance(spec, DualSpec) else 4
    nominal = spec.clearance_mm * MM
    travels = []
    for k in range(n_directions):
        phi = math.pi * k / n_directions  # half circle: each direction is measured both ways
        u = np.array([math.cos(phi), math.sin(phi), 0.0])
        t_pos = _free_travel(m, d, q0, u, pairs, nominal / 4, 1e-4 * nominal)
        t_neg = _free_travel(m, d, q0, -u, pairs, nominal / 4, 1e-4 * nominal)
        travels.append(t_pos + t_neg)
    return min(travels) / MM


@dataclass(frozen=True)
class DropResult:
    """Outcome of a drop test: gaps between tip and hole bottom, mm."""

    gap_mujoco_mm: float
    gap_mjx_mm: float | None
    mjx_error: str | None = None

    @property
    def gap_mm(self) -> float:
        gaps = [self.gap_mujoco_mm] + ([self.gap_mjx_mm] if self.gap_mjx_mm is not None else [])
        return max(gaps)

    @property
    def passed(self) -> bool:
        return self.mjx_ok and self.gap_mm <= DROP_TOLERANCE_MM

    @property
    def mjx_ok(self) -> bool:
        return self.gap_mjx_mm is not None and math.isfinite(self.gap_mjx_mm)


def drop_duration_s(depth_m: float) -> float:
    """Free-fall time over the hole depth plus a settling margin."""
    return math.sqrt(2 * depth_m / 9.81) + 0.15


def drop_gap_mujoco(m: mujoco.MjModel, depth_m: float) -> float:
    """Drop in MuJoCo C; returns tip-to-bottom gap in mm at the end."""
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("mouth").id)
    n = round(drop_duration_s(depth_m) / m.opt.timestep)
    for _ in range(n):
        mujoco.mj_step(m, d)
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
    """Drop the free peg into the hole in MuJoCo C and (optionally) MJX-JAX."""
    m = m or free_peg_model(spec)
    depth = spec.hole_depth_mm * MM
    gap_c = drop_gap_mujoco(m, depth)
    if not mjx_too:
        return DropResult(gap_c, None, "not run")
    try:
        gap_x = drop_gap_mjx(m, depth)
        err = None if math.isfinite(gap_x) else "NaN state"
    except NotImplementedError as exc:  # an unsupported collision pair
        gap_x, err = None, f"mjx.put_model: {exc}"
    return DropResult(gap_c, gap_x, err)


@dataclass(frozen=True)
class PresetReport:
    """One row of ``peghole models check``."""

    preset: str
    nominal_clearance_mm: float
    effective_clearance_mm: float
    clearance_error_pct: float
    drop_test_gap_mm: float
    drop_test_gap_mujoco_mm: float
    drop_test_gap_mjx_mm: float | None
    mjx_jax_ok: bool
    n_convex_geoms: int
    passed: bool
    failures: list[str]

    def as_dict(self) -> dict:
        return asdict(self)


def n_collision_geoms(m: mujoco.MjModel) -> int:
    """Number of distinct geoms that take part in a contact pair."""
    return len({g for pair in contact_pairs(m) for g in pair})


def check_spec(name: str, spec: PegHoleSpec, mjx_too: bool = True) -> PresetReport:
    """Run the clearance measurement and drop tests for one spec."""
    m = free_peg_model(spec)
    nominal = spec.clearance_mm
    eff = effective_clearance_mm(spec, m)
    err_pct = 100.0 * (eff - nominal) / nominal
    drop = drop_test(spec, m, mjx_too=mjx_too)
    failures = []
    if abs(err_pct) > 100 * CLEARANCE_TOLERANCE:
        failures.append(f"effective clearance off by {err_pct:+.1f} %")
    if drop.gap_mm > DROP_TOLERANCE_MM:
        failures.append(f"drop test: tip stopped {drop.gap_mm:.2f} mm above the bottom")
    if mjx_too and not drop.mjx_ok:
        failures.append(f"MJX-JAX: {drop.mjx_error}")
    return PresetReport(
        preset=name,
        nominal_clearance_mm=round(nominal, 6),
        effective_clearance_mm=round(eff, 6),
        clearance_error_pct=round(err_pct, 3),
        drop_test_gap_mm=round(drop.gap_mm, 4),
        drop_test_gap_mujoco_mm=round(drop.gap_mujoco_mm, 4),
        drop_test_gap_mjx_mm=None if drop.gap_mjx_mm is None else round(drop.gap_mjx_mm, 4),
        mjx_jax_ok=drop.mjx_ok,
        n_convex_geoms=n_collision_geoms(m),
        passed=not failures,
        failures=failures,
    )
