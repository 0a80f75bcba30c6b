"""User CAD parts: load, convex-decompose with CoACD, measure the deviation, write an MJCF.

Convention for user meshes: both parts in their ASSEMBLED pose (peg fully in the hole), in the
same frame, +z the extraction direction, units given by ``units`` (CAD default: mm).

The deviation of a decomposition is measured, not assumed: points sampled on the surface of
the union of hulls are projected onto the input surface. ``excess`` is the largest distance of
a hull point lying OUTSIDE the input solid (material the simulation has and the part has not:
for a hole block, this is how far the hulls intrude into the hole). A warning is raised when
the excess of either part exceeds ``WARN_FRACTION`` of the radial clearance, because the
hulls then eat the clearance.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from peghole_mjx._optional import optional_import
from peghole_mjx.errors import UserInputError
from peghole_mjx.geometry.specs import MM, DualSpec, PegHoleSpec, RectSpec

#: warn when the hulls' excess deviation exceeds this fraction of the radial clearance
WARN_FRACTION = 0.25
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def _cad(name: str):
    """Module ``name`` of the ``cad`` extra, or a one-line error naming the install command."""
    return optional_import(name, "decomposing CAD parts (peghole models decompose)")


class DecompositionWarning(UserWarning):
    """The convex decomposition deviates from the part by a large fraction of the clearance."""


@dataclass(frozen=True)
class CoacdParams:
    """CoACD parameters exposed on the command line (see ``coacd.run_coacd``)."""

    threshold: float = 0.01  # concavity threshold: smaller = more, tighter hulls
    max_convex_hull: int = -1
    preprocess_mode: str = "auto"
    preprocess_resolution: int = 50
    resolution: int = 2000
    mcts_nodes: int = 20
    mcts_iterations: int = 150
    mcts_max_depth: int = 3
    max_ch_vertex: int = 64  # MJX: keep hulls small (stack notes: <= 64)
    seed: int = 0

    def __post_init__(self):
        """Refuse values CoACD aborts on or never finishes with (ranges in
        ``peghole_mjx.validation.RANGES``)."""
        from peghole_mjx.validation import check

        for name in (
            "threshold",
            "max_convex_hull",
            "preprocess_resolution",
            "resolution",
            "mcts_iterations",
            "max_ch_vertex",
            "seed",
        ):
            check(name, getattr(self, name), f"CoACD {name}")
        if self.preprocess_mode not in ("auto", "on", "off"):
            raise UserInputError("CoACD preprocess_mode must be auto, on or off")


def load_mesh(path: str | Path, units: str = "mm"):
    """Load an STL/OBJ/PLY file as one watertight trimesh in metres.

    Raises :class:`UserInputError` for a missing file, an unreadable or empty mesh, or a mesh
    that is not watertight (open edges: no inside/outside, no volume).
    """
    trimesh = _cad("trimesh")

    path = Path(path)
    if units not in UNITS:
        raise UserInputError(f"unknown units {units!r}; choose one of {sorted(UNITS)}")
    if not path.is_file():
        raise UserInputError(f"mesh file not found: {path}")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except ImportError:  # trimesh guesses a text encoding (an optional module) for garbage
        raise UserInputError(f"cannot read mesh {path}: not a valid STL, OBJ or PLY file") from None
    except Exception as exc:  # trimesh raises many types for malformed files
        raise UserInputError(f"cannot read mesh {path}: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise UserInputError(f"{path} holds no triangles")
    mesh.merge_vertices()
    if not mesh.is_watertight:
        from trimesh.grouping import group_rows

        open_edges = len(group_rows(mesh.edges_sorted, require_count=1))
        raise UserInputError(
            f"{path} is not a closed manifold solid ({open_edges} open edges): "
            "repair it in CAD (close holes, remove duplicate faces) and export again"
        )
    if mesh.volume <= 0:
        mesh.invert()
    mesh.apply_scale(UNITS[units])
    return mesh


def run_coacd(mesh, params: CoacdParams = CoacdParams()) -> list[np.ndarray]:
    """Convex hulls (list of vertex arrays, metres) of ``mesh`` by CoACD."""
    coacd = _cad("coacd")
    trimesh = _cad("trimesh")

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
        threshold=params.threshold,
        max_convex_hull=params.max_convex_hull,
        preprocess_mode=params.preprocess_mode,
        preprocess_resolution=params.preprocess_resolution,
        resolution=params.resolution,
        mcts_nodes=params.mcts_nodes,
        mcts_iterations=params.mcts_iterations,
        mcts_max_depth=params.mcts_max_depth,
        decimate=True,  # enforce max_ch_vertex (CoACD ignores it otherwise)
        max_ch_vertex=params.max_ch_vertex,
        seed=params.seed,
    )
    hulls = []
    for verts, faces in parts:
        hull = trimesh.Trimesh(verts, faces).convex_hull
        hulls.append(np.asarray(hull.vertices))
    return hulls


@dataclass(frozen=True)
class Deviation:
    """Deviation of a set of hulls from the input surface, mm."""

    excess_mm: float  # max distance of hull-surface points outside the input solid
    excess_p95_mm: float
    n_hulls: int
    hull_vertices_max: int


def measure_deviation(
    mesh, hulls: list[np.ndarray], n_samples: int = 20000, seed: int = 0
) -> Deviation:
    """Sample the hulls' surfaces; measure how far the points outside the part lie from it."""
    trimesh = _cad("trimesh")
    _cad("rtree")  # trimesh's proximity queries

    rng = np.random.default_rng(seed)
    hull_meshes = [trimesh.Trimesh(h).convex_hull for h in hulls]
    areas = np.array([h.area for h in hull_meshes])
    counts = rng.multinomial(n_samples, areas / areas.sum())
    pts = np.concatenate(
        [
            trimesh.sample.sample_surface(h, max(int(c), 1), seed=int(rng.integers(1 << 31)))[0]
            for h, c in zip(hull_meshes, counts, strict=True)
        ]
    )
    outside = ~mesh.contains(pts)  # hull surface where the part has no material
    _, excess, _ = trimesh.proximity.closest_point(mesh, pts[outside])
    return Deviation(
        excess_mm=float(excess.max() / MM) if len(excess) else 0.0,
        excess_p95_mm=float(np.percentile(excess, 95) / MM) if len(excess) else 0.0,
        hull_vertices_max=max(len(h) for h in hulls),
        n_hulls=len(hulls),
    )


def estimate_radial_clearance_mm(peg, hole) -> float:
    """Radial clearance of the assembled pair: the smallest gap between the peg's side faces
    (normals within 10 degrees of horizontal) and the hole surface, mm."""
    trimesh = _cad("trimesh")
    _cad("rtree")  # trimesh's proximity queries

    pts, face_idx = trimesh.sample.sample_surface(peg, 20000, seed=1)
    side = np.abs(peg.face_normals[face_idx][:, 2]) < math.sin(math.radians(10))
    z_lo, z_hi = hole.bounds[:, 2]
    side &= (pts[:, 2] > z_lo) & (pts[:, 2] < z_hi)
    if not side.any():
        raise UserInputError(
            "the peg's side faces do not overlap the hole in height: "
            "export both parts in their assembled pose, +z = extraction"
        )
    hole_side = hole.submesh(
        [np.abs(hole.face_normals[:, 2]) < math.sin(math.radians(10))], append=True
    )
    _, dist, _ = trimesh.proximity.closest_point(hole_side, pts[side])
    return float(dist.min() / MM)


@dataclass
class DecomposeReport:
    """What ``peghole models decompose`` measured and wrote."""

    peg: Deviation
    hole: Deviation
    radial_clearance_mm: float
    warn_threshold_mm: float
    warnings: list[str] = field(default_factory=list)
    mjcf: str = ""
    hole_depth_mm: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def _assembled_sites(peg, hole) -> tuple[np.ndarray, np.ndarray | None]:
    """Peg tip (centre of its lowest downward face) and the hole bottom under it (or None)."""
    down = np.flatnonzero(peg.face_normals[:, 2] < -0.9)
    if not len(down):
        raise UserInputError("the peg has no downward-facing end face (+z must be extraction)")
    centres = peg.triangles_center[down]
    tip = centres[np.argmin(centres[:, 2])]
    origins = np.array([[tip[0], tip[1], tip[2] + 1e-6]])
    locs, _, _ = hole.ray.intersects_location(origins, np.array([[0.0, 0.0, -1.0]]))
    bottom = None
    if len(locs):
        bottom = locs[np.argmax(locs[:, 2])]
    return tip, bottom


def write_user_mjcf(
    peg,
    hole,
    peg_hulls: list[np.ndarray],
    hole_hulls: list[np.ndarray],
    out: Path,
    friction: float,
    peg_mass_kg: float | None = None,
    sim=None,
) -> tuple[Path, float | None]:
    """Free peg + fixed hole block MJCF with every hull pair as a contact pair.

    Returns the XML path and the hole depth (m) if a hole bottom was found under the peg.
    The keyframe ``mouth`` lifts the peg so that its tip is at the top of the hole block.
    """
    import mujoco

    from peghole_mjx.geometry.mjcf import SimOptions, _set_options

    sim = sim or SimOptions()
    s = mujoco.MjSpec()
    s.modelname = "user_peghole"
    _set_options(s, sim)
    s.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[1, 1, 0.05],
        contype=0,
        conaffinity=0,
        pos=[0, 0, hole.bounds[0, 2]],
    )
    s.worldbody.add_light(name="top_light", pos=[0, 0, 1.5], dir=[0, 0, -1])
    tip, bottom = _assembled_sites(peg, hole)
    hole_body = s.worldbody.add_body(name="hole", mocap=True)
    peg_body = s.worldbody.add_body(name="peg")
    peg_body.add_freejoint(name="peg_free")
    mass = peg_mass_kg if peg_mass_kg is not None else 1200.0 * peg.volume  # ~PLA density
    vols = np.array([_hull_volume(h) for h in peg_hulls])
    peg_names, hole_names = [], []
    for i, (h, v) in enumerate(zip(peg_hulls, vols, strict=True)):
        mesh = s.add_mesh(name=f"peg_hull{i:03d}_mesh")
        mesh.uservert = h.ravel().tolist()
        peg_body.add_geom(
            name=f"peg_hull{i:03d}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            contype=0,
            conaffinity=0,
            mass=mass * v / vols.sum(),
            rgba=[0.2, 0.45, 0.85, 1],
        )
        peg_names.append(f"peg_hull{i:03d}")
    for i, h in enumerate(hole_hulls):
        mesh = s.add_mesh(name=f"hole_hull{i:03d}_mesh")
        mesh.uservert = h.ravel().tolist()
        hole_body.add_geom(
            name=f"hole_hull{i:03d}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            contype=0,
            conaffinity=0,
            rgba=[0.75, 0.72, 0.65, 1],
        )
        hole_names.append(f"hole_hull{i:03d}")
    for a in peg_names:
        for b in hole_names:
            s.add_pair(
                name=f"{a}__{b}",
                geomname1=a,
                geomname2=b,
                condim=3,
                friction=[friction, friction, 0, 0, 0],
                solref=list(sim.solref),
                solimp=list(sim.solimp),
            )
    peg_body.add_site(name="peg_tip", pos=tip.tolist(), size=[0.002] * 3, group=3)
    depth = None
    if bottom is not None:
        hole_body.add_site(name="hole_bottom", pos=bottom.tolist(), size=[0.002] * 3, group=3)
        depth = float(hole.bounds[1, 2] - bottom[2])
    lift = hole.bounds[1, 2] - tip[2]
    s.add_key(name="mouth", qpos=[0, 0, lift, 1, 0, 0, 0])
    s.compile()
    from peghole_mjx import fileio

    out.mkdir(parents=True, exist_ok=True)
    path = fileio.write_text(out / "user_peghole.xml", s.to_xml())
    return path, depth


def _hull_volume(vertices: np.ndarray) -> float:
    from scipy.spatial import ConvexHull

    return float(ConvexHull(vertices).volume)


def decompose_parts(
    peg_path: str | Path,
    hole_path: str | Path,
    out_dir: str | Path,
    *,
    units: str = "mm",
    params: CoacdParams = CoacdParams(),
    friction: float = 0.266,
    peg_mass_kg: float | None = None,
    clearance_mm: float | None = None,
    warn_fraction: float = WARN_FRACTION,
) -> DecomposeReport:
    """The whole user-part pipeline: load, decompose, measure, write MJCF and report.json."""
    from peghole_mjx.validation import check, dumps

    friction = check("friction", friction)
    warn_fraction = check("warn_fraction", warn_fraction)
    if peg_mass_kg is not None:
        peg_mass_kg = check("peg_mass_kg", peg_mass_kg, kind="mass_kg")
    if clearance_mm is not None:
        clearance_mm = check("clearance_mm", clearance_mm)
    peg = load_mesh(peg_path, units)
    hole = load_mesh(hole_path, units)
    if clearance_mm is None:
        clearance_mm = estimate_radial_clearance_mm(peg, hole)
    if clearance_mm <= 0:
        raise UserInputError(
            f"radial clearance {clearance_mm:.4f} mm: the peg touches or overlaps the hole in "
            "the assembled pose; pass --clearance-mm if that is intended"
        )
    peg_hulls = run_coacd(peg, params)
    hole_hulls = run_coacd(hole, params)
    dev_peg = measure_deviation(peg, peg_hulls)
    dev_hole = measure_deviation(hole, hole_hulls)
    limit = warn_fraction * clearance_mm
    msgs = []
    for label, dev in (("peg", dev_peg), ("hole", dev_hole)):
        if dev.excess_mm > limit:
            msg = (
                f"{label} hulls deviate up to {dev.excess_mm:.3f} mm outside the part, more "
                f"than {warn_fraction:.0%} of the {clearance_mm:.3f} mm radial clearance "
                f"({limit:.3f} mm): lower --threshold or raise --resolution"
            )
            msgs.append(msg)
            warnings.warn(msg, DecompositionWarning, stacklevel=2)
    out = Path(out_dir)
    path, depth = write_user_mjcf(peg, hole, peg_hulls, hole_hulls, out, friction, peg_mass_kg)
    report = DecomposeReport(
        dev_peg,
        dev_hole,
        clearance_mm,
        limit,
        msgs,
        str(path),
        None if depth is None else depth / MM,
    )
    from peghole_mjx import fileio

    fileio.write_text(out / "report.json", dumps(report.as_dict(), indent=2))
    return report


def cad_meshes(spec: PegHoleSpec, sections: int = 128):
    """CAD-like (true round, not polygonal) peg and hole-block meshes of a spec, in mm,
    in the assembled pose (peg fully inserted, hole mouth at z = 0, +z up). For round trips."""
    trimesh = _cad("trimesh")
    _cad("manifold3d")  # trimesh's boolean difference

    depth = spec.hole_depth_mm
    if isinstance(spec, RectSpec):
        w, v, t, f = spec.hole_w_mm, spec.hole_v_mm, spec.wall_mm, spec.floor_mm
        block = trimesh.creation.box([w + 2 * t, v + 2 * t, depth + f])
        block.apply_translation([0, 0, -(depth + f) / 2])
        cavity = trimesh.creation.box([w, v, depth + 1.0])
        cavity.apply_translation([0, 0, -depth / 2 + 0.5])
        hole = block.difference(cavity)
        peg = trimesh.creation.box([spec.peg_w_mm, spec.peg_v_mm, spec.length_mm])
        peg.apply_translation([0, 0, -depth + spec.length_mm / 2])
        return peg, hole
    assert isinstance(spec, DualSpec)
    t, f = spec.wall_mm, spec.floor_mm
    half_h = 0.5 * spec.hole_distance_mm
    Rm = max(spec.hole_radii_mm)
    block = trimesh.creation.box([2 * half_h + 2 * (Rm + t), 2 * (Rm + t), depth + f])
    block.apply_translation([0, 0, -(depth + f) / 2])
    cavities = []
    for x, R in zip((-half_h, half_h), spec.hole_radii_mm, strict=True):
        c = trimesh.creation.cylinder(radius=R, height=depth + 1.0, sections=sections)
        c.apply_translation([x, 0, -depth / 2 + 0.5])
        cavities.append(c)
    hole = block.difference(cavities[0]).difference(cavities[1])
    half_p = 0.5 * spec.peg_distance_mm
    pieces = []
    for x, r in zip((-half_p, half_p), spec.peg_radii_mm, strict=True):
        c = trimesh.creation.cylinder(radius=r, height=spec.length_mm, sections=sections)
        c.apply_translation([x, 0, -depth + spec.length_mm / 2])
        pieces.append(c)
    rmax = max(spec.peg_radii_mm)
    bridge = trimesh.creation.box([2 * half_p + 2 * rmax, 2 * rmax, spec.bridge_mm])
    bridge.apply_translation([0, 0, -depth + spec.length_mm + spec.bridge_mm / 2])
    pieces.append(bridge)
    peg = pieces[0].union(pieces[1]).union(pieces[2])
    return peg, hole
