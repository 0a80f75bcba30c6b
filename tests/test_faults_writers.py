"""One writer per output, links and long names, a changed final policy, advice that applies
(issue 53, decided 2026-12-04; docs/guide/reliability_files.md).

Cheap by design: every command here is refused before any MJX graph is compiled (the sweep
runs synthetic slices: ``fake_sweep``). Cases touching the user's files list and hash them
before and after.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_faults import assert_one_line, peghole
from test_faults_experiments import fake_sweep, no_sim, tiny_cfg  # noqa: F401 (fixtures)

from peghole_mjx import policies
from peghole_mjx.cli.demo import REPORT_TITLE
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.experiments import sweep
from peghole_mjx.files import fileio
from peghole_mjx.files.checkpoint_folders import checkpoint_name, seal
from peghole_mjx.files.lock import OUTPUT_LOCK, OutputLock, RunLockedError, _proc_start

PRETRAINED = Path(policies.__file__).parent / "rect_extract"


def hashes(folder: Path) -> dict[str, str]:
    """``relative path -> SHA-256`` of every file (and link target) under ``folder``."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.is_symlink():
            out[rel] = "link -> " + os.readlink(p)
        elif p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture
def holder():
    """A live process of this host (another writer), killed afterwards."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    yield proc
    proc.kill()
    proc.wait()


def hold_lock(path: Path, proc, command: str) -> None:
    rec = {"pid": proc.pid, "host": socket.gethostname(), "start": _proc_start(proc.pid)}
    rec |= {"since": "2026-12-04T23:00:00Z", "command": command}
    path.write_text(json.dumps(rec) + "\n")


# ---------------------------------------------------------------------- 1. one writer
def test_a_second_export_into_one_folder_is_refused_naming_the_holder(tmp_path, capsys, holder):
    (tmp_path / "keep.txt").write_text("the user's\n")
    hold_lock(tmp_path / ".mydata.lock", holder, "peghole export")
    before = hashes(tmp_path)
    rc, out, err = peghole(["export", "rect", "--out", tmp_path / "mydata"], capsys)
    assert rc == 2, out
    assert_one_line(err, "is being written by another process", f"pid {holder.pid}")
    assert "peghole export" in err
    assert hashes(tmp_path) == before  # nothing created, the holder's lock kept


def test_the_output_lock_is_one_writer_and_is_released(tmp_path, holder):
    target = tmp_path / "res.json"
    with OutputLock(target, "peghole test") as lock:
        assert lock.path == tmp_path / ".res.json.lock"
        assert json.loads(lock.path.read_text())["command"] == "peghole test"
    assert not lock.path.exists()
    # a link to the output shares its lock
    (tmp_path / "link.json").symlink_to(target)
    assert OutputLock(tmp_path / "link.json", "x").path == lock.path
    hold_lock(lock.path, holder, "peghole experiment sweep --geometry rect")
    with pytest.raises(RunLockedError, match=rf"sweep --geometry rect, pid {holder.pid} "):
        OutputLock(target, "peghole test").acquire()


def test_a_sweep_of_other_parameters_is_refused_unless_force(tmp_path, fake_sweep):  # noqa: F811
    out = tmp_path / "sweep"
    cfg = tiny_cfg(batch_worlds=4)
    sweep.run_sweep(cfg, out, progress=False)
    results = out / "compliance_sweep_rect.json"
    assert results.exists()
    before = hashes(out)
    other = sweep.SweepConfig(grid=cfg.grid, seed=1, batch_worlds=4)
    with pytest.raises(
        UserInputError, match=r"other parameters .*differing: seed\).*--force"
    ) as exc:
        sweep.run_sweep(other, out, progress=False)
    assert "\n" not in str(exc.value)
    assert hashes(out) == before  # results kept, nothing run
    ran = len(fake_sweep)
    sweep.run_sweep(cfg, out, progress=False)  # the same parameters: resumed, nothing rerun
    assert len(fake_sweep) == ran
    res = sweep.run_sweep(other, out, progress=False, force=True)
    assert json.loads(results.read_text())["settings"]["seed"] == 1 == res["settings"]["seed"]


def test_a_sweep_started_while_another_of_other_parameters_runs_is_refused(
    tmp_path,
    holder,
    fake_sweep,  # noqa: F811
):
    # the first sweep recorded its parameters at its start and still runs (no results yet)
    out = tmp_path / "sweep"
    out.mkdir()
    first = sweep.SweepConfig(grid=tiny_cfg().grid, seed=7, batch_worlds=4)
    sweep.check_settings(first, out, force=False)
    rec = json.loads(sweep.settings_path(out, "rect").read_text())
    rec["written_by"]["pid"] = holder.pid
    sweep.settings_path(out, "rect").write_text(json.dumps(rec))
    with pytest.raises(UserInputError, match=rf"recorded by pid {holder.pid} .*differing: seed"):
        sweep.run_sweep(tiny_cfg(batch_worlds=4), out, progress=False)
    assert fake_sweep == []  # refused before any slice
    assert not (out / "compliance_sweep_rect.json").exists()


@pytest.mark.parametrize(
    "other, differing",
    [(["--grid", "tiny", "--seed", "3"], "seed"), (["--grid", "cpu"], "grid.")],
    ids=["seed", "grid"],
)
def test_sweep_cli_refuses_other_parameters_in_one_line(
    tmp_path,
    capsys,
    fake_sweep,  # noqa: F811
    other,
    differing,
):
    out = tmp_path / "sweep"
    sweep.run_sweep(tiny_cfg(batch_worlds=4), out, progress=False)
    before = hashes(out)
    ran = len(fake_sweep)
    argv = ["experiment", "sweep", "--geometry", "rect", *other]
    rc, _, err = peghole([*argv, "--engine", "mujoco", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, "holds a rect sweep of other parameters", differing, "--force")
    assert hashes(out) == before
    assert len(fake_sweep) == ran  # refused before any slice


def test_a_sweep_whose_output_is_locked_is_refused(tmp_path, holder, fake_sweep):  # noqa: F811
    out = tmp_path / "sweep"
    out.mkdir()
    hold_lock(out / ".compliance_sweep_rect.json.lock", holder, "peghole experiment sweep")
    with pytest.raises(RunLockedError, match=rf"pid {holder.pid}"):
        sweep.run_sweep(tiny_cfg(batch_worlds=4), out, progress=False)
    assert fake_sweep == []


@pytest.mark.parametrize("command", ["compliance", "contact-check"])
def test_experiment_outputs_in_use_are_refused_before_any_simulation(
    tmp_path,
    capsys,
    holder,
    command,
    no_sim,  # noqa: F811
):
    if command == "compliance":
        out = tmp_path / "exp"
        out.mkdir()
        hold_lock(out / OUTPUT_LOCK, holder, "peghole experiment compliance --geometry rect")
        argv = ["experiment", "compliance", "--geometry", "rect", "--quick", "--out", out]
    else:
        out = tmp_path / "contacts.json"
        hold_lock(tmp_path / ".contacts.json.lock", holder, "peghole experiment contact-check")
        argv = ["experiment", "contact-check", "--engine", "mujoco", "--out", out]
    before = hashes(tmp_path)
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "is being written by another process", f"pid {holder.pid}", command)
    assert hashes(tmp_path) == before


# ---------------------------------------------------------------------- 2. links and names
def test_a_symlinked_output_file_is_written_through(tmp_path):
    target = tmp_path / "real" / "result.json"
    target.parent.mkdir()
    target.write_text("old\n")
    link = tmp_path / "result.json"
    link.symlink_to(target)
    fileio.check_out_file(link)
    fileio.write_text(link, "new\n")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text() == "new\n"
    fileio.write_many({link: "both\n"})
    assert link.is_symlink() and target.read_text() == "both\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["real", "result.json"]


def test_a_symlink_loop_as_out_is_refused_in_one_line(tmp_path, capsys):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    (tmp_path / "keep.txt").write_text("the user's\n")
    before = hashes(tmp_path)
    rc, _, err = peghole(["export", "rect", "--out", loop], capsys)
    assert rc == 2
    assert_one_line(err, f"--out {loop} is a symbolic link loop")
    for check in (fileio.check_out_file, fileio.check_out_dir):
        with pytest.raises(UserInputError, match="symbolic link loop"):
            check(loop)
    with pytest.raises(UserInputError, match="symbolic link loop"):
        fileio.write_text(loop, "x")
    assert hashes(tmp_path) == before


def test_a_name_too_long_for_its_temporary_names_is_refused_before_the_work(tmp_path, capsys):
    name = "a" * (255 - fileio.TEMP_NAME_EXTRA + 1)  # fits alone, not with ".NAME.tmp-XXXXXXXX"
    (tmp_path / "keep.txt").write_text("the user's\n")
    before = hashes(tmp_path)
    rc, _, err = peghole(["export", "rect", "--out", tmp_path / name], capsys)
    assert rc == 2
    assert_one_line(err, "the temporary names written beside it", "at most 241 bytes")
    for check in (fileio.check_out_file, fileio.check_out_dir):
        with pytest.raises(UserInputError, match="at most 241 bytes"):
            check(tmp_path / name)
    assert hashes(tmp_path) == before
    ok = tmp_path / ("b" * (255 - fileio.TEMP_NAME_EXTRA))
    fileio.write_text(ok, "fits\n")  # the longest accepted name: its temporary names fit
    fileio.check_out_file(ok)


LONG_NAME_COMMANDS = {
    "evaluate": ["evaluate", "rect", "--episodes", "1", "--out", "{out}"],
    "compare": ["compare", "{d}/run", "--out", "{out}"],
    "task make": ["task", "make", "{d}/peg.stl", "{d}/hole.stl", "--out", "{out}"],
    "experiment contact-check": [
        "experiment",
        "contact-check",
        "--engine",
        "mujoco",
        "--out",
        "{out}",
    ],
}


@pytest.mark.parametrize("case", sorted(LONG_NAME_COMMANDS))
def test_every_writer_checks_its_name_with_the_temporary_suffix_first(tmp_path, capsys, case):
    """evaluate, compare and task make (after CoACD) failed after their work on a name that
    fits alone but not with its temporary suffix: each is refused first, in one line."""
    (tmp_path / "run").mkdir()
    (tmp_path / "keep.txt").write_text("the user's\n")
    out = tmp_path / ("a" * (255 - fileio.TEMP_NAME_EXTRA + 1))
    before = hashes(tmp_path)
    argv = [a.format(d=tmp_path, out=out) for a in LONG_NAME_COMMANDS[case]]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "the temporary names written beside it", "at most 241 bytes")
    assert hashes(tmp_path) == before


# ---------------------------------------------------------------------- 3. final policy
def _run_with_final_policy(root: Path) -> Path:
    """A training run folder: final_policy/ and the checkpoint of the same step (sealed)."""
    run = root / "run"
    step = json.loads((PRETRAINED / "policy.json").read_text())["env_steps"]
    for folder in (run / "final_policy", run / "checkpoints" / checkpoint_name(step)):
        folder.mkdir(parents=True)
        for f in ("policy.json", "params.npz"):
            shutil.copy(PRETRAINED / f, folder / f)
    seal(run / "checkpoints" / checkpoint_name(step))
    return run


def _edit_one_weight(params: Path) -> None:
    with np.load(params) as z:
        arrays = {k: z[k] for k in z.files}
    key = next(k for k, v in arrays.items() if v.dtype.kind == "f" and v.size > 1)
    arrays[key] = arrays[key].copy()
    arrays[key].flat[0] += 0.5
    np.savez(params, **arrays)


def test_evaluate_refuses_an_edited_final_policy(tmp_path, capsys):
    run = _run_with_final_policy(tmp_path)
    policies.check_recorded_params(run / "final_policy")  # as written: accepted
    # the same arrays written again (another zip timestamp): accepted
    with np.load(run / "final_policy" / "params.npz") as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(run / "final_policy" / "params.npz", **arrays)
    policies.check_recorded_params(run / "final_policy")
    _edit_one_weight(run / "final_policy" / "params.npz")
    before = hashes(tmp_path)
    # --engine mujoco: without the check this is refused later (trained on mjx), not run
    argv = ["evaluate", run / "final_policy", "--episodes", "1", "--engine", "mujoco"]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "final_policy/params.npz was changed after it was written", "manifest")
    rc, _, err = peghole(["evaluate", run, "--episodes", "1", "--engine", "mujoco"], capsys)
    assert rc == 2 and "params.npz was changed" in err
    assert hashes(tmp_path) == before


def test_a_saved_policy_records_its_params_hash(tmp_path):
    bundle = policies.load_policy(PRETRAINED)
    pol = tmp_path / "pol"
    policies.save_policy(pol, bundle.params, bundle.meta)
    assert fileio.recorded_sha256(pol, "params.npz") == fileio.sha256_file(pol / "params.npz")
    policies.check_recorded_params(pol)
    _edit_one_weight(pol / "params.npz")
    with pytest.raises(CorruptFileError, match=r"pol/params.npz was changed .*peghole_manifest"):
        policies.check_recorded_params(pol)
    # a policy folder without any record: nothing new is said
    policies.check_recorded_params(PRETRAINED)


# ---------------------------------------------------------------------- 4. advice
def test_demo_advises_force_only_where_force_is_accepted(tmp_path, capsys):
    out = tmp_path / "demo"
    (out / "models").mkdir(parents=True)
    (out / "models" / "mine.xml").write_text("<mujoco/>\n")
    before = hashes(tmp_path)
    rc, _, err = peghole(["demo", "--out", out, "--profile", "quick"], capsys)
    assert rc == 2
    assert_one_line(err, "not a demo's folder", "choose another --out")
    assert "--force" not in err
    rc, _, err = peghole(["demo", "--out", out, "--profile", "quick", "--force"], capsys)
    assert rc == 2 and "not a demo's folder" in err  # what --force would have said
    assert hashes(tmp_path) == before
    (out / "report.md").write_text(REPORT_TITLE + "\n")  # an older demo: --force applies
    rc, _, err = peghole(["demo", "--out", out, "--profile", "quick"], capsys)
    assert rc == 2
    assert_one_line(err, "an older demo", "pass --force")


# ---------------------------------------------------------------- files written one by one
# (decided 2026-12-05): every writer takes the output's lock and replaces only its own files


def _users_file(path: Path, text: str = "precious\n") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


#: command -> (the user's file it would overwrite, relative to tmp_path)
USERS_FILE_CASES = {
    "models build": (["models", "build", "--preset", "rect-1", "--out", "{d}/m"], "m/free_peg.xml"),
    "models check": (
        ["models", "check", "--preset", "rect-1", "--no-mjx", "--out", "{d}/rows.json", "--force"],
        "rows.json",
    ),
    "models decompose": (
        ["models", "decompose", "{d}/peg.stl", "{d}/hole.stl", "--out", "{d}/dec"],
        "dec/report.json",
    ),
    "analyze figure": (["analyze", "figure", "2.11", "--out", "{d}/图"], "图/fig_2_11.csv"),
    "analyze jamming": (
        ["analyze", "jamming", "--geometry", "rect", "--depth", "20", "--out", "{d}/j", "--force"],
        "j/jamming.json",
    ),
    "evaluate": (["evaluate", "rect", "--episodes", "2", "--out", "{d}/notes.json"], "notes.json"),
    "compare": (["compare", "{d}/run", "--out", "{d}/c.png"], "c.png"),
}


@pytest.mark.parametrize("case", sorted(USERS_FILE_CASES))
def test_writers_never_replace_a_file_of_the_users(tmp_path, capsys, case):
    argv, users = USERS_FILE_CASES[case]
    _users_file(tmp_path / users)
    (tmp_path / "run").mkdir()
    before = hashes(tmp_path)
    rc, _, err = peghole([a.format(d=tmp_path) for a in argv], capsys)
    assert rc == 2
    assert_one_line(err, "peghole_mjx did not write", Path(users).name)
    assert hashes(tmp_path) == before  # --force does not make a file of the user's ours


def test_an_output_file_whose_record_is_damaged_is_not_the_programs(tmp_path, capsys):
    _users_file(tmp_path / "c.png")
    _users_file(tmp_path / ".c.png.peghole.json", "[" * 100_000)  # RecursionError if parsed
    (tmp_path / "run").mkdir()
    before = hashes(tmp_path)
    rc, _, err = peghole(["compare", tmp_path / "run", "--out", tmp_path / "c.png"], capsys)
    assert rc == 2
    assert_one_line(err, "did not write")
    assert hashes(tmp_path) == before


def test_a_rerun_of_other_parameters_is_refused_unless_force(tmp_path, capsys):
    jam = ["analyze", "jamming", "--geometry", "rect", "--out", tmp_path / "j"]
    assert peghole([*jam, "--depth", "20"], capsys)[0] == 0
    rec = json.loads((tmp_path / "j" / ".jamming.json.peghole.json").read_text())
    assert rec["sha256"] == fileio.sha256_file(tmp_path / "j" / "jamming.json")
    assert rec["parameters"]["depth"] == 20
    before = hashes(tmp_path)
    rc, _, err = peghole([*jam, "--depth", "25"], capsys)
    assert rc == 2
    assert_one_line(err, "other parameters", "differing: depth", "--force")
    assert hashes(tmp_path) == before
    assert peghole([*jam, "--depth", "20"], capsys)[0] == 0  # the same parameters: rewritten
    assert peghole([*jam, "--depth", "25", "--force"], capsys)[0] == 0
    assert json.loads((tmp_path / "j" / "jamming.json").read_text())["depth_mm"] == 25
    # a file of ours changed since: no longer provably ours, not even with --force
    _users_file(tmp_path / "j" / "jamming.json", "{}\n")
    before = hashes(tmp_path)
    rc, _, err = peghole([*jam, "--depth", "25", "--force"], capsys)
    assert rc == 2
    assert_one_line(err, "changed since it was written")
    assert hashes(tmp_path) == before


def _fake_task_folder(folder: Path, parameters: dict | None) -> None:
    """A task folder of the program's (its manifest names its files), made with
    ``parameters`` (None: before they were recorded)."""
    folder.mkdir()
    for name in ("task.json", "manifest.json", "scene.xml"):
        (folder / name).write_text("{}\n")
    fileio.write_owner_manifest(folder, parameters=parameters)


BUILTIN = ["task", "builtin", "cylinder", "--contact-worlds", "1", "--contact-steps", "5"]


@pytest.mark.parametrize("slash", ["", "/"])
def test_a_task_folder_of_other_parameters_is_refused_unless_force(tmp_path, capsys, slash):
    t = tmp_path / "t"
    _fake_task_folder(t, {"command": "task builtin", "builtin": "cylinder", "clearance_mm": 0.3})
    before = hashes(tmp_path)
    rc, _, err = peghole([*BUILTIN, "--out", f"{t}{slash}"], capsys)
    assert rc == 2
    assert_one_line(err, "other parameters", "clearance_mm", "--force")
    assert hashes(tmp_path) == before


def test_a_task_folder_without_recorded_parameters_needs_force(tmp_path, capsys):
    t = tmp_path / "t"
    _fake_task_folder(t, None)
    before = hashes(tmp_path)
    rc, _, err = peghole([*BUILTIN, "--out", t], capsys)
    assert rc == 2
    assert_one_line(err, "not recorded", "--force")
    assert hashes(tmp_path) == before


def test_task_make_checks_its_output_before_any_work(tmp_path, capsys):
    os.symlink("b", tmp_path / "a")
    os.symlink("a", tmp_path / "b")
    os.symlink("nowhere", tmp_path / "dangling")
    _users_file(tmp_path / "file")
    cases = {
        tmp_path / "a" / "t": "symbolic link loop",
        tmp_path / "dangling": "is a symbolic link",  # replaced whole: it failed after the work
        tmp_path / ("é" * 122 + "x"): "choose a name of at most 241 bytes",
        tmp_path / "file": "existing file",
    }
    before = hashes(tmp_path)
    for out, needle in cases.items():
        rc, _, err = peghole([*BUILTIN, "--out", out], capsys)
        assert rc == 2, out
        assert_one_line(err, needle)
    assert hashes(tmp_path) == before


WRITER_LOCKS = {
    "task builtin": ([*BUILTIN, "--out", "{d}/t"], ".t.lock"),
    "models build": (["models", "build", "--preset", "rect-1", "--out", "{d}/m"], ".m.lock"),
    "analyze figure": (["analyze", "figure", "2.11", "--out", "{d}/f"], ".f.lock"),
    "evaluate": (["evaluate", "rect", "--episodes", "2", "--out", "{d}/e.json"], ".e.json.lock"),
    "compare": (["compare", "{d}", "--out", "{d}/c.png"], ".c.png.lock"),
}


@pytest.mark.parametrize("case", sorted(WRITER_LOCKS))
def test_every_writer_refuses_a_second_one_naming_the_holder(tmp_path, capsys, holder, case):
    argv, lock = WRITER_LOCKS[case]
    hold_lock(tmp_path / lock, holder, "peghole export")
    before = hashes(tmp_path)
    rc, _, err = peghole([a.format(d=tmp_path) for a in argv], capsys)
    assert rc == 2
    assert_one_line(err, "being written by another process", f"pid {holder.pid}", "export")
    assert hashes(tmp_path) == before


def test_a_writers_lock_left_by_a_dead_process_is_taken_over(tmp_path, capsys):
    dead = {"pid": 2**22 + 1, "host": socket.gethostname(), "start": "1", "command": "x"}
    (tmp_path / ".f.lock").write_text(json.dumps(dead))
    rc, _, err = peghole(["analyze", "figure", "2.11", "--out", tmp_path / "f"], capsys)
    assert rc == 0, err
    assert "stale lock" in err
    assert not (tmp_path / ".f.lock").exists()
    assert fileio.file_record(tmp_path / "f" / "fig_2_11.csv") is not None


def test_a_recorded_file_counts_as_the_programs_in_a_folder_replaced_whole(tmp_path):
    folder = tmp_path / "pol"
    folder.mkdir()
    (folder / "policy.json").write_text("{}")
    fileio.write_owner_manifest(folder)
    (folder / "eval.json").write_text("{}")
    fileio.write_file_record(folder / "eval.json", "peghole evaluate", {"episodes": 2})
    assert fileio.foreign_files(folder) == []
    (folder / "eval.json").write_text('{"edited": 1}')  # changed since: no longer provably ours
    assert fileio.foreign_files(folder) == [".eval.json.peghole.json", "eval.json"]
