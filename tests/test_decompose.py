"""User CAD parts through CoACD, and the command line's handling of bad input."""

import subprocess
import sys

import numpy as np
import pytest
import trimesh

from peghole_mjx.cli.main import main
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import loads as strict_json  # no bare NaN
from peghole_mjx.geometry.decompose import (
    CoacdParams,
    cad_meshes,
    estimate_radial_clearance_mm,
    load_mesh,
    measure_deviation,
    run_coacd,
)
from peghole_mjx.geometry.specs import PRESETS


@pytest.fixture(scope="module")
def rect1_stl(tmp_path_factory):
    d = tmp_path_factory.mktemp("rect1")
    peg, hole = cad_meshes(PRESETS["rect-1"])
    peg.export(d / "peg.stl")
    hole.export(d / "hole.stl")
    return d


def test_cad_round_trip_rect1_passes_the_drop_test(rect1_stl, tmp_path, capsys):
    """rect-1 hole block and peg exported to STL, decomposed by CoACD, drop-tested."""
    rc = main(
        [
            "models",
            "decompose",
            str(rect1_stl / "peg.stl"),
            str(rect1_stl / "hole.stl"),
            "--out",
            str(tmp_path),
            "--peg-mass",
            "0.4",
            "--drop-test",
            "--json",
        ]
    )
    report = strict_json(capsys.readouterr().out)
    assert rc == 0
    assert report["drop_test_passed"] and abs(report["drop_test_gap_mm"]) < 1.0
    assert report["radial_clearance_mm"] == pytest.approx(0.3, abs=0.005)
    assert report["peg"]["excess_mm"] < 0.01  # a box is its own hull
    assert report["hole"]["n_hulls"] >= 4  # a block with a hole needs at least 4 pieces
    assert report["hole_depth_mm"] == pytest.approx(150.0, abs=0.01)
    saved = strict_json((tmp_path / "report.json").read_text())
    assert saved["drop_test_gap_mm"] == report["drop_test_gap_mm"]


def test_deviation_measures_a_known_bulge():
    """A hull set that sticks 1 mm out of a cube must report ~1 mm of excess."""
    cube = trimesh.creation.box([0.02, 0.02, 0.02])
    exact = measure_deviation(cube, [np.asarray(cube.vertices)])
    assert exact.excess_mm < 1e-6
    bulged = np.asarray(cube.vertices) * np.array([1.0, 1.0, (0.01 + 0.001) / 0.01])
    dev = measure_deviation(cube, [bulged])
    assert dev.excess_mm == pytest.approx(1.0, rel=0.05)


def test_clearance_estimate_and_coacd_on_dual_peg():
    peg, hole = cad_meshes(PRESETS["dual-2"], sections=64)
    peg.apply_scale(1e-3)
    hole.apply_scale(1e-3)
    # 64-gon cylinders: the gap between the faces is (R - r) cos(pi/64) ~ 0.1 mm
    assert estimate_radial_clearance_mm(peg, hole) == pytest.approx(0.1, rel=0.02)
    hulls = run_coacd(peg, CoacdParams(threshold=0.05, max_ch_vertex=32))
    assert len(hulls) >= 2  # two pegs joined by a bridge are not convex
    assert max(len(h) for h in hulls) <= 32


def test_missing_and_non_manifold_meshes_are_rejected(tmp_path):
    with pytest.raises(UserInputError, match="not found"):
        load_mesh(tmp_path / "nope.stl")
    box = trimesh.creation.box([10, 10, 10])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])  # two triangles missing
    open_box.export(tmp_path / "open.stl")
    with pytest.raises(UserInputError, match="not a closed manifold"):
        load_mesh(tmp_path / "open.stl")
    (tmp_path / "garbage.stl").write_text("this is not a mesh")
    with pytest.raises(UserInputError):
        load_mesh(tmp_path / "garbage.stl")
    with pytest.raises(UserInputError, match="units"):
        load_mesh(tmp_path / "open.stl", units="furlong")


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "peghole_mjx.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.parametrize(
    "args, message",
    [
        (
            [
                "models",
                "build",
                "--geometry",
                "rect",
                "--hole",
                "60.1x40.1",
                "--peg",
                "60.5x40.5",
                "--length",
                "150",
            ],
            "w' < w violated",
        ),
        (
            [
                "models",
                "build",
                "--geometry",
                "dual",
                "--hole-radius",
                "6.1",
                "--peg-radius",
                "6.5",
                "--distance",
                "40",
                "--length",
                "50",
            ],
            "eq 2.1",
        ),
        (
            [
                "models",
                "build",
                "--geometry",
                "rect",
                "--hole",
                "60.1x40.1",
                "--peg=0x40",
                "--length",
                "150",
            ],
            "argument --peg: must be a finite number in [1, 700], got 0.0",
        ),
        (["models", "build", "--geometry", "dual", "--hole-radius", "6.1"], "needs --peg-radius"),
        (["models", "decompose", "missing_peg.stl", "missing_hole.stl"], "mesh file not found"),
    ],
)
def test_cli_bad_input_gives_one_line_and_nonzero_exit(tmp_path, args, message, capsys):
    """In-process (the program's own process is tested by the scene build below)."""
    try:
        rc = main([*args, "--out", str(tmp_path / "out")])
    except SystemExit as exc:  # argparse
        rc = exc.code
    err = capsys.readouterr().err
    assert rc != 0
    assert message in err
    assert "Traceback" not in err


def test_cli_non_manifold_mesh(tmp_path, rect1_stl, capsys):
    box = trimesh.creation.box([10, 10, 10])
    trimesh.Trimesh(box.vertices, box.faces[:-1]).export(tmp_path / "open.stl")
    argv = ["models", "decompose", str(tmp_path / "open.stl"), str(rect1_stl / "hole.stl")]
    rc = main([*argv, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "not a closed manifold" in err
    assert "Traceback" not in err


def test_cli_build_writes_loadable_scenes(tmp_path):
    import mujoco

    res = _cli(
        "models",
        "build",
        "--geometry",
        "rect",
        "--hole",
        "60.1x40.1",
        "--peg",
        "59.8x39.8",
        "--length",
        "150",
        "--out",
        str(tmp_path),
    )
    assert res.returncode == 0, res.stderr
    for name in ("scene.xml", "free_peg.xml"):
        m = mujoco.MjModel.from_xml_path(str(tmp_path / name))
        assert m.npair == 28  # the rect default: edge capsules (geometry/edges.py)


def test_cli_check_one_preset_json():
    res = _cli("models", "check", "--preset", "rect-2", "--no-mjx", "--json")
    assert res.returncode == 0, res.stderr
    rows = strict_json(res.stdout)
    assert [r["representation"] for r in rows] == ["edges", "box"]
    row = rows[0]
    for key in (
        "preset",
        "nominal_clearance_mm",
        "effective_clearance_mm",
        "clearance_error_pct",
        "drop_test_gap_mm",
        "mjx_jax_ok",
        "n_convex_geoms",
    ):
        assert key in row
    assert row["preset"] == "rect-2" and abs(row["clearance_error_pct"]) < 10
