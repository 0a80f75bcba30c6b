"""Policies on disk, ``peghole evaluate``, ``peghole demo`` and SIGTERM: every case ends in
one clear line (exit 2) before any env is built or simulated, or is handled with nothing lost
(docs/guide/reliability.md). Cheap: the simulation entry points are replaced by stand-ins that fail
the test if they are reached, or by quick fakes; no env is compiled."""

from __future__ import annotations

import importlib
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx.core.errors import CorruptFileError
from peghole_mjx.files import fileio
from peghole_mjx.policies import PRETRAINED, load_policy

evaluate_module = importlib.import_module("peghole_mjx.training.evaluate")
demo = importlib.import_module("peghole_mjx.demo")


# ---------------------------------------------------------------------- helpers
@pytest.fixture
def rect_copy(tmp_path):
    dest = tmp_path / "rect_copy"
    shutil.copytree(PRETRAINED["rect"], dest)
    return dest


@pytest.fixture
def no_simulation(monkeypatch):
    """Building an env or starting a rollout fails the test (an internal error, exit 1)."""
    import peghole_mjx.envs as envs

    def boom(*a, **k):
        raise AssertionError("an env was built or a simulation started")

    monkeypatch.setattr(envs, "load", boom)
    monkeypatch.setattr(evaluate_module, "rollout", boom)


def _edit_meta(path, edit):
    meta = json.loads((path / "policy.json").read_text())
    edit(meta)
    (path / "policy.json").write_text(json.dumps(meta))


def _edit_arrays(path, edit):
    with np.load(path / "params.npz") as z:
        arrays = {k: z[k] for k in z.files}
    edit(arrays)
    np.savez(path / "params.npz", **arrays)


def _observation_size(name: str) -> int:
    """A published policy's observation size, as its policy.json states it."""
    meta = json.loads((PRETRAINED[name] / "policy.json").read_text())
    return meta["network"]["observation_size"]


# ---------------------------------------------------------------------- 1. shapes
def test_params_of_another_policy_name_the_array_its_shape_and_the_expected_one(
    rect_copy, capsys, no_simulation
):
    n_dual, n_rect = _observation_size("dual"), _observation_size("rect")
    assert n_dual != n_rect
    shutil.copy(PRETRAINED["dual"] / "params.npz", rect_copy / "params.npz")
    match = rf"array 0/mean has shape \({n_dual},\).*expects \({n_rect},\)"
    with pytest.raises(CorruptFileError, match=match):
        load_policy(rect_copy)
    rc, out, err = peghole(["evaluate", rect_copy, "--json"], capsys)
    assert rc == 2 and out == ""
    assert_one_line(
        err, "params.npz", f"array 0/mean has shape ({n_dual},)", f"expects ({n_rect},)"
    )


def test_one_transposed_weight_is_named_with_both_shapes(rect_copy, capsys, no_simulation):
    key = "1/params/hidden_0/kernel"
    _edit_arrays(rect_copy, lambda a: a.update({key: a[key].T.copy()}))
    rc, _, err = peghole(["evaluate", rect_copy], capsys)
    assert rc == 2
    n = _observation_size("rect")
    assert_one_line(err, f"array {key} has shape (256, {n})", f"expects ({n}, 256)")


# ---------------------------------------------------------------------- 2. schema on load
@pytest.mark.parametrize(
    "damage, needle",
    [
        ("train_config_string", 'train_config must be an object, got "oops"'),
        ("train_config_env_overrides", "train_config.env_overrides must be an object"),
        ("deep_nesting", "nested 200001 deep (at most 64 read)"),
        ("int8_params", "array 1/params/hidden_0/kernel has dtype int8, expected float32"),
        ("flipped_normaliser", "normalize_observations is false, but the normaliser holds"),
        ("zero_std", "0/std holds values <= 0"),
        ("format_version_true", "format_version must be an integer (1 or 2), got true"),
        ("format_version_string", 'format_version must be an integer (1 or 2), got "2"'),
        ("env_list", "env ['RectExtract'] is not one of"),
    ],
)
def test_tampered_policy_is_refused_on_load_before_any_env_is_built(
    rect_copy, capsys, no_simulation, damage, needle
):
    if damage == "train_config_string":
        _edit_meta(rect_copy, lambda m: m.update(train_config="oops"))
    elif damage == "train_config_env_overrides":
        _edit_meta(rect_copy, lambda m: m["train_config"].update(env_overrides=[1]))
    elif damage == "deep_nesting":
        n = 200_000
        (rect_copy / "policy.json").write_text('{"a": ' + "[" * n + "]" * n + "}")
    elif damage == "int8_params":
        key = "1/params/hidden_0/kernel"
        _edit_arrays(rect_copy, lambda a: a.update({key: a[key].astype(np.int8)}))
    elif damage == "flipped_normaliser":  # statistics under a false flag (whatever rect's is)
        _edit_meta(rect_copy, lambda m: m["network"].update(normalize_observations=False))
        _edit_arrays(rect_copy, lambda a: a["0/mean"].__setitem__(0, 1.0))
    elif damage == "zero_std":  # a normalising policy with a zero standard deviation
        _edit_meta(rect_copy, lambda m: m["network"].update(normalize_observations=True))
        _edit_arrays(rect_copy, lambda a: a["0/std"].__setitem__(0, 0.0))
    elif damage == "format_version_true":
        _edit_meta(rect_copy, lambda m: m.update(format_version=True))
    elif damage == "format_version_string":
        _edit_meta(rect_copy, lambda m: m.update(format_version="2"))
    else:
        _edit_meta(rect_copy, lambda m: m.update(env=["RectExtract"]))
    with pytest.raises(CorruptFileError) as info:
        load_policy(rect_copy)
    assert needle in str(info.value)
    for argv in (
        ["evaluate", rect_copy],
        ["envs", "rollout", "--env", "RectExtract", "--policy", rect_copy],
    ):
        rc, _, err = peghole(argv, capsys)
        assert rc == 2
        assert_one_line(err, needle)


def test_committed_policies_pass_the_load_checks():
    """Every committed policy loads (its normaliser agrees with its flag, checked by the loader)
    and its network records the normaliser setting it was trained with (rect and dual with
    one, rect_hard and dual_hard without: the one-update-per-env-step protocol)."""
    for name in PRETRAINED:
        bundle = load_policy(name)
        flag = bundle.meta["network"]["normalize_observations"]
        assert flag is bundle.meta["train_config"]["normalize_observations"], name


# ---------------------------------------------------------------------- 3. all paths first
def test_every_policy_path_is_checked_before_the_first_evaluation(tmp_path, capsys, no_simulation):
    rc, _, err = peghole(["evaluate", "rect", tmp_path / "nonexistent", "--json"], capsys)
    assert rc == 2
    assert_one_line(err, f"no policy at {tmp_path / 'nonexistent'}")
    # a second policy whose env the requested settings contradict: refused before the first
    rc, _, err = peghole(["evaluate", "rect", "dual", "--preset", "rect-1"], capsys)
    assert rc == 2
    assert_one_line(err, "differs from the policy's training env")


def test_evaluate_outputs_are_checked_before_the_first_evaluation(
    tmp_path, capsys, monkeypatch, no_simulation
):
    parts = tmp_path / "parts"
    # two envs cannot share one --parts folder's baseline: refused now, not after rect's run
    rc, _, err = peghole(["evaluate", "rect", "dual", "--parts", parts], capsys)
    assert rc == 2
    assert_one_line(err, "--parts", "DualExtract and RectExtract")
    # a --parts folder holding another seed's baseline
    (parts / "baseline").mkdir(parents=True)
    key = {"env": "RectExtract", "seed": 0, "batch": 256, "speed_m_s": 0.02, "env_config": "{}"}
    (parts / "baseline" / "key.json").write_text(json.dumps(key))
    rc, _, err = peghole(["evaluate", "rect", "--parts", parts, "--seed", "1"], capsys)
    assert rc == 2
    assert_one_line(err, "holds the slices of another evaluation", "seed")
    # a damaged key.json is named
    (parts / "baseline" / "key.json").write_text('{"env": ')
    rc, _, err = peghole(["evaluate", "rect", "--parts", parts], capsys)
    assert rc == 2
    assert_one_line(err, str(parts / "baseline" / "key.json"), "damaged")
    # no room on the disk for the slices and the result
    monkeypatch.setattr(fileio, "free_bytes", lambda path: 1000)
    out = tmp_path / "ev.json"
    rc, _, err = peghole(["evaluate", "rect", "--out", out, "--parts", tmp_path / "p2"], capsys)
    assert rc == 2
    assert_one_line(err, "--parts", "free, the command writes about")
    assert not out.exists()


def test_evaluate_parts_folder_that_cannot_be_written_is_one_line(
    tmp_path, capsys, monkeypatch, no_simulation
):
    real_open = open

    def read_only(path, *a, **k):
        if ".peghole_write_probe" in str(path):
            raise OSError(30, "Read-only file system", str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr("builtins.open", read_only)
    rc, _, err = peghole(["evaluate", "rect", "--parts", tmp_path / "parts"], capsys)
    assert rc == 2
    assert_one_line(err, "--parts", "not writable", "Read-only file system")


# ---------------------------------------------------------------------- 4. damaged slices
def _slice(folder: Path, start: int, n: int, fill: float = 1.0) -> Path:
    from peghole_mjx.envs.metrics import EPISODE_RECORD

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"episodes_{start:07d}_{n:07d}.npz"
    np.savez(path, **{k: np.full(n, fill, np.float32) for k in EPISODE_RECORD})
    return path


def test_damaged_slices_are_set_aside_with_one_line_each_and_run_again(tmp_path, capsys):
    folder = tmp_path / "policy-x"
    good = _slice(folder, 0, 4)
    random_bytes = folder / "episodes_0000004_0000004.npz"
    random_bytes.write_bytes(np.random.default_rng(0).bytes(2000))  # "pickled data"
    truncated = _slice(folder, 8, 4)
    truncated.write_bytes(truncated.read_bytes()[:300])
    short = _slice(folder, 12, 3)  # named for 3 episodes: ok
    wrong = _slice(folder, 16, 4)
    with np.load(wrong) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["success"] = arrays["success"][:2]
    np.savez(wrong, **arrays)
    pickled = folder / "episodes_0000020_0000004.npz"
    np.savez(pickled, success=np.array([{"x": 1}], dtype=object))
    unfinished = folder / "episodes_0000024_0000004.tmp.npz"  # a kill's leftover: not a slice
    unfinished.write_bytes(b"x")
    moved = evaluate_module.check_slices(folder)
    err = capsys.readouterr().err
    bad = [random_bytes, truncated, wrong, pickled]
    assert sorted(moved) == sorted(p.with_name(p.name + ".damaged") for p in bad)
    assert all(not p.exists() for p in bad) and all(p.exists() for p in moved)  # kept aside
    assert good.exists() and short.exists() and unfinished.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 4 and "Traceback" not in err
    for path, line in zip(sorted(bad), lines, strict=True):
        assert line.startswith(f"peghole: warning: {path} is damaged") and "run again" in line
    assert "pickled" in lines[0] and "array success has shape (2,)" in err
    assert evaluate_module.check_slices(folder) == []  # now clean


def test_evaluate_sets_damaged_slices_aside_before_its_rollout(tmp_path, capsys, monkeypatch):
    """Through :func:`evaluate` (the env is built, the rollout is a stand-in): the damaged
    slice is set aside before the rollout starts, so its episodes are run again."""
    seen = []

    class Result:  # the part of envs.rollout.RolloutResult that evaluate reads
        def __init__(self):
            self.per_episode = {}

        def summary(self):
            return type("Summary", (), {"as_dict": lambda s: {"mean_fz_N": 1.0}})()

    def fake_rollout(env, policy, episodes, parts_dir=None, **kw):
        seen.append(sorted(p.name for p in Path(parts_dir).iterdir()))
        return Result()

    monkeypatch.setattr(evaluate_module, "rollout", fake_rollout)
    parts = tmp_path / "parts"
    bundle = load_policy("rect")
    evaluate_module.evaluate(bundle, 4, batch=4, parts_dir=parts, progress=False)
    policy_dir = next(parts.glob("policy-*"))
    _slice(policy_dir, 0, 4)  # a finished slice ...
    (parts / "baseline" / "episodes_0000000_0000004.npz").write_bytes(b"garbage")  # ... a bad one
    capsys.readouterr()
    seen.clear()
    evaluate_module.evaluate(bundle, 4, batch=4, parts_dir=parts, progress=False)
    err = capsys.readouterr().err
    assert "baseline/episodes_0000000_0000004.npz is damaged" in err
    assert seen == [
        ["episodes_0000000_0000004.npz", "key.json"],  # the good slice stays for reuse
        ["episodes_0000000_0000004.npz.damaged", "key.json"],
    ]


# ---------------------------------------------------------------------- 5. demo in place
@pytest.fixture
def fake_demo(monkeypatch):
    """The demo's stages replaced by quick stand-ins that write small files; returns the
    list of stages run (in order). ``fail[stage]`` makes that stage raise once."""
    calls: list[str] = []
    fail: dict[str, BaseException] = {}

    def stage(name, write):
        def work(*a):
            calls.append(name)
            result = write(*a)
            if name in fail:
                raise fail.pop(name)
            return result

        return work

    def models(out):
        for preset in ("rect-2", "dual-2"):
            (out / preset).mkdir(parents=True)
            (out / preset / "scene.xml").write_text(f"<mujoco model='{preset}'/>")

    def experiment(out):
        out.mkdir()
        (out / "summary.json").write_text("{}")

    def train(out, cfg):
        out.mkdir()
        (out / "run.json").write_text("{}")
        (out / "metrics.csv").write_text("step\n0\n")
        return {"env_steps": 10, "final_eval": {"mean_return": float("nan")}}

    ev = {"policy": {"mean_fz_N": 1.0}, "baseline": {"mean_fz_N": 2.0}, "episodes": 4}
    monkeypatch.setattr(demo, "_build_models", stage("models", models))
    monkeypatch.setattr(demo, "_run_experiment", stage("experiment", experiment))
    monkeypatch.setattr(demo, "_train", stage("training", train))

    def fake_evaluate(policy, episodes):
        calls.append("training_eval" if policy != "rect" else "evaluation")
        return {**ev, "episodes": episodes}

    monkeypatch.setattr(demo, "_evaluate", fake_evaluate)
    monkeypatch.setattr(
        demo, "_report", lambda out, tr, ev, timings, profile: f"{demo.REPORT_TITLE}\n{tr}\n"
    )
    return calls, fail


ALL_STAGES = ["models", "experiment", "training", "training_eval", "evaluation"]


def test_interrupted_demo_reruns_in_place_reusing_its_complete_stages(tmp_path, capsys, fake_demo):
    calls, fail = fake_demo
    out = tmp_path / "demo"
    argv = ["demo", "--out", out, "--profile", "quick", "--episodes", "4"]
    fail["training"] = KeyboardInterrupt()  # the run is stopped inside the training stage
    rc, _, err = peghole(argv, capsys)
    assert rc == 130 and err.strip().splitlines()[-1] == "peghole: interrupted"
    assert calls == ["models", "experiment", "training"]
    state = json.loads((out / "demo.json").read_text())["stages"]
    assert state["models"]["done"] and not state["training"]["done"]
    (out / "train" / "stale_from_the_killed_run").write_text("x")
    calls.clear()
    rc, _, err = peghole(argv, capsys)
    assert rc == 0, err
    assert calls == ["training", "training_eval", "evaluation"]  # 1 and 2 reused
    assert "interrupted before it completed" in err
    assert not (out / "train" / "stale_from_the_killed_run").exists()  # redone afresh
    assert (out / "report.md").read_text().startswith(demo.REPORT_TITLE)
    # complete: a rerun reuses everything and rewrites the report
    calls.clear()
    rc, _, _ = peghole(argv, capsys)
    assert rc == 0 and calls == []
    # a changed file is verified and its stage redone; other settings redo what they change
    (out / "models" / "rect-2" / "scene.xml").write_text("<mujoco/>")
    rc, _, err = peghole([*argv[:-1], "8"], capsys)
    assert rc == 0
    assert calls == ["models", "training_eval", "evaluation"]
    assert "models/rect-2/scene.xml is missing or changed" in err
    # --force starts afresh
    calls.clear()
    rc, _, _ = peghole([*argv, "--force"], capsys)
    assert rc == 0 and calls == ALL_STAGES


def test_demo_refuses_outputs_it_did_not_record_and_force_only_deletes_a_demo(
    tmp_path, capsys, fake_demo
):
    calls, _ = fake_demo
    out = tmp_path / "old_demo"  # an older demo's folder: a report, no demo.json
    (out / "models").mkdir(parents=True)
    (out / "report.md").write_text(demo.REPORT_TITLE + "\n")
    argv = ["demo", "--out", out, "--profile", "quick", "--episodes", "4"]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2 and calls == []
    assert_one_line(err, "models, report.md", "no demo.json", "--force")
    rc, _, _ = peghole([*argv, "--force"], capsys)
    assert rc == 0 and calls == ALL_STAGES
    # someone's training run is not a demo: --force refuses to delete it
    calls.clear()
    other = tmp_path / "runs"
    (other / "train").mkdir(parents=True)
    (other / "train" / "run.json").write_text("{}")
    rc, _, err = peghole(["demo", "--out", other, "--force"], capsys)
    assert rc == 2 and calls == []
    assert_one_line(err, "not a demo's folder, nothing deleted")
    assert (other / "train" / "run.json").read_text() == "{}"
    # a damaged demo.json
    (out / "demo.json").write_text("[" * 100 + "]" * 100)
    rc, _, err = peghole(argv, capsys)
    assert rc == 2 and calls == []
    assert_one_line(err, "demo.json is damaged", "--force")


def test_demo_output_is_checked_before_any_stage(tmp_path, capsys, monkeypatch, fake_demo):
    calls, _ = fake_demo
    monkeypatch.setattr(fileio, "free_bytes", lambda path: 10 * 2**20)
    rc, _, err = peghole(["demo", "--out", tmp_path / "d", "--profile", "quick"], capsys)
    assert rc == 2 and calls == []
    assert_one_line(err, "--out", "10.0 MiB free, the command writes about")
    blocker = tmp_path / "file"
    blocker.write_text("keep")
    rc, _, err = peghole(["demo", "--out", blocker], capsys)
    assert rc == 2 and calls == [] and blocker.read_text() == "keep"
    assert_one_line(err, "is an existing file")


# ---------------------------------------------------------------------- 6. SIGTERM
SLOW_COMMAND = textwrap.dedent(
    """
    import sys, time
    from peghole_mjx.cli import main as cli
    import peghole_mjx.demo as demo
    from peghole_mjx.files.lock import RunLock

    def slow(args):
        with RunLock(sys.argv[1]):
            print("ready", flush=True)
            time.sleep(120)
        return 0

    demo.cmd_demo = slow
    cli.GROUPS = {"demo": "peghole_mjx.demo"}
    sys.exit(cli.main(["demo"]))
    """
)


def _as_from_a_shell():
    """In the child before exec: signals unblocked and SIGINT at its default, as a shell
    starts a command. A child inherits its parent's blocked and ignored signals; in the full
    suite (not alone, with or without pytest-xdist, 2026-12-02) the SIGINT case timed out as
    if the child never saw the signal. Which earlier test leaves the test process so was not
    isolated; this test is about peghole's handling, so it starts peghole as a shell would."""
    signal.pthread_sigmask(signal.SIG_SETMASK, [])
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("sig, rc", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_sigterm_is_handled_like_ctrl_c_one_line_lock_released(tmp_path, sig, rc):
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW_COMMAND, str(run)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
        preexec_fn=_as_from_a_shell,
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        assert (run / "run.lock").exists()
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == rc, err
    assert time.monotonic() - t0 < 30  # not after the 120 s sleep
    assert "Traceback" not in err
    want = "peghole: terminated (SIGTERM)" if sig == signal.SIGTERM else "peghole: interrupted"
    assert err.strip().splitlines() == [want]
    assert not (run / "run.lock").exists()  # the lock was released on the way out
    assert os.listdir(run) == []


# the broad handlers the package keeps, each for a stated reason; none turns a user's mistake
# into silence (a new one must be added here with its reason, or narrowed)
BROAD_HANDLERS = {
    "cli/main.py": 1,  # the bug catcher: traceback + "internal error", exit 1
    "training/run.py": 2,  # a learning-curve plot must never lose a finished run (warned)
    "training/seeds.py": 1,  # same, for a multi-seed run
    "experiments/report.py": 1,  # the analytic cross-check of one cell, recorded as an error
    "geometry/decompose.py": 1,  # trimesh's many exception types -> UserInputError (one line)
    "geometry/coacd_child.py": 1,  # CoACD's process reports whatever ends it, in one line
    "training/commands.py": 1,  # remove the empty --out a refused train created, then re-raise
    "policies/__init__.py": 2,  # remove the half-written policy folder, then re-raise
    "files/provenance.py": 1,  # device name for a result file: falls back to the CPU's
    "deploy.py": 1,  # onnxruntime's own error classes for a damaged file -> one line
    "policies/export.py": 1,  # remove the half-written export, then re-raise
    "envs/task_make.py": 1,  # remove the half-written task folder, then re-raise
    "files/lock.py": 1,  # record the files a writer changed before it failed, then re-raise
}


def test_broad_exception_handlers_are_the_stated_few():
    import re

    root = Path(__file__).resolve().parents[1] / "peghole_mjx"
    found = {}
    for f in root.rglob("*.py"):
        n = len(re.findall(r"except (?:Exception|BaseException)\b", f.read_text()))
        if n and f.name != "fileio.py":  # fileio: remove a temporary, then re-raise
            found[f.relative_to(root).as_posix()] = n
    assert found == BROAD_HANDLERS
