"""Pieces of revolved parts (geometry/revolve.py) in ``peghole task make``: a stepped pin and a
tapered pin in their round bores (64-facet exports, manifold3d revolutions in a 50 x 50 x 30
mm block), the N of the sagitta bound, the refusal when N cannot meet the cap, and the
pieces' clearance equal to the meshes'. Skipped without the ``cad`` extra."""

import math

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")
manifold3d = pytest.importorskip("manifold3d")

from peghole_mjx.core.errors import UserInputError  # noqa: E402
from peghole_mjx.envs import task_make  # noqa: E402
from peghole_mjx.envs.task_make import ContactRun, make_task  # noqa: E402
from peghole_mjx.geometry import task as tf  # noqa: E402
from peghole_mjx.geometry.extrusion import mesh_free_travel_mm  # noqa: E402
from peghole_mjx.geometry.revolve import (  # noqa: E402
    SAGITTA_FRACTION,
    choose_sides,
    revolution_bands,
    revolved_pair,
    sagitta_mm,
)

MM = 1e-3
SHORT = ContactRun(worlds=2, env_steps=40)


def _tm(m):
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def _rev(profile, segments: int):
    return manifold3d.Manifold.revolve(
        manifold3d.CrossSection([np.asarray(profile, float)]), segments
    )


def _block():
    return manifold3d.Manifold.cube((50, 50, 30), center=True).translate((0, 0, -15))


def stepped_pair(c: float = 0.5, segments: int = 64):
    """A pin r 4 mm (18 mm) under r 6 mm (27 mm), resting in a stepped blind bore ``c``
    larger all round, 28 mm deep; mm."""
    peg = _rev([[0, -28], [4, -28], [4, -10], [6, -10], [6, 17], [0, 17]], segments)
    cav = _rev([[0, -28], [4 + c, -28], [4 + c, -10], [6 + c, -10], [6 + c, 1], [0, 1]], segments)
    return _tm(peg), _tm(_block() - cav)


def tapered_pair(c: float = 0.25, segments: int = 64):
    """A tapered pin r 4 -> 6 mm over 45 mm in a conical blind bore ``c`` larger (radially at
    equal height), 28 mm deep; mm."""
    peg = _rev([[0, -28], [4, -28], [6, 17], [0, 17]], segments)
    cav = _rev([[0, -28], [4 + c, -28], [4 + c + 2 * 29 / 45, 1], [0, 1]], segments)
    return _tm(peg), _tm(_block() - cav)


def _m(mesh):
    m = mesh.copy()
    m.apply_scale(MM)
    return m


def test_revolved_parts_are_recognised_with_their_profile():
    peg, hole = (_m(x) for x in stepped_pair())
    p, h = revolution_bands(peg, "peg"), revolution_bands(hole, "hole")
    radii = np.array([(b.r0_mm, b.r1_mm) for b in p.bands])
    np.testing.assert_allclose(radii, [[4, 4], [6, 6]], atol=1e-4)
    assert [b.round for b in h.bands] == [False, True, True]  # the floor, two bore steps
    assert [b.r0_mm for b in h.bands[1:]] == pytest.approx([4.5, 6.5], abs=1e-4)
    tp, th = (_m(x) for x in tapered_pair())
    cone = revolution_bands(tp, "peg").bands
    assert len(cone) == 1 and (cone[0].r0_mm, cone[0].r1_mm) == pytest.approx((4, 6), abs=1e-4)
    bore = revolution_bands(th, "hole").bands[-1]
    assert bore.r0_mm == pytest.approx(4.25, abs=1e-4)
    # a bushing: a round outer wall is a wall, the bore inside it the round loop
    bush = _m(_tm(_rev([[0, -30], [20, -30], [20, 0], [4.3, 0], [4.3, -28], [0, -28]], 64)))
    pin = _m(_tm(_rev([[0, -28], [4, -28], [4, 17], [0, 17]], 64)))
    pair = revolved_pair(pin, bush, 0.3, tf.MAX_HULLS)
    assert pair.sides == choose_sides(4.3, 0.3) and len(pair.hole_hulls) == pair.sides + 4
    # not revolutions: a box, a hex prism (6 vertices a loop), a peg with a flat
    assert not revolution_bands(trimesh.creation.box([0.01, 0.01, 0.02]), "peg").ok
    hexagon = trimesh.creation.cylinder(radius=0.005, height=0.02, sections=6)
    assert not revolution_bands(hexagon, "peg").ok


def test_sides_meet_the_sagitta_bound_and_the_fewest_do():
    for r, c in ((6.5, 0.5), (4.25, 0.25), (8.0, 0.05)):
        n = choose_sides(r, c)
        assert sagitta_mm(r, n) <= SAGITTA_FRACTION * c + 1e-12
        assert n == 8 or sagitta_mm(r, n - 1) > SAGITTA_FRACTION * c
    assert choose_sides(6.5, 0.5, facets=16) == 16  # the mesh's own N-gon is exact


def test_pieces_fit_the_caps_and_a_fine_clearance_is_refused_in_one_line():
    peg, hole = (_m(x) for x in stepped_pair())
    pair = revolved_pair(peg, hole, 0.5, tf.MAX_HULLS)
    assert pair.sides == choose_sides(6.5, 0.5, 64) == 26
    assert len(pair.hole_hulls) == 2 * 26 + 1  # two bands of wedges and the floor
    assert len(pair.peg_hulls) == 4  # two frusta of a 26-gon, each in two <= 20-gon pieces
    assert max(len(h) for h in (*pair.peg_hulls, *pair.hole_hulls)) <= tf.MAX_HULL_VERTICES
    assert tf.max_face_vertices([*pair.peg_hulls, *pair.hole_hulls]) <= tf.MJX_MAX_FACE_VERTICES
    assert pair.records["hole"]["sides"] == 26 and "sagitta_bound" in pair.records["peg"]
    with pytest.raises(UserInputError) as e:
        revolved_pair(peg, hole, 0.05, tf.MAX_HULLS)
    msg = str(e.value)
    assert "\n" not in msg and "N = 64" in msg and "cap of 64" in msg and "0.05 mm" in msg


def _mesh_travel(out) -> list[float]:
    peg = trimesh.load(out / tf.PEG_MESH)
    hole = trimesh.load(out / tf.HOLE_MESH)
    dirs = [(math.cos(math.pi * k / 8), math.sin(math.pi * k / 8), 0.0) for k in range(8)]
    return [
        mesh_free_travel_mm(peg, hole, u) + mesh_free_travel_mm(peg, hole, [-c for c in u])
        for u in dirs
    ]


@pytest.mark.parametrize("name", ["stepped", "tapered"])
def test_revolved_pairs_are_tasks_at_the_mesh_clearance_without_coacd(name, tmp_path, monkeypatch):
    """``task make`` (auto): the 64-facet bores' exact extrusion pieces (65 and more) exceed
    the cap, CoACD is not run; the N-gon pieces' free travel is the meshes' within 1 % of
    the clearance."""
    monkeypatch.setattr(task_make, "run_coacd", lambda *a: pytest.fail("CoACD ran"))
    peg, hole = stepped_pair() if name == "stepped" else tapered_pair()
    (tmp_path / "in").mkdir()
    peg.export(tmp_path / "in" / "peg.stl")
    hole.export(tmp_path / "in" / "hole.stl")
    out = tmp_path / "task"
    doc = make_task(tmp_path / "in" / "peg.stl", tmp_path / "in" / "hole.stl", out, contacts=SHORT)
    assert doc["source"]["pieces"] == "revolution N-gons"
    cl = doc["checks"]["clearance"]
    mesh = _mesh_travel(out)
    tol = 0.01 * 2 * cl["radial_mm"]
    assert cl["effective_min_mm"] == pytest.approx(min(mesh), abs=tol)
    assert cl["effective_max_mm"] == pytest.approx(max(mesh), abs=tol)
    assert doc["caps"]["engines"] == ["mujoco", "mjx"]
