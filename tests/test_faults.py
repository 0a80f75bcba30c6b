"""Fault injection and bad input: every case ends in one clear line (exit 2) or is handled,
and nothing that existed before is lost or left half-written (docs/guide/reliability.md).

Cheap by design: the CLI runs in-process, faults are injected by patching writes (a full disk
is ``os.fsync`` raising ENOSPC), kills are simulated by the folders a kill leaves behind, and
checkpoints are written with small stand-in files. The cases that need a real training run
(a corrupted newest checkpoint, a concurrent resume of a running training) are in
``test_training.py``, which shares its compiled run.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest
from ml_collections import config_dict

from peghole_mjx.cli import main as cli
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import RANGES, dumps, json_safe
from peghole_mjx.core.validation import loads as strict_json  # no bare NaN
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import RunLock, _proc_start
from peghole_mjx.training import checkpoints
from peghole_mjx.training.config import CONFIG_DIR, TrainConfig, load_train_config

TINY = {
    "num_envs": 8,
    "steps_per_call": 10,
    "eval_every": 400,
    "num_eval_envs": 8,
    "batch_size": 128,
    "grad_updates_per_step": 8,
    "min_replay_size": 80,
    "max_replay_size": 20000,
    "env.episode_length": 25,
}


# ---------------------------------------------------------------------- helpers
def peghole(argv, capsys) -> tuple[int, str, str]:
    """Run the CLI in-process: (exit status, stdout, stderr)."""
    try:
        rc = cli.main([str(a) for a in argv])
    except SystemExit as exc:  # argparse
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line(err: str, *needles: str) -> None:
    """stderr ends in exactly one ``error:`` line holding every needle; no traceback."""
    assert "Traceback" not in err, err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1, err
    assert err.strip().splitlines()[-1] == errors[0]
    for n in needles:
        assert n in errors[0], errors[0]


def snapshot(folder) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def full_disk(monkeypatch):
    """Every fsync fails as on a full disk (the data never reaches it)."""

    def enospc(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(fileio.os, "fsync", enospc)


def fake_checkpoint(ckpt_dir, step: int, fill: float = 1.0):
    """A checkpoint of small stand-in files, written like a real one."""

    def write_files(folder):
        fileio.write_text(folder / "policy.json", json.dumps({"step": step}))
        fileio.write_bytes_with(folder / "params.npz", lambda f: np.savez(f, a=np.ones(3)))
        saved = checkpoints.save_state(folder, stand_in_state(fill))
        sched = {"step": step, "wall_s": 1.0, "n_eval": step // 400 + 1, **saved}
        fileio.write_text(folder / "state.json", json.dumps(sched))

    return checkpoints.write(ckpt_dir, step, write_files)


def stand_in_state(fill: float = 0.0, n: int = 1000):
    """A small carry-like tree: nested names, an integer leaf and a zero-size leaf."""
    return {"ts": {"w": np.full(n, fill), "k": np.arange(5)}, "act": np.zeros((4, 0))}


def load_stand_in(path):
    sched = json.loads((path / "state.json").read_text())
    tree = checkpoints.restore_state(path, stand_in_state(), sched.pop("empty_leaves"))
    return tree, sched


def run_folder(tmp_path, steps=(0, 400, 800)):
    """A run folder: run.json of the tiny config, metrics.csv with rows at ``steps``."""
    from peghole_mjx.training.run import METRIC_COLUMNS

    out = tmp_path / "run"
    out.mkdir()
    cfg = load_train_config("RectExtract", "quick", TINY, compliance_strategy=True)
    (out / "run.json").write_text(json.dumps({"config": cfg.as_dict()}, indent=2) + "\n")
    rows = [",".join(METRIC_COLUMNS)]
    rows += [",".join([str(s)] + ["1"] * (len(METRIC_COLUMNS) - 1)) for s in steps]
    (out / "metrics.csv").write_text("\n".join(rows) + "\n")
    return out, cfg


def bare_run(out, cfg):
    """A TrainingRun without env or learner (enough for its file logic)."""
    from peghole_mjx.training.run import TrainingRun

    run = TrainingRun.__new__(TrainingRun)
    run.cfg, run.out, run.ckpt_dir = cfg, out, out / "checkpoints"
    run.lock, run._pending_meta = None, None
    # what the run records of its env: the engine (run.json, policy.json) and the strategy
    run.env = types.SimpleNamespace(
        config=config_dict.ConfigDict({"engine": "mujoco", "compliance_strategy": True})
    )
    return run


def steps_in(out) -> list[int]:
    return [int(line.split(",")[0]) for line in (out / "metrics.csv").read_text().splitlines()[1:]]


# ---------------------------------------------------------------------- 1. run lock
def test_resume_of_a_run_in_use_is_refused_naming_the_holder(tmp_path, capsys):
    out, _ = run_folder(tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        rec = {"pid": holder.pid, "host": socket.gethostname(), "start": _proc_start(holder.pid)}
        (out / "run.lock").write_text(json.dumps(rec))
        before = snapshot(out)
        rc, _, err = peghole(["train", "--resume", out], capsys)
        assert rc == 2
        assert_one_line(err, f"pid {holder.pid}", "in use")
        assert snapshot(out) == before
        # a fresh training into the same folder is refused as well
        rc, _, err = peghole(["train", "--env", "RectExtract", "--quick", "--out", out], capsys)
        assert rc == 2 and snapshot(out) == before
    finally:
        holder.kill()
        holder.wait()


def test_stale_garbled_and_foreign_locks(tmp_path, capsys):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    lock = RunLock(tmp_path)
    (tmp_path / "run.lock").write_text(json.dumps({"pid": gone.pid, "host": socket.gethostname()}))
    with lock:  # the process is gone: taken over with a warning
        assert json.loads((tmp_path / "run.lock").read_text())["pid"] == os.getpid()
        with pytest.raises(UserInputError, match="already locked by this process"):
            RunLock(tmp_path).acquire()
    assert "stale lock" in capsys.readouterr().err
    assert not (tmp_path / "run.lock").exists()  # released
    (tmp_path / "run.lock").write_text("{garbled")
    with RunLock(tmp_path):
        pass
    (tmp_path / "run.lock").write_text(json.dumps({"pid": 1, "host": "elsewhere"}))
    with pytest.raises(UserInputError, match="pid 1 on elsewhere"):
        RunLock(tmp_path).acquire()


# ---------------------------------------------------------------------- 2, 11. checkpoints
def test_checkpoints_keep_two_states_and_temporary_folders_never_count(tmp_path):
    ckpt = tmp_path / "checkpoints"
    for step in (400, 800, 1200):
        fake_checkpoint(ckpt, step)
    names = [p.name for p in checkpoints.checkpoint_dirs(ckpt)]
    assert names == ["step_0000000400", "step_0000000800", "step_0000001200"]
    assert [checkpoints.has_state(ckpt / n) for n in names] == [False, True, True]
    for n in names:
        checkpoints.verify(ckpt / n)  # policies kept and intact
    # what kills leave behind: an unfinished folder, a folder being replaced, a set-aside one
    for junk in ("step_0000001600.tmp", "step_0000002000.old", "step_0000002400.corrupt"):
        shutil.copytree(ckpt / names[-1], ckpt / junk)
    assert [p.name for p in checkpoints.checkpoint_dirs(ckpt)] == names
    path, _ = checkpoints.newest_valid(ckpt, load_stand_in)
    assert path.name == names[-1]
    # `peghole evaluate RUN` (no final_policy yet) takes the newest real checkpoint
    from peghole_mjx.policies import resolve_policy_path

    (ckpt / "step_0000001600.tmp" / "policy.json").write_text("{}")
    assert resolve_policy_path(tmp_path).name == names[-1]


def test_kill_during_a_checkpoint_write_keeps_the_earlier_ones(tmp_path):
    ckpt = tmp_path / "checkpoints"
    fake_checkpoint(ckpt, 400)
    fake_checkpoint(ckpt, 800)
    before = snapshot(ckpt)

    def killed_midway(folder):
        (folder / "policy.json").write_text("{")
        raise KeyboardInterrupt  # stands in for the kill: the rest is never written

    with pytest.raises(KeyboardInterrupt):
        checkpoints.write(ckpt, 1200, killed_midway)
    assert (ckpt / "step_0000001200.tmp").exists()
    assert checkpoints.newest_valid(ckpt, load_stand_in)[0].name == "step_0000000800"
    assert {k: v for k, v in snapshot(ckpt).items() if ".tmp" not in k} == before
    fake_checkpoint(ckpt, 1200)  # the next write of that step starts afresh
    assert not (ckpt / "step_0000001200.tmp").exists()
    checkpoints.verify(ckpt / "step_0000001200", checkpoints.STATE_FILES)


def test_full_disk_during_a_checkpoint_write_keeps_the_earlier_ones(tmp_path, monkeypatch):
    ckpt = tmp_path / "checkpoints"
    fake_checkpoint(ckpt, 400)
    fake_checkpoint(ckpt, 800)
    before = snapshot(ckpt)
    full_disk(monkeypatch)
    with pytest.raises(OSError, match="No space left"):
        fake_checkpoint(ckpt, 1200)
    monkeypatch.undo()
    assert [p.name for p in checkpoints.checkpoint_dirs(ckpt)][-1] == "step_0000000800"
    assert {k: v for k, v in snapshot(ckpt).items() if ".tmp" not in k} == before
    assert checkpoints.newest_valid(ckpt, load_stand_in)[0].name == "step_0000000800"


@pytest.mark.parametrize("damage", ["flipped_byte", "truncated", "garbled_json", "no_manifest"])
def test_corrupt_newest_checkpoint_falls_back_to_the_previous_one(tmp_path, capsys, damage):
    ckpt = tmp_path / "checkpoints"
    fake_checkpoint(ckpt, 400, fill=4.0)
    newest = fake_checkpoint(ckpt, 800, fill=8.0)
    state = max((p for p in (newest / "state").rglob("*") if p.is_file()), key=os.path.getsize)
    data = bytearray(state.read_bytes())
    if damage == "flipped_byte":
        data[len(data) // 2] ^= 0xFF
        state.write_bytes(bytes(data))
    elif damage == "truncated":
        state.write_bytes(bytes(data[: len(data) // 2]))
    elif damage == "garbled_json":
        (newest / "state.json").write_text('{"step": 8')
    else:  # a state without a manifest is never trusted
        (newest / checkpoints.MANIFEST).unlink()
    path, (tree, sched) = checkpoints.newest_valid(ckpt, load_stand_in)
    assert path.name == "step_0000000400" and sched["step"] == 400
    assert tree["ts"]["w"][0] == 4.0 and tree["act"].shape == (4, 0)
    assert (ckpt / "step_0000000800.corrupt").is_dir()  # kept for inspection, out of the way
    err = capsys.readouterr().err
    assert "step_0000000800 is corrupt" in err and "falling back" in err


def test_a_checkpoint_of_another_config_is_refused_not_set_aside(tmp_path):
    ckpt = tmp_path / "checkpoints"
    fake_checkpoint(ckpt, 400)

    def mismatch(path):
        raise UserInputError(f"{path}: saved state does not match this run's config")

    with pytest.raises(UserInputError, match="does not match"):
        checkpoints.newest_valid(ckpt, mismatch)
    assert (ckpt / "step_0000000400").is_dir()


def test_a_state_of_another_structure_is_refused_by_name_not_by_leaf_order(tmp_path):
    """A state is restored by tree path: a template with the same number, order and shapes of
    leaves but other names is refused in one line naming them, as are other shapes."""
    path = fake_checkpoint(tmp_path / "checkpoints", 400, fill=4.0)
    empty = json.loads((path / "state.json").read_text())["empty_leaves"]
    renamed = {"ts": {"v": np.zeros(1000), "k": np.arange(5)}, "act": np.zeros((4, 0))}
    with pytest.raises(UserInputError) as e:
        checkpoints.restore_state(path, renamed, empty)
    msg = str(e.value)
    assert "\n" not in msg and "missing ts/v" in msg and "unexpected ts/w" in msg
    with pytest.raises(UserInputError, match=r"another shape or dtype \(e.g. ts/w"):
        checkpoints.restore_state(path, stand_in_state(n=999), empty)
    with pytest.raises(UserInputError, match="missing extra"):
        checkpoints.restore_state(path, {**stand_in_state(), "extra": np.zeros(2)}, empty)
    tree = checkpoints.restore_state(path, stand_in_state(), empty)
    assert tree["ts"]["w"][0] == 4.0 and tree["ts"]["k"].dtype == np.arange(5).dtype


def test_checkpoints_of_the_positional_npz_format_are_refused_as_not_resumable(tmp_path):
    old = tmp_path / "checkpoints" / checkpoints.checkpoint_name(400)
    old.mkdir(parents=True)
    np.savez(old / "state.npz", leaf_00000=np.ones(3))
    (old / "state.json").write_text(json.dumps({"step": 400, "wall_s": 1.0, "n_eval": 2}))
    with pytest.raises(UserInputError, match="positional state.npz.*not resumable"):
        checkpoints.newest_valid(tmp_path / "checkpoints", load_stand_in)
    assert old.is_dir()  # left as it is, not set aside


_SAVE_FOREVER = """
import sys, json
from pathlib import Path
import numpy as np
from peghole_mjx.files import fileio
from peghole_mjx.training import checkpoints
ckpt = Path(sys.argv[1])
step = 400
while True:
    def write_files(folder, step=step):
        tree = {"ts": {"w": np.full(4_000_000, float(step)), "k": np.arange(5)}}
        saved = checkpoints.save_state(folder, tree)
        text = json.dumps({"step": step, "wall_s": 1.0, "n_eval": 1, **saved})
        fileio.write_text(folder / "state.json", text)
        fileio.write_text(folder / "policy.json", "{}")
        fileio.write_text(folder / "params.npz", "")
    checkpoints.write(ckpt, step, write_files)
    print(step, flush=True)
    step += 400
"""


def test_kill_9_during_an_orbax_save_leaves_the_previous_checkpoint_restorable(tmp_path):
    """A process saving 32 MB states in a loop is SIGKILLed while a save is in progress: the
    newest complete checkpoint restores, holding exactly what was saved at its step."""
    ckpt = tmp_path / "checkpoints"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen(
        [sys.executable, "-c", _SAVE_FOREVER, str(ckpt)], env=env, stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "400"  # one complete checkpoint
        deadline = time.monotonic() + 120
        while not any(ckpt.glob("*.tmp/state*")):  # the next save has begun writing its state
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.01)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    template = {"ts": {"w": np.zeros(4_000_000), "k": np.arange(5)}}

    def load(path):
        sched = json.loads((path / "state.json").read_text())
        return checkpoints.restore_state(path, template, sched.pop("empty_leaves")), sched

    path, (tree, sched) = checkpoints.newest_valid(ckpt, load)
    assert tree["ts"]["w"][0] == tree["ts"]["w"][-1] == sched["step"] >= 400
    assert path.name == checkpoints.checkpoint_name(sched["step"])
    assert any(p.name.endswith(".tmp") for p in ckpt.iterdir())  # the killed save, ignored


# ---------------------------------------------------------------------- 2, 3, 4. resume records
def test_resume_rewrites_nothing_before_the_config_is_valid(tmp_path, capsys):
    out, _ = run_folder(tmp_path)
    before = snapshot(out)
    for value, needle in (
        ("50", "min_replay_size (80) must be < num_timesteps (50)"),
        ("99.9", "must be an integer"),
        ("abc", "must be an integer"),
        ("NaN", "must be an integer"),
    ):
        rc, _, err = peghole(["train", "--resume", out, "--set", f"num_timesteps={value}"], capsys)
        assert rc == 2
        assert_one_line(err, needle)
        assert snapshot(out) == before  # run.json untouched: a plain --resume still works
    assert not (out / "run.lock").exists()


def test_resume_rewrites_nothing_when_the_checkpoint_does_not_fit(tmp_path):
    out, cfg = run_folder(tmp_path)
    fake_checkpoint(out / "checkpoints", 400)
    before = snapshot(out)
    run = bare_run(out, cfg)
    run._pending_meta = {"config": {**cfg.as_dict(), "num_timesteps": 8000}}

    def mismatch(path):
        raise UserInputError(f"{path}: saved state does not match this run's config")

    run.load_checkpoint = mismatch
    with pytest.raises(UserInputError, match="does not match"):
        run.prepare(resume=True)
    assert snapshot(out) == before


def test_resume_truncates_metrics_to_the_checkpoint(tmp_path):
    out, cfg = run_folder(tmp_path, steps=(0, 400, 800, 1200))
    with (out / "metrics.csv").open("a") as f:
        f.write("1600,3.2,1")  # a row cut short by the kill
    fake_checkpoint(out / "checkpoints", 400)
    fake_checkpoint(out / "checkpoints", 800)
    run = bare_run(out, cfg)
    run._pending_meta = {"config": {**cfg.as_dict(), "num_timesteps": 8000}, "resumed_with": []}
    run.load_checkpoint = load_stand_in
    path, _, sched = run.prepare(resume=True)
    assert (
        path.name == "step_0000000800" and sched["step"] == 800 and steps_in(out) == [0, 400, 800]
    )
    assert json.loads((out / "run.json").read_text())["config"]["num_timesteps"] == 8000


def test_resume_before_the_first_checkpoint_starts_over_without_duplicate_rows(tmp_path, capsys):
    out, cfg = run_folder(tmp_path, steps=(0,))  # killed after the untrained evaluation
    run = bare_run(out, cfg)
    assert run.prepare(resume=True) is None
    assert steps_in(out) == []  # the step-0 row is redone, not duplicated
    assert "starting over" in capsys.readouterr().err


# ---------------------------------------------------------------------- 5, 6. decompose inputs
@pytest.mark.parametrize(
    "option, value, needle",
    [
        ("--threshold", "1.5", "[0.01, 1]"),
        ("--threshold", "0", "[0.01, 1]"),
        ("--threshold", "-1", "[0.01, 1]"),
        ("--threshold", "nan", "got nan"),
        ("--resolution", "0", "[100, 100000]"),
        ("--max-ch-vertex", "0", "at least 4 vertices"),
        ("--max-convex-hull", "0", "-1 (no cap)"),
        ("--friction", "nan", "[0, 2]"),
        ("--friction", "99", "[0, 2]"),
        ("--peg-mass", "nan", "(0, 100]"),
        ("--peg-mass", "0", "(0, 100]"),
        ("--clearance-mm", "nan", "got nan"),
        ("--clearance-mm", "inf", "got inf"),
        ("--seed", str(2**70), "[0, 4294967295]"),
    ],
)
def test_decompose_refuses_bad_numbers_before_any_work(tmp_path, capsys, option, value, needle):
    mesh = tmp_path / "part.stl"
    mesh.write_bytes(b"")
    rc, _, err = peghole(
        ["models", "decompose", mesh, mesh, "--out", tmp_path / "o", option, value], capsys
    )
    assert rc == 2
    assert_one_line(err, option, needle)
    assert not (tmp_path / "o").exists()


def test_coacd_params_and_decompose_parts_check_their_ranges(tmp_path):
    from peghole_mjx.geometry.decompose import CoacdParams, decompose_parts

    for bad in ({"threshold": 1.5}, {"resolution": 0}, {"max_ch_vertex": 0}, {"seed": -1}):
        with pytest.raises(UserInputError):
            CoacdParams(**bad)
    for kw in ({"friction": float("nan")}, {"peg_mass_kg": float("nan")}, {"clearance_mm": 0}):
        with pytest.raises(UserInputError):
            decompose_parts("a.stl", "b.stl", tmp_path, **kw)


def test_unreadable_meshes_give_one_line(tmp_path, capsys):
    rng = np.random.default_rng(0)
    for suffix in ("stl", "obj", "ply"):
        junk = tmp_path / f"junk.{suffix}"
        junk.write_bytes(rng.bytes(3000))
        rc, _, err = peghole(["models", "decompose", junk, junk, "--out", tmp_path / "o"], capsys)
        assert rc == 2
        assert_one_line(err, str(junk))
        assert "charset_normalizer" not in err


# ---------------------------------------------------------------------- 6, 10. env config, JSON
@pytest.mark.parametrize(
    "override, needle",
    [
        ("randomization.lateral_error_mm=NaN", "must be a finite number"),
        ("randomization.hole_xy_mm=Infinity", "must be a finite number"),
        ("randomization.friction_scale=[0.8, 9]", "outside [0, 2]"),
        ("episode_length=abc", "episode_length"),
        ("randomization.hole_yaw_deg=-1", ">= 0"),
    ],
)
def test_env_overrides_are_checked_before_any_work(capsys, override, needle):
    rc, _, err = peghole(["envs", "rollout", "--env", "RectExtract", "--set", override], capsys)
    assert rc == 2
    assert_one_line(err, needle)


@pytest.mark.parametrize(
    "key, value",
    [
        ("learning_rate", float("nan")),
        ("learning_rate", -1e-3),
        ("tau", float("nan")),
        ("num_eval_envs", 0),
        ("num_envs", 2.5),
        ("hidden_layer_sizes", [0]),
        ("hidden_layer_sizes", []),
        ("reward_scaling", float("inf")),
        ("batch_size", 1e9),
        ("alpha", float("nan")),
        ("num_timesteps", "abc"),
        ("num_timesteps", 99.9),
        ("seed", 2**70),
        ("discounting", 1.0),
        ("normalize_observations", "yes"),
        ("lr_schedule", "cosine"),
        ("entropy_backup", "no"),
        ("q_target_clip", 1),
    ],
)
def test_training_config_rejects_nonsense(key, value):
    with pytest.raises(UserInputError, match=key if key != "hidden_layer_sizes" else "hidden"):
        load_train_config("RectExtract", "quick", {key: value})


def test_training_config_from_a_damaged_run_json():
    good = load_train_config("RectExtract", "quick").as_dict()
    with pytest.raises(UserInputError, match="lacks the keys"):
        TrainConfig.from_dict({k: v for k, v in good.items() if k != "batch_size"})
    assert TrainConfig.from_dict({**good, "num_timesteps": 1e6}).num_timesteps == 1_000_000


def test_train_config_owns_every_default_and_the_cli_agrees_with_python(tmp_path):
    """TrainConfig holds the shared defaults, TRAINING_ENV_DEFAULTS the env entries training
    sets (compliance strategy on); ``peghole train`` without flags and ``load_train_config``
    from Python build the same config, but for the physics engine the CLI picks
    (``--engine auto``: sim.engines.default_engine)."""
    from peghole_mjx.cli.main import build_parser
    from peghole_mjx.sim.engines import default_engine
    from peghole_mjx.training.cli import train_config_from_args
    from peghole_mjx.training.config import TRAINING_ENV_DEFAULTS, default

    auto = {"env.engine": default_engine()}

    assert TRAINING_ENV_DEFAULTS == {
        "compliance_strategy": True,
        "reward_config.kind": "outcome",
        "action.residual": True,
    }
    assert default("learning_rate") == 3e-4
    assert "compliance_strategy" not in TrainConfig.__dataclass_fields__  # one home: the env
    for env in ("RectExtract", "DualExtract"):
        raw = json.loads((CONFIG_DIR / f"{env}.json").read_text())
        assert "common" not in raw  # no second copy of the shared defaults
        py = load_train_config(env, "quick", auto)
        assert py.env_overrides["compliance_strategy"] is True
        assert "compliance_strategy" not in py.as_dict()
        assert py.learning_rate == default("learning_rate")
        argv = ["train", "--env", env, "--quick", "--out", str(tmp_path / "run")]
        assert train_config_from_args(build_parser().parse_args(argv)) == py
        off = train_config_from_args(
            build_parser().parse_args([*argv, "--compliance-strategy", "off"])
        )
        assert off == load_train_config(env, "quick", auto, compliance_strategy=False)
        assert off.env_overrides["compliance_strategy"] is False
    # --compliance-strategy is a shorthand of env.compliance_strategy; a contradiction is refused
    cfg = load_train_config("RectExtract", "quick", {"env.compliance_strategy": False})
    assert cfg.env_overrides["compliance_strategy"] is False
    with pytest.raises(UserInputError, match="disagree"):
        load_train_config(
            "RectExtract", "quick", {"env.compliance_strategy": False}, compliance_strategy=True
        )
    # a run.json / policy.json written while TrainConfig had the field loads: read as the env
    # override (both were always written equal); written before the field: the override alone
    old = load_train_config("RectExtract", "quick", compliance_strategy=False).as_dict()
    assert TrainConfig.from_dict(old).env_overrides["compliance_strategy"] is False
    legacy = {**old, "compliance_strategy": False}
    assert TrainConfig.from_dict(legacy) == TrainConfig.from_dict(old)
    no_env = {**legacy, "env_overrides": {}}
    assert TrainConfig.from_dict(no_env).env_overrides == {"compliance_strategy": False}
    with pytest.raises(UserInputError, match="compliance_strategy is True but env_overrides"):
        TrainConfig.from_dict({**old, "compliance_strategy": True})


def test_train_cli_bad_values_are_one_line(tmp_path, capsys):
    out = tmp_path / "run"
    for sets, needle in (
        (["num_timesteps=abc"], "num_timesteps"),
        (["learning_rate=NaN"], "learning_rate"),
        (["env.randomization.lateral_error_mm=NaN"], "lateral_error_mm"),
    ):
        argv = ["train", "--env", "RectExtract", "--quick", "--out", out]
        rc, _, err = peghole([*argv, *(f"--set={s}" for s in sets)], capsys)
        assert rc == 2
        assert_one_line(err, needle)
    assert not (out / "run.json").exists()


def test_json_output_never_holds_bare_nan():
    data = {"a": float("nan"), "b": [1.0, float("inf")], "c": np.float32("nan"), "d": np.ones(2)}
    assert json_safe(data) == {"a": None, "b": [1.0, None], "c": None, "d": [1.0, 1.0]}
    assert strict_json(dumps(data)) == json_safe(data)
    with pytest.raises(ValueError, match="bare NaN"):
        strict_json('{"a": NaN}')


# ---------------------------------------------------------------------- 7. evaluate --out
FAKE_RESULT = {
    "policy": {"success_rate": 0.0, "mean_time_s": float("nan"), "mean_fz_N": 1.0},
    "baseline": {"success_rate": 1.0, "mean_time_s": 2.0, "mean_fz_N": 0.0},
    "force_reduction_pct": float("nan"),
}


@pytest.fixture
def fake_evaluate(monkeypatch):
    import importlib

    module = importlib.import_module("peghole_mjx.training.evaluate")
    calls = []
    monkeypatch.setattr(module, "evaluate", lambda *a, **k: calls.append(a) or FAKE_RESULT)
    return calls


def test_evaluate_out_is_checked_before_the_evaluation(tmp_path, capsys, fake_evaluate):
    existing_dir = tmp_path / "d"
    existing_dir.mkdir()
    blocker = tmp_path / "file"
    blocker.write_text("keep")
    for out, needle in ((existing_dir, "is a folder"), (blocker / "x.json", "existing file")):
        rc, _, err = peghole(["evaluate", "rect", "--json", "--out", out], capsys)
        assert rc == 2
        assert_one_line(err, needle)
    assert fake_evaluate == [] and blocker.read_text() == "keep"


def test_evaluate_prints_the_result_before_a_failed_write(
    tmp_path, capsys, fake_evaluate, monkeypatch
):
    out = tmp_path / "ev.json"
    assert peghole(["evaluate", "rect", "--json", "--out", out], capsys)[0] == 0
    old = out.read_text()  # the program's own file (its record beside it): rewritten below
    written = strict_json(old)  # the result, with where, when and how it was made
    assert written["command"] == f"peghole evaluate rect --json --out {out}"
    assert {"device", "versions", "date", "commit"} <= written.keys()
    assert written["config"]["episodes"] == 256 and written["config"]["env_overrides"] == {}
    with monkeypatch.context() as m:
        # the disk fills during the evaluation: the check before it (a real write probe, which
        # a disk already full refuses: test_faults_policies.py) still passed
        m.setattr(fileio, "_probe_write", lambda folder, what: None)
        real_fsync = os.fsync

        def enospc_after_the_evaluation(fd):  # the output's lock was taken before, on disk
            if len(fake_evaluate) > 1:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return real_fsync(fd)

        m.setattr(fileio.os, "fsync", enospc_after_the_evaluation)
        rc, stdout, err = peghole(["evaluate", "rect", "--json", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, "No space left on device")
    assert strict_json(stdout)["force_reduction_pct"] is None  # printed, valid JSON
    names = sorted(p.name for p in tmp_path.iterdir())
    assert out.read_text() == old and names == [".ev.json.peghole.json", "ev.json"]
    rc, _, _ = peghole(["evaluate", "rect", "--json", "--out", out], capsys)
    assert rc == 0 and strict_json(out.read_text())["policy"]["mean_time_s"] is None
    assert len(fake_evaluate) == 3


def test_evaluate_several_checkpoints_share_one_baseline_and_policy_only(
    tmp_path, capsys, monkeypatch
):
    import importlib

    module = importlib.import_module("peghole_mjx.training.evaluate")
    calls = []

    def fake(checkpoint, episodes, **kw):
        calls.append((checkpoint, kw["seed"], kw["policy_only"], kw["baselines"]))
        return {**FAKE_RESULT, "policy_path": checkpoint}

    monkeypatch.setattr(module, "evaluate", fake)
    out = tmp_path / "ev.json"
    argv = ["evaluate", "rect", "dual", "--seed", "3", "--json", "--out", out]
    rc, stdout, _ = peghole(argv, capsys)
    assert rc == 0
    res = strict_json(stdout)
    assert [r["policy_path"] for r in res] == ["rect", "dual"] == [c[0] for c in calls]
    stamps = ("device", "versions", "date", "command", "config", "commit")
    written = strict_json(out.read_text())
    assert [{k: v for k, v in r.items() if k not in stamps} for r in written] == res
    assert all(r["command"].startswith("peghole evaluate rect dual --seed 3") for r in written)
    assert calls[0][3] is calls[1][3]  # one baseline cache for the whole command
    assert {c[1:3] for c in calls} == {(3, False)}
    calls.clear()
    rc, stdout, _ = peghole(["evaluate", "rect", "--policy-only", "--json"], capsys)
    assert rc == 0 and isinstance(strict_json(stdout), dict) and calls[0][2] is True


# ---------------------------------------------------------------------- 8. models build
def test_models_build_writes_both_files_or_neither(tmp_path, capsys, monkeypatch):
    out = tmp_path / "scene"
    rc, _, _ = peghole(["models", "build", "--preset", "rect-1", "--out", out], capsys)
    assert rc == 0
    before = snapshot(out)
    argv = ["models", "build", "--preset", "rect-2", "--out", out, "--force"]
    full_disk(monkeypatch)
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "No space left on device")
    assert snapshot(out) == before  # no scene.xml of rect-2 beside a free_peg.xml of rect-1
    monkeypatch.undo()

    real_open = open

    def read_only(path, mode="r", *a, **k):
        """Reads work (the files' ownership records), every write fails."""
        if any(c in mode for c in "wax+"):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real_open(path, mode, *a, **k)

    monkeypatch.setattr(fileio, "open", read_only, raising=False)
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "Read-only file system")
    assert snapshot(out) == before


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--geometry", "rect", "--hole", "1200.1x40.1", "--peg", "1200x40", "--length", "50"],
         "robot's reach"),
        (["--geometry", "rect", "--hole", "60.1x40.1", "--peg", "59.8x39.8", "--length", "1000"],
         "robot's reach"),
        (["--geometry", "dual", "--hole-radius", "6.1", "--peg-radius", "5.9", "--distance",
          "5000", "--length", "50"], "robot's reach"),
        (["--preset", "rect-1", "--friction", "nan"], "[0, 2]"),
        (["--geometry", "rect", "--hole", "nanx40", "--peg", "59.8x39.8", "--length", "50"],
         "got nan"),
    ],
)  # fmt: skip
def test_models_build_refuses_bad_geometry_in_one_line(tmp_path, capsys, argv, needle):
    rc, _, err = peghole(["models", "build", *argv, "--out", tmp_path / "o"], capsys)
    assert rc == 2
    assert_one_line(err, needle)
    assert not (tmp_path / "o").exists()


def test_unreachable_inserted_pose_is_one_line(tmp_path, capsys, monkeypatch):
    from peghole_mjx.geometry import mjcf

    def no_ik(*a, **k):
        raise RuntimeError("IK did not converge: residual 8.01e-01")

    monkeypatch.setattr(mjcf, "build_scene", no_ik)
    rc, _, err = peghole(["models", "build", "--preset", "rect-1", "--out", tmp_path], capsys)
    assert rc == 2
    assert_one_line(err, "cannot reach")


def test_a_spec_beyond_the_robots_reach_names_the_limit():
    from peghole_mjx.geometry.specs import InfeasibleGeometryError, dual_spec

    with pytest.raises(InfeasibleGeometryError, match="700.*robot's reach"):
        dual_spec(6.1, 5.9, 5000.0, 50.0)
    assert RANGES["size_mm"].hi == 700


# ---------------------------------------------------------------------- 9. --out paths
@pytest.mark.parametrize(
    "argv",
    [
        ["models", "build", "--preset", "rect-1", "--out", "{file}"],
        ["analyze", "figure", "2.11", "--out", "{file}"],
        ["train", "--env", "RectExtract", "--quick", "--out", "{file}"],
        ["models", "decompose", "{file}", "{file}", "--out", "{file}"],
        ["evaluate", "rect", "--out", "{dir}"],
        ["models", "check", "--preset", "rect-1", "--out", "{dir}"],
        ["compare", "{dir}", "--out", "{dir}"],
    ],
)
def test_out_pointing_at_the_wrong_kind_of_path_is_one_line(tmp_path, capsys, argv):
    blocker = tmp_path / "file"
    blocker.write_text("keep")
    (tmp_path / "dir").mkdir()
    (tmp_path / "dir" / "metrics.csv").write_text("step\n")
    argv = [a.format(file=blocker, dir=tmp_path / "dir") for a in argv]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err)
    assert blocker.read_text() == "keep"


# ---------------------------------------------------------------------- 9, 12. policies
@pytest.fixture
def policy_copy(tmp_path):
    from peghole_mjx.policies import PRETRAINED

    dest = tmp_path / "policy"
    dest.mkdir()
    for name in ("policy.json", "params.npz"):
        shutil.copy(PRETRAINED["rect"] / name, dest / name)
    return dest


def _edit_meta(path, edit):
    meta = json.loads((path / "policy.json").read_text())
    edit(meta)
    (path / "policy.json").write_text(json.dumps(meta))


@pytest.mark.parametrize(
    "damage, needle",
    [
        ("truncated_params", "params.npz"),
        ("garbled_params", "params.npz"),
        ("pickled_params", "params.npz"),
        ("nan_params", "NaN"),
        ("garbled_json", "not valid JSON"),
        ("missing_network", "network"),
        ("relabelled", "trained on 'RectExtract'"),
        ("huge_network", "hidden_layer_sizes"),
        ("huge_observation", "observation_size"),
        ("other_version", "format_version 99 is unknown: this peghole_mjx reads 1 and 2"),
        ("renamed_array", "missing 0/mean"),
    ],
)
def test_damaged_or_foreign_policy_is_refused_before_anything_is_allocated(
    policy_copy, capsys, damage, needle
):
    params, meta = policy_copy / "params.npz", policy_copy / "policy.json"
    data = params.read_bytes()
    if damage == "truncated_params":
        params.write_bytes(data[: len(data) // 2])
    elif damage == "garbled_params":
        params.write_bytes(np.random.default_rng(0).bytes(len(data)))
    elif damage == "pickled_params":
        np.savez(params, **{"0/mean": np.array([{"x": 1}], dtype=object)})
    elif damage == "nan_params":
        with np.load(params) as z:
            arrays = {k: z[k] for k in z.files}
        key = sorted(arrays)[-1]  # a network weight
        arrays[key] = np.full_like(arrays[key], np.nan)
        np.savez(params, **arrays)
    elif damage == "garbled_json":
        meta.write_text('{"format_version": 1, "env": ')
    elif damage == "missing_network":
        _edit_meta(policy_copy, lambda m: m.pop("network"))
    elif damage == "relabelled":
        _edit_meta(policy_copy, lambda m: m.update(env="DualExtract"))
    elif damage == "huge_network":
        _edit_meta(policy_copy, lambda m: m["network"].update(hidden_layer_sizes=[10**9]))
    elif damage == "huge_observation":
        _edit_meta(policy_copy, lambda m: m["network"].update(observation_size=10**12))
    elif damage == "renamed_array":  # same arrays, one under another name: refused by name
        with np.load(params) as z:
            arrays = {("0/average" if k == "0/mean" else k): z[k] for k in z.files}
        np.savez(params, **arrays)
    else:
        _edit_meta(policy_copy, lambda m: m.update(format_version=99))
    from peghole_mjx.policies import load_policy

    with pytest.raises(CorruptFileError, match=needle):
        load_policy(policy_copy)
    rc, _, err = peghole(
        ["envs", "rollout", "--env", "RectExtract", "--policy", policy_copy], capsys
    )
    assert rc == 2
    assert_one_line(err, needle)


def _as_format_1(src, dest):
    """``src`` rewritten in policy format 1: the arrays stored by position (``leaf_0000``...,
    in tree order), ``format_version`` 1."""
    dest.mkdir()
    with np.load(src / "params.npz") as z:
        arrays = {f"leaf_{i:04d}": z[k] for i, k in enumerate(z.files)}
    np.savez(dest / "params.npz", **arrays)
    meta = json.loads((src / "policy.json").read_text())
    (dest / "policy.json").write_text(json.dumps({**meta, "format_version": 1}, indent=2) + "\n")


@pytest.mark.parametrize("name", ["rect", "dual"])
def test_committed_policy_gives_identical_actions_in_format_1_and_after_the_upgrade(tmp_path, name):
    """The committed policy (format 2), the same in format 1 (read with the in-loader upgrade)
    and that copy rewritten by ``upgrade_policy`` give identical actions; the rewritten files
    equal the committed ones."""
    import jax

    from peghole_mjx.policies import FORMAT_VERSION, PRETRAINED, load_policy, upgrade_policy

    committed = load_policy(name)
    assert committed.meta["format_version"] == FORMAT_VERSION == 2
    old = tmp_path / "v1"
    _as_format_1(PRETRAINED[name], old)
    as_v1 = load_policy(old)
    assert as_v1.meta["format_version"] == 1
    assert upgrade_policy(old) and not upgrade_policy(old)  # once; then already current
    upgraded = load_policy(old)
    obs = np.random.default_rng(0).normal(size=(8, committed.meta["network"]["observation_size"]))
    act = jax.jit(committed.policy_fn())
    want = np.asarray(act(committed.params, obs.astype(np.float32), jax.random.PRNGKey(0)))
    for other in (as_v1, upgraded):
        got = act(other.params, obs.astype(np.float32), jax.random.PRNGKey(0))
        np.testing.assert_array_equal(np.asarray(got), want)
    assert (old / "policy.json").read_text() == (PRETRAINED[name] / "policy.json").read_text()
    with np.load(old / "params.npz") as a, np.load(PRETRAINED[name] / "params.npz") as b:
        assert a.files == b.files and all(
            a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]) for k in a.files
        )


def test_policy_is_checked_against_the_env_it_runs_in(policy_copy):
    from peghole_mjx.envs import load
    from peghole_mjx.policies import load_policy

    bundle = load_policy(policy_copy)
    with pytest.raises(UserInputError, match="not for DualExtract"):
        bundle.check_env(load("DualExtract"))
    env = bundle.make_env()  # the policy's own env fits
    wrong = bundle.meta["network"]["observation_size"] + 1
    bundle.meta["network"]["observation_size"] = wrong
    with pytest.raises(UserInputError, match=f"observations of size {wrong}"):
        bundle.check_env(env)


# ---------------------------------------------------------------------- 9. the CLI's net
@pytest.mark.parametrize(
    "exc, needle",
    [
        (OSError(errno.ENOSPC, "No space left on device", "/x/y"), "/x/y: No space left"),
        (PermissionError(errno.EACCES, "Permission denied", "/x"), "Permission denied"),
        (json.JSONDecodeError("Expecting value", "{", 1), "Expecting value"),
        (__import__("zipfile").BadZipFile("File is not a zip file"), "not a zip file"),
        (UserInputError("two\nlines"), "two lines"),
    ],
)
def test_expected_failures_are_one_line_and_exit_2(monkeypatch, capsys, exc, needle):
    def boom(args):
        raise exc

    monkeypatch.setattr(cli, "GROUPS", {"demo": "peghole_mjx.demo"})
    import peghole_mjx.demo as demo

    monkeypatch.setattr(demo, "cmd_demo", boom)
    rc, _, err = peghole(["demo"], capsys)
    assert rc == 2
    assert_one_line(err, needle)


def test_a_bug_shows_its_traceback_and_asks_for_a_report(monkeypatch, capsys):
    import peghole_mjx.demo as demo

    def bug(args):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(cli, "GROUPS", {"demo": "peghole_mjx.demo"})
    monkeypatch.setattr(demo, "cmd_demo", bug)
    rc, _, err = peghole(["demo"], capsys)
    assert rc == 1
    assert "Traceback" in err and "please report it" in err.splitlines()[-1]


def test_bad_numbers_on_every_command_are_one_argparse_line(capsys):
    for argv, needle in (
        (["evaluate", "rect", "--seed", str(2**70)], "--seed"),
        (["evaluate", "rect", "--episodes", "0"], "--episodes"),
        (["envs", "rollout", "--env", "RectExtract", "--seed", "-1"], "--seed"),
        (["analyze", "jamming", "--geometry", "dual", "--depth", "10", "--mu", "1e6"], "--mu"),
        (["analyze", "jamming", "--geometry", "dual", "--depth", "nan"], "--depth"),
        (["train", "--env", "RectExtract", "--stop-at-success", "nan"], "--stop-at-success"),
    ):
        rc, _, err = peghole(argv, capsys)
        assert rc == 2
        assert_one_line(err, needle)
