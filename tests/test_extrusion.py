"""Exact convex pieces of extruded parts (geometry/extrusion.py) in ``peghole task make``.

The parts are real meshes generated in code (trimesh and manifold3d): a triangular peg in a
50 x 50 x 30 mm block (issue 54's case), a keyed D-shaft, a 6-tooth spline and a T-slot, each
an extrusion along +z in a blind hole; a chamfered hole (not an extrusion) falls back to
CoACD. The six built-in shapes (geometry/shapes.py) exported to STL and read back (three
through the exact path, the other three through ``task make``) must give their code-made
pieces' volume and clearance. Bad pairs (an undercut in a non-extruded hole, a peg longer than
the block, units off by 1000) are refused in one line before any piece. No CoACD runs for an
extrusion: ``run_coacd`` is replaced by a function that fails. Skipped without the ``cad``
extra.
"""

import math

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
manifold3d = pytest.importorskip("manifold3d")
pytest.importorskip("coacd")

from test_tasks import _refused  # noqa: E402 (the task tests' one-line refusal check)

from peghole_mjx.cli.main import main  # noqa: E402
from peghole_mjx.core.errors import UserInputError  # noqa: E402
from peghole_mjx.core.validation import loads  # noqa: E402
from peghole_mjx.envs import task_make  # noqa: E402
from peghole_mjx.envs.task_make import ContactRun, make_task  # noqa: E402
from peghole_mjx.geometry import coacd_budget  # noqa: E402
from peghole_mjx.geometry import task as tf  # noqa: E402
from peghole_mjx.geometry.decompose import CoacdParams, load_mesh  # noqa: E402
from peghole_mjx.geometry.extrusion import (  # noqa: E402
    MAX_POLYGON_VERTICES,
    convex_polygons,
    exact_pieces,
    mesh_free_travel_mm,
    pieces_volume,
)
from peghole_mjx.geometry.shapes import BUILTINS, builtin_parts, offset_convex  # noqa: E402

#: the contact count of these tests: 2 worlds, 40 env steps per policy
SHORT = ContactRun(worlds=2, env_steps=40)
MM = 1e-3


def _solid(cs, z0: float, z1: float):
    """The extrusion of a manifold3d CrossSection (mm) from z0 to z1, a trimesh (mm)."""
    m = manifold3d.Manifold.extrude(cs, z1 - z0).translate((0.0, 0.0, z0))
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def _pair(peg_poly, hole_cs, length=45.0, depth=28.0, block=50.0, height=30.0):
    """A prismatic peg (``peg_poly``, mm) resting on the bottom of a blind hole (``hole_cs``)
    ``depth`` deep in a ``block`` x ``block`` x ``height`` mm block, mouth at z = 0."""
    peg = _solid(manifold3d.CrossSection([np.asarray(peg_poly, float)]), -depth, length - depth)
    outer = manifold3d.CrossSection.square((block, block), center=True)
    floor = _solid(outer, -height, -depth)
    walls = _solid(outer - hole_cs, -depth, 0.0)
    hole = trimesh.boolean.union([floor, walls], engine="manifold")
    return peg, hole


def _offset(poly, d: float):
    """The hole of a peg cross-section: every edge moved out by ``d`` (mitred corners)."""
    cs = manifold3d.CrossSection([np.asarray(poly, float)])
    return cs.offset(d, manifold3d.JoinType.Miter, 10.0)


def triangle_pair():
    """Issue 54: an equilateral peg, 16 mm sides, 45 mm long, in a blind triangular hole 0.25
    mm larger all round in a 50 x 50 x 30 mm block."""
    r = 16.0 / math.sqrt(3)
    tri = np.array(
        [[r * math.cos(a), r * math.sin(a)] for a in np.pi / 2 + 2 * np.pi * np.arange(3) / 3]
    )
    hole = manifold3d.CrossSection([offset_convex(tri, 0.25)])
    return (*_pair(tri, hole), 0.25)


def keyed_pair():
    """A D-shaft r 8 mm with a flat 6 mm from the axis (24 arc points), 0.05 mm radial."""
    a = math.asin(6.0 / 8.0)
    phi = np.linspace(np.pi - a, 2 * np.pi + a, 24)
    d = np.stack([8.0 * np.cos(phi), 8.0 * np.sin(phi)], 1)
    return (*_pair(d, _offset(d, 0.05)), 0.05)


def spline_pair():
    """A 6-tooth spline shaft: root r 7 mm, teeth to r 9 mm, 3 mm wide, 0.1 mm radial."""
    pts = []
    for k in range(6):
        c = 2 * np.pi * k / 6
        w = math.asin(1.5 / 9.0)
        for ang, rad in (
            (c - w, 7.0),
            (c - w, 9.0),
            (c + w, 9.0),
            (c + w, 7.0),
            (c + np.pi / 6, 7.0),
        ):
            pts.append([rad * math.cos(ang), rad * math.sin(ang)])
    poly = np.array(pts)
    return (*_pair(poly, _offset(poly, 0.1)), 0.1)


def tslot_pair():
    """A T-section peg (a 24 x 6 mm bar on an 8 x 14 mm stem), 0.25 mm radial (0.5 mm
    diametral)."""
    t = np.array([[-4, -10], [4, -10], [4, 4], [12, 4], [12, 10], [-12, 10], [-12, 4], [-4, 4]])
    return (*_pair(t, _offset(t, 0.25)), 0.25)


GALLERY = {
    "triangle": triangle_pair,
    "keyed": keyed_pair,
    "spline": spline_pair,
    "tslot": tslot_pair,
}


def _write(folder, peg, hole):
    folder.mkdir(parents=True, exist_ok=True)
    peg.export(folder / "peg.stl")
    hole.export(folder / "hole.stl")
    return str(folder / "peg.stl"), str(folder / "hole.stl")


@pytest.fixture
def no_coacd(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("CoACD was called for an extruded part")

    monkeypatch.setattr(task_make, "run_coacd", fail)


def _mesh_diametral_mm(out, doc) -> list[float]:
    """The meshes' diametral free travel at the task's start pose (the peg centred as the
    pieces' check centred it), in the task check's 8 directions (manifold3d booleans)."""
    peg = trimesh.load(out / tf.PEG_MESH)
    hole = trimesh.load(out / tf.HOLE_MESH)
    n = 8
    dirs = [(math.cos(math.pi * k / n), math.sin(math.pi * k / n), 0.0) for k in range(n)]
    return [
        mesh_free_travel_mm(peg, hole, u) + mesh_free_travel_mm(peg, hole, [-c for c in u])
        for u in dirs
    ]


def _check_exact_task(out, doc, radial_mm: float) -> None:
    src = doc["source"]
    assert src["pieces"] == "exact extrusion" and "coacd" not in src
    for part in ("peg", "hole"):
        assert src["decomposition"][part]["method"] == "exact extrusion"
    assert doc["checks"]["hull_intrusion"]["pieces"] == "exact"
    cl = doc["checks"]["clearance"]
    assert cl["radial_mm"] == pytest.approx(radial_mm, rel=0.01)
    # the pieces' clearance (MuJoCo) is the meshes' (booleans) within 1 % of the clearance
    mesh = _mesh_diametral_mm(out, doc)
    tol = 0.01 * 2 * radial_mm
    assert cl["effective_min_mm"] == pytest.approx(min(mesh), abs=tol)
    assert cl["effective_max_mm"] == pytest.approx(max(mesh), abs=tol)
    assert doc["caps"]["engines"] == ["mujoco", "mjx"]  # every face <= 20 vertices
    spec = tf.load_task(out)
    assert max(len(h) for h in (*spec.peg_hulls, *spec.hole_hulls)) <= tf.MAX_HULL_VERTICES


# ------------------------------------------------------------------ recognition, pieces


@pytest.mark.parametrize("name", sorted(GALLERY))
def test_extruded_parts_become_exact_pieces_whose_volume_is_the_mesh(name):
    peg, hole, _ = GALLERY[name]()
    for mesh in (peg, hole):
        mesh.apply_scale(MM)
        res = exact_pieces(mesh)
        assert not isinstance(res, str), res
        assert pieces_volume(res.hulls) == pytest.approx(mesh.volume, rel=1e-9)
        assert len(res.hulls) <= tf.MAX_HULLS
        assert tf.max_face_vertices(res.hulls) <= tf.MJX_MAX_FACE_VERTICES
    # the blind hole: a floor band and a walls band
    assert exact_pieces(hole).record["bands_mm"] == [[-30.0, -28.0], [-28.0, 0.0]]


def test_hertel_mehlhorn_pieces_are_convex_and_tile_the_region():
    square = np.array([[-25.0, -25.0], [25.0, -25.0], [25.0, 25.0], [-25.0, 25.0]])
    hole = np.array([[0.0, 5.0], [-5.0, -5.0], [5.0, -5.0]])[::-1]  # clockwise: a hole
    pieces = convex_polygons([square, hole])

    def area(p):
        q = np.roll(p, -1, axis=0)
        return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))

    assert all(area(p) > 0 for p in pieces)  # counter-clockwise
    assert sum(area(p) for p in pieces) == pytest.approx(2500.0 - 50.0, rel=1e-12)
    assert len(pieces) <= 6
    circle = np.stack([np.cos(np.linspace(0, 2 * np.pi, 64, endpoint=False))] * 2, 1)
    circle[:, 1] = np.sin(np.linspace(0, 2 * np.pi, 64, endpoint=False))
    parts = convex_polygons([10 * circle])
    assert max(len(p) for p in parts) <= MAX_POLYGON_VERTICES and len(parts) >= 4


def test_parts_with_a_sloped_face_are_not_extrusions():
    tapered = builtin_parts("tapered", 0.2)  # the hole's mouth chamfered 2 mm x 45 deg
    why = exact_pieces(tapered.hole_mesh)
    assert isinstance(why, str) and "neither horizontal nor vertical" in why
    assert not isinstance(exact_pieces(tapered.peg_mesh), str)
    cone = trimesh.creation.cone(radius=0.01, height=0.02)
    assert isinstance(exact_pieces(cone), str)


@pytest.mark.parametrize("name", ["hex", "keyed", "l_section"])
def test_builtin_meshes_through_the_exact_path_match_their_code_made_pieces(name, tmp_path):
    """Reuse check: a built-in's meshes written to STL (mm) and read back as a user's files
    give exact pieces of the mesh's volume (the peg's: the code-made pieces'; the hole's
    code-made wedges leave out the block's corners), and the same clearance, start depth."""
    parts = builtin_parts(name, 0.2)
    files = []
    for label, mesh in (("peg", parts.peg_mesh), ("hole", parts.hole_mesh)):
        m = mesh.copy()
        m.apply_scale(1.0 / MM)
        m.export(tmp_path / f"{label}.stl")
        files.append(load_mesh(tmp_path / f"{label}.stl", "mm"))
    peg, hole = files
    code = {"peg": parts.peg_hulls, "hole": parts.hole_hulls}
    for label, mesh in (("peg", peg), ("hole", hole)):
        res = exact_pieces(mesh)
        assert not isinstance(res, str), res
        vol, code_vol = pieces_volume(res.hulls), pieces_volume(code[label])
        assert vol == pytest.approx(mesh.volume, rel=1e-9)
        if label == "peg" or name == "l_section":  # the same solid
            assert vol == pytest.approx(code_vol, rel=1e-6)  # STL: float32
        else:  # the code's wedges cover 10 mm of wall, not the block's corners
            assert code_vol < vol
        code[label + "_exact"] = res.hulls
    from peghole_mjx.geometry.task_check import place_and_check
    from peghole_mjx.sim.free import run_passive

    kw = {"friction": 0.266, "peg_mass_kg": 0.02, "radial_clearance_mm": 0.1}
    kw["run_passive"] = run_passive
    a = place_and_check(peg, hole, code["peg"], code["hole"], **kw)
    b = place_and_check(peg, hole, code["peg_exact"], code["hole_exact"], **kw)
    assert b.effective_min_mm == pytest.approx(a.effective_min_mm, abs=0.002)  # 1 % of 0.2
    assert b.effective_max_mm == pytest.approx(a.effective_max_mm, abs=0.002)
    assert b.rest_depth_mm == pytest.approx(a.rest_depth_mm, abs=1e-6)


#: the built-ins the test above leaves out (it covers hex, keyed and l_section)
OTHER_BUILTINS = sorted(set(BUILTINS) - {"hex", "keyed", "l_section"})


@pytest.mark.parametrize("name", OTHER_BUILTINS)
def test_the_other_builtins_through_task_make_from_stl_get_their_code_made_pieces(
    name, tmp_path, monkeypatch, no_coacd
):
    """Issue 54, reuse, for the other three built-ins (cylinder, three_pin, tapered): their
    meshes written to STL (mm) and given to ``task make`` as a user's pair (the pipeline
    after the pieces stubbed) get pieces without CoACD (exact extrusion; the chamfered
    ``tapered`` hole: revolution N-gons, the mesh's own 16-gon) whose peg is the code-made
    peg's solid and whose checks (clearance, start depth) are the code-made pieces' within
    1 % of the clearance."""
    from peghole_mjx.envs.config import sim_options
    from peghole_mjx.envs.mesh_extract import default_config
    from peghole_mjx.geometry.decompose import estimate_radial_clearance_mm
    from peghole_mjx.geometry.task_check import place_and_check
    from peghole_mjx.sim.free import run_passive

    parts = builtin_parts(name, 0.2)
    for label, mesh in (("peg", parts.peg_mesh), ("hole", parts.hole_mesh)):
        m = mesh.copy()
        m.apply_scale(1.0 / MM)
        m.export(tmp_path / f"{label}.stl")
    seen = {}

    def stub(peg_mesh, hole_mesh, peg_hulls, hole_hulls, out, **kw):
        seen.update(kw, peg=peg_mesh, hole=hole_mesh, peg_hulls=peg_hulls, hole_hulls=hole_hulls)
        return {}

    monkeypatch.setattr(task_make, "build_task", stub)
    make_task(tmp_path / "peg.stl", tmp_path / "hole.stl", tmp_path / "task")
    method = "revolution N-gons" if name == "tapered" else "exact extrusion"
    assert seen["source"]["pieces"] == method and "coacd" not in seen["source"]
    peg_hulls, hole_hulls = seen["peg_hulls"], seen["hole_hulls"]
    assert len(peg_hulls) == len(parts.peg_hulls)
    assert pieces_volume(peg_hulls) == pytest.approx(pieces_volume(parts.peg_hulls), rel=1e-6)
    if name == "tapered":  # the same wedges as the code's (16-gon, to the block's circle)
        assert len(hole_hulls) == len(parts.hole_hulls)
        assert pieces_volume(hole_hulls) == pytest.approx(pieces_volume(parts.hole_hulls), rel=1e-6)
    else:  # the exact pieces are the hole part itself (the code's wedges leave out corners)
        assert pieces_volume(hole_hulls) == pytest.approx(seen["hole"].volume, rel=1e-9)
    kw = {
        "friction": 0.266,
        "peg_mass_kg": task_make.PEG_DENSITY_KG_M3 * float(seen["peg"].volume),
        "radial_clearance_mm": estimate_radial_clearance_mm(seen["peg"], seen["hole"]),
        "sim": sim_options(default_config()),
        "run_passive": run_passive,
    }
    code = place_and_check(seen["peg"], seen["hole"], parts.peg_hulls, parts.hole_hulls, **kw)
    stl = place_and_check(seen["peg"], seen["hole"], peg_hulls, hole_hulls, **kw)
    assert stl.effective_min_mm == pytest.approx(code.effective_min_mm, abs=0.002)  # 1 % of 0.2
    assert stl.effective_max_mm == pytest.approx(code.effective_max_mm, abs=0.002)
    assert stl.rest_depth_mm == pytest.approx(code.rest_depth_mm, abs=1e-4)  # STL: float32


# ------------------------------------------------------------------ task make


def test_the_triangular_peg_hole_is_a_checked_task_in_a_minute_without_coacd(
    tmp_path, capsys, no_coacd
):
    """Issue 54's pair through ``peghole task make``: exact pieces, checked, at the mesh's
    clearance (0.25 mm radial), the meshes, pieces and checks within 60 s (CoACD took 10 min
    and gave 300 pieces). The contact count after them (the env's compile and rollouts, the
    same for any task) is timed in task.json, not bounded here: it depends on the CPU's load."""
    peg, hole, radial = triangle_pair()
    pe, ho = _write(tmp_path / "in", peg, hole)
    out = tmp_path / "task"
    argv = ["task", "make", pe, ho, "--units", "mm", "--out", str(out), "--json"]
    argv += ["--contact-worlds", "2", "--contact-steps", "40"]
    assert main(argv) == 0
    doc = loads(capsys.readouterr().out)
    timing = doc["timing_s"]
    assert timing["meshes_and_pieces"] + timing["checks"] <= 60.0, timing
    _check_exact_task(out, doc, radial)
    assert doc["peg"]["hulls"] == 1 and doc["hole"]["hulls"] <= 8
    assert doc["peg"]["length_mm"] == pytest.approx(45.0, abs=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["keyed", "spline", "tslot"])
def test_extruded_gallery_parts_are_checked_tasks_at_the_mesh_clearance(name, tmp_path, no_coacd):
    peg, hole, radial = GALLERY[name]()
    pe, ho = _write(tmp_path / "in", peg, hole)
    out = tmp_path / "task"
    doc = make_task(pe, ho, out, pieces="exact", contacts=SHORT)
    timing = doc["timing_s"]
    assert timing["meshes_and_pieces"] + timing["checks"] <= 60.0, timing
    print(name, timing, doc["peg"]["hulls"], doc["hole"]["hulls"], doc["checks"]["clearance"])
    _check_exact_task(out, doc, radial)


def test_a_part_that_is_not_an_extrusion_falls_back_to_coacd(tmp_path, monkeypatch):
    """A hole whose mouth is chamfered: CoACD for the hole (as before), exact pieces for the
    box peg; ``--pieces exact`` refuses it in one line. The pipeline after the pieces is
    stubbed (the CoACD call is what is checked)."""
    peg = trimesh.creation.box([10, 10, 30])
    peg.apply_translation([0, 0, -10])  # z from -25 to 5
    block = trimesh.creation.box([24, 24, 30])
    block.apply_translation([0, 0, -15])
    cavity = trimesh.creation.box([12, 12, 30])
    cavity.apply_translation([0, 0, -10])
    chamfer = trimesh.Trimesh(
        np.array(
            [
                *([-6, -6, -2], [6, -6, -2], [6, 6, -2], [-6, 6, -2]),
                *([-9, -9, 1], [9, -9, 1], [9, 9, 1], [-9, 9, 1]),
            ],
            float,
        )
    ).convex_hull
    hole = trimesh.boolean.difference([block, cavity, chamfer], engine="manifold")
    pe, ho = _write(tmp_path / "in", peg, hole)
    calls = []
    real = task_make.run_coacd

    def counting(mesh, params, **kw):
        calls.append(params)
        return real(mesh, params, **kw)

    seen = {}

    def stub(peg_mesh, hole_mesh, peg_hulls, hole_hulls, out, **kw):
        seen.update(kw, peg_hulls=peg_hulls, hole_hulls=hole_hulls)
        return {}

    monkeypatch.setattr(task_make, "run_coacd", counting)
    monkeypatch.setattr(task_make, "build_task", stub)
    params = CoacdParams(threshold=0.05)
    make_task(pe, ho, tmp_path / "t", params=params)
    # the hole only: its coarse estimate (geometry/coacd_budget.py), then the given options
    assert calls == [coacd_budget.coarse_params(params), params]
    src = seen["source"]
    assert src["pieces"] == "CoACD + exact extrusion" and src["coacd"]["threshold"] == 0.05
    assert src["decomposition"]["peg"]["method"] == "exact extrusion"
    assert src["decomposition"]["hole"]["method"] == "CoACD"
    assert "neither horizontal nor vertical" in src["decomposition"]["hole"]["why"]
    assert len(seen["peg_hulls"]) == 1 and seen["exact"] is False
    with pytest.raises(UserInputError, match="the hole part is not an extrusion along"):
        make_task(pe, ho, tmp_path / "t", pieces="exact")
    calls.clear()
    make_task(pe, ho, tmp_path / "t", params=params, pieces="coacd")
    assert len(calls) == 4 and seen["source"]["pieces"] == "CoACD"  # an estimate each


# ------------------------------------------------------------------ bad input, before work


def test_bad_pairs_are_refused_in_one_line_before_any_decomposition(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(task_make, "run_coacd", lambda *a: pytest.fail("CoACD ran"))
    peg, hole, _ = triangle_pair()
    pe, ho = _write(tmp_path / "ok", peg, hole)
    # the peg 3 mm longer than the block is high, through a through hole
    r = 16.0 / math.sqrt(3)
    tri = np.array(
        [[r * math.cos(a), r * math.sin(a)] for a in np.pi / 2 + 2 * np.pi * np.arange(3) / 3]
    )
    outer = manifold3d.CrossSection.square((50.0, 50.0), center=True)
    through = _solid(outer - manifold3d.CrossSection([offset_convex(tri, 0.25)]), -30.0, 0.0)
    long_peg = _solid(manifold3d.CrossSection([tri]), -33.0, 12.0)
    pt, ht = _write(tmp_path / "long", long_peg, through)
    pk, hk = _write(tmp_path / "keyed", *keyed_pair()[:2])  # 25 exact hole pieces
    cases = (
        ([pk, hk, "--max-hulls", "10"], "exact convex pieces number 25, more than the cap"),
        ([pe, pe, "--units", "mm"], "the peg and the hole part are the same solid"),
        ([pe, ho, "--units", "m"], "are the units right?"),  # 50 m: mm files read as m
        ([pt, ht], "below the hole part's lowest point"),
    )
    for i, (args, match) in enumerate(cases):
        out = tmp_path / f"out{i}"
        _refused(["task", "make", *args, "--out", str(out)], capsys, match)
        assert not out.exists()


def _tm(m):
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def undercut_pair():
    """A dovetail: a square peg whose foot (11 x 11 mm) narrows to 8 x 8 mm at the mouth of a
    square blind hole that narrows the same way (12 x 12 -> 8.5 x 8.5 mm, 20 mm deep) in a 30 x
    30 x 25 mm block. Sloped faces (no extrusion), square (no revolution): only CoACD could cut
    it, and the foot cannot come out along +z."""
    sq = manifold3d.CrossSection.square
    peg = manifold3d.Manifold.extrude(sq((11.0, 11.0), center=True), 20.0, scale_top=(8 / 11,) * 2)
    peg = peg.translate((0, 0, -20)) + manifold3d.Manifold.extrude(
        sq((8.0, 8.0), center=True), 11.0
    ).translate((0, 0, -1))
    cavity = manifold3d.Manifold.extrude(
        sq((12.0, 12.0), center=True), 20.0, scale_top=(8.5 / 12,) * 2
    ).translate((0, 0, -20))
    mouth = manifold3d.Manifold.extrude(sq((8.5, 8.5), center=True), 2.0).translate((0, 0, -1))
    block = manifold3d.Manifold.cube((30, 30, 25), center=True).translate((0, 0, -12.5))
    return (_tm(m) for m in (peg, block - cavity - mouth))


def test_an_undercut_a_long_peg_or_units_off_by_1000_are_one_line_before_any_pieces(
    tmp_path, capsys, monkeypatch
):
    """Issue 54's bad inputs to ``task make``: a non-extruded hole with an undercut, a peg
    longer than the block (through a through hole), mm files read as metres and metre files
    read as mm. Each is one line (exit 2), the whole of stderr, before any piece is made:
    every step from the exact pieces on (extrusion, revolution, the clearance that sizes
    them, CoACD's estimate and run) fails the test, and no folder is written."""

    def forbidden(*a, **k):
        raise AssertionError("work started before the refusal")

    for name in ("exact_pieces", "revolved_pair", "estimate_radial_clearance_mm", "run_coacd"):
        monkeypatch.setattr(task_make, name, forbidden)
    monkeypatch.setattr(coacd_budget, "estimate", forbidden)
    peg, hole = undercut_pair()
    scaled = [m.copy() for m in (peg, hole)]
    assert isinstance(exact_pieces(scaled[1]), str)  # the hole is no extrusion
    pu, hu = _write(tmp_path / "undercut", peg, hole)
    for m in scaled:
        m.apply_scale(MM)  # the same parts in metres
    pm, hm = _write(tmp_path / "metres", *scaled)
    r = 16.0 / math.sqrt(3)
    tri = np.array(
        [[r * math.cos(a), r * math.sin(a)] for a in np.pi / 2 + 2 * np.pi * np.arange(3) / 3]
    )
    outer = manifold3d.CrossSection.square((50.0, 50.0), center=True)
    through = _solid(outer - manifold3d.CrossSection([offset_convex(tri, 0.25)]), -30.0, 0.0)
    long_peg = _solid(manifold3d.CrossSection([tri]), -33.0, 12.0)  # 45 mm through a 30 mm block
    pl, hl = _write(tmp_path / "long", long_peg, through)
    pe, ho = _write(tmp_path / "ok", *triangle_pair()[:2])
    cases = (
        ([pu, hu], "extractable along +z", "undercut"),
        ([pl, hl], "below the hole part's lowest point"),
        ([pe, ho, "--units", "m"], "are the units right?"),  # 50 m: mm files read as metres
        ([pm, hm, "--units", "mm"], "are the units right?"),  # 0.03 mm: metre files read as mm
    )
    for i, (args, *needles) in enumerate(cases):
        out = tmp_path / f"out{i}"
        rc = main(["task", "make", *args, "--out", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, err
        assert err[0].startswith("peghole: error: "), err
        assert all(n in err[0] for n in needles), err[0]
        assert not out.exists()
