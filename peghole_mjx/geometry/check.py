"""Model checks: effective clearance by MuJoCo distance queries, and the free-peg drop test's
model, duration, tolerance and report.

* :func:`effective_clearance_range_mm` - the diametral free travel of the centred, aligned peg
  until contact, found by bisection on ``mujoco.mj_geomDistance`` over every peg-hole contact
  pair, minimum and maximum over several directions in the hole plane (4 for rectangular holes,
  ``2 n`` for round ones, each measured both ways); :func:`effective_clearance_mm` is the
  minimum. Each collision representation (``parts.REPRESENTATIONS``) is checked on its own.
* the drop test - the free peg (:func:`free_peg_model`), released centred and aligned with its
  tip at the hole mouth, falls under gravity; the gap between its tip and the hole bottom is
  measured in MuJoCo C and in MJX-JAX. A hole filled by its convex hull would stop the peg at
  the mouth. The drop is stepped in :mod:`peghole_mjx.sim.free` (``drop_test``), which also
  fills a :class:`PresetReport` per preset (``check_spec``): physics is stepped in ``sim/``
  only; :func:`drop_duration_s`, :data:`DROP_TOLERANCE_MM` and :class:`DropResult` are here.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from peghole_mjx.core._mjx import mjx
from peghole_mjx.geometry import mjcf
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
    """Outcome of a drop test (:func:`peghole_mjx.sim.free.drop_test`): gaps between tip and
    hole bottom, mm."""

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


@dataclass(frozen=True)
class PresetReport:
    """One row of ``peghole models check``: one preset in one collision representation
    (:func:`peghole_mjx.sim.free.check_spec`).

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
