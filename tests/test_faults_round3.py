"""Resume means the same run, guards before long work, and messages that name the cause
(issue 53, decided 2026-12-04; docs/guide/reliability_files.md).

Cheap by design: every command here is refused before any MJX graph is compiled (an env is
built with the ``mujoco`` engine where one is needed; ``jax.eval_shape`` traces shapes only).
Cases touching the user's files list and hash them before and after.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from test_faults import assert_one_line, full_disk, peghole

from peghole_mjx import envs
from peghole_mjx.cli import main as cli
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check, reduction_pct
from peghole_mjx.envs import rollout as rollout_mod
from peghole_mjx.files import fileio
from peghole_mjx.geometry import decompose
from peghole_mjx.training import commands
from peghole_mjx.training.config import load_train_config, write_run_record
from peghole_mjx.training.run import naming

ROOT = Path(__file__).resolve().parents[1]
MUJOCO = {"engine": "mujoco"}


def hashes(folder: Path) -> dict[str, str]:
    """``relative path -> SHA-256`` of every file under ``folder``."""
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture
def recorded_run(tmp_path) -> Path:
    """A run folder whose run.json records RectExtract, profile quick, engine mujoco, the
    compliance strategy on and 20000 env steps (no checkpoint: every case is refused first)."""
    cfg = load_train_config(
        "RectExtract", "quick", {"env.engine": "mujoco", "num_timesteps": 20000}
    )
    out = tmp_path / "run"
    out.mkdir()
    write_run_record(out, {"config": cfg.as_dict(), "env": "RectExtract"})
    (out / "metrics.csv").write_text("step,eval/success_rate\n0,0.0\n")
    return out


# ---------------------------------------------------------------------- 1. the same run
@pytest.mark.parametrize(
    "flags, needles",
    [
        (["--engine", "mjx"], ["--engine mjx differs from the run's engine mujoco"]),
        (
            ["--compliance-strategy", "off"],
            ["--compliance-strategy off differs from the run's compliance strategy on"],
        ),
        (["--profile", "full"], ["--profile full differs from the run's profile quick"]),
        (["--out", "elsewhere"], ["--out elsewhere differs from the run's folder"]),
        (
            ["--set", "num_timesteps=10000"],
            ["num_timesteps=10000 is below the run's num_timesteps=20000"],
        ),
    ],
)
def test_resume_refuses_flags_that_differ_from_the_run(recorded_run, capsys, flags, needles):
    before = hashes(recorded_run.parent)
    rc, _, err = peghole(["train", "--resume", recorded_run, *flags], capsys)
    assert rc == 2
    assert_one_line(err, "--resume", *needles)
    assert hashes(recorded_run.parent) == before  # run.json not rewritten, nothing created


def test_resume_accepts_flags_equal_to_the_runs_own(recorded_run):
    parser = cli.build_parser()
    argv = ["train", "--resume", str(recorded_run), "--engine", "mujoco", "--quick"]
    argv += ["--compliance-strategy", "on", "--out", str(recorded_run)]
    argv += ["--set", "num_timesteps=40000"]  # extending is allowed
    commands.check_resume_flags(parser.parse_args(argv))  # no error
    args = parser.parse_args(["train", "--resume", str(recorded_run), "--profile", "quick"])
    commands.check_resume_flags(args)


@pytest.mark.parametrize(
    "flags, needles",
    [
        (["--quick", "--profile", "full"], ["--quick and --profile full contradict"]),
        (
            ["--engine", "mjx", "--set", "env.engine=mujoco"],
            ["--engine mjx and --set env.engine=mujoco contradict"],
        ),
    ],
)
def test_contradicting_flags_are_refused_and_create_no_out(tmp_path, capsys, flags, needles):
    out = tmp_path / "new"
    rc, _, err = peghole(["train", "--env", "RectExtract", "--out", out, *flags], capsys)
    assert rc == 2
    assert_one_line(err, *needles)
    assert not out.exists()


def test_actions_of_the_wrong_length_are_refused_before_any_compile():
    env = envs.load("RectExtract", config_overrides=MUJOCO)
    assert env.action_size not in (4, 9)
    for n in (4, 9):
        with pytest.raises(UserInputError, match=rf"shape \({n},\).*action_size"):
            rollout_mod.rollout(env, lambda obs, rng, n=n: jnp.zeros(n), 2, progress=False)
        gym = pytest.importorskip("peghole_mjx.gym")
        with pytest.raises(UserInputError, match=rf"must have shape \({env.action_size},\)"):
            gym._checked_action(np.zeros(n, np.float32), (env.action_size,), "action")
    with pytest.raises(UserInputError, match="dtype bool"):
        rollout_mod.check_policy_actions(env, lambda obs, rng: jnp.zeros(6, bool))
    rollout_mod.check_policy_actions(env, rollout_mod.scripted_policy(env))  # the right one


def test_load_refuses_a_config_of_another_scene():
    with pytest.raises(UserInputError, match="preset 'dual-2' is not a rect scene"):
        envs.load("RectExtract", config=envs.get_default_config("DualExtract"))
    with pytest.raises(UserInputError, match="not a dual scene"):
        envs.load("DualExtractHard", config=envs.get_default_config("RectExtract"))


def test_envs_rollout_of_a_policy_in_another_task_needs_cross_but_not_on_another_engine(capsys):
    # the pretrained rect policy was trained on mjx: another engine is no difference (the
    # engine is provenance), another episode length is, refused before the env is built
    argv = ["envs", "rollout", "--env", "RectExtract", "--policy", "rect", "--engine", "mujoco"]
    rc, _, err = peghole([*argv, "--set", "episode_length=7", "--episodes", "1"], capsys)
    assert rc == 2
    assert_one_line(err, "episode_length (trained", "--cross")
    assert "engine" not in err


# ---------------------------------------------------------------------- 2. guards
@pytest.mark.parametrize("over", [None, MUJOCO], ids=["mjx", "mujoco"])
def test_vector_env_sizes_its_worlds_against_memory(over):
    # MJX: about 24 kB of state a world; MuJoCo C: a small state and a 19 kB MjData a world
    gym = pytest.importorskip("peghole_mjx.gym")
    with pytest.raises(UserInputError, match=r"PegHoleVectorEnv\(num_envs=1048576\).*GiB"):
        gym.PegHoleVectorEnv("RectExtract", 1048576, config_overrides=over)


def test_coacd_refuses_a_mesh_of_too_many_faces(monkeypatch):
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.creation.icosphere(subdivisions=7)  # 327 680 faces
    assert len(mesh.faces) > decompose.COACD_MAX_FACES

    def forbidden(*a, **k):
        raise AssertionError("CoACD started")

    monkeypatch.setattr(decompose, "_in_child", forbidden)
    with pytest.raises(UserInputError) as exc:
        decompose.run_coacd(mesh)
    msg = str(exc.value)
    assert f"{len(mesh.faces)} faces" in msg and str(decompose.COACD_MAX_FACES) in msg
    assert "simplify_quadric_decimation" in msg and "\n" not in msg


HANG = """
import signal
import sys

# a foreground command's SIGINT (a shell's background job inherits it ignored, and Python then
# installs no KeyboardInterrupt handler)
signal.signal(signal.SIGINT, signal.default_int_handler)

from peghole_mjx.cli import main as cli
from peghole_mjx.geometry import decompose

# as CoACD's native loop: deaf to SIGINT and SIGTERM
CHILD = (
    "import os, signal, sys, time; from pathlib import Path; "
    "signal.signal(signal.SIGTERM, signal.SIG_IGN); signal.signal(signal.SIGINT, signal.SIG_IGN); "
    "Path(sys.argv[1]).write_text(str(os.getpid()))\\nwhile True: time.sleep(0.1)"
)

if __name__ == "__main__":
    cli._handle_sigterm()
    try:
        decompose._in_child(["-c", CHILD, sys.argv[1]])
    except cli.Terminated:
        print("terminated", flush=True)
        sys.exit(cli.EXIT_TERMINATED)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(cli.EXIT_INTERRUPTED)
"""


@pytest.mark.parametrize(
    "sig, status, said",
    [
        (signal.SIGTERM, cli.EXIT_TERMINATED, "terminated"),
        (signal.SIGINT, cli.EXIT_INTERRUPTED, "interrupted"),
    ],
    ids=["SIGTERM", "SIGINT"],
)
def test_a_deaf_coacd_child_ends_with_its_parent_on_a_signal(tmp_path, sig, status, said):
    script, pidfile = tmp_path / "hang.py", tmp_path / "child.pid"
    script.write_text(textwrap.dedent(HANG))
    proc = subprocess.Popen(
        [sys.executable, str(script), str(pidfile)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.time() + 120
        while not pidfile.exists() or not pidfile.read_text():
            assert proc.poll() is None and time.time() < deadline, proc.communicate()
            time.sleep(0.2)
        child = int(pidfile.read_text())
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=90)  # a loaded 2-core machine: its exit, JAX imported
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status and said in out, err
    time.sleep(0.5)
    with pytest.raises(ProcessLookupError):  # the child was killed and reaped
        os.kill(child, 0)


# ---------------------------------------------------------------------- 3. messages
def test_a_full_disk_names_the_file_being_written(tmp_path, monkeypatch):
    target = tmp_path / "run" / "metrics.csv"
    target.parent.mkdir()
    full_disk(monkeypatch)
    with pytest.raises(OSError) as exc, naming(target):
        fileio.write_text(target, "step\n")
    assert exc.value.errno == errno.ENOSPC
    assert cli._one_line(exc.value) == f"{target}: No space left on device"


def test_numpy_integers_are_integers():
    assert check("num_envs", np.int64(4)) == 4 and type(check("num_envs", np.int32(4))) is int
    assert check("ctrl_dt", np.float32(0.01), kind="env.ctrl_dt") == pytest.approx(0.01)
    for refused in (np.True_, True, np.int64(0)):
        with pytest.raises(UserInputError):
            check("num_envs", refused)


def test_too_many_seeds_name_seeds_and_leave_no_out(tmp_path, capsys):
    out = tmp_path / "new"
    rc, _, err = peghole(
        ["train", "--env", "RectExtract", "--out", out, "--seeds", 100000000], capsys
    )
    assert rc == 2 and "--seeds" in err and "4096" in err
    assert not out.exists()
    # within run.json's limit but beyond memory: the advice names --seeds; --out not left
    argv = ["train", "--env", "RectExtract", "--out", out, "--seeds", 4096, "--quick"]
    argv += ["--engine", "mujoco", "--set", "max_replay_size=1000000"]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, "4096 seeds", "fewer --seeds")
    assert not out.exists()


def test_a_reduction_of_unresolved_forces_is_not_reported():
    # the sweep at mu = 0 (the frictionless oracle): peaks of 0.0004 N gave "-390 %"
    assert reduction_pct(np.array([0.00196]), np.array([0.0004])) is None
    assert reduction_pct(2.0, float("nan")) is None
    assert reduction_pct([1.0, 3.0], np.array([8.0])) == pytest.approx(75.0)
    assert reduction_pct(0.005, 1.0, floor_N=0.001) == pytest.approx(99.5)


def test_a_run_refused_for_memory_leaves_no_empty_out(tmp_path, capsys):
    out = tmp_path / "new"
    argv = ["train", "--env", "RectExtract", "--out", out, "--quick", "--engine", "mujoco"]
    rc, _, err = peghole([*argv, "--set", "max_replay_size=1000000000"], capsys)
    assert rc == 2
    assert_one_line(err, "the replay buffer", "lower --set max_replay_size")
    assert not out.exists()  # check_out_dir made it to probe it; the refusal removed it


@pytest.mark.parametrize("shape", [(4,), (9,), (1,), (6, 1), (1, 6)])
def test_the_raw_env_refuses_actions_of_the_wrong_length_when_traced(shape):
    """``env.step`` with 4 or 9 actions for a 6-action task, or an action of shape (1,),
    (A, 1) or (1, A): one line at trace time (shapes only, nothing compiled or run)."""
    import jax

    env = envs.load("RectExtract", config_overrides=MUJOCO)
    state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    needle = re.escape(f"action of shape {shape}: RectExtract takes 6")
    with pytest.raises(UserInputError, match=needle):
        jax.eval_shape(env.step, state, jax.ShapeDtypeStruct(shape, "float32"))
