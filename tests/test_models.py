"""MJCF models: robot, scenes, model hygiene, clearance, drop tests, the convex-hull failure."""

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from peghole_mjx.cli.main import main
from peghole_mjx.core._mjx import mjx
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry import cli as gcli
from peghole_mjx.geometry import mjcf
from peghole_mjx.geometry.check import (
    CLEARANCE_TOLERANCE,
    effective_clearance_mm,
    effective_clearance_range_mm,
    free_peg_model,
)
from peghole_mjx.geometry.parts import (
    RECT_REPRESENTATIONS,
    REPRESENTATIONS,
    peg_parts,
    resolve_representation,
)
from peghole_mjx.geometry.specs import MM, PRESETS
from peghole_mjx.sim.free import check_spec, drop_gap_mujoco, drop_test

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scenes() -> dict[str, mujoco.MjModel]:
    return {name: mjcf.compile_scene(spec) for name, spec in PRESETS.items()}


def test_robot_model_matches_reference():
    m = mujoco.MjModel.from_xml_path(str(mjcf.ROBOT_XML))
    assert m.nq == m.nv == m.nu == 7
    torques = [320, 320, 176, 176, 110, 40, 40]
    for i, tau in enumerate(torques, start=1):
        act = m.actuator(f"joint{i}_motor")
        np.testing.assert_allclose(act.ctrlrange, [-tau, tau])
        np.testing.assert_allclose(act.forcerange, [-tau, tau])
        assert m.jnt_limited[m.joint(f"joint{i}").id]
    np.testing.assert_allclose(m.jnt_range[m.joint("joint7").id], [-3.05433, 3.05433])
    link_mass = sum(m.body(f"link{i}").mass[0] for i in range(1, 8))
    assert link_mass == pytest.approx(5.76 + 6.35 + 3.5 * 3 + 1.8 + 1.2)
    assert {m.sensor(i).name for i in range(m.nsensor)} == {"ft_force", "ft_torque"}
    # no collision anywhere on the robot
    assert not m.geom_contype.any() and not m.geom_conaffinity.any()


def test_flange_pose_at_home_follows_the_kinematic_chain():
    m = mujoco.MjModel.from_xml_path(str(mjcf.ROBOT_XML))
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)  # q = 0: the arm stands straight up
    z_flange = 0.1575 + 0.2025 + 0.2045 + 0.2155 + 0.1845 + 0.2155 + 0.081 + 0.045
    np.testing.assert_allclose(d.site("flange").xpos, [0, 0, z_flange], atol=1e-9)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_scene_hygiene_and_start_pose(scenes, name):
    m = scenes[name]
    for kind, count in (
        ("body", m.nbody),
        ("geom", m.ngeom),
        ("site", m.nsite),
        ("joint", m.njnt),
        ("actuator", m.nu),
    ):
        for i in range(1 if kind == "body" else 0, count):  # body 0 is the world
            assert getattr(m, kind)(i).name, f"unnamed {kind} {i}"
    # contacts come only from the explicit peg-hole pairs
    assert not m.geom_contype.any() and not m.geom_conaffinity.any() and m.npair > 0
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    assert d.ncon == 0, "the peg must start clear of the hole"
    gap = d.site("peg_tip").xpos[2] - d.site("hole_bottom").xpos[2]
    assert gap == pytest.approx(mjcf.SimOptions().tip_gap_mm * MM, abs=1e-7)
    np.testing.assert_allclose(d.site("peg_tip").xpos[:2], d.site("hole_mouth").xpos[:2], atol=1e-7)
    np.testing.assert_allclose(d.site("tool").xmat.reshape(3, 3), mjcf.TOOL_DOWN_MAT, atol=1e-7)
    assert m.body_subtreemass[m.body("peg").id] == pytest.approx(PRESETS[name].peg_mass_kg)


def test_ft_sensor_reads_the_peg_weight_at_rest(scenes):
    m = scenes["rect-2"]
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    d.ctrl[:] = d.qfrc_bias  # gravity compensation: the arm holds still (qacc = 0)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.qacc, 0, atol=1e-6)
    f_site = d.sensor("ft_force").data  # force on the tool side, in the site frame
    f_world = d.site("ft_site").xmat.reshape(3, 3) @ f_site
    # the sensor holds the peg up: it measures -weight (downward pull of the peg) or +weight
    assert abs(f_world[2]) == pytest.approx(0.4 * 9.81, rel=1e-6)
    assert np.linalg.norm(f_world[:2]) < 1e-9


def test_timestep_is_set_in_exactly_one_place():
    xml_text = " ".join(p.read_text() for p in (REPO / "mjcf").glob("*.xml"))
    assert not re.search(r"timestep\s*=", xml_text) and "<option" not in xml_text
    literal, applied = [], []
    for path in (REPO / "peghole_mjx").rglob("*.py"):
        for line in path.read_text().splitlines():
            if re.search(r"\b(timestep|sim_dt)\b\s*(:\s*float\s*)?=\s*[0-9.]", line):
                literal.append(f"{path.name}: {line.strip()}")
            if re.search(r"opt(ion)?\.timestep\s*=(?!=)", line):
                applied.append(f"{path.name}: {line.strip()}")
    # one numeric value (SimOptions' default) and one place that writes it into a model
    assert len(literal) == 1 and "timestep: float = " in literal[0], literal
    assert applied == ["mjcf.py: s.option.timestep = sim.timestep"], applied


def test_written_scene_loads_in_mujoco_and_mjx(tmp_path):
    path = mjcf.write_scene(PRESETS["dual-2"], tmp_path)
    m = mujoco.MjModel.from_xml_path(str(path))
    assert m.key("inserted") is not None and m.opt.timestep == mjcf.SimOptions().timestep
    mx = mjx.put_model(m, impl="jax")
    assert mx.nq == m.nq


def test_effective_clearance_of_the_rect_hole_is_exact():
    spec = PRESETS["rect-3"]
    assert effective_clearance_mm(spec) == pytest.approx(spec.clearance_mm, rel=1e-3)


@pytest.mark.parametrize("name", ["dual-1", "dual-2", "dual-3"])
@pytest.mark.parametrize("rep", REPRESENTATIONS)
def test_dual_effective_clearance_within_two_percent_in_every_direction(name, rep):
    """mesh: aligned 16-gons, travel between cos(pi/16) (R-r) and R-r; capsule and cylinder:
    round pegs in a circumscribed 16-gon of box walls, between R-r and (R-r) / cos(pi/16)."""
    spec = PRESETS[name]
    lo, hi = effective_clearance_range_mm(spec, free_peg_model(spec, representation=rep))
    c, a = spec.clearance_mm, np.cos(np.pi / 16)
    expect = (c * a, c) if rep == "mesh" else (c, c / a)
    np.testing.assert_allclose([lo, hi], expect, rtol=1e-3)
    assert abs(lo / c - 1) <= CLEARANCE_TOLERANCE and abs(hi / c - 1) <= CLEARANCE_TOLERANCE


def test_representations_build_their_collision_geometry():
    spec = PRESETS["dual-2"]
    n = spec.n_sides
    geom = mujoco.mjtGeom
    mesh = mjcf.compile_scene(spec, robot=False, representation="mesh")
    # shared meshes: one wedge and one prism asset for the symmetric preset
    assert mesh.nmesh == 2 and mesh.npair == 2 * (n + 1)
    cap = mjcf.compile_scene(spec, robot=False)  # the dual default
    assert cap.nmesh == 0 and cap.npair == 2 * (n + 1)
    pegs = [cap.geom(f"peg{i}").id for i in (1, 2)]
    assert all(cap.geom_type[g] == geom.mjGEOM_CAPSULE for g in pegs)
    assert cap.numeric("max_contact_points").data[0] == mjcf.CONTACT_CAPS[("dual", "capsule")].cap
    # walls and floor reach r deeper than the hole: the rounded end clears the floor
    d = mujoco.MjData(cap)
    mujoco.mj_kinematics(cap, d)
    floor = cap.geom("hole1_floor").id
    top = d.geom_xpos[floor][2] + cap.geom_size[floor][2]
    bottom = d.site("hole_bottom").xpos[2]
    assert bottom - top == pytest.approx(spec.peg_radii_mm[0] * MM, abs=1e-9)
    cyl = mjcf.compile_scene(spec, robot=False, representation="cylinder")
    assert cyl.geom_type[cyl.geom("peg1").id] == geom.mjGEOM_CYLINDER
    # rect: "box" pairs the peg box with the wall boxes; "edges" (the default) pairs edge
    # capsules with boxes (and parallel capsules with each other) and never box with box
    rect = mjcf.compile_scene(PRESETS["rect-2"], robot=False, representation="box")
    assert (rect.geom_type[list(rect.pair_geom1)] == geom.mjGEOM_BOX).all()
    edges = mjcf.compile_scene(PRESETS["rect-2"], robot=False)
    t1, t2 = edges.geom_type[list(edges.pair_geom1)], edges.geom_type[list(edges.pair_geom2)]
    assert edges.npair == 28 and not ((t1 == geom.mjGEOM_BOX) & (t2 == geom.mjGEOM_BOX)).any()
    with pytest.raises(UserInputError, match="dual parts'"):
        mjcf.compile_scene(PRESETS["rect-2"], robot=False, representation="capsule")
    for m in (mesh, cap):  # masses add up in every representation
        assert m.body_subtreemass[m.body("peg").id] == pytest.approx(spec.peg_mass_kg)


def test_bad_representation_and_cap_are_one_line_errors():
    spec = PRESETS["dual-2"]
    with pytest.raises(UserInputError, match="unknown collision representation 'sphere'"):
        resolve_representation(spec, "sphere")
    with pytest.raises(UserInputError, match="cannot run with impl='jax'"):
        resolve_representation(spec, "cylinder", impl="jax")
    assert resolve_representation(spec, "cylinder", impl="warp") == "cylinder"
    measured = mjcf.CONTACT_CAPS[("dual", "capsule")].measured_max
    with pytest.raises(UserInputError, match="below the measured maximum"):
        mjcf.build_scene(spec, robot=False, contact_cap=measured - 1)
    m = mjcf.compile_scene(spec, robot=False, contact_cap=0)  # 0: no cap
    assert m.nnumeric == 0


def test_check_reports_each_representation_without_mjx():
    rows = {
        r: check_spec("dual-1", PRESETS["dual-1"], mjx_too=False, representation=r)
        for r in REPRESENTATIONS
    }
    assert all(r.passed for r in rows.values()), rows
    cap = mjcf.CONTACT_CAPS[("dual", "capsule")].cap
    assert rows["capsule"].contact_cap == cap and rows["capsule"].contacts_allocated == cap
    assert rows["mesh"].contacts_allocated == 4 * 2 * 17 and rows["mesh"].contact_cap == 0
    assert rows["cylinder"].contacts_allocated is None  # MJX-JAX cannot build it
    assert rows["capsule"].constraint_rows < rows["mesh"].constraint_rows


def test_check_table_says_what_the_clearance_error_is(capsys):
    """``models check``: a rect hole's clearance is checked along its axes; its diagonal
    travel (+41.42 % = sqrt(2) - 1, by the geometry of a rectangular gap) is labelled as such
    and explained below the table, not shown as a passing +41 % error."""
    argv = ["models", "check", "--preset", "rect-2", "--representation", "edges", "--no-mjx"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    row = next(ln for ln in out.splitlines() if ln.startswith("rect-2"))
    assert "-0.01 (axes; diag +41.42)" in row and row.endswith("pass")
    assert "clearance err %" in out.splitlines()[0]
    legend = " ".join(out.split("\n\n", 1)[1].split())
    assert "sqrt(2) - 1 = +41.42 %" in legend and "not an error" in legend
    assert "Rect holes: checked along the axes" in legend

    class Row:  # the two numbers clearance_error_text reads
        def __init__(self, lo, hi):
            self.clearance_error_pct, self.clearance_error_max_pct = lo, hi

    assert gcli.clearance_error_text(Row(-1.92, 0.01), "dual") == "-1.92..+0.01"
    assert gcli.clearance_error_text(Row(-0.01, 41.42), "rect") == "-0.01 (axes; diag +41.42)"
    # a rect hole whose diagonal adds nothing over the tolerance shows the axes alone
    assert gcli.clearance_error_text(Row(-0.01, 0.5), "rect") == "-0.01 (axes)"


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_drop_test_mujoco_c_reaches_the_bottom(name):
    spec = PRESETS[name]
    for rep in REPRESENTATIONS if name.startswith("dual") else RECT_REPRESENTATIONS:
        gap = drop_gap_mujoco(free_peg_model(spec, representation=rep), spec.hole_depth_mm * MM)
        assert abs(gap) < 1.0, rep


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rect-2", "dual-2"])
def test_drop_test_mjx_jax_reaches_the_bottom(name):
    res = drop_test(PRESETS[name])  # dual: the capsule default (the mesh one: models_check.json)
    assert res.mjx_ok and res.passed, res
    assert abs(res.gap_mjx_mm) < 0.1


def test_convex_hull_failure_is_avoided():
    """R6: the dual peg collided as ONE convex hull stops at the mouth; decomposed, it drops."""
    spec = PRESETS["dual-1"]
    depth = spec.hole_depth_mm * MM
    assert len(peg_parts(spec, single_hull=True)) == 1
    gap_hull = drop_gap_mujoco(free_peg_model(spec, peg_single_hull=True), depth)
    gap_decomposed = drop_gap_mujoco(free_peg_model(spec), depth)
    assert gap_hull > spec.hole_depth_mm - 1.0  # stuck at the mouth
    assert abs(gap_decomposed) < 1.0


def test_ik_reports_unreachable_targets():
    s = mjcf.build_scene(PRESETS["rect-1"], ik=False)
    with pytest.raises(RuntimeError, match="IK did not converge"):
        mjcf.solve_tool_ik(s, np.array([3.0, 0.0, 0.2]), max_iter=50)


def test_cli_bad_representation_and_cap_are_one_line_errors(tmp_path, capsys):
    from peghole_mjx.cli.main import main

    for args, msg in (
        (["check", "--preset", "dual-2", "--representation", "sphere"], "unknown collision"),
        (["build", "--preset", "dual-2", "--contact-cap", "3", "--out", str(tmp_path)], "below"),
    ):
        rc = main(["models", *args])
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.startswith("peghole: error")]
        assert rc == 2 and len(lines) == 1 and msg in lines[0], err


def test_capsule_mouth_lips_keep_the_clearance(monkeypatch):
    """The experimental rounded mouth lips (parts.LIP_RADIUS_MM > 0; off by default) add one
    capsule per wall and keep the effective clearance band."""
    from peghole_mjx.geometry import parts

    spec = PRESETS["dual-2"]
    monkeypatch.setattr(parts, "LIP_RADIUS_MM", 0.3)
    m = free_peg_model(spec, representation="capsule")
    assert m.npair == 2 * (2 * spec.n_sides + 1)
    lo, hi = effective_clearance_range_mm(spec, m)
    c = spec.clearance_mm
    assert abs(lo / c - 1) <= CLEARANCE_TOLERANCE and abs(hi / c - 1) <= CLEARANCE_TOLERANCE
