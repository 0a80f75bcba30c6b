"""MJCF scene emission: the iiwa with the peg on its tool flange, the hole block and a floor.

Scenes are built in memory with :class:`mujoco.MjSpec` from a :mod:`specs` spec and the convex
pieces of :mod:`parts`, so the same code serves ``peghole models build`` (writes XML), the
checks and the environments. The simulator options (timestep, solver, contact softness) are
set here and only here (:class:`SimOptions`): the robot XML has no ``<option>``.

Contacts are explicit ``<pair>`` elements between peg pieces and hole pieces (dual: peg i only
meets hole i's pieces), so MJX tests no useless geom pairs and robot links never collide.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.files import fileio
from peghole_mjx.geometry import edges
from peghole_mjx.geometry.parts import (
    ConvexPart,
    hole_parts,
    peg_parts,
    peg_tip_z_m,
    resolve_representation,
)
from peghole_mjx.geometry.specs import MM, DualSpec, RectSpec
from peghole_mjx.geometry.specs import PegHoleSpec as PresetSpec
from peghole_mjx.geometry.task import TaskSpec

#: what a scene is built from: a preset's (or custom) spec, or a task folder's parts
PegHoleSpec = PresetSpec | TaskSpec

#: where the robot model lives: inside an installed package, or the repository's mjcf/
_PKG_MJCF = Path(__file__).resolve().parents[1] / "_mjcf"
_REPO_MJCF = Path(__file__).resolve().parents[2] / "mjcf"
MJCF_DIR = _PKG_MJCF if _PKG_MJCF.is_dir() else _REPO_MJCF
ROBOT_XML = MJCF_DIR / "iiwa14.xml"

#: robot joint and actuator names (looked up by name, never by index)
JOINTS = tuple(f"joint{i}" for i in range(1, 8))
ACTUATORS = tuple(f"joint{i}_motor" for i in range(1, 8))
#: the names of the scene's bodies, sites, sensors and keyframe that the envs, the sim layer and
#: the experiments look up (the strings of the robot file ``iiwa14.xml`` and of the scene built
#: below)
PEG_BODY = "peg"
HOLE_BODY = "hole"  # a mocap body: the env moves the hole per episode
PEG_TIP_SITE = "peg_tip"
HOLE_MOUTH_SITE = "hole_mouth"
FLANGE_SITE = "flange"
FT_SITE = "ft_site"  # frame of the flange F/T sensor
FT_FORCE_SENSOR = "ft_force"
FT_TORQUE_SENSOR = "ft_torque"
START_KEYFRAME = "inserted"  # the peg inserted in the nominal hole
HOME_QPOS = np.array([0.0, 0.785398, 0.0, -1.5708, 0.0, 0.0, 0.0])

#: hole mouth position in the world, metres (x, y); z is the block's top face
HOLE_XY_M = (0.6, 0.0)


@dataclass(frozen=True)
class SimOptions:
    """Simulator options: the one place where the timestep and contact softness are set.

    ``contact_timeconst`` defaults to twice the timestep (MuJoCo's stiffest stable value);
    ``solimp`` near 1 keeps steady penetration to micrometres, below the tightest clearance.

    ``friction_timeconst`` (the pairs' ``solreffriction``, s) relaxes the frictional rows of
    each contact on their own, slower time scale. With the frictional rows as stiff as the
    normal one, a sliding contact in MuJoCo's convex (Anitescu-type) friction model gains a
    separating normal velocity of about ``mu * v_slide``: a peg pulled at 20 mm/s at
    mu = 0.266 then bounces between the walls as single-step 50-100 N impulses instead of
    resting in two-point contact. A 1 s friction time constant removes the bounce (both walls
    loaded in >= 94 % of physics steps in two-point windows, per-step peak ~1x the 20 ms mean)
    while a sliding contact still carries mu * N (measured mu_eff 0.26 at mu 0.266). Evidence:
    ``peghole models contact-check`` (benchmarks/results/evals/contact_check.json,
    docs/research/contact.md).
    Slow slides under large normal forces get less than mu * N: the arm-held peg of the
    compliance experiment keeps mu_eff 0.26 down to 0.5 mm/s (benchmarks/studies/pull_speed.py), a
    free
    peg jammed under 80-95 N normal forces at mu 0.01 sliding at 2 mm/s carries 15-39 % less F_z
    than Coulomb rows, and as much at 5 and 20 mm/s (``benchmarks/studies/capsule_fidelity.py
    jam_envs_friction``, docs/research/models.md). Under the tens of newtons of normal force of the
    tilted dual experiment at 0.5 mm/s mu_eff falls to 0.04-0.17 at mu 0.266; no friction
    model of the map in ``benchmarks/studies/friction_frontier.py`` (time constants, Coulomb rows,
    ``impratio``, no-slip) holds mu there and both walls at 20 mm/s within the experiment's
    bounds (docs/research/contact.md).
    ``None``: the frictional rows use ``solref`` (MuJoCo's default).
    """

    timestep: float = 0.002
    iterations: int = 20  # 8 left the arm-in-contact solve unconverged: 50 N force chatter
    ls_iterations: int = 10
    integrator: str = "euler"  # implicitfast went unstable for the free dual peg at rest
    cone: str = "elliptic"  # pyramidal: near-duplicate rows at mu = 0.01 broke MJX's float32 solve
    contact_timeconst: float | None = None
    contact_dampratio: float = 1.0
    solimp: tuple[float, float, float, float, float] = (0.99, 0.999, 0.0002, 0.5, 2.0)
    friction_timeconst: float | None = 1.0
    torsional_friction: float = 0.0
    tip_gap_mm: float = 0.5  # gap between the peg tip and the hole bottom in the start pose

    @property
    def solref(self) -> tuple[float, float]:
        tc = self.contact_timeconst if self.contact_timeconst is not None else 2 * self.timestep
        return (tc, self.contact_dampratio)

    @property
    def solreffriction(self) -> tuple[float, float]:
        """The pairs' ``solreffriction`` ((0, 0): MuJoCo uses ``solref`` for friction)."""
        if self.friction_timeconst is None:
            return (0.0, 0.0)
        return (self.friction_timeconst, 1.0)


def _set_options(s: mujoco.MjSpec, sim: SimOptions) -> None:
    s.option.timestep = sim.timestep
    s.option.iterations = sim.iterations
    s.option.ls_iterations = sim.ls_iterations
    s.option.integrator = {
        "euler": mujoco.mjtIntegrator.mjINT_EULER,
        "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
        "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    }[sim.integrator]
    s.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
    s.option.cone = {
        "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL,
        "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC,
    }[sim.cone]
    s.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    # MuJoCo C's multi-point CCD (on by default in MuJoCo 4; MJX-JAX collides meshes with its
    # own routine, MuJoCo Warp follows the flag) makes C's mesh-mesh contacts depart from
    # MJX-JAX and the quasi-static oracle: a jammed dual peg's F_z +37 % to +105 % (off: +3 to
    # +4 %), the dual compliance pull's late peak at L_C = top 0.12 N (off: 0.17 N = MJX =
    # oracle). The price: off, C returns one contact per mesh pair, so a face resting on a
    # face sinks a little deeper (the dual mesh drop test's gap -3.5 to -12 um, on -0.2 um;
    # MJX-JAX -1.2 um). Box and capsule pairs do not use CCD. Evidence: docs/research/models.md
    # (capsule fidelity), benchmarks/results/evals/models_check.json, 2026-11-29.
    s.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_MULTICCD
    s.compiler.autolimits = True


def _add_part(
    s: mujoco.MjSpec,
    body: mujoco.MjsBody,
    part: ConvexPart,
    prefix: str,
    rgba: tuple[float, ...],
    mass: float | None = None,
) -> mujoco.MjsGeom:
    kw = {
        "name": f"{prefix}{part.name}",
        "contype": 0,
        "conaffinity": 0,
        "rgba": list(rgba),
        "pos": list(part.pos),
        "quat": list(part.quat),
    }
    if part.kind == "box":
        geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(part.half_size), **kw)
    elif part.kind in ("capsule", "cylinder"):
        kind = (
            mujoco.mjtGeom.mjGEOM_CAPSULE
            if part.kind == "capsule"
            else mujoco.mjtGeom.mjGEOM_CYLINDER
        )
        geom = body.add_geom(type=kind, size=[*part.half_size, 0.0], **kw)
    else:
        # pieces naming the same ``mesh`` share one asset (MJX: one collision group per pair
        # of mesh assets, so sharing cuts compile time and the number of groups)
        mesh_name = f"{prefix}{part.mesh or part.name}_mesh"
        if s.mesh(mesh_name) is None:
            mesh = s.add_mesh(name=mesh_name)
            mesh.uservert = np.asarray(part.vertices, float).ravel().tolist()
        geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh_name, **kw)
    if mass is not None:
        geom.mass = mass
    return geom


def _add_peg(
    s: mujoco.MjSpec,
    body: mujoco.MjsBody,
    spec: PegHoleSpec,
    single_hull: bool = False,
    representation: str | None = None,
) -> list[ConvexPart]:
    parts = peg_parts(spec, single_hull=single_hull, representation=representation)
    vols = np.array([p.volume for p in parts])
    for part, vol in zip(parts, vols, strict=True):
        _add_part(
            s, body, part, "", (0.2, 0.45, 0.85, 1.0), mass=spec.peg_mass_kg * vol / vols.sum()
        )
    tip = peg_tip_z_m(spec)
    body.add_site(name="peg_mount", pos=[0, 0, 0], size=[0.003] * 3, group=3)
    body.add_site(name="peg_tip", pos=[0, 0, tip], size=[0.003] * 3, group=3)
    return parts


def _add_hole(
    s: mujoco.MjSpec, spec: PegHoleSpec, top_z: float, representation: str | None = None
) -> tuple[list[ConvexPart], mujoco.MjsBody]:
    hole = s.worldbody.add_body(name="hole", pos=[HOLE_XY_M[0], HOLE_XY_M[1], top_z], mocap=True)
    parts = hole_parts(spec, representation=representation)
    for part in parts:
        _add_part(s, hole, part, "", (0.75, 0.72, 0.65, 1.0))
    hole.add_site(name="hole_mouth", pos=[0, 0, 0], size=[0.003] * 3, group=3)
    hole.add_site(
        name="hole_bottom", pos=[0, 0, -spec.hole_depth_mm * MM], size=[0.003] * 3, group=3
    )
    return parts, hole


def _pair_names(
    pegs: list[ConvexPart], holes: list[ConvexPart], spec: PegHoleSpec
) -> list[tuple[str, str]]:
    """(peg geom, hole geom) pairs of the part representation (dual: peg i meets hole i)."""
    out = []
    for p in pegs:
        if isinstance(spec, DualSpec) and p.name == "peg_bridge":
            continue  # the bridge stays above the block: the pegs reach the floor first
        for h in holes:
            if p.group is not None and h.group is not None and p.group != h.group:
                continue
            out.append((p.name, h.name))
    return out


def _add_pairs(
    s: mujoco.MjSpec, names: list[tuple[str, str]], spec: PegHoleSpec, sim: SimOptions
) -> None:
    mu = spec.friction
    for g1, g2 in names:
        s.add_pair(
            name=f"{g1}__{g2}",
            geomname1=g1,
            geomname2=g2,
            condim=3,
            friction=[mu, mu, sim.torsional_friction, 0.0, 0.0],
            solref=list(sim.solref),
            solreffriction=list(sim.solreffriction),
            solimp=list(sim.solimp),
            margin=0.0,
            gap=0.0,
        )


@dataclass(frozen=True)
class ContactCap:
    """The contact cap of one scene kind and representation, sized from measurement.

    ``measured_max``: the most active contacts (distance <= 0) seen in any world at any physics
    step, over MuJoCo C and MJX-JAX rollouts of the env under the scripted and a random policy
    (``benchmarks/perf/contact_caps.py``, ``benchmarks/results/perf/contact_caps.json``); ``cap``:
    the
    ``max_contact_points`` set in the scene, above it with a margin.
    """

    measured_max: int
    cap: int


#: (scene kind, representation) -> measured maximum and cap (see ContactCap), measured
#: 2026-11-30 on the 2-core CPU (8 worlds, 400 env steps in MuJoCo C, 300 in MJX-JAX, scripted
#: and random actions, in each default env and its hard variant; benchmarks.perf.contact_caps,
#: benchmarks/results/perf/contact_caps.json). cap 0 = none. Rect: the box scene's 5 box-box pairs
#: allocate 20 contacts (4 each) and a random rollout makes all 20 active; the edges scene (the
#: default) allocates 52 (2 per capsule-box pair) and at most 20 are active (RectExtract and
#: RectExtractHard alike), uncapped. Dual: the mesh scene is the exact-geometry reference and
#: stays uncapped (37 of 136 active); the capsule scene allocates 32 of its 68: the most seen
#: is 26 (DualExtractHard, dual-3 at mu 0.266, random actions, MuJoCo C; its scripted pull
#: jams with 19), DualExtract's 20.
CONTACT_CAPS: dict[tuple[str, str], ContactCap] = {
    ("rect", "box"): ContactCap(measured_max=20, cap=0),
    ("rect", "edges"): ContactCap(measured_max=20, cap=0),
    ("dual", "capsule"): ContactCap(measured_max=26, cap=32),
    ("dual", "mesh"): ContactCap(measured_max=37, cap=0),
}


def contact_cap_entry(spec: PegHoleSpec, representation: str) -> ContactCap | None:
    """The measured contact cap of a scene: :data:`CONTACT_CAPS`'s entry, or a task folder's
    own (measured when the folder was made); None where none was measured."""
    if isinstance(spec, TaskSpec):
        return ContactCap(measured_max=spec.contact_measured_max, cap=spec.contact_cap)
    return CONTACT_CAPS.get((spec.kind, representation))


def contact_cap_for(spec: PegHoleSpec, representation: str, cap: int | None = None) -> int:
    """The ``max_contact_points`` of a scene: ``cap`` checked, or the measured default (0: none).

    Raises :class:`UserInputError` when ``cap`` is below the measured maximum of active
    contacts of this scene (rollouts would lose contacts).
    """
    entry = contact_cap_entry(spec, representation)
    if cap is None:
        return entry.cap if entry else 0
    if cap < 0:
        raise UserInputError(f"contact cap must be >= 0 (0: no cap), got {cap}")
    if cap and entry and cap < entry.measured_max:
        raise UserInputError(
            f"contact cap {cap} is below the measured maximum of {entry.measured_max} active "
            f"contacts of the {spec.kind} scene ({representation}): use >= {entry.measured_max}"
            f" (default {entry.cap}) or 0 for no cap"
        )
    return int(cap)


def block_top_z(spec: PegHoleSpec) -> float:
    """World height of the hole mouth: the block (depth + floor) stands on the floor."""
    return (spec.hole_depth_mm + spec.floor_mm) * MM


def start_depth_m(spec: PegHoleSpec, sim: SimOptions) -> float:
    """Depth of the peg tip below the mouth in the start pose (keyframe ``inserted``): the
    hole depth less ``sim.tip_gap_mm``, or a task folder's start pose (made the same way)."""
    if isinstance(spec, TaskSpec):
        return spec.start_depth_mm * MM
    return (spec.hole_depth_mm - sim.tip_gap_mm) * MM


def check_edges_fit(spec: PegHoleSpec, rep: str) -> None:
    """The rect ``edges`` representation needs a peg wider than four edge-capsule radii
    (``edges.check_radius``); a one-line :class:`UserInputError` otherwise."""
    if not (isinstance(spec, RectSpec) and rep == "edges"):
        return
    try:
        edges.check_radius(spec, edges.EDGE_RADIUS_M)
    except ValueError:
        lim = 4 * edges.EDGE_RADIUS_M / MM
        raise UserInputError(
            f"the rect peg's sides ({spec.peg_w_mm:g} x {spec.peg_v_mm:g} mm) must exceed "
            f"{lim:g} mm for the edges representation (its {edges.EDGE_RADIUS_M / MM:g} mm "
            "edge capsules would meet); use --representation box"
        ) from None


def build_scene(
    spec: PegHoleSpec,
    *,
    robot: bool = True,
    sim: SimOptions | None = None,
    ik: bool = True,
    peg_single_hull: bool = False,
    representation: str | None = None,
    contact_cap: int | None = None,
) -> mujoco.MjSpec:
    """The complete scene as an :class:`mujoco.MjSpec`.

    ``representation``: the collision representation (:func:`parts.resolve_representation`):
    for the rect parts ``edges`` (the default: tip- and mouth-edge capsules,
    :mod:`peghole_mjx.geometry.edges`) or ``box``; for the dual parts ``capsule`` (the default),
    ``mesh`` or ``cylinder``. ``contact_cap``: MJX's
    ``max_contact_points`` (the most contacts allocated per world); ``None`` = the measured
    cap of :data:`CONTACT_CAPS`, 0 = no cap; a cap below the measured maximum is refused.

    ``robot=True``: the iiwa with the peg welded to its tool flange, keyframes ``home`` and
    ``inserted`` (peg fully in the hole, tip ``tip_gap_mm`` above the bottom, found by IK).
    ``robot=False``: the free peg (a ``freejoint``) alone, keyframe ``mouth`` (tip at the mouth).
    ``peg_single_hull=True`` collides the peg as one convex hull (the PyBullet failure mode).
    """
    sim = sim or SimOptions()
    rep = resolve_representation(spec, representation)
    if not peg_single_hull:
        check_edges_fit(spec, rep)
    cap = contact_cap_for(spec, rep, contact_cap)
    top_z = block_top_z(spec)
    if robot:
        s = mujoco.MjSpec.from_file(str(ROBOT_XML))
        s.modelname = f"iiwa14_{spec.kind}_peghole"
        peg = s.body("tool").add_body(name="peg")
    else:
        s = mujoco.MjSpec()
        s.modelname = f"free_{spec.kind}_peg"
        # peg frame as on the robot: z down (mount above, tip below), x along world -x
        peg = s.worldbody.add_body(
            name="peg", pos=[HOLE_XY_M[0], HOLE_XY_M[1], 0.0], quat=[0, 0, 1, 0]
        )
        peg.add_freejoint(name="peg_free")
    _set_options(s, sim)
    s.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[1.5, 1.5, 0.05],
        contype=0,
        conaffinity=0,
        rgba=[0.9, 0.9, 0.92, 1],
    )
    s.worldbody.add_light(name="top_light", pos=[0.5, 0, 2.0], dir=[0, 0, -1])
    pegs = _add_peg(s, peg, spec, single_hull=peg_single_hull, representation=rep)
    holes, hole_body = _add_hole(s, spec, top_z, representation=rep)
    if isinstance(spec, RectSpec) and rep == "edges" and not peg_single_hull:
        pairs = edges.edge_pairs(
            edges.add_peg_edges(peg, spec),
            edges.add_mouth_edges(hole_body, spec),
            pegs[0].name,
            [h.name for h in holes],
        )
    else:
        pairs = _pair_names(pegs, holes, spec)
    _add_pairs(s, pairs, spec, sim)
    if cap:
        s.add_numeric(name="max_contact_points", data=[float(cap)])
    tip = peg_tip_z_m(spec)
    if robot:
        s.add_sensor(
            name="peg_tip_pos",
            type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objname="peg_tip",
            objtype=mujoco.mjtObj.mjOBJ_SITE,
        )
        if ik:
            target_tool_z = top_z - start_depth_m(spec, sim) + tip
            q = solve_tool_ik(s, np.array([HOLE_XY_M[0], HOLE_XY_M[1], target_tool_z]))
            s.add_key(name="inserted", qpos=q.tolist())
    else:
        start = [HOLE_XY_M[0], HOLE_XY_M[1], top_z + tip, 0.0, 0.0, 1.0, 0.0]
        s.add_key(name="mouth", qpos=start)
    return s


#: the orientation of the tool frame when the peg hangs straight down into the hole
TOOL_DOWN_MAT = np.diag([-1.0, 1.0, -1.0])  # tool z = world -z, tool x = world -x
#: IK seed: elbow up, wrist bent so that the flange faces the floor
IK_SEED_QPOS = np.array([0.0, 0.5, 0.0, -1.6, 0.0, 1.0, 0.0])


def solve_tool_ik(
    s: mujoco.MjSpec,
    target_pos: np.ndarray,
    target_mat: np.ndarray = TOOL_DOWN_MAT,
    q0: np.ndarray = IK_SEED_QPOS,
    tol: float = 1e-9,
    max_iter: int = 500,
) -> np.ndarray:
    """Joint angles placing site ``tool`` at ``target_pos`` with orientation ``target_mat``.

    Damped least squares from ``q0`` with a null-space pull to ``q0``; raises RuntimeError when
    the pose is unreachable within the joint ranges.
    """
    m = s.compile()
    d = mujoco.MjData(m)
    qadr = np.array([m.joint(j).qposadr[0] for j in JOINTS])
    dadr = np.array([m.joint(j).dofadr[0] for j in JOINTS])
    lo, hi = m.jnt_range[[m.joint(j).id for j in JOINTS]].T
    site = m.site("tool").id
    q = np.array(q0, float)
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    err = np.inf
    for _ in range(max_iter):
        d.qpos[qadr] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        pos, mat = d.site_xpos[site], d.site_xmat[site].reshape(3, 3)
        e_rot = 0.5 * sum(np.cross(mat[:, i], target_mat[:, i]) for i in range(3))
        e = np.concatenate([target_pos - pos, e_rot])
        err = np.linalg.norm(e)
        if err < tol:
            break
        mujoco.mj_jacSite(m, d, jacp, jacr, site)
        J = np.vstack([jacp, jacr])[:, dadr]
        JJt = J @ J.T + 1e-8 * np.eye(6)
        J_pinv = J.T @ np.linalg.inv(JJt)
        dq = J_pinv @ e + (np.eye(7) - J_pinv @ J) @ (0.1 * (q0 - q))
        q = np.clip(q + dq, lo, hi)
    if err > 1e-6:
        raise RuntimeError(f"IK did not converge: residual {err:.2e} for target {target_pos}")
    return q


def compile_scene(spec: PegHoleSpec, **kw) -> mujoco.MjModel:
    """Compile :func:`build_scene` to an :class:`mujoco.MjModel`."""
    return build_scene(spec, **kw).compile()


def write_scene(
    spec: PegHoleSpec,
    out_dir: Path | str,
    *,
    robot: bool = True,
    sim: SimOptions | None = None,
    name: str = "scene.xml",
    representation: str | None = None,
    contact_cap: int | None = None,
) -> Path:
    """Write the scene as a self-contained MJCF (meshes inline) and return its path."""
    out = Path(out_dir)
    s = build_scene(
        spec, robot=robot, sim=sim, representation=representation, contact_cap=contact_cap
    )
    s.compile()
    xml = s.to_xml()
    fileio.check_out_dir(out)
    fileio.check_room(out, len(xml.encode()) + ROOM_MARGIN_BYTES)
    return fileio.write_text(out / name, xml)


#: what ``models build`` writes, an upper estimate checked against the free disk before the
#: work (a scene and its free peg are tens of kB; the exact size is checked again before
#: writing)
SCENES_BYTES = 1 << 20
#: room left over beside an output (the file system's own blocks, a temporary copy)
ROOM_MARGIN_BYTES = 1 << 20


def with_sim(sim: SimOptions, **changes) -> SimOptions:
    return dataclasses.replace(sim, **changes)


def write_scenes(
    spec: PegHoleSpec,
    out: str | Path,
    representation: str | None = None,
    contact_cap: int | None = None,
) -> tuple[Path, Path, str]:
    """Write ``scene.xml`` (robot, peg on the flange, hole block, floor) and ``free_peg.xml``
    of ``spec`` into directory ``out``; return their paths and the collision representation.

    Both scenes are built and compiled in memory first, then written together (both files or
    neither). ``representation=None``: the preset's default (``parts.resolve_representation``).
    """
    out = Path(out)
    rep = resolve_representation(spec, representation)
    check_edges_fit(spec, rep)
    contact_cap_for(spec, rep, contact_cap)
    fileio.check_out_dir(out)
    fileio.check_room(out, SCENES_BYTES + ROOM_MARGIN_BYTES)  # before the IK and compiles
    xml = {}
    for name, robot in (("scene.xml", True), ("free_peg.xml", False)):
        try:
            s = build_scene(spec, robot=robot, representation=rep, contact_cap=contact_cap)
            s.compile()
        except RuntimeError as exc:  # the inserted pose's inverse kinematics
            raise UserInputError(
                f"the robot cannot reach this geometry's inserted pose ({exc}); keep every "
                f"size within the robot's reach"
            ) from None
        xml[out / name] = s.to_xml()
    fileio.check_room(out, sum(len(x.encode()) for x in xml.values()) + ROOM_MARGIN_BYTES)
    fileio.write_many(xml)
    return out / "scene.xml", out / "free_peg.xml", rep
