"""Geometry, CAD parts, analytic commands and benchmark outputs: bad input ends in one line
(exit 2) before any work, and outputs are checked and written atomically
(docs/guide/reliability.md, the geometry rows).

Cheap by design: no CoACD run (``run_coacd`` is replaced by a function that fails the test, or
by a trivial hull where the write itself is tested), no IK or MuJoCo compile for a refusal, and
the CAD parts are small boxes made with trimesh and manifold3d.
"""

from __future__ import annotations

import argparse
import errno
import os

import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx.core.errors import InfeasibleGeometryError, UserInputError
from peghole_mjx.core.validation import MIN_PART_MM, RANGES
from peghole_mjx.files import fileio

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("manifold3d")  # cad_meshes' boolean difference
pytest.importorskip("rtree")  # trimesh's proximity and ray queries


# ---------------------------------------------------------------------- helpers
def no_work(monkeypatch):
    """Make every expensive step fail the test: CoACD, scene building, figure evaluation."""
    from peghole_mjx.analysis import figures
    from peghole_mjx.geometry import decompose, mjcf
    from peghole_mjx.sim import free

    def forbidden(*a, **k):
        raise AssertionError("work started before the refusal")

    monkeypatch.setattr(decompose, "run_coacd", forbidden)
    monkeypatch.setattr(mjcf, "build_scene", forbidden)
    monkeypatch.setattr(free, "check_spec", forbidden)
    monkeypatch.setattr(figures, "write_family", forbidden)


def small_disk(monkeypatch, free: int = 4096):
    """The output's file system has ``free`` bytes left."""
    monkeypatch.setattr(fileio, "free_bytes", lambda path: free)


def rect_parts(hole=20.0, peg=19.6, length=30.0):
    """CAD peg and hole block of a small rect peg-hole (mm, assembled pose), unvalidated."""
    from peghole_mjx.geometry.decompose import cad_meshes
    from peghole_mjx.geometry.specs import RectSpec

    return cad_meshes(RectSpec(hole, hole, peg, peg, length))


def export(tmp_path, peg, hole) -> tuple[str, str]:
    peg.export(tmp_path / "peg.stl")
    hole.export(tmp_path / "hole.stl")
    return str(tmp_path / "peg.stl"), str(tmp_path / "hole.stl")


def decompose(tmp_path, capsys, peg_file, hole_file, *extra):
    out = tmp_path / "out"
    rc, _, err = peghole(["models", "decompose", peg_file, hole_file, "--out", out, *extra], capsys)
    # (the hidden records beside the files: fileio.write_file_record, 2026-12-05)
    written = sorted(p.name for p in out.iterdir() if p.name[0] != ".") if out.exists() else []
    return rc, err, written


def undercut_parts():
    """A peg whose head sits in a wide chamber under a narrow mouth: a ship in a bottle."""
    block = trimesh.creation.box([40.0, 40.0, 30.0])
    block.apply_translation([0, 0, -15.0])
    chamber = trimesh.creation.box([20.0, 20.0, 20.0])
    chamber.apply_translation([0, 0, -15.0])  # z in [-25, -5]
    mouth = trimesh.creation.box([10.0, 10.0, 7.0])
    mouth.apply_translation([0, 0, -2.5])  # z in [-6, 1]
    hole = block.difference(chamber).difference(mouth)
    head = trimesh.creation.box([18.0, 18.0, 15.0])
    head.apply_translation([0, 0, -16.0])  # z in [-23.5, -8.5]
    stem = trimesh.creation.box([8.0, 8.0, 20.0])
    stem.apply_translation([0, 0, 0.0])  # z in [-10, 10]
    return head.union(stem), hole


# ---------------------------------------------------------------------- 1. CAD sanity
def test_cad_peg_wider_than_its_hole_is_refused_with_the_interference(
    tmp_path, capsys, monkeypatch
):
    """A peg 2 % wider than its hole: interference, not 'radial clearance 0.35 mm'."""
    no_work(monkeypatch)
    peg_file, hole_file = export(tmp_path, *rect_parts(hole=20.0, peg=20.4))
    rc, err, written = decompose(tmp_path, capsys, peg_file, hole_file)
    assert rc == 2
    # the corner reaches 0.2 sqrt(2) mm into the wall; (20.4^2 - 20^2) mm^2 x 30 mm overlap
    assert_one_line(err, "no interference", "0.2828 mm deep at", "volume 484.8 mm^3")
    assert "clearance 0." not in err
    assert "user_peghole.xml" not in written and "report.json" not in written


def test_cad_peg_one_metre_beside_the_hole_is_refused(tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    peg, hole = rect_parts()
    peg.apply_translation([1000.0, 0.0, 0.0])
    rc, err, written = decompose(tmp_path, capsys, *export(tmp_path, peg, hole))
    assert rc == 2
    assert_one_line(err, "peg inside the hole", "100 %", "not in its cavity")
    assert written == []


@pytest.mark.parametrize(
    "dz, needle",
    [
        (100.0, "lowest point is 70 mm above the hole part's top"),  # hovering above the block
        (-200.0, "no part of the peg lies within the hole part's height"),  # under the block
    ],
)
def test_cad_peg_not_inserted_is_refused(tmp_path, capsys, monkeypatch, dz, needle):
    no_work(monkeypatch)
    peg, hole = rect_parts()
    peg.apply_translation([0.0, 0.0, dz])
    rc, err, written = decompose(tmp_path, capsys, *export(tmp_path, peg, hole))
    assert rc == 2
    assert_one_line(err, "peg inside the hole", needle, "assembled pose")
    assert written == []


def test_cad_peg_and_hole_swapped_are_refused(tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    peg_file, hole_file = export(tmp_path, *rect_parts())
    rc, err, written = decompose(tmp_path, capsys, hole_file, peg_file)  # swapped
    assert rc == 2
    assert_one_line(err, "peg inside the hole", "PEG_MESH HOLE_MESH")
    assert written == []


def test_cad_parts_a_kilometre_and_a_half_across_are_refused(tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    peg, hole = rect_parts()
    for part in (peg, hole):
        part.apply_scale(50_000.0)  # the 30 mm peg becomes 1.5 km long
    rc, err, written = decompose(tmp_path, capsys, *export(tmp_path, peg, hole))
    assert rc == 2
    assert_one_line(err, "part size", "1.5e+06 mm across", "2000", "units")
    assert written == []


@pytest.mark.parametrize(
    "scale, units, needle",
    [
        (1.0, "m", "peg part is 30000 mm across with --units m"),  # a mm file read as metres
        (1e-3, "mm", "peg part is 0.03 mm across with --units mm"),  # a metre file read as mm
        (5e-5, "mm", "smallest part MuJoCo builds"),  # micrometre parts
    ],
)
def test_cad_parts_in_the_wrong_units_are_refused(
    tmp_path, capsys, monkeypatch, scale, units, needle
):
    no_work(monkeypatch)
    peg, hole = rect_parts()
    for part in (peg, hole):
        part.apply_scale(scale)
    rc, err, written = decompose(tmp_path, capsys, *export(tmp_path, peg, hole), "--units", units)
    assert rc == 2
    assert_one_line(err, "part size", needle)
    assert written == []


def test_cad_peg_with_an_undercut_is_refused(tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    rc, err, written = decompose(tmp_path, capsys, *export(tmp_path, *undercut_parts()))
    assert rc == 2
    assert_one_line(err, "extractable along +z", "undercut")
    assert written == []


@pytest.mark.parametrize("copy", [False, True], ids=["same_file", "two_copies"])
def test_identical_peg_and_hole_are_two_parts_not_an_undercut(tmp_path, capsys, monkeypatch, copy):
    """The same solid given as peg and hole (one file twice, or two copies): refused as one
    solid given twice, not reported as an "undercut"."""
    no_work(monkeypatch)
    _, hole = rect_parts()
    peg_file, hole_file = export(tmp_path, hole, hole)
    rc, err, written = decompose(tmp_path, capsys, hole_file, hole_file if not copy else peg_file)
    assert rc == 2
    assert_one_line(err, "not a peg-hole (two parts)", "the same solid")
    assert "undercut" not in err
    assert written == []


@pytest.mark.parametrize("preset", ["rect-1", "dual-2"])
def test_a_real_peg_hole_passes_the_cad_checks(preset):
    """The checks do not refuse the thesis's parts (true round, tip on the hole bottom)."""
    from peghole_mjx.geometry.decompose import cad_meshes, check_assembly
    from peghole_mjx.geometry.specs import PRESETS

    peg, hole = cad_meshes(PRESETS[preset])
    peg.apply_scale(1e-3)
    hole.apply_scale(1e-3)
    check_assembly(peg, hole)


# ---------------------------------------------------------------------- 2, 3. minimum sizes
@pytest.mark.parametrize(
    "argv, option",
    [
        (["--geometry", "rect", "--hole", "60.1x40.1", "--peg", "59.8x39.8", "--length",
          "0.0001"], "--length"),
        (["--geometry", "dual", "--hole-radius", "0.002", "--peg-radius", "0.001",
          "--distance", "40", "--length", "50"], "--hole-radius"),
        (["--geometry", "dual", "--hole-radius", "6.1", "--peg-radius", "0.001",
          "--distance", "40", "--length", "50"], "--peg-radius"),
        (["--geometry", "rect", "--hole", "0.002x0.002", "--peg", "0.001x0.001", "--length",
          "0.001"], "--hole"),
    ],
)  # fmt: skip
def test_models_build_refuses_sizes_below_what_mujoco_builds(
    tmp_path, capsys, monkeypatch, argv, option
):
    no_work(monkeypatch)
    rc, _, err = peghole(["models", "build", *argv, "--out", tmp_path / "o"], capsys)
    assert rc == 2
    assert_one_line(err, option, f"[{MIN_PART_MM:g}, 700]", "smallest part MuJoCo builds")
    assert not (tmp_path / "o").exists()


def test_the_minimum_size_is_in_the_ranges_table():
    from peghole_mjx.geometry.specs import RectSpec, dual_spec, validate

    assert RANGES["size_mm"].lo == MIN_PART_MM == RANGES["cad_part_mm"].lo
    with pytest.raises(InfeasibleGeometryError, match="minimum size.*smallest part MuJoCo"):
        dual_spec(6.1, 6.0, 40.0, 0.0001)
    with pytest.raises(InfeasibleGeometryError, match="wall_mm is below 1 mm"):
        validate(RectSpec(60.1, 40.1, 59.8, 39.8, 150.0, wall_mm=0.001))


def test_a_rect_peg_too_thin_for_its_edge_capsules_is_one_line(tmp_path, capsys, monkeypatch):
    no_work(monkeypatch)
    argv = ["--geometry", "rect", "--hole", "1.6x1.6", "--peg", "1.5x1.5", "--length", "5"]
    rc, _, err = peghole(["models", "build", *argv, "--out", tmp_path / "o"], capsys)
    assert rc == 2
    assert_one_line(err, "must exceed 2 mm", "edge capsules", "--representation box")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "changes, needle",
    [
        ({"peg_w_mm": True}, "peg_w_mm must be a number, got True"),
        ({"length_mm": False}, "length_mm must be a number"),
        ({"peg_w_mm": "59"}, "peg_w_mm must be a number, got '59'"),
        ({"peg_w_mm": 0.001}, "minimum size"),
        ({"friction": True}, "friction out of range"),
    ],
)
def test_spec_check_refuses_booleans_and_micrometre_rect_sizes(changes, needle):
    """``--set geometry={"peg_w_mm": true}`` reaches specs.with_changes (the env config)."""
    from peghole_mjx.geometry.specs import PRESETS, with_changes

    with pytest.raises(InfeasibleGeometryError) as exc:
        with_changes(PRESETS["rect-1"], **changes)
    assert needle in str(exc.value)


def test_env_config_geometry_of_micrometre_parts_is_one_line():
    """``--set env.geometry={"peg_w_mm": 0.001}``: the spec check's minimum size."""
    from peghole_mjx.envs.config import base_config, env_spec

    cfg = base_config("rect-1")
    cfg.geometry = '{"peg_w_mm": 0.001}'
    with pytest.raises(UserInputError, match="minimum size.*smallest part MuJoCo builds"):
        env_spec(cfg)


@pytest.mark.parametrize(
    "changes, needle",
    [
        ({"n_sides": True}, "n_sides must be an integer, got True"),
        ({"n_sides": 16.0}, "n_sides must be an integer"),
        ({"peg_radii_mm": (6.0, 6.0, 6.0)}, "peg_radii_mm must be two numbers"),
        ({"hole_radii_mm": 6.1}, "hole_radii_mm must be two numbers"),
        ({"peg_radii_mm": (0.001, 0.001)}, "minimum size"),
        ({"hole_radii_mm": (True, 6.1)}, "must be a number, got True"),
    ],
)
def test_spec_check_refuses_bad_dual_fields(changes, needle):
    from peghole_mjx.geometry.specs import PRESETS, with_changes

    with pytest.raises(InfeasibleGeometryError) as exc:
        with_changes(PRESETS["dual-2"], **changes)
    assert needle in str(exc.value)


@pytest.mark.parametrize("geometry", ["dual", "rect"])
@pytest.mark.parametrize("wrench", [None, "0.5,2,10"])
def test_jamming_at_a_vanishing_depth_is_one_line(tmp_path, capsys, geometry, wrench):
    argv = ["analyze", "jamming", "--geometry", geometry, "--depth", "1e-300"]
    argv += ["--out", tmp_path / "j"] + (["--wrench", wrench] if wrench else [])
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "--depth 1e-300 mm", "two-point contact")
    assert not (tmp_path / "j").exists()


def test_jamming_exact_test_refuses_a_depth_without_two_point_contact():
    from peghole_mjx.analysis import jamming

    assert jamming.two_point_min_depth_mm(6.0, 0.2) == pytest.approx(np.sqrt(12.2**2 - 144))
    with pytest.raises(UserInputError, match="no two-point contact"):
        jamming.jams_exact(0.5, 2.0, 10.0, 1e-300, 6.0, 0.3, 0.2)


# ---------------------------------------------------------------------- 4. outputs
@pytest.mark.parametrize(
    "argv",
    [
        ["models", "build", "--preset", "rect-1", "--out", "{out}"],
        ["models", "check", "--preset", "rect-2", "--no-mjx", "--out", "{out}/check.json"],
        ["analyze", "figure", "2.11", "--out", "{out}"],
        ["analyze", "jamming", "--geometry", "dual", "--depth", "30", "--out", "{out}"],
    ],
)
def test_writing_commands_refuse_a_full_disk_before_the_work(tmp_path, capsys, monkeypatch, argv):
    no_work(monkeypatch)
    small_disk(monkeypatch)
    rc, _, err = peghole([a.format(out=tmp_path / "o") for a in argv], capsys)
    assert rc == 2
    assert_one_line(err, "0.0 MiB free, the command writes about")
    assert not any(p.is_file() for p in tmp_path.rglob("*"))


def test_decompose_refuses_a_full_disk_before_coacd(tmp_path, capsys, monkeypatch):
    peg_file, hole_file = export(tmp_path, *rect_parts())
    no_work(monkeypatch)
    small_disk(monkeypatch)
    rc, err, written = decompose(tmp_path, capsys, peg_file, hole_file)
    assert rc == 2
    assert_one_line(err, "free, the command writes about")
    assert written == []


def test_decompose_refuses_a_read_only_out_before_loading(tmp_path, capsys, monkeypatch):
    peg_file, hole_file = export(tmp_path, *rect_parts())
    no_work(monkeypatch)

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(a[0]))

    monkeypatch.setattr(fileio, "open", read_only, raising=False)
    rc, err, _ = decompose(tmp_path, capsys, peg_file, hole_file)
    assert rc == 2
    assert_one_line(err, "not writable", "Read-only file system")


def _hull_only(mesh, params=None):
    """A stand-in for CoACD: each part as its convex hull (fast; fine for testing writes)."""
    return [np.asarray(mesh.convex_hull.vertices)]


def test_decompose_writes_the_mjcf_and_report_together_or_neither(tmp_path, capsys, monkeypatch):
    from peghole_mjx.geometry import decompose as dec

    peg_file, hole_file = export(tmp_path, *rect_parts())
    monkeypatch.setattr(dec, "run_coacd", _hull_only)
    rc, _, written = decompose(tmp_path, capsys, peg_file, hole_file)
    assert rc == 0 and written == ["report.json", "user_peghole.xml"]
    out = tmp_path / "out"
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    real_fsync = os.fsync

    def enospc_on_the_report(fd):  # the MJCF reaches the disk, report.json does not
        if "report.json" in os.readlink(f"/proc/self/fd/{fd}"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", enospc_on_the_report)
    rc, err, written = decompose(
        tmp_path, capsys, peg_file, hole_file, "--friction", "0.5", "--force"
    )
    assert rc == 2
    assert_one_line(err, "No space left on device")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # old pair, no temp


def test_benchmark_out_paths_are_checked_before_the_work(tmp_path, monkeypatch):
    from benchmarks import common as bench_common

    (tmp_path / "d").mkdir()
    with pytest.raises(UserInputError, match="is a folder, not a file"):
        bench_common.check_out(tmp_path / "d")
    with pytest.raises(argparse.ArgumentTypeError, match="is a folder, not a file"):
        bench_common.out_file(str(tmp_path / "d"))
    small_disk(monkeypatch)
    with pytest.raises(UserInputError, match="free, the command writes about 16.0 MiB"):
        bench_common.check_out(tmp_path / "r.json")
    monkeypatch.undo()

    def read_only(*a, **k):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(a[0]))

    monkeypatch.setattr(fileio, "open", read_only, raising=False)
    with pytest.raises(UserInputError, match="Read-only file system"):
        bench_common.check_out(tmp_path / "r.json")
    monkeypatch.undo()
    assert bench_common.check_out(tmp_path / "new" / "r.json") == tmp_path / "new" / "r.json"
    assert not (tmp_path / "new" / "r.json").exists()  # checked, not written


def test_benchmark_csv_is_written_atomically(tmp_path, monkeypatch):
    from benchmarks import common as bench_common

    row = dict.fromkeys(bench_common.COLUMNS, "x")
    row["worlds"] = 1
    path = bench_common.write_csv(tmp_path / "t.csv", [row])
    before = path.read_bytes()
    with pytest.raises(ValueError, match="extra"):
        bench_common.write_csv(path, [row, {**row, "bogus": 1}])
    assert path.read_bytes() == before

    def enospc(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", enospc)
    with pytest.raises(OSError):
        bench_common.write_csv(path, [row, row])
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]
