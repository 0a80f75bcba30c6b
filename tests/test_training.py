"""Brax SAC training: learning, full resets, checkpoint fidelity, kill -9 and resume, evaluate.

All tests share one tiny configuration (8 worlds, 25-step episodes), so the graphs are
compiled once per session (and cached on disk for the subprocesses). The worlds run on the
``mujoco`` engine, the CPU default of ``peghole train``: what is tested here (learning, resets,
checkpoints, resume, evaluation) is the driver's, the same on either engine. One training call
through the MJX engine is tested here too (:func:`test_a_training_call_through_the_mjx_engine`).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.training.config import PROFILES, load_train_config

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
    "env.engine": "mujoco",
}
LEARN_STEPS = 4000


def tiny_config(**extra):
    return load_train_config("RectExtract", "quick", {**TINY, **extra}, compliance_strategy=True)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from peghole_mjx.training.run import TrainingRun

    out = tmp_path_factory.mktemp("run")
    # eq (4.4) on plain actions, as before training's defaults became the residual learner:
    # its per-step progress pays a pull within these 25-step episodes, which the outcome
    # reward (paid at an extraction, out of reach in 25 steps) does not; the default learner
    # is measured by the learning benchmark (benchmarks/evals/learning.py)
    thesis = {"env.reward_config.kind": "thesis", "env.action.residual": False}
    cfg = tiny_config(num_timesteps=LEARN_STEPS, **thesis)
    run = TrainingRun(cfg, out, progress=False, render=False)
    summary = run.run()
    return run, summary


@pytest.mark.slow  # compiles the MJX env inside SAC's training call: one to two minutes
def test_a_training_call_through_the_mjx_engine():
    """The learner with its worlds on MJX: after the prefill, one training call of 2 worlds
    takes gradient steps, changes the policy and leaves every learner array finite."""
    from peghole_mjx.core.treenames import named_leaves
    from peghole_mjx.envs import load
    from peghole_mjx.training.sac import SACTrainer

    small = {"num_envs": 2, "num_eval_envs": 2, "steps_per_call": 5, "batch_size": 8}
    small |= {"grad_updates_per_step": 1, "min_replay_size": 10, "hidden_layer_sizes": [16, 16]}
    cfg = tiny_config(**small, **{"env.episode_length": 10, "env.engine": "mjx"})
    env = load(cfg.env, config_overrides=cfg.env_overrides)
    assert env.engine.name == "mjx"
    trainer = SACTrainer(env, cfg)
    carry, _ = trainer.prefill(trainer.init_carry(cfg.seed))
    before = named_leaves(jax.tree.map(lambda x: np.asarray(x[0]), carry.ts))
    carry, _, _ = trainer.train_call(carry)
    after = named_leaves(jax.tree.map(lambda x: np.asarray(x[0]), carry.ts))
    assert int(after["gradient_steps"]) == int(before["gradient_steps"]) + 5
    assert all(np.isfinite(v).all() for v in after.values() if v.dtype.kind == "f")
    changed = [k for k in after if k.startswith("policy_params") and (after[k] != before[k]).any()]
    assert changed, "the training call left the policy as it was"


def test_training_improves_eval_return_over_untrained(trained):
    run, summary = trained
    rows = run._read_rows()
    assert [int(r["step"]) for r in rows] == [
        0,
        400,
        800,
        1200,
        1600,
        2000,
        2400,
        2800,
        3200,
        3600,
        4000,
    ]
    before = float(rows[0]["eval/mean_return"])
    after = max(float(r["eval/mean_return"]) for r in rows[-3:])
    # untrained: near-zero progress; trained: pulls out at several mm per step
    assert after > before + 5.0, (before, after)
    assert summary["untrained_eval_return"] == pytest.approx(before)
    for key in ("train/episodes", "train/mean_fz_N", "train/mean_discounted_return", "loss/critic"):
        assert rows[-1][key] != ""


def test_finished_worlds_get_fresh_randomised_starts(trained):
    """Brax's AutoResetWrapper would restore each world's first start: we must not."""
    run, _ = trained
    first = run.trainer.init_carry(run.cfg.seed).env_state.info["hole_pos"]
    now = run.carry.env_state.info["hole_pos"]
    # every world has finished >= 10 episodes of 25 steps by now
    assert np.all(np.abs(np.asarray(now) - np.asarray(first)).max(axis=-1) > 1e-6)


def test_checkpoint_restores_the_whole_carry_bit_for_bit(trained, tmp_path):
    run, _ = trained
    tr = run.trainer
    carry = tr.init_carry(3)
    carry, _ = tr.prefill(carry)
    for _ in range(2):
        carry, _, _ = tr.train_call(carry)
    # save, reload, continue: identical to going straight on
    run.ckpt_dir = tmp_path / "checkpoints"
    path = run.save_checkpoint(carry, 999, {"wall_s": 1.0, "n_eval": 1})
    loaded, sched = run.load_checkpoint(path)
    assert sched == {"step": 999, "wall_s": 1.0, "n_eval": 1}
    straight, _, _ = tr.train_call(carry)
    resumed, _, _ = tr.train_call(loaded)
    a, b = jax.tree.leaves(straight), jax.tree.leaves(resumed)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_evaluate_runs_policy_and_baseline_on_same_episodes(trained):
    from peghole_mjx.training.evaluate import evaluate

    run, _ = trained
    res = evaluate(run.out / "final_policy", episodes=8, seed=1, progress=False, env=run.env)
    assert set(res) >= {"policy", "baseline", "force_reduction_pct", "episodes"}
    assert res["batch"] == 8  # one slice of all the episodes when no batch is given
    keys = {"success_rate", "mean_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N"}
    assert keys <= set(res["policy"]) and keys <= set(res["baseline"])
    p, b = res["policy"]["mean_fz_N"], res["baseline"]["mean_fz_N"]
    assert res["force_reduction_pct"] == pytest.approx(100 * (b - p) / b)
    # same episodes: the baseline is the scripted rollout with the same seed, deterministic
    again = evaluate(run.out / "final_policy", episodes=8, seed=1, progress=False, env=run.env)
    for who in ("policy", "baseline"):
        np.testing.assert_equal(again[who], res[who])  # NaN-aware (mean_time_s without success)
    # and a different seed meets different episodes
    other = evaluate(run.out / "final_policy", episodes=8, seed=2, progress=False, env=run.env)
    assert other["baseline"]["mean_fz_N"] != res["baseline"]["mean_fz_N"]


def test_batched_rollout_meets_the_same_episodes_and_resumes_from_saved_parts(trained, tmp_path):
    """rollout(batch=...) runs slices of the same start states; parts_dir keeps finished ones."""
    from peghole_mjx.envs.rollout import rollout, scripted_policy

    run, _ = trained
    env, policy = run.env, scripted_policy(run.env)
    whole = rollout(env, policy, 8, seed=1, progress=False).per_episode
    parts = tmp_path / "parts"
    halves = rollout(env, policy, 8, seed=1, progress=False, batch=4, parts_dir=parts).per_episode
    np.testing.assert_array_equal(halves["success"], whole["success"])
    # float differences between batch shapes grow in contact (about 2 % here): same episodes,
    # not bit-identical ones; a slicing error would meet other episodes (factors apart)
    np.testing.assert_allclose(halves["mean_fz_N"], whole["mean_fz_N"], rtol=0.05, atol=1e-3)
    np.testing.assert_allclose(halves["extraction_time_s"], whole["extraction_time_s"], atol=0.1)
    # prefix-stable episodes: a 4-episode run is the first slice of the 8-episode one
    four = rollout(env, policy, 4, seed=1, progress=False).per_episode
    np.testing.assert_array_equal(four["mean_fz_N"], halves["mean_fz_N"][:4])
    saved = sorted(parts.glob("episodes_*.npz"))
    assert [p.name for p in saved] == [
        "episodes_0000000_0000004.npz",
        "episodes_0000004_0000004.npz",
    ]
    # a rerun loads the saved slices instead of recomputing them: mark one and see it come back
    with np.load(saved[1]) as z:
        marked = {k: z[k] for k in z.files}
    marked["mean_fz_N"] = marked["mean_fz_N"] + 100.0
    np.savez(saved[1], **marked)
    saved[0].unlink()  # an interrupted run: only this slice is computed again
    again = rollout(env, policy, 8, seed=1, progress=False, batch=4, parts_dir=parts).per_episode
    np.testing.assert_array_equal(again["mean_fz_N"][:4], halves["mean_fz_N"][:4])
    np.testing.assert_allclose(again["mean_fz_N"][4:], halves["mean_fz_N"][4:] + 100.0)
    # 6 episodes in slices of 4: the short last slice is padded to the compiled shape
    six = rollout(env, policy, 6, seed=1, progress=False, batch=4).per_episode
    assert all(len(v) == 6 for v in six.values())


def test_evaluate_parts_folder_refuses_another_evaluation_and_shares_the_baseline(
    trained, tmp_path
):
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training.evaluate import evaluate, params_sha256

    run, _ = trained
    ev = tmp_path / "ev"
    kw = dict(episodes=8, progress=False, env=run.env, batch=8, parts_dir=ev)
    final = load_policy(run.out / "final_policy")
    res = evaluate(final, seed=1, **kw)
    (pol_dir,) = ev.glob(f"policy-{params_sha256(final.params)[:12]}-*")
    assert len(list(pol_dir.glob("*.npz"))) == 1
    assert len(list((ev / "baseline").glob("*.npz"))) == 1
    again = evaluate(final, seed=1, **kw)  # loaded from the parts
    for who in ("policy", "baseline"):
        np.testing.assert_equal(again[who], res[who])  # NaN-aware
    with pytest.raises(UserInputError, match="differs in seed"):
        evaluate(final, seed=2, **kw)
    # another policy in the same folder, in an env that differs only in a feed-forward bound
    # the baseline never uses: its own slices, the baseline's loaded (marked here)
    (base_npz,) = (ev / "baseline").glob("*.npz")
    with np.load(base_npz) as z:
        marked = {k: z[k] for k in z.files}
    marked["mean_fz_N"] = marked["mean_fz_N"] + 100.0
    np.savez(base_npz, **marked)
    ckpt = sorted((run.out / "checkpoints").glob("step_*"))[0]
    capped = run.env.__class__(run.env.config, {"action.max_ff_xy_N": 2.0})
    with pytest.raises(UserInputError, match="action.max_ff_xy_N"):  # not its training env
        evaluate(ckpt, seed=1, **{**kw, "env": capped})
    other = evaluate(ckpt, seed=1, cross=True, **{**kw, "env": capped})
    assert other["differs_from_training"]["action.max_ff_xy_N"][1] == 2.0
    assert len(list(ev.glob("policy-*"))) == 2
    assert other["baseline"]["mean_fz_N"] == pytest.approx(res["baseline"]["mean_fz_N"] + 100.0)
    # a baseline-relevant env change (the pulling-speed bound) is refused for the baseline
    slower = run.env.__class__(
        run.env.config, {"action.max_speed_m_s": 0.5 * run.env.config.action.max_speed_m_s}
    )
    with pytest.raises(UserInputError, match=r"baseline holds .* \(differs in env_config\)"):
        evaluate(final, seed=1, cross=True, **{**kw, "env": slower})


def test_publish_screening_picks_the_best_screened_checkpoint(trained, monkeypatch):
    """train/publish_policy.py --screen: re-ranks checkpoints on fresh episodes."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "train"))
    from publish_policy import SCREEN_SEED, screen_checkpoints

    run, _ = trained
    path, sel = screen_checkpoints(run.out, 4, candidates=[3600, 4000])
    assert set(sel["screen"]) == {"3600", "4000"}
    best = max(sel["screen"].items(), key=lambda kv: (kv[1]["success_rate"], -kv[1]["mean_fz_N"]))
    assert str(sel["step"]) == best[0]
    assert (path / "policy.json").exists()
    assert path.name in ("final_policy", f"step_{sel['step']:010d}")
    assert str(SCREEN_SEED) in sel["rule"]
    with pytest.raises(SystemExit, match="none of the checkpoints"):
        screen_checkpoints(run.out, 4, candidates=[123])
    # a rerun (e.g. after an interrupted evaluation) takes the kept screens, keyed by parameters
    cache = run.out / f"screen_seed{SCREEN_SEED}_4.json"
    assert set(json.loads(cache.read_text())) == {"3600", "4000"}
    with monkeypatch.context() as m:
        m.setattr("peghole_mjx.envs.rollout.rollout", _no_rollout)
        assert screen_checkpoints(run.out, 4, candidates=[3600, 4000]) == (path, sel)
    cache.unlink()


def _no_rollout(*args, **kwargs):
    raise AssertionError("screened again")


def test_publish_has_no_deployment_option(tmp_path, monkeypatch):
    """A published policy runs as trained: publish_policy.py takes no env changes."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "train"))
    import publish_policy

    from peghole_mjx import policies

    monkeypatch.setitem(policies.PRETRAINED, "rect", tmp_path / "published")
    argv = ["publish_policy.py", str(tmp_path), "rect", "--deploy-set", "action.max_ff_xy_N=0.5"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as exit_:
        publish_policy.main()
    assert exit_.value.code == 2
    assert not (tmp_path / "published").exists()


def test_publish_refuses_a_checkpoint_not_in_its_training_env_and_keeps_the_published_policy(
    tmp_path, monkeypatch
):
    """A checkpoint whose env_overrides contradict its training config (or that carries a
    deployment record) fails before the published policy folder is replaced."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "train"))
    import publish_policy

    from peghole_mjx import policies

    src = tmp_path / "ckpt"
    shutil.copytree(policies.PRETRAINED["rect"], src)
    meta = json.loads((src / "policy.json").read_text())
    meta["env_overrides"]["action.max_speed_m_s"] = 0.05  # trained with 0.025
    (src / "policy.json").write_text(json.dumps(meta))
    dest = tmp_path / "published"
    dest.mkdir()
    (dest / "policy.json").write_text("{}")
    monkeypatch.setitem(policies.PRETRAINED, "rect", dest)
    monkeypatch.setattr(publish_policy, "choose_checkpoint", lambda run, which: (src, {}))
    monkeypatch.setattr(sys, "argv", ["publish_policy.py", str(tmp_path), "rect"])
    with pytest.raises(UserInputError, match=r"action.max_speed_m_s \(0.05, trained 0.025\)"):
        publish_policy.main()
    assert (dest / "policy.json").read_text() == "{}"


def _peghole(*args):
    return [sys.executable, "-m", "peghole_mjx.cli.main", *args]


def test_kill_9_then_resume_continues_from_last_checkpoint(trained, tmp_path):
    out = tmp_path / "run"
    sets = [f"--set={k}={v}" for k, v in {**TINY, "num_timesteps": 1200}.items()]
    cmd = _peghole("train", "--env", "RectExtract", "--quick", "--out", str(out), *sets)
    proc = subprocess.Popen([*cmd, "--no-progress", "--no-video"], stderr=subprocess.PIPE)
    deadline = time.time() + 600
    ckpt = None
    while time.time() < deadline and proc.poll() is None:
        # a finished checkpoint: step_N/ (step_N.tmp/ is one being written, not yet sealed)
        done = sorted(
            p
            for p in out.glob("checkpoints/step_*/state.json")
            if not p.parent.name.endswith(".tmp")
        )
        if done:
            ckpt = done[-1].parent
            break
        time.sleep(0.2)
    assert ckpt is not None, proc.stderr.read().decode() if proc.poll() is not None else "timeout"
    # a resume while the run is still training is refused (frozen meanwhile, not finished)
    os.kill(proc.pid, signal.SIGSTOP)
    busy = subprocess.run(
        _peghole("train", "--resume", str(out), "--no-progress", "--no-video"),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert busy.returncode == 2 and f"pid {proc.pid}" in busy.stderr, busy.stderr
    assert "Traceback" not in busy.stderr
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "final_policy").exists()
    killed_at = int(json.loads((ckpt / "state.json").read_text())["step"])
    assert killed_at < 1200
    rows_before = (out / "metrics.csv").read_text().splitlines()

    res = subprocess.run(
        _peghole("train", "--resume", str(out), "--no-progress", "--no-video"),
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert res.returncode == 0, res.stderr
    assert f"at {killed_at} env steps" in res.stderr
    assert "stale lock" in res.stderr  # the killed run's lock, taken over
    assert not (out / "run.lock").exists()
    rows = (out / "metrics.csv").read_text().splitlines()
    steps = [int(r.split(",")[0]) for r in rows[1:]]
    assert steps == sorted(set(steps)) and steps[-1] == 1200
    # completed progress is kept: every row up to the checkpoint is unchanged
    kept = [r for r in rows_before[1:] if int(r.split(",")[0]) <= killed_at]
    assert rows[1 : 1 + len(kept)] == kept
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env_steps"] == 1200
    assert (out / "final_policy" / "params.npz").exists()
    # --engine auto on a machine without a GPU: the MuJoCo C engine, recorded in the run and
    # in the policy as provenance (engine), not in the policy's task (env_overrides)
    run = json.loads((out / "run.json").read_text())
    policy = json.loads((out / "final_policy" / "policy.json").read_text())
    assert not {"engine", "impl", "mujoco_threads"} & set(policy["env_overrides"])
    assert run["engine"] == policy["engine"]
    if jax.default_backend() == "cpu":
        assert run["config"]["env_overrides"]["engine"] == policy["engine"] == "mujoco"


def test_corrupt_newest_checkpoint_falls_back_and_the_run_finishes(trained, tmp_path, capsys):
    """The two newest checkpoints keep their state: a damaged newest one is set aside, the run
    resumes from the one before and ends with one metrics row per evaluation."""
    from peghole_mjx.training import checkpoints
    from peghole_mjx.training.run import TrainingRun

    run, _ = trained
    out = tmp_path / "run"
    shutil.copytree(run.out, out, ignore=shutil.ignore_patterns("tb", "final_policy", "*.png"))
    *_, before, newest = checkpoints.checkpoint_dirs(out / "checkpoints")
    assert checkpoints.has_state(before) and newest.name == "step_0000004000"
    state = max((p for p in (newest / "state").rglob("*") if p.is_file()), key=os.path.getsize)
    data = bytearray(state.read_bytes())
    data[len(data) // 2] ^= 0xFF
    state.write_bytes(bytes(data))
    capsys.readouterr()
    summary = TrainingRun.resume(out, progress=False, render=False).run(resume=True)
    err = capsys.readouterr().err
    assert "step_0000004000 is corrupt" in err and "at 3600 env steps" in err
    steps = [int(r.split(",")[0]) for r in (out / "metrics.csv").read_text().splitlines()[1:]]
    assert steps == list(range(0, LEARN_STEPS + 1, 400))  # none missing, none twice
    assert summary["env_steps"] == LEARN_STEPS
    assert (out / "checkpoints" / "step_0000004000.corrupt").is_dir()
    checkpoints.verify(newest, checkpoints.STATE_FILES)  # written again, intact


def test_bad_training_config_is_rejected_with_the_reason():
    with pytest.raises(UserInputError, match="unknown training config keys"):
        load_train_config("RectExtract", "quick", {"learning_rat": 1e-3})
    with pytest.raises(UserInputError, match="alpha"):
        load_train_config("RectExtract", "quick", {"alpha": -1})
    with pytest.raises(UserInputError, match="min_replay_size"):
        load_train_config("RectExtract", "quick", {"min_replay_size": 10**9})
    with pytest.raises(UserInputError, match="profile"):
        load_train_config("RectExtract", "huge")
    with pytest.raises(UserInputError, match="no training config"):
        load_train_config("SquareExtract")


def test_every_registered_env_has_a_training_config_for_every_profile():
    from peghole_mjx.envs import ALL_ENVS

    for env in ALL_ENVS:
        for profile in PROFILES:
            cfg = load_train_config(env, profile)
            assert cfg.env == env and cfg.profile == profile


#: RectExtractHard's training settings beyond RectExtract's (docs/research/index.md, "Four recipes")
RECT_HARD_ADDED = {
    "action.max_ff_xy_N": 2.0,
    "obs.commands": True,
    "reward_config.w_stf_rot": 0.5,
}
#: DualExtract's training settings that DualExtractHard's profiles leave out: obs.commands
#: joined DualExtract's on 2026-11-30, after the dual_hard policy was trained
DUAL_HARD_DROPPED = ("obs.commands",)
#: DualExtract's settings that DualExtractHard's profiles keep at an earlier value: the lateral
#: feed-forward bound went from 2 N to 0.5 N in DualExtract's on 2026-11-30, after dual_hard
DUAL_HARD_KEPT = {"action.max_ff_xy_N": 2.0}


def test_hard_variant_configs_are_the_base_configs_but_for_their_stated_changes():
    """train/configs/*Hard.json copy RectExtract's / DualExtract's hyperparameters; the only
    differences are the env overrides their descriptions state (decided before training):
    ``added`` (key: value), ``dropped`` (keys of the base profile left out) and ``kept``
    (key: the value the base profile had when the hard policy was trained)."""
    stated = {
        ("RectExtractHard", "cpu"): {"added": RECT_HARD_ADDED},
        ("RectExtractHard", "full"): {"added": RECT_HARD_ADDED},
        # and the env's own 8 s episodes instead of DualExtract's 4 s
        ("DualExtractHard", "cpu"): {
            "dropped": (*DUAL_HARD_DROPPED, "episode_length"),
            "kept": DUAL_HARD_KEPT,
        },
        ("DualExtractHard", "full"): {"dropped": DUAL_HARD_DROPPED, "kept": DUAL_HARD_KEPT},
    }
    for hard, base in (("RectExtractHard", "RectExtract"), ("DualExtractHard", "DualExtract")):
        for profile in PROFILES:
            h = load_train_config(hard, profile).as_dict()
            b = load_train_config(base, profile).as_dict()
            diff = {k for k in h if h[k] != b[k]} - {"env"}
            want = stated.get((hard, profile), {})
            assert diff == ({"env_overrides"} if want else set()), (hard, profile, diff)
            for key in want.get("dropped", ()):
                assert key in b["env_overrides"] and key not in h["env_overrides"]
                b["env_overrides"].pop(key)
            for key, value in want.get("added", {}).items():
                assert key not in b["env_overrides"] and h["env_overrides"].pop(key) == value
            for key, value in want.get("kept", {}).items():
                assert b["env_overrides"].pop(key) != value == h["env_overrides"].pop(key)
            assert h["env_overrides"] == b["env_overrides"]


def test_train_cli_refuses_to_overwrite_a_run(tmp_path):
    (tmp_path / "run.json").write_text("{}")
    res = subprocess.run(
        _peghole("train", "--env", "RectExtract", "--quick", "--out", str(tmp_path)),
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2
    assert "already holds a training run" in res.stderr


def test_training_budget_stops_the_run_after_a_last_evaluation(tmp_path):
    """``budget_train_s``: the run ends at the first train call past the budget, evaluated."""
    import csv

    from peghole_mjx.training.run import TrainingRun

    cfg = tiny_config(num_timesteps=LEARN_STEPS)
    run = TrainingRun(cfg, tmp_path / "run", progress=False, render=False, budget_train_s=0.0)
    summary = run.run()
    per_call = cfg.num_envs * cfg.steps_per_call
    assert summary["env_steps"] == cfg.min_replay_size + per_call < cfg.num_timesteps
    with (tmp_path / "run" / "metrics.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows] == [0, summary["env_steps"]]  # the last evaluation


def test_baseline_slices_are_keyed_without_what_the_baseline_never_uses():
    """The scripted baseline's constant action ignores the observation and its feed-forward
    and offset settings: envs differing only there share its slices; a pull-speed bound
    (which changes no scripted action either, but is not listed) and the reward do not."""
    from types import SimpleNamespace

    from peghole_mjx.envs import get_default_config
    from peghole_mjx.envs.config import apply_overrides
    from peghole_mjx.training.evaluate import BASELINE_IGNORED_CONFIG, _config_key

    def key(over):
        cfg = apply_overrides(get_default_config("RectExtractHard"), over)
        return _config_key(SimpleNamespace(config=cfg), BASELINE_IGNORED_CONFIG)

    base = key({})
    assert key({"obs.commands": True, "obs.torques": True}) == base
    assert key({"action.max_ff_xy_N": 2.0}) == base
    assert key({"reward_config.w_stf_rot": 0.5}) != base
    assert key({"randomization.angular_error_deg": 1.0}) != base
