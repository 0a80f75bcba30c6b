"""Model checks: effective clearance by MuJoCo distance queries and the free-peg drop test.

* :func:`effective_clearance_range_mm` - the diametral free travel of the centred, aligned peg
  until contact, found by bisection on ``mujoco.mj_geomDistance`` over every peg-hole contact
  pair, minimum and maximum over several directions in the hole plane (4 for rectangular holes,
  ``2 n`` for round ones, each measured both ways); :func:`effective_clearance_mm` is the
  minimum. Each collision representation (``parts.REPRESENTATIONS``) is checked on its own.
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

from peghole_mjx.core._mjx import mjx
from peghole_mjx.geometry import mjcf
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec

#: the drop test passes if the tip ends within this distance of the hole bottom
DROP_TOLERANCE_MM = 1.0
#: the effective clearance passes if within this fraction of the nominal clearance in EVERY
#: direction for round holes (min and max over directions; rect: the min): the exact mesh
#: 16-gons are -1.92 %, the capsules in circumscribed box walls +1.96 % at worst
#: (1 - cos(pi / 16), 1 / cos(pi / 16) - 1)
CLEARANCE_TOLERANCE = 0.02


def contact_pairs(m: mujoco.MjModel) -> list[tuple[int, int]]:
    """(geom1, geom2) of every explicit contact pair of the model."""
    return [(int(a), int(b)) for a, b in zip(m.pair_geom1, m.pair_geom2, strict=True)]


def min_pair_distance(
    m: mujoco.MjModel, d: mujoco.MjData, pairs: list[tuple[int, int]], distmax: float = 0.01
) -> float:
    """Smallest signed distance (m) over the given geom pairs at the current state."""
    return min(mujoco.mj_geomDistance(m, d, g1, g2, distmax, None) for g1, g2 in pairs)


def free_travel(
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


def free_peg_model(
    spec: PegHoleSpec, peg_single_hull: bool = False, representation: str | None = None
) -> mujoco.MjModel:
    """The free peg above its hole block (keyframe ``mouth``)."""
    return mjcf.build_scene(
        spec, robot=False, peg_single_hull=peg_single_hull, representation=representation
    ).compile()


def effective_clearance_mm(
    spec: PegHoleSpec, m: mujoco.MjModel | None = None, n_directions: int | None = None
) -> float:
    """Measured diametral clearance (mm) of the centred, aligned peg at half depth: the
    minimum over directions (see :func:`effective_clearance_range_mm`)."""
    return effective_clearance_range_mm(spec, m, n_directions)[0]


def effective_clearance_range_mm(
    spec: PegHoleSpec, m: mujoco.MjModel | None = None, n_directions: int | None = None
) -> tuple[float, float]:
    """(min, max) over directions of the diametral free travel (mm) of the centred, aligned
    peg at half depth."""
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
        t_pos = free_travel(m, d, q0, u, pairs, nominal / 4, 1e-4 * nominal)
        t_neg = free_travel(m, d, q0, -u, pairs, nominal / 4, 1e-4 * nominal)
        travels.append(t_pos + t_neg)
    return min(travels) / MM, max(travels) / MM


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
    if (m.geom_type == mujoco.mjtGeom.mjGEOM_CYLINDER).any():
        return DropResult(gap_c, None, "not run: cylinder-box is MuJoCo Warp only")
    try:
        gap_x = drop_gap_mjx(m, depth)
        err = None if math.isfinite(gap_x) else "NaN state"
    except NotImplementedError as exc:  # an unsupported collision pair
        gap_x, err = None, f"mjx.put_model: {exc}"
    return DropResult(gap_c, gap_x, err)


@dataclass(frozen=True)
class PresetReport:
    """One row of ``peghole models check``: one preset in one collision representation.

    ``contacts_allocated`` and ``constraint_rows`` are MJX-JAX's static buffer sizes for the
    env's scene (robot + peg + hole block; None where MJX-JAX cannot build it), after the
    ``contact_cap`` (``max_contact_points``, 0 = none).
    """

    preset: str
    representation: str
    nominal_clearance_mm: float
    effective_clearance_mm: float
    effective_clearance_max_mm: float
    clearance_error_pct: float
    clearance_error_max_pct: float
    drop_test_gap_mm: float
    drop_test_gap_mujoco_mm: float
    drop_test_gap_mjx_mm: float | None
    mjx_jax_ok: bool
    n_convex_geoms: int
    n_geoms: int
    n_pairs: int
    contacts_allocated: int | None
    constraint_rows: int | None
    contact_cap: int
    passed: bool
    failures: list[str]

    def as_dict(self) -> dict:
        return asdict(self)


def n_collision_geoms(m: mujoco.MjModel) -> int:
    """Number of distinct geoms that take part in a contact pair."""
    return len({g for pair in contact_pairs(m) for g in pair})


def mjx_buffer_sizes(m: mujoco.MjModel) -> tuple[int, int] | None:
    """(contacts allocated, constraint rows) of MJX-JAX's data for ``m``, None if unsupported."""
    try:
        d = mjx.make_data(m, impl="jax")
    except (NotImplementedError, ValueError):
        return None
    return int(d._impl.contact.dist.shape[0]), int(d._impl.efc_J.shape[0])


def numeric(m: mujoco.MjModel, name: str) -> int:
    """The value of a ``<numeric>`` element (0 if absent)."""
    i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    return int(m.numeric_data[m.numeric_adr[i]]) if i >= 0 else 0


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
