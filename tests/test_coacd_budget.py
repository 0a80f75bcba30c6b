"""CoACD bounded (geometry/coacd_budget.py): its log read into parts searched and pieces, the
estimate of a coarse run, the one-line refusal with the options that would fit, the bar of a
fraction, and ``task make`` refusing a part over the piece or the time cap, or accepting one
under them, within 30 s. ``--pieces revolve`` refuses a pair that is not revolved. Small meshes
only. Skipped without the ``cad`` extra."""

import argparse
import re
import subprocess
import sys
import time

import pytest

trimesh = pytest.importorskip("trimesh")
manifold3d = pytest.importorskip("manifold3d")
pytest.importorskip("coacd")

from benchmarks.studies.coacd_verdict import chamfered_pair  # noqa: E402
from peghole_mjx.cli.main import main  # noqa: E402
from peghole_mjx.core import progress as prog  # noqa: E402
from peghole_mjx.core.errors import UserInputError  # noqa: E402
from peghole_mjx.envs import task_cli, task_make  # noqa: E402
from peghole_mjx.geometry import coacd_budget as cb  # noqa: E402
from peghole_mjx.geometry import decompose  # noqa: E402
from peghole_mjx.geometry.decompose import CoacdParams  # noqa: E402

#: CoACD 1.0.14's info log of a cube less an octagonal bore (threshold 0.05): rounds of 1, 2,
#: 4 and 8 parts, then the merge to 8 pieces (trimmed to the lines the reader uses)
LOG = """\
[CoACD] [info]  - Decomposition (MCTS)
[CoACD] [info] iter 0 ---- waiting pool: 1
[CoACD] [info] Processing [0.0%]
[CoACD] [info] Processing [100.0%]
[CoACD] [info] iter 1 ---- waiting pool: 2
[CoACD] [info] Processing [0.0%]
[CoACD] [info] Processing [50.0%]
[CoACD] [info] Processing [100.0%]
[CoACD] [info] iter 2 ---- waiting pool: 4
[CoACD] [info] Processing [50.0%]
"""
LOG_END = """\
[CoACD] [info] Processing [100.0%]
[CoACD] [info] iter 3 ---- waiting pool: 8
[CoACD] [info] Processing [100.0%]
[CoACD] [info]  - Merge Convex Hulls
[CoACD] [info] Compute Time: 13.88s
[CoACD] [info] # Convex Hulls: 8
"""


def bored_cube():
    """A 1 m cube less an octagonal bore (48 faces): CoACD cuts it in a few seconds."""
    bore = trimesh.creation.cylinder(radius=0.3, height=2, sections=8)
    return trimesh.creation.box([1, 1, 1]).difference(bore)


def test_the_log_gives_parts_searched_and_a_lower_bound_on_the_pieces():
    log = cb.CoacdLog()
    log.feed(LOG)
    # rounds of 1 and 2 parts searched, half of the round of 4: 1 + 2 + 2
    assert log.searched == pytest.approx(5.0)
    # no part finished yet (each was cut in two), 4 waiting: at least 4 pieces
    assert log.finished == 0 and log.pieces_at_least == 4 and not log.merging
    log.feed(LOG_END)
    assert log.merging and log.hulls == 8
    assert log.searched == 15 and log.tree_parts == 15  # 2 x 8 pieces - 1
    assert log.finished == 8 and log.pieces_at_least == 8


def test_a_refusal_is_one_line_naming_the_estimate_and_options_that_fit():
    mesh = trimesh.creation.box([0.05, 0.05, 0.03])
    params = CoacdParams()
    est = cb.CoacdEstimate(pieces=300, seconds=900.0, tree_parts=599, coarse_s=12.0, complete=False)
    text = cb.refusal("hole", est, params, mesh, max_hulls=64, max_s=600.0, clearance_mm=0.25)
    assert "\n" not in text
    assert "at least 300 convex pieces and at least 15 min" in text
    assert "more than 1.25 x the cap of 64 pieces (--max-hulls" in text
    assert "longer than 10 min (--coacd-max-s)" in text
    assert "--max-convex-hull 64" in text and "--coacd-max-s 1380" in text
    t = float(re.search(r"--threshold ([\d.]+)", text).group(1))
    assert t == pytest.approx(0.01 * 300 / 64 * 1.5, rel=0.01)
    assert "against a 0.25 mm radial clearance" in text
    ok = cb.CoacdEstimate(pieces=20, seconds=100.0, tree_parts=39, coarse_s=3.0, complete=True)
    assert cb.refusal("hole", ok, params, mesh, 64, 600.0) is None


def test_the_estimate_and_the_bounded_run_show_a_fraction(capsys):
    mesh = bored_cube()
    cheap = CoacdParams(threshold=0.05, mcts_iterations=20, mcts_nodes=10, resolution=500)
    est = cb.estimate(mesh, cheap, budget_s=60.0)
    assert est.complete and est.pieces >= 2 and est.tree_parts >= 2 * est.pieces - 1
    assert 0 < est.seconds < 60.0
    hulls = cb.run_bounded(mesh, cheap, est, "test", max_s=120.0, progress=True)
    assert len(hulls) >= 2
    err = capsys.readouterr().err
    # a bar of parts searched out of a total, ending full
    done = re.findall(r"(\d+)/(\d+)", err)
    assert done and done[-1][0] == done[-1][1]


def test_a_coarse_run_past_its_budget_gives_lower_bounds():
    mesh = bored_cube()
    t = time.perf_counter()
    est = cb.estimate(mesh, CoacdParams(threshold=0.01), budget_s=0.5)
    assert time.perf_counter() - t < 10.0  # the child was stopped
    assert not est.complete and "at least" in est.text()


def make_argv(tmp_path) -> list[str]:
    """``peghole task make`` of the chamfered pair, exported as STL into ``tmp_path``."""
    peg, hole = chamfered_pair(fine=False)
    peg.export(tmp_path / "peg.stl")
    hole.export(tmp_path / "hole.stl")
    return ["task", "make", str(tmp_path / "peg.stl"), str(tmp_path / "hole.stl")]


def test_task_make_refuses_a_coacd_part_over_the_cap_within_30_s(tmp_path, capsys):
    argv = make_argv(tmp_path)
    out = tmp_path / "task"
    t = time.perf_counter()
    rc = main([*argv, "--out", str(out), "--max-hulls", "4"])
    took = time.perf_counter() - t
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc != 0 and took < 30.0, (rc, took)
    assert "the hole part needs CoACD: an estimated" in err
    assert "x the cap of 4 pieces" in err and "--max-convex-hull 4" in err
    assert not out.exists()
    # --pieces revolve: a square pair is not revolved, refused in one line before any work
    rc = main([*argv, "--out", str(out), "--pieces", "revolve"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc != 0 and "--pieces revolve: the pair is not revolved about +z" in err


def test_task_make_refuses_a_coacd_part_over_its_time_cap_within_30_s(tmp_path, capsys):
    """The other cap: an estimated time past --coacd-max-s is refused up front in one line
    naming the estimate and the --coacd-max-s that would fit, before the full run."""
    argv = make_argv(tmp_path)
    out = tmp_path / "task"
    t = time.perf_counter()
    rc = main([*argv, "--out", str(out), "--coacd-max-s", "1"])
    took = time.perf_counter() - t
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and took < 30.0, (rc, took)
    assert [line for line in err if "error:" in line] == [err[-1]]
    assert "the hole part needs CoACD: an estimated" in err[-1]
    assert "longer than 1 s (--coacd-max-s)" in err[-1]
    fit = int(re.search(r"--coacd-max-s (\d+)", err[-1].split("options")[1]).group(1))
    assert fit > 1 and not out.exists()


def test_task_make_accepts_a_coacd_part_within_30_s_with_a_bar_of_a_fraction(
    tmp_path, capsys, monkeypatch
):
    """A part under the caps: the verdict (the full run's start) within 30 s of the command's
    start, then the full run's bar counts parts searched out of the estimated total and ends
    full. The pipeline after the pieces is stubbed (it ends the command in one line)."""
    argv = make_argv(tmp_path)
    starts = []
    real = task_make.run_coacd

    def timed(mesh, params, **kw):
        starts.append((time.perf_counter(), params.mcts_iterations))
        return real(mesh, params, **kw)

    def stub(peg_mesh, hole_mesh, peg_hulls, hole_hulls, out, **kw):
        raise UserInputError(f"stub: {len(hole_hulls)} hole pieces")

    monkeypatch.setattr(task_make, "run_coacd", timed)
    monkeypatch.setattr(task_make, "build_task", stub)
    argv += ["--out", str(tmp_path / "task"), "--threshold", "0.05", "--mcts-iterations", "40"]
    t = time.perf_counter()
    assert main([*argv, "--resolution", "1000"]) == 2
    err = capsys.readouterr().err
    # the hole only: the coarse estimate (30 iterations), then the full run (40)
    assert [it for _, it in starts] == [cb.COARSE["mcts_iterations"], 40]
    assert starts[1][0] - t < 30.0, starts[1][0] - t
    assert err.strip().splitlines()[-1].startswith("peghole: error: stub: ")
    bar = [line for line in re.split(r"[\r\n]", err) if "parts searched / estimated" in line]
    fractions = [tuple(map(int, m)) for line in bar for m in re.findall(r"(\d+)/(\d+)", line)]
    assert fractions and all(0 <= n <= total for n, total in fractions)
    assert fractions[-1][0] == fractions[-1][1] > 1  # ends full


def test_the_cli_default_is_the_modules_time_cap():
    p = argparse.ArgumentParser()
    task_cli.add_parser(p.add_subparsers())
    args = p.parse_args(["task", "make", "a.stl", "b.stl", "--out", "x"])
    assert args.coacd_max_s == cb.COACD_MAX_S


def test_the_estimate_budget_is_what_is_left_of_the_30_s():
    assert cb.estimate_budget(0.0, 1) == cb.ESTIMATE_S
    assert cb.estimate_budget(0.0, 2) == cb.ESTIMATE_S / 2
    late = cb.VERDICT_S - cb.VERDICT_MARGIN_S - 10.0
    assert cb.estimate_budget(late, 1) == pytest.approx(10.0)
    assert cb.estimate_budget(late, 2) == pytest.approx(5.0)
    assert cb.estimate_budget(cb.VERDICT_S, 1) == cb.MIN_ESTIMATE_S


def test_task_make_counts_the_budget_from_the_commands_start(tmp_path, monkeypatch):
    """Inside a command (its clock started 20 s ago: the imports) the coarse run gets what is
    left of the 30 s; outside one the clock starts with make_task."""
    budgets = []

    def fake_estimate(mesh, params, budget_s, run):
        budgets.append(budget_s)
        raise UserInputError("estimate reached")

    monkeypatch.setattr(cb, "estimate", fake_estimate)
    argv = make_argv(tmp_path)
    peg, hole = argv[2], argv[3]
    with prog.command_clock(time.perf_counter() - 20.0):
        with pytest.raises(UserInputError, match="estimate reached"):
            task_make.make_task(peg, hole, tmp_path / "a")
        assert prog.command_start() is not None
    assert prog.command_start() is None
    with pytest.raises(UserInputError, match="estimate reached"):
        task_make.make_task(peg, hole, tmp_path / "b")
    left = cb.VERDICT_S - cb.VERDICT_MARGIN_S - 20.0
    assert cb.MIN_ESTIMATE_S <= budgets[0] <= left, budgets
    assert budgets[1] > left + 10.0, budgets


def test_the_process_age_counts_from_the_process_start():
    code = (
        "import time; time.sleep(1.5); from peghole_mjx.core.progress import process_age_s; "
        "print(process_age_s())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert 1.5 <= float(out.stdout) < 15.0, out


def test_a_coacd_child_without_a_result_is_one_line(monkeypatch):
    """The child's exit status comes back; one that ends without writing a result (killed
    for memory, a crash) is named in one line."""
    assert decompose._in_child(["-c", "import sys; sys.exit(3)"]) == 3
    monkeypatch.setattr(decompose, "_in_child", lambda argv, stdout=None, watch=None: -9)
    with pytest.raises(UserInputError, match=r"its process exited with -9: out of memory"):
        decompose.run_coacd(bored_cube())


def test_fine_meshes_are_checked_in_seconds_and_interference_still_found():
    """A fine export (3,072 / 9,216 faces): the interference check tests only the points in
    the bounds of the parts' intersection (a boolean); the pair passes, and the same peg moved
    0.4 mm into a wall of its 0.25 mm gap is refused with the depth."""
    mm = 1e-3
    peg, hole = chamfered_pair(fine=True)
    assert (len(peg.faces), len(hole.faces)) == (3072, 9216)
    peg.apply_scale(mm)
    hole.apply_scale(mm)
    shared = decompose.overlap(peg, hole)
    assert shared is not None and shared.volume_mm3 == pytest.approx(0.0, abs=1e-6)
    decompose.check_assembly(peg, hole)
    moved = peg.copy()
    moved.apply_translation([0.4 * mm, 0.0, 0.0])
    shared = decompose.overlap(moved, hole)
    # 0.15 mm x 10 mm x the 13 mm of straight wall below the chamfer (and a sliver in it)
    assert shared.volume_mm3 == pytest.approx(0.15 * 10 * 13, rel=0.02)
    with pytest.raises(UserInputError, match=r"no interference.*0\.1[45]\d* mm deep"):
        decompose.check_assembly(moved, hole)
