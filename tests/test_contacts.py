"""The contact record of one episode (envs/contacts.py, ``peghole envs contacts``).

On the ``mujoco`` engine (fast to compile; the record reads the state through MjData, the same
on either engine): every recorded point lies on the peg's surface, in the tip frame, inside
its cross-section; forces are compressive; the inserted peg with its commanded errors touches
the walls from the first step; the episode is deterministic for a seed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.cli.main import main
from peghole_mjx.envs.contacts import (
    COLUMNS,
    TWO_POINT_DZ_MM,
    plot_contacts,
    record_contacts,
    two_point_steps,
)
from peghole_mjx.envs.rollout import scripted_policy

STEPS = 60


@pytest.fixture(scope="module")
def rect():
    return envs.load("RectExtract", config_overrides={"engine": "mujoco"})


@pytest.fixture(scope="module")
def trace(rect):
    return record_contacts(rect, scripted_policy(rect), seed=3, max_steps=STEPS, progress=False)


def test_points_lie_on_the_pegs_surface_in_the_tip_frame(rect, trace):
    spec = rect.spec
    x, y, z = (trace.column(k) for k in ("x_mm", "y_mm", "z_mm"))
    a, b = spec.peg_w_mm / 2, spec.peg_v_mm / 2
    tol = 0.05  # mm: contact points sit within the solver's penetration of the surface
    assert len(x) > 0
    assert np.all(np.abs(x) <= a + tol) and np.all(np.abs(y) <= b + tol)
    assert np.all(z <= tol) and np.all(z >= -spec.length_mm - tol)
    # on a side face (|x| = a or |y| = b) or on the tip face (z = 0), never inside the peg
    on_side = (np.abs(np.abs(x) - a) <= tol) | (np.abs(np.abs(y) - b) <= tol)
    on_tip = np.abs(z) <= tol
    assert np.all(on_side | on_tip)


def test_normals_are_unit_and_point_from_the_wall_into_the_peg(rect, trace):
    """On the peg's +x face the wall pushes towards -x, on its -y face towards +y, and so on."""
    x, y, z = (trace.column(k) for k in ("x_mm", "y_mm", "z_mm"))
    n = np.stack([trace.column(k) for k in ("nx", "ny", "nz")], axis=1)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
    a, b, tol = rect.spec.peg_w_mm / 2, rect.spec.peg_v_mm / 2, 0.05
    on_x = (np.abs(np.abs(x) - a) <= tol) & (np.abs(y) < b - tol) & (z < -tol)
    on_y = (np.abs(np.abs(y) - b) <= tol) & (np.abs(x) < a - tol) & (z < -tol)
    assert on_x.any() and on_y.any()
    np.testing.assert_allclose(n[on_x, 0], -np.sign(x[on_x]), atol=1e-2)
    np.testing.assert_allclose(n[on_y, 1], -np.sign(y[on_y]), atol=1e-2)


def _row(step, z, normal, force=1.0):
    return (step, 0.0, 0.0, 0.0, z, *normal, force, "wall")


def test_two_point_contact_needs_opposite_normals_apart_along_the_peg():
    rows = [
        _row(1, -1.0, (1, 0, 0)),  # tilted: tip on one wall, the mouth on the other
        _row(1, -40.0, (-1, 0, 0)),
        _row(2, -20.0, (1, 0, 0)),  # squeezed at one height: not two-point
        _row(2, -20.0 - TWO_POINT_DZ_MM / 2, (-1, 0, 0)),
        _row(3, -1.0, (1, 0, 0)),  # one wall only
        _row(3, -40.0, (1, 0, 0)),
        _row(4, -1.0, (0, 1, 0)),  # adjacent walls
        _row(4, -40.0, (1, 0, 0)),
        _row(5, -1.0, (1, 0, 0)),  # the opposite contact carries no force
        _row(5, -40.0, (-1, 0, 0), force=0.0),
    ]
    assert two_point_steps(rows) == {1}


def test_forces_are_compressive_and_walls_are_touched_from_the_start(trace):
    f = trace.column("normal_N")
    assert np.all(f >= 0.0) and f.max() > 0.0
    assert trace.column("step").min() == 1  # the inserted peg touches at once
    assert all(g.startswith(("hole_", "mouth_")) for g in trace.column("hole_geom"))
    s = trace.summary()
    assert s["env_steps"] == STEPS and s["contact_rows"] == len(trace.rows)
    assert s["most_contacts_at_one_step"] >= 1
    assert 0 <= s["two_point_steps"] <= s["steps_in_contact"]


def test_the_record_is_deterministic_for_a_seed(rect, trace):
    again = record_contacts(rect, scripted_policy(rect), seed=3, max_steps=STEPS, progress=False)
    assert again.rows == trace.rows


def test_plot_and_csv(trace, tmp_path):
    png = plot_contacts(trace, tmp_path / "c.png", "test")
    assert png.stat().st_size > 10_000
    trace.write_csv(tmp_path / "c.csv")
    lines = (tmp_path / "c.csv").read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS) and len(lines) == len(trace.rows) + 1


def test_cli_writes_the_record(tmp_path, capsys):
    out = tmp_path / "rec"
    argv = ["envs", "contacts", "--env", "RectExtract", "--engine", "mujoco", "--out", str(out)]
    assert main([*argv, "--set", "episode_length=20"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env"] == "RectExtract" and summary["engine"] == "mujoco"
    assert summary["env_steps"] == 20
    assert (out / "contacts.png").exists() and (out / "contacts.csv").exists()
    assert json.loads(capsys.readouterr().out) == summary


def test_cli_refuses_an_out_that_is_a_file(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    argv = ["envs", "contacts", "--env", "RectExtract", "--engine", "mujoco", "--out", str(f)]
    assert main(argv) == 2
    assert "existing file, not a folder" in capsys.readouterr().err
