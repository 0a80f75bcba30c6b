"""A task's frames, start pose and checks, measured on its convex pieces in MuJoCo C.

:func:`place_and_check` takes the peg's and the hole part's meshes and convex pieces in the
assembled pose (+z the extraction direction) and, on the free peg among the hole's pieces
(MuJoCo distance queries, :func:`peghole_mjx.geometry.check.min_pair_distance`):

1. **start pose**: the peg's pieces lifted ``tip_gap_mm`` must not touch the hole's (else the
   pieces overlap: hull intrusion, or parts exported touching); the peg is then centred in
   its clearance along x and y (half the difference of its free travel each way), and set
   ``tip_gap_mm`` above the hole's bottom (its free travel down; no bottom within 1 m: a
   through hole, refused);
2. **clearance**: the diametral free travel of the peg at the start pose in 8 directions of
   the hole plane, each both ways (min and max), against the meshes' radial clearance;
3. **extraction sweep**: the peg pulled straight up along +z until it is clear of the hole
   part, by sphere tracing (each advance is the least distance to the hole's pieces, so no
   obstacle is stepped over): any contact is an undercut or a piece intruding into the hole;
4. **drop test**: the free peg released at the mouth falls under gravity (MuJoCo C, stepped by
   the caller's ``run_passive``, :func:`peghole_mjx.sim.free.run_passive`: the geometry layer
   does not step physics); its tip must end within ``check.DROP_TOLERANCE_MM`` of the bottom;
5. **hull intrusion**: how far the pieces stick out of the meshes
   (:func:`peghole_mjx.geometry.decompose.measure_deviation`: for the hole part, into the
   hole).

It returns the parts in the task frames (:mod:`peghole_mjx.geometry.task`) and every measured
number; a failed check is a :class:`UserInputError` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry import check
from peghole_mjx.geometry.decompose import add_hull_geoms, compile_pieces, measure_deviation
from peghole_mjx.geometry.mjcf import SimOptions, _set_options
from peghole_mjx.geometry.specs import MM

#: directions of the clearance measurement, over a half turn (each measured both ways)
CLEARANCE_DIRECTIONS = 8
#: a sweep step closer than this to the hole's pieces (m) counts as contact (MuJoCo's steady
#: penetration is micrometres)
SWEEP_CONTACT_M = 2e-6
#: the sweep ends this far above the mouth (m): the peg's lowest point clear of the hole part
SWEEP_BEYOND_M = 1e-3


@dataclass
class TaskGeometry:
    """The parts in the task frames and what the checks measured (lengths in mm)."""

    peg_hulls: list[np.ndarray]  # peg frame, m
    hole_hulls: list[np.ndarray]  # hole frame, m
    peg_mesh: object  # trimesh, hole frame, start pose, m
    hole_mesh: object
    length_mm: float
    start_depth_mm: float
    rest_depth_mm: float
    floor_mm: float
    centring_mm: tuple[float, float]
    start_gap_mm: float  # least distance between the parts' pieces at the start pose
    effective_min_mm: float
    effective_max_mm: float
    sweep_min_gap_mm: float
    sweep_steps: int
    drop_gap_mm: float
    excess_peg_mm: float
    excess_hole_mm: float
    peg_mass_kg: float
    warnings: list[str] = field(default_factory=list)


def tip_point(peg_mesh, peg_hulls) -> np.ndarray:
    """The peg's tip point: x, y the area-weighted centre of its lowest downward faces (within
    0.01 mm of its lowest point; a multi-pin peg: of all its pins' ends), z the lowest point
    of its convex pieces."""
    down = np.flatnonzero(peg_mesh.face_normals[:, 2] < -0.9)
    if not len(down):
        raise UserInputError("the peg has no downward-facing end face (+z must be extraction)")
    centres = peg_mesh.triangles_center[down]
    low = centres[:, 2] < centres[:, 2].min() + 1e-5
    area = peg_mesh.area_faces[down][low]
    xy = (centres[low, :2] * area[:, None]).sum(0) / area.sum()
    z = min(float(h[:, 2].min()) for h in peg_hulls)
    return np.array([xy[0], xy[1], z])


def check_blind_hole(peg_mesh, hole_mesh) -> None:
    """Refuse, before any decomposition, a pair with no hole bottom under the peg (meshes in
    metres, assembled pose): a peg reaching below the hole part's lowest point (longer than
    the hole is deep: it passes through), or nothing of the hole part straight under the
    peg's tip point. A task needs a blind hole: its bottom sets the start pose and the drop
    test (:func:`place_and_check`)."""
    tol = 1e-6
    below = float(hole_mesh.bounds[0, 2] - peg_mesh.bounds[0, 2])
    if below >= -tol:
        raise UserInputError(
            f"not a task (blind hole): the peg reaches {max(below, 0.0) / MM:.4g} mm below the "
            "hole part's lowest point (a peg longer than its hole is deep, through the part): "
            "a task needs a blind hole, whose bottom sets the start pose"
        )
    down = np.flatnonzero(peg_mesh.face_normals[:, 2] < -0.9)
    if not len(down):
        raise UserInputError("the peg has no downward-facing end face (+z must be extraction)")
    centres = peg_mesh.triangles_center[down]
    low = centres[centres[:, 2] < centres[:, 2].min() + 1e-5]
    hit = hole_mesh.ray.intersects_any(low, np.tile([0.0, 0.0, -1.0], (len(low), 1)))
    if not hit.any():
        x, y = low[0, :2] / MM
        raise UserInputError(
            f"not a task (blind hole): no hole part under the peg's tip at ({x:.3g}, {y:.3g}) "
            "mm (a through hole): a task needs a blind hole, whose bottom sets the start pose"
        )


def _free_peg_model(peg_hulls, hole_hulls, friction: float, mass: float, sim: SimOptions):
    """The free peg (a ``freejoint`` at the origin, its pieces where they are) among the hole
    part's pieces (a static body), every peg piece x hole piece a contact pair."""
    s = mujoco.MjSpec()
    s.modelname = "task_free_peg"
    _set_options(s, sim)
    hole = s.worldbody.add_body(name="hole")
    peg = s.worldbody.add_body(name="peg")
    peg.add_freejoint(name="peg_free")
    add_hull_geoms(s, peg, "peg", peg_hulls, mass=mass)
    add_hull_geoms(s, hole, "hole", hole_hulls)
    for i in range(len(peg_hulls)):
        for j in range(len(hole_hulls)):
            s.add_pair(
                geomname1=f"peg_hull{i:03d}",
                geomname2=f"hole_hull{j:03d}",
                condim=3,
                friction=[friction, friction, sim.torsional_friction, 0.0, 0.0],
                solref=list(sim.solref),
                solreffriction=list(sim.solreffriction),
                solimp=list(sim.solimp),
            )
    m = compile_pieces(s, "the convex pieces")
    m.opt.ccd_tolerance = 1e-12
    m.opt.ccd_iterations = 200
    return m


def _qpos(offset) -> np.ndarray:
    return np.array([offset[0], offset[1], offset[2], 1.0, 0.0, 0.0, 0.0])


def _gap(m, d, q, pairs, distmax: float = 0.01) -> float:
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    return check.min_pair_distance(m, d, pairs, distmax)


def _sweep(m, d, q0, pairs, travel: float) -> tuple[float, int, float]:
    """Pull the peg from ``q0`` straight up by ``travel`` (m), each advance the least distance
    to the hole (sphere tracing: 1-Lipschitz, so nothing is skipped). Returns (least gap m,
    steps, the travel at which it was least); raises on contact."""
    t, steps, least, where = 0.0, 0, math.inf, 0.0
    while t < travel:
        q = q0.copy()
        q[2] += t
        g = _gap(m, d, q, pairs)
        steps += 1
        if g < least:
            least, where = g, t
        if g <= SWEEP_CONTACT_M:
            raise UserInputError(
                "not extractable along +z (the convex pieces): pulled straight up from the "
                f"start pose, the peg meets the hole part after {t / MM:.3g} mm of "
                f"{travel / MM:.3g} mm (an undercut, or hole pieces reaching into the hole: "
                "lower --threshold)"
            )
        t += g
    return least, steps, where


#: ``run_passive(m, d, n_steps)``: steps ``d`` ``n_steps`` times in MuJoCo C
#: (:func:`peghole_mjx.sim.free.run_passive`)
RunPassive = Callable[[mujoco.MjModel, mujoco.MjData, int], object]


def _drop(m, q_mouth, rest_z: float, tip_z0: float, run_passive: RunPassive) -> float:
    """Release the free peg at ``q_mouth`` and let ``run_passive`` step it; return how far (mm)
    its tip ends above the rest."""
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET  # a diverging drop fails
    d = mujoco.MjData(m)
    d.qpos[:] = q_mouth
    n = round(check.drop_duration_s(q_mouth[2] - (rest_z - tip_z0)) / m.opt.timestep)
    run_passive(m, d, n)
    if not np.isfinite(d.qpos).all():
        return math.nan
    return (float(d.qpos[2]) + tip_z0 - rest_z) / MM


def place_and_check(
    peg_mesh,
    hole_mesh,
    peg_hulls: list[np.ndarray],
    hole_hulls: list[np.ndarray],
    *,
    friction: float,
    peg_mass_kg: float,
    radial_clearance_mm: float,
    run_passive: RunPassive,
    sim: SimOptions | None = None,
) -> TaskGeometry:
    """Frames, start pose and checks of a peg-hole (see the module docstring): meshes and
    pieces in metres, assembled pose, +z extraction. ``run_passive``: the drop test's physics
    (:func:`peghole_mjx.sim.free.run_passive`). ``sim``: the simulator options of the env that
    will run the task (its contact settings; the caller passes the env config's)."""
    sim = sim or SimOptions()
    tip = tip_point(peg_mesh, peg_hulls)
    top = max(float(h[:, 2].max()) for h in hole_hulls)
    origin = np.array([tip[0], tip[1], top])  # the preliminary hole frame: mouth above the tip
    peg = [np.asarray(h, float) - origin for h in peg_hulls]
    hole = [np.asarray(h, float) - origin for h in hole_hulls]
    m = _free_peg_model(peg, hole, friction, peg_mass_kg, sim)
    d = mujoco.MjData(m)
    pairs = check.contact_pairs(m)
    gap_m = sim.tip_gap_mm * MM
    tip_z = tip[2] - top  # the tip's height in the preliminary frame, assembled (< 0)
    q = _qpos((0.0, 0.0, gap_m))
    g0 = _gap(m, d, q, pairs)
    if g0 <= SWEEP_CONTACT_M:
        raise UserInputError(
            "the peg's convex pieces touch or overlap the hole part's in the assembled pose "
            f"lifted {sim.tip_gap_mm:g} mm ({max(-g0, 0.0) / MM:.4g} mm deep): hull intrusion "
            "(lower --threshold, raise --resolution) or parts exported touching (centre the peg "
            "in its hole)"
        )
    c = max(radial_clearance_mm * MM, 1e-6)
    tol = 1e-4 * c

    def travel(u, q0):
        try:
            return check.free_travel(m, d, q0, np.asarray(u, float), pairs, c / 2, tol)
        except RuntimeError:
            return None

    t = [travel(u, q) for u in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0))]
    if any(v is None for v in t):
        raise UserInputError(
            "the peg is not held sideways by the hole part's pieces (no wall within 1 m along "
            "x or y): not a peg in a hole"
        )
    shift = np.array([0.5 * (t[0] - t[1]), 0.5 * (t[2] - t[3]), 0.0])
    q[:3] += shift
    below = travel((0, 0, -1), q)
    if below is None:
        raise UserInputError(
            "no hole bottom under the peg (a through hole?): a task needs a blind hole, whose "
            "bottom sets the start pose and the drop test"
        )
    rest_z = tip_z + gap_m - below  # the tip's height resting on the bottom
    start_z = rest_z + gap_m
    q[2] = start_z - tip_z
    start_gap = _gap(m, d, q, pairs)
    dirs = [
        (
            math.cos(math.pi * k / CLEARANCE_DIRECTIONS),
            math.sin(math.pi * k / CLEARANCE_DIRECTIONS),
            0.0,
        )
        for k in range(CLEARANCE_DIRECTIONS)
    ]
    diam = [travel(u, q) + travel(-np.asarray(u), q) for u in dirs]
    least, steps, _ = _sweep(m, d, q, pairs, -start_z + SWEEP_BEYOND_M)
    q_mouth = q.copy()
    q_mouth[2] = -tip_z  # the tip at the mouth
    drop = _drop(m, q_mouth, rest_z, tip_z, run_passive)
    if not math.isfinite(drop):
        raise UserInputError(
            "drop test: the free peg's simulation diverged (NaN) on its way into the hole"
        )
    if abs(drop) > check.DROP_TOLERANCE_MM:
        raise UserInputError(
            f"drop test: the free peg released at the mouth stops {drop:.3g} mm above the "
            f"hole's bottom (tolerance {check.DROP_TOLERANCE_MM:g} mm): the hole's pieces hold it"
        )
    dev_peg = measure_deviation(peg_mesh, peg_hulls)
    dev_hole = measure_deviation(hole_mesh, hole_hulls)
    warnings = []
    if dev_hole.excess_mm > 0.25 * radial_clearance_mm:
        warnings.append(
            f"the hole's pieces stick up to {dev_hole.excess_mm:.3g} mm out of the part, more "
            f"than 25 % of the {radial_clearance_mm:.3g} mm radial clearance"
        )
    # the final frames: the hole frame's origin on the centred peg's tip point; the peg frame
    # from its mount (top, above the tip point), z down, x along the hole's -x
    lift = np.array([0.0, 0.0, start_z - tip_z])
    hole_h = [h - shift for h in hole]
    peg_h = [h + lift for h in peg]  # the peg moved by shift + lift, the frame by shift
    mount_z = max(float(h[:, 2].max()) for h in peg_h)
    flip = np.array([-1.0, 1.0, -1.0])
    peg_p = [(h - np.array([0.0, 0.0, mount_z])) * flip for h in peg_h]
    peg_mesh_h = peg_mesh.copy()
    peg_mesh_h.apply_translation(-origin + lift)
    hole_mesh_h = hole_mesh.copy()
    hole_mesh_h.apply_translation(-origin - shift)
    floor = rest_z - min(float(h[:, 2].min()) for h in hole)
    return TaskGeometry(
        peg_hulls=peg_p,
        hole_hulls=hole_h,
        peg_mesh=peg_mesh_h,
        hole_mesh=hole_mesh_h,
        length_mm=(mount_z - start_z) / MM,
        start_depth_mm=-start_z / MM,
        rest_depth_mm=-rest_z / MM,
        floor_mm=floor / MM,
        centring_mm=(float(shift[0] / MM), float(shift[1] / MM)),
        start_gap_mm=start_gap / MM,
        effective_min_mm=min(diam) / MM,
        effective_max_mm=max(diam) / MM,
        sweep_min_gap_mm=least / MM,
        sweep_steps=steps,
        drop_gap_mm=drop,
        excess_peg_mm=dev_peg.excess_mm,
        excess_hole_mm=dev_hole.excess_mm,
        peg_mass_kg=peg_mass_kg,
        warnings=warnings,
    )
