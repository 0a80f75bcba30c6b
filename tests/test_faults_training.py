"""Training runs and ``peghole compare`` under faults: multi-seed resume, damaged states,
memory and disk sized before any work, strict JSON outputs, the run lock on a full disk,
``--set`` keys that cannot be set, damaged metrics.csv / history.csv / run.json
(docs/guide/reliability.md). Every case ends in one line (exit 2) before any simulation, or is
handled with nothing lost.

Cheap by design, as tests/test_faults.py: the CLI runs in-process; the file logic of a run
runs on a bare run object (no env, no learner) with small stand-in checkpoints; a compile or a
simulation that should not happen fails the test (``no_simulation``).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from test_faults import (
    TINY,
    assert_one_line,
    bare_run,
    fake_checkpoint,
    full_disk,
    load_stand_in,
    peghole,
    run_folder,
    snapshot,
    stand_in_state,
    steps_in,
)

from peghole_mjx.core import memory
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import loads as strict_json
from peghole_mjx.files.lock import RunLock, _proc_start
from peghole_mjx.training import checkpoints

TINY_SETS = [f"--set={k}={v}" for k, v in TINY.items()]


@pytest.fixture
def no_simulation(monkeypatch):
    """Fail the test if a learner is initialised or a training call starts (a compile)."""
    from peghole_mjx.training import functional, sac

    def never(*a, **k):
        raise AssertionError("a simulation started")

    monkeypatch.setattr(sac.SACTrainer, "init_carry", never)
    monkeypatch.setattr(sac.SACTrainer, "train_call", never)
    monkeypatch.setattr(functional.Train, "init", never)


def flip_a_state_byte(ckpt: Path) -> None:
    state = max((p for p in (ckpt / "state").rglob("*") if p.is_file()), key=os.path.getsize)
    data = bytearray(state.read_bytes())
    data[len(data) // 2] ^= 0xFF
    state.write_bytes(bytes(data))


# ---------------------------------------------------------------------- 1. multi-seed resume
def bare_seeds_run(out: Path, seeds: int = 2):
    """A SeedsRun without env or learner; its policies are small stand-in files."""
    from peghole_mjx.training.config import load_train_config
    from peghole_mjx.training.seeds import SeedsRun

    run = SeedsRun.__new__(SeedsRun)
    run.cfg = load_train_config("RectExtract", "quick", TINY, compliance_strategy=True)
    run.seeds, run.out, run.ckpt_dir, run.progress = seeds, out, out / "checkpoints", False
    run._template = stand_in_state

    def save_policy(path, carry, k, step, atomic=True):
        path.mkdir(parents=True, exist_ok=True)
        (path / "policy.json").write_text(json.dumps({"seed": k, "step": step}))
        np.savez(path / "params.npz", w=np.full(3, float(k)))

    run._save_policy = save_policy
    return run


def history(steps, seeds=(0, 1)) -> str:
    from peghole_mjx.training.seeds import HISTORY_COLUMNS

    rows = [",".join(HISTORY_COLUMNS)]
    rows += [
        ",".join([str(s), str(step)] + ["1"] * (len(HISTORY_COLUMNS) - 2))
        for step in steps
        for s in seeds
    ]
    return "\n".join(rows) + "\n"


def test_multi_seed_checkpoints_are_verified_by_their_own_layout_and_resume(tmp_path, capsys):
    out = tmp_path / "seeds"
    out.mkdir()
    run = bare_seeds_run(out)
    (out / "run.json").write_text(json.dumps({"config": run.cfg.as_dict(), "seeds": 2}))
    (out / "history.csv").write_text(history((400, 800, 1200)))
    run._save(stand_in_state(4.0), 400)
    run._save(stand_in_state(8.0), 800)
    newest = out / "checkpoints" / "step_0000000800"
    assert not (newest / "policy.json").exists() and (newest / "seed_1" / "params.npz").exists()
    found, rows = run.prepare(resume=True)
    path, (carry, step) = found
    assert path == newest and step == 800 and float(carry["ts"]["w"][0]) == 8.0
    assert {int(r["step"]) for r in rows} == {400, 800}  # the rows after it are redone
    assert not list((out / "checkpoints").glob("*.corrupt"))
    assert "corrupt" not in capsys.readouterr().err
    # a damaged seed policy is what makes such a checkpoint corrupt: the one before is used
    (newest / "seed_1" / "params.npz").write_bytes(b"garbage")
    path, (carry, step) = run.prepare(resume=True)[0]
    assert step == 400 and float(carry["ts"]["w"][0]) == 4.0
    assert (out / "checkpoints" / "step_0000000800.corrupt").is_dir()


# ---------------------------------------------------------------------- 2. history kept
def test_damaged_states_start_over_with_the_history_set_aside_never_truncated(tmp_path, capsys):
    out, cfg = run_folder(tmp_path, steps=(0, 400, 800, 1200))
    for step in (400, 800, 1200):
        fake_checkpoint(out / "checkpoints", step)
    for name in ("summary.json", "curves.png"):
        (out / name).write_text(name)
    for ckpt in checkpoints.checkpoint_dirs(out / "checkpoints")[1:]:
        flip_a_state_byte(ckpt)  # both states damaged; three intact policies remain
    before = snapshot(out)
    run = bare_run(out, cfg)
    run.load_checkpoint = load_stand_in
    run._pending_meta = {"config": {**cfg.as_dict(), "num_timesteps": 8000}, "resumed_with": []}
    assert run.prepare(resume=True) is None
    err = capsys.readouterr().err
    assert "starting over" in err and "kept in" in err and "history_1" in err
    kept = out / "history_1"
    assert (kept / "metrics.csv").read_bytes() == before["metrics.csv"]
    assert (kept / "summary.json").read_bytes() == before["summary.json"]
    assert (kept / "run.json").read_bytes() == before["run.json"]  # the run.json it had
    for name in ("step_0000000400", "step_0000000800.corrupt", "step_0000001200.corrupt"):
        checkpoints.verify(kept / "checkpoints" / name)  # the three policies, intact
    assert steps_in(out) == [] and not (out / "checkpoints").exists()
    assert json.loads((out / "run.json").read_text())["config"]["num_timesteps"] == 8000
    # starting over again never overwrites the first history
    (out / "metrics.csv").write_text((kept / "metrics.csv").read_text())
    assert run.prepare(resume=True) is None
    assert (out / "history_2" / "metrics.csv").exists()
    assert (kept / "metrics.csv").read_bytes() == before["metrics.csv"]


def test_multi_seed_start_over_keeps_history_csv(tmp_path, capsys):
    out = tmp_path / "seeds"
    out.mkdir()
    run = bare_seeds_run(out)
    (out / "run.json").write_text(json.dumps({"config": run.cfg.as_dict(), "seeds": 2}))
    (out / "history.csv").write_text(history((400, 800)))
    run._save(stand_in_state(4.0), 400)
    flip_a_state_byte(out / "checkpoints" / "step_0000000400")
    found, rows = run.prepare(resume=True)
    assert found is None and rows == []
    assert (out / "history_1" / "history.csv").read_text() == history((400, 800))
    assert (out / "history.csv").read_text().count("\n") == 1  # the header
    assert "history_1" in capsys.readouterr().err


# ---------------------------------------------------------------------- 3. memory and disk
@pytest.fixture
def host_memory(monkeypatch):
    """The host has 16 GiB available (and no accelerator is asked)."""
    monkeypatch.setattr(memory, "host_available_bytes", lambda: 16 << 30)
    monkeypatch.setattr(memory, "device_available_bytes", lambda: None)


def test_a_replay_buffer_larger_than_memory_is_refused_before_anything(
    tmp_path, capsys, host_memory, no_simulation
):
    out = tmp_path / "run"
    argv = ["train", "--env", "RectExtract", "--quick", "--out", out, "--no-progress"]
    rc, _, err = peghole([*argv, "--set", "max_replay_size=1e9"], capsys)
    assert rc == 2
    assert_one_line(err, "replay buffer", "max_replay_size=1000000000", "GiB", "host memory")
    assert not out.exists()  # the refused run created it and removed it: the --out is free
    out.mkdir()
    # a folder an earlier run left when it died before its first evaluation (out of memory
    # while compiling: run.json and an empty tb/) does not block the same --out either
    (out / "run.json").write_text(json.dumps({"config": good_config()}))
    (out / "tb").mkdir()
    (out / "tb" / "events.out.tfevents.1").write_bytes(b"")
    rc, _, err = peghole([*argv, "--set", "max_replay_size=1e9"], capsys)
    assert rc == 2 and "already holds" not in err
    assert_one_line(err, "replay buffer")


def test_worlds_beyond_memory_are_refused_naming_the_setting(
    tmp_path, capsys, monkeypatch, no_simulation
):
    monkeypatch.setattr(memory, "host_available_bytes", lambda: 256 << 20)
    monkeypatch.setattr(memory, "device_available_bytes", lambda: None)
    out = tmp_path / "run"
    argv = ["train", "--env", "RectExtract", "--quick", "--out", out, "--set", "num_envs=65536"]
    rc, _, err = peghole([*argv, "--set", "eval_every=2000000"], capsys)
    assert rc == 2
    assert_one_line(err, "65536 + ", "worlds", "num_envs", "MiB available")
    assert not out.exists()  # created by the refused run and removed


def test_train_refuses_an_out_without_room_for_its_checkpoints(
    tmp_path, capsys, monkeypatch, no_simulation
):
    from peghole_mjx.files import fileio

    monkeypatch.setattr(fileio, "free_bytes", lambda path: 1 << 20)
    out = tmp_path / "run"
    rc, _, err = peghole(["train", "--env", "RectExtract", "--quick", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, f"--out {out}", "1.0 MiB free", "writes about")
    assert not out.exists()  # created by the refused run and removed


def test_a_failed_start_is_replaced_but_a_started_run_is_not(tmp_path, capsys):
    from peghole_mjx.training.run import failed_start

    out, cfg = run_folder(tmp_path, steps=())
    (out / "tb").mkdir()
    run = bare_run(out, cfg)
    run.trainer = types.SimpleNamespace(network={"observation_size": 1})
    assert failed_start(out)
    assert run.prepare(resume=False) is None
    assert "stopped before its first evaluation" in capsys.readouterr().err
    assert json.loads((out / "run.json").read_text())["network"] == {"observation_size": 1}
    assert not (out / "tb").exists()
    (tmp_path / "b").mkdir()
    started, _ = run_folder(tmp_path / "b", steps=(0,))  # the untrained evaluation is kept
    assert not failed_start(started)
    with pytest.raises(UserInputError, match="already holds a training run"):
        bare_run(started, cfg).prepare(resume=False)
    (out / "run.json").write_text("{}")  # not a run record: never taken for a failed start
    assert not failed_start(out)


# ---------------------------------------------------------------------- 4. strict JSON
def test_summary_json_of_a_run_without_a_successful_episode_is_strict_json(tmp_path, monkeypatch):
    from peghole_mjx.training import run as run_mod

    out, cfg = run_folder(tmp_path, steps=(0, 400))
    text = (out / "metrics.csv").read_text().splitlines()
    text[1:] = [",".join(["0"] + ["nan"] * (text[0].count(",")))]  # no eval succeeded
    (out / "metrics.csv").write_text("\n".join(text) + "\n")
    run = bare_run(out, cfg)
    run.render = False
    run.trainer = types.SimpleNamespace(network={}, policy_params=lambda c: None)
    monkeypatch.setattr(run_mod, "save_policy", lambda *a, **k: None)
    run.finish(None, 400, 1.0)
    summary = strict_json((out / "summary.json").read_text())
    assert summary["final_eval"]["success_rate"] is None


def test_seeds_json_of_seeds_without_a_successful_episode_is_strict_json(tmp_path, monkeypatch):
    import peghole_mjx.envs.rollout as rollout_mod
    import peghole_mjx.policies as policies

    out = tmp_path / "seeds"
    out.mkdir()
    run = bare_seeds_run(out)
    run.env = None
    run.train = types.SimpleNamespace(network={}, policy_params=lambda c: {"w": np.zeros((2, 3))})
    stats = {"success_rate": 0.0, "mean_time_s": float("nan"), "episodes": 8}
    result = types.SimpleNamespace(summary=lambda: types.SimpleNamespace(as_dict=lambda: stats))
    monkeypatch.setattr(rollout_mod, "rollout", lambda *a, **k: result)
    monkeypatch.setattr(policies, "make_policy_fn", lambda *a, **k: None)
    run.finish({}, 400)
    summary = strict_json((out / "seeds.json").read_text())
    assert [e["mean_time_s"] for e in summary["final_eval"]] == [None, None]
    assert summary["final_eval_over_seeds"]["mean_time_s"] == {"mean": None, "ci95_t": None}


# ---------------------------------------------------------------------- 5. lock, full disk
def test_a_full_disk_while_taking_the_lock_names_the_file_and_leaves_nothing(
    tmp_path, capsys, monkeypatch
):
    full_disk(monkeypatch)
    with pytest.raises(UserInputError, match=r"cannot write the lock file .*run\.lock.*space"):
        RunLock(tmp_path).acquire()
    assert list(tmp_path.iterdir()) == []
    out, _ = run_folder(tmp_path)
    before = snapshot(out)
    rc, _, err = peghole(["train", "--resume", out], capsys)
    assert rc == 2
    assert_one_line(err, str(out / "run.lock"), "No space left")
    assert snapshot(out) == before  # no .run.lock.<pid>, no run.lock


# ---------------------------------------------------------------------- 6. --set env/profile
@pytest.mark.parametrize(
    "setting, needle",
    [
        ("env=DualExtract", "--env NAME"),
        ("profile=full", "--profile full|cpu|quick"),
        ("env_overrides={}", "--set env.KEY=VALUE"),
    ],
)
def test_set_of_a_key_chosen_by_a_flag_is_refused_not_ignored(
    tmp_path, capsys, setting, needle, no_simulation
):
    out = tmp_path / "run"
    argv = ["train", "--env", "RectExtract", "--quick", "--out", out, "--set", setting]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, f"--set {setting.split('=')[0]}=", needle)
    assert not out.exists()


# ---------------------------------------------------------------------- 7. metrics.csv
def damage(out: Path, how: str) -> str:
    path = out / "metrics.csv"
    if how == "nul_tail":
        path.write_bytes(path.read_bytes() + b"\0" * 64)
        return "NUL bytes"
    lines = path.read_text().splitlines()
    if how == "text_step":
        lines[2] = "four hundred" + lines[2][3:]
        path.write_text("\n".join(lines) + "\n")
        return "line 3: step must be a whole number"
    if how == "no_step_column":
        lines[0] = lines[0].replace("step,", "stop,", 1)
        path.write_text("\n".join(lines) + "\n")
        return "line 1: the header lacks the columns ['step']"
    lines[1] = lines[1] + ",1,2"  # a row with extra fields
    path.write_text("\n".join(lines) + "\n")
    return "line 2:"


@pytest.mark.parametrize("how", ["nul_tail", "text_step", "no_step_column", "extra_fields"])
def test_compare_refuses_a_damaged_metrics_csv_naming_file_and_line(tmp_path, capsys, how):
    out, _ = run_folder(tmp_path)
    needle = damage(out, how)
    png = tmp_path / "c.png"
    rc, _, err = peghole(["compare", out, "--out", png], capsys)
    assert rc == 2
    assert_one_line(err, str(out / "metrics.csv"), needle)
    assert not png.exists()


def test_compare_refuses_an_out_that_is_not_an_image_and_draws_a_good_run(tmp_path, capsys):
    out, _ = run_folder(tmp_path)
    rc, _, err = peghole(["compare", out, "--out", tmp_path / "c.txt"], capsys)
    assert rc == 2
    assert_one_line(err, "c.txt", ".txt is not an image format", ".png")
    assert not (tmp_path / "c.txt").exists()
    rc, _, err = peghole(["compare", out, "--out", tmp_path / "c.svg"], capsys)
    assert rc == 0, err
    assert (tmp_path / "c.svg").read_text().lstrip().startswith("<?xml")


@pytest.mark.parametrize("how", ["text_step", "no_step_column", "extra_fields"])
def test_resume_refuses_a_damaged_metrics_csv_before_any_work(tmp_path, capsys, how, no_simulation):
    out, _ = run_folder(tmp_path)
    needle = damage(out, how)
    before = snapshot(out)
    rc, _, err = peghole(["train", "--resume", out, "--no-progress"], capsys)
    assert rc == 2
    assert_one_line(err, str(out / "metrics.csv"), needle)
    assert snapshot(out) == before


def test_resume_drops_the_nul_tail_a_power_cut_leaves(tmp_path):
    out, cfg = run_folder(tmp_path, steps=(0, 400, 800))
    with (out / "metrics.csv").open("ab") as f:
        f.write(b"1200,3.2,1" + b"\0" * 40)  # the last row, cut short and padded by the crash
    fake_checkpoint(out / "checkpoints", 400)
    run = bare_run(out, cfg)
    run.load_checkpoint = load_stand_in
    _, _, sched = run.prepare(resume=True)
    assert sched["step"] == 400 and steps_in(out) == [0, 400]


def test_a_damaged_history_csv_is_refused_naming_file_and_line(tmp_path):
    out = tmp_path / "seeds"
    out.mkdir()
    run = bare_seeds_run(out)
    (out / "history.csv").write_text(history((400,)).replace("0,400", "0,4e2", 1))
    with pytest.raises(CorruptFileError, match=r"history.csv line 2: step must be a whole"):
        run.prepare(resume=True)


# ---------------------------------------------------------------------- 8. run.json
def good_config() -> dict:
    from peghole_mjx.training.config import load_train_config

    return load_train_config("RectExtract", "quick", TINY).as_dict()


@pytest.mark.parametrize(
    "record, needle",
    [
        ("[1, 2]", "a JSON object expected"),
        ('{"network": {}}', "'config' must be an object"),
        ('{"config": [1]}', "'config' must be an object"),
        ('CFG_WITH:num_envs="8"', "num_envs must be an integer"),
        ('CFG_WITH:hidden_layer_sizes="big"', "hidden_layer_sizes must be a list"),
        ("CFG_WITHOUT:batch_size", "lacks the keys ['batch_size']"),
        ("CFG_WITH:num_timesteps=NaN", "bare NaN"),
        ('{"config": CFG, "seeds": "2"}', "'seeds' must be a whole number"),
        ('{"config": CFG, "seeds": 0}', "'seeds' must be a whole number"),
        ('{"config": CFG, "resumed_with": 5}', "'resumed_with' must be a list"),
        ("[" * 100 + "]" * 100, "nested 100 deep"),
        ('{"config": ', "not a readable run record"),
    ],
)
def test_a_damaged_run_json_is_one_line_before_any_work(tmp_path, capsys, record, needle):
    out, _ = run_folder(tmp_path)
    cfg = good_config()
    if record.startswith("CFG_WITH:"):
        key, value = record[9:].split("=", 1)
        text = json.dumps({"config": {**cfg, key: "@"}}).replace('"@"', value)
    elif record.startswith("CFG_WITHOUT:"):
        text = json.dumps({"config": {k: v for k, v in cfg.items() if k != record[12:]}})
    else:
        text = record.replace("CFG", json.dumps(cfg))
    (out / "run.json").write_text(text)
    before = snapshot(out)
    rc, _, err = peghole(["train", "--resume", out, "--no-progress"], capsys)
    assert rc == 2
    assert_one_line(err, "run.json", needle)
    assert snapshot(out) == before
    rc, _, err = peghole(["compare", out, "--out", tmp_path / "c.png"], capsys)
    if "CFG" not in record:  # compare reads only the env and its overrides
        assert rc == 2
        assert_one_line(err, "run.json")


# ---------------------------------------------------------------------- 9. lock holders
def test_the_lock_checks_the_holders_start_time_and_names_it(tmp_path, capsys):
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        rec = {"pid": holder.pid, "host": socket.gethostname(), "since": "2026-12-02T04:00:00Z"}
        lock = tmp_path / "run.lock"
        lock.write_text(json.dumps({**rec, "start": _proc_start(holder.pid)}))
        with pytest.raises(UserInputError) as e:
            RunLock(tmp_path).acquire()
        msg = str(e.value)
        assert f"pid {holder.pid} on {socket.gethostname()}" in msg and "04:00:00Z" in msg
        assert str(lock) in msg  # where to look if that run is known to be over
        # the same PID started at another time: a reused PID, the lock is stale
        lock.write_text(json.dumps({**rec, "start": "1"}))
        with RunLock(tmp_path):
            assert json.loads(lock.read_text())["pid"] == os.getpid()
        assert "stale lock" in capsys.readouterr().err
    finally:
        holder.kill()
        holder.wait()
    assert not lock.exists()
