"""MJCF models: robot, scenes, model hygiene, clearance, drop tests, the convex-hull failure."""

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest
from mujoco import mjx

from peghole_mjx.geometry import mjcf
from peghole_mjx.geometry.check import (
    drop_gap_mujoco,
    drop_test,
    effective_clearance_mm,
    free_peg_model,
)
from peghole_mjx.geometry.parts import peg_parts
from peghole_mjx.geometry.specs import MM, PRESETS

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


@pytest.mark.parametrize("name", ["rect-3", "dual-3"])
def test_effective_clearance_is_measured_within_ten_percent(name):
    spec = PRESETS[name]
    eff = effective_clearance_mm(spec)
    assert eff == pytest.approx(spec.clearance_mm, rel=0.10)
    if name.startswith("dual"):  # aligned 16-gons: travel between cos(pi/16) (R-r) and R-r
        assert eff == pytest.approx(spec.clearance_mm * np.cos(np.pi / 16), rel=1e-3)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_drop_test_mujoco_c_reaches_the_bottom(name):
    spec = PRESETS[name]
    gap = drop_gap_mujoco(free_peg_model(spec), spec.hole_depth_mm * MM)
    assert abs(gap) < 1.0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rect-2", "dual-2"])
def test_drop_test_mjx_jax_reaches_the_bottom(name):
    res = drop_test(PRESETS[name])
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
