"""The learning benchmark's statistics (benchmarks/evals/learning.py) against hand-computed
values (its runs are :class:`TrainingRun` and :func:`evaluate`, tested in their own files),
and its two SB3 stacks (benchmarks/evals/learning_stacks.py) at a tiny size: their files and
fields, resuming from a checkpoint, a finished run not trained again, their refusals."""

from __future__ import annotations

import csv
import json

import gymnasium
import numpy as np
import pytest
import torch
from stable_baselines3 import SAC

from benchmarks.evals import learning as lb
from benchmarks.evals import learning_stacks as stacks
from peghole_mjx.training.config import load_train_config, reward_discount


def test_iqm_is_the_mean_of_the_middle_half():
    assert lb.iqm([0.0, 1.0, 2.0, 3.0]) == pytest.approx(1.5)  # middle two
    assert lb.iqm([0.0, 0.9, 0.95, 1.0, 10.0]) == pytest.approx(np.mean([0.9, 0.95, 1.0]))
    assert lb.iqm([0.5] * 5) == 0.5


def test_bootstrap_interval_holds_the_iqm_and_is_deterministic():
    x = [0.2, 0.9, 0.95, 0.97, 1.0]
    lo, hi = lb.bootstrap_ci(x)
    assert lo <= lb.iqm(x) <= hi and 0.2 <= lo and hi <= 1.0
    assert lb.bootstrap_ci(x) == [lo, hi]  # same seed, same interval
    assert lb.bootstrap_ci([1.0] * 5) == [1.0, 1.0]


def test_t_interval_matches_the_textbook_value():
    lo, hi = lb.t_ci([1.0, 2.0, 3.0])  # mean 2, s 1, t(0.975, 2) = 4.3027
    assert (lo, hi) == pytest.approx((2 - 4.3027 / 3**0.5, 2 + 4.3027 / 3**0.5), abs=1e-3)
    assert lb.t_ci([1.0]) is None


def test_first_evaluation_at_the_target():
    rows = [
        {"step": "0", "eval/success_rate": "0.0"},
        {"step": "1600", "eval/success_rate": "nan"},
        {"step": "3200", "eval/success_rate": "0.953125"},
        {"step": "4800", "eval/success_rate": "1.0"},
    ]
    assert lb.first_at(rows)["step"] == "3200"
    assert lb.first_at(rows[:2]) is None


def _seed(seed, final, best, steps, fz=(5.0, 8.0)):
    return {
        "seed": seed,
        "final_success": final,
        "best_eval": best,
        "steps_to_95": steps,
        "clock_to_95_s": None if steps is None else steps / 100,
        "policy_mean_fz_N": fz[0],
        "baseline_mean_fz_N": fz[1],
        "policy_peak_fz_N": 2 * fz[0],
        "baseline_peak_fz_N": 2 * fz[1],
    }


def test_task_summary_counts_collapse_success_share_and_times():
    per_seed = [
        _seed(100, 1.0, 1.0, 3200),
        _seed(101, 0.96, 1.0, 4800),  # within 5 points of its best: not collapsed
        _seed(102, 0.40, 1.0, 1600),  # fell from 1.0: collapsed
        _seed(103, 0.98, 0.98, None, fz=(9.0, 8.0)),
        _seed(104, 0.99, 0.99, 6400),
    ]
    t = lb.task_summary("RectExtract", per_seed)
    assert t["seeds_collapsed"] == [102]
    assert t["share_at_95"] == pytest.approx(0.8)
    assert t["reached_95"] == 4
    assert t["steps_to_95"]["median"] == pytest.approx(np.median([3200, 4800, 1600, 6400]))
    assert t["final_success_iqm"] == pytest.approx(np.mean([0.96, 0.98, 0.99]))
    assert t["mean_fz_minus_baseline_N"] == pytest.approx((4 * -3.0 + 1.0) / 5)
    lo, hi = t["mean_fz_minus_baseline_ci95"]
    assert lo < t["mean_fz_minus_baseline_N"] < hi


def test_task_summary_reports_the_untrained_evaluation_beside_the_final_force():
    per_seed = [
        _seed(200, 1.0, 1.0, 0),
        _seed(201, 1.0, 1.0, 0, fz=(3.0, 8.0)),
        _seed(202, 1, 1, 0),
    ]
    per_seed[0] |= {"untrained_success": 1.0, "untrained_mean_fz_N": 4.0}
    per_seed[1] |= {"untrained_success": 0.5, "untrained_mean_fz_N": 5.0}
    per_seed[2] |= {"untrained_success": None, "untrained_mean_fz_N": None}  # none recorded
    t = lb.task_summary("RectExtract", per_seed)
    assert t["untrained_success_mean"] == pytest.approx(0.75)
    assert t["untrained_mean_fz_N"] == pytest.approx(4.5)
    assert t["final_mean_fz_N"] == pytest.approx((5.0 + 3.0 + 5.0) / 3)
    assert t["at_95_untrained"] == 1  # seed 200 was at 95 % before any learning


def test_zero_action_summary_is_each_final_policy_minus_the_zero_action():
    """On a residual env: the zero action's result on the final episodes and each final policy
    minus it with t intervals over seeds; None (no residual) reports nothing."""
    per_seed = [_seed(200, 1.0, 1.0, 0, fz=(3.0, 8.0)), _seed(201, 0.5, 1.0, 0, fz=(5.0, 8.0))]
    zero = {"success_rate": 0.75, "mean_fz_N": 4.0, "peak_fz_N": 9.0, "mean_time_s": 8.0}
    z = lb.zero_action_summary(zero, per_seed)
    assert z["zero_action"] == zero
    assert z["final_minus_zero_action_success"] == pytest.approx(0.0)  # +0.25 and -0.25
    assert z["final_minus_zero_action_mean_fz_N"] == pytest.approx(0.0)  # -1 and +1
    lo, hi = z["final_minus_zero_action_mean_fz_ci95"]
    assert lo < -1.0 and hi > 1.0  # two seeds: a wide t interval (t 12.7)
    assert lb.zero_action_summary(None, per_seed) == {"zero_action": None}


def test_seed_record_reads_the_untrained_evaluation_at_step_0(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"config": {"seed": 7}, "commit": "abc"}))
    (run / "metrics.csv").write_text(
        "step,eval/success_rate,eval/mean_fz_N,train_wall_s\n0,1.0,4.25,0.0\n1600,0.5,3.0,9.0\n"
    )
    side = {"success_rate": 1.0, "mean_fz_N": 3.5, "peak_fz_N": 9.0}
    rec = lb.seed_record(run, {"policy": side, "baseline": side, "episodes": 256})
    assert (rec["untrained_success"], rec["untrained_mean_fz_N"]) == (1.0, 4.25)
    assert rec["curve"] == [(0, 1.0), (1600, 0.5)]


def test_task_summary_without_a_baseline_has_no_force_difference():
    per_seed = [_seed(100, 1.0, 1.0, 3200), _seed(101, 0.9, 1.0, None)]
    for s in per_seed:
        s["baseline_mean_fz_N"] = s["baseline_peak_fz_N"] = None
    t = lb.task_summary("RectExtract", per_seed)
    assert t["mean_fz_minus_baseline_N"] is None and t["mean_fz_minus_baseline_ci95"] is None
    assert t["peak_fz_minus_baseline_N"] is None and t["final_success_iqm"] == 0.95


# ---------------------------------------------------------------------- the SB3 stacks
#: the tiny size of the stacks' runs: 300 env steps of 20-step episodes, 2-episode evaluations
#: every 100 env steps, 3 final episodes (not the protocol's sizes: the code paths only)
TINY = [
    "--tasks",
    "RectExtract",
    "--num-timesteps",
    "300",
    "--eval-every",
    "100",
    "--eval-episodes",
    "2",
    "--final-episodes",
    "3",
    "--set",
    "env.episode_length=20",
]
PROVENANCE = ("device", "versions", "date", "command", "config", "commit")


def _no_provenance(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k not in ("date", "command", "commit")}


def _check_stack_files(out, stack: str, seeds: list[int]) -> dict:
    """The stack's files beside (never in place of) ours, with the benchmark's fields."""
    doc = json.loads((out / f"learning_{stack}.json").read_text())
    assert not (out / "learning.json").exists() and not (out / "runs").exists()
    assert all(doc[k] for k in PROVENANCE) and doc["stack"] == stack
    assert {"sb3", "torch", "gymnasium"} <= set(doc["versions"])
    (t,) = doc["tasks"]
    assert t["task"] == "RectExtract" and t["seeds"] == seeds
    for key in ("final_success_iqm", "share_at_95", "reached_95", "updates_per_env_step"):
        assert isinstance(t[key], int | float)
    lo, hi = t["final_success_ci95"]
    assert 0.0 <= lo <= t["final_success_iqm"] <= hi <= 1.0
    assert isinstance(t["mean_fz_minus_baseline_N"], float)  # a baseline on the same episodes
    assert isinstance(t["seeds_collapsed"], list)
    for rec in t["per_seed"]:
        assert [s for s, _ in rec["curve"]] == [0, 100, 200, 300]
        assert rec["final_episodes"] == 3 and rec["baseline_mean_fz_N"] > 0
        assert rec["config"]["stack"] == stack and rec["config"]["num_eval_envs"] == 2
        run = out / f"runs_{stack}" / "RectExtract" / f"seed_{rec['seed']}"
        state = json.loads((run / "state.json").read_text())
        assert state["finished"] and state["env_steps"] == 300
        assert 0 < state["train_clock_s"] and (run / "final_model.zip").exists()
        assert not list((run / "checkpoints").iterdir())  # replay buffers gone once finished
        assert all(json.loads((run / "run.json").read_text())[k] for k in PROVENANCE[:4])
    with open(out / f"learning_{stack}.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(lb.CSV_FIELDS) and rows[0]["stack"] == stack
    assert (out / f"curves_{stack}_RectExtract.png").stat().st_size > 0
    return doc


def test_seed_stack_runs_resumes_from_its_checkpoint_and_reruns_nothing(tmp_path, monkeypatch):
    out = tmp_path / "bench"
    argv = ["--out", str(out), "--stack", "seed", "--seeds", "0", "1", *TINY]
    calls = {"evals": 0, "loaded": []}
    evaluate_into = stacks.evaluate_into

    def interrupted(*a, **k):  # stop in seed 0's evaluation at step 200
        calls["evals"] += 1
        if calls["evals"] == 3:
            raise KeyboardInterrupt
        return evaluate_into(*a, **k)

    monkeypatch.setattr(stacks, "evaluate_into", interrupted)
    with pytest.raises(KeyboardInterrupt):
        lb.main(argv)
    run0 = out / "runs_seed" / "RectExtract" / "seed_0"
    state = json.loads((run0 / "state.json").read_text())
    assert state["env_steps"] == 100 and not state["finished"]
    monkeypatch.setattr(stacks, "evaluate_into", evaluate_into)
    load_buffer = stacks.load_buffer

    def spy(buf, path):
        load_buffer(buf, path)
        calls["loaded"].append(buf.pos)

    monkeypatch.setattr(stacks, "load_buffer", spy)
    assert lb.main(argv) == 0
    assert calls["loaded"] == [100]  # resumed at step 100 with its 100 transitions
    doc = _check_stack_files(out, "seed", [0, 1])
    (t,) = doc["tasks"]
    assert t["engine"] == "pybullet" and t["reward_kind"] == "thesis"
    assert t["updates_per_env_step"] == pytest.approx(1 / 50)  # train_freq 50, 1 step each
    assert t["config"]["sac"]["ent_coef"] == 0.2 and t["config"]["sac"]["gamma"] == 0.99

    def no_training(*a, **k):
        raise AssertionError("a finished run was trained again")

    monkeypatch.setattr(stacks, "train", no_training)
    assert lb.main(argv) == 0
    again = json.loads((out / "learning_seed.json").read_text())
    assert _no_provenance(again) == _no_provenance(doc)


def test_sb3_stack_on_our_adapter_runs_and_reruns_nothing(tmp_path, monkeypatch, capsys):
    out = tmp_path / "bench"
    argv = ["--out", str(out), "--stack", "sb3", "--seeds", "3", *TINY]
    assert lb.main(argv) == 0
    doc = _check_stack_files(out, "sb3", [3])
    (t,) = doc["tasks"]
    over = t["config"]["env_overrides"]
    assert t["engine"] == "mujoco" and t["reward_kind"] == "outcome"
    assert t["updates_per_env_step"] == 1.0
    assert t["config"]["sac"]["gamma"] == reward_discount("RectExtract", over)
    profile = load_train_config("RectExtract", "cpu").env_overrides
    # the protocol's reward (outcome) over the profile's default (eq 4.4)
    expected = {**profile, "engine": "mujoco", "episode_length": 20}
    assert over == {**expected, "reward_config.kind": "outcome"}

    def no_training(*a, **k):
        raise AssertionError("a finished run was trained again")

    monkeypatch.setattr(stacks, "train", no_training)
    assert lb.main(argv) == 0
    again = json.loads((out / "learning_sb3.json").read_text())
    assert _no_provenance(again) == _no_provenance(doc)
    # another evaluation schedule into the same folder is refused, in one line
    capsys.readouterr()
    assert lb.main([*argv, "--eval-episodes", "4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress bar
    assert err.startswith("learning: error:") and "holds a run of another config" in err


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--stack", "seed", "--tasks", "RectExtract", "DualExtract"], "RectExtractHard only"),
        (["--stack", "sb3", "--set", "learning_rate=0.001"], "env config changes only"),
        (["--stack", "seed", "--engine", "mjx"], "no engine choice"),
        (["--stack", "seed", "--set", "env.obs.commands=True"], "cannot honour"),
    ],
)
def test_stacks_refuse_what_they_cannot_run_in_one_line(tmp_path, capsys, args, says):
    out = tmp_path / "bench"
    assert lb.main(["--out", str(out), *args, "--num-timesteps", "100"]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and "\n" not in err and err.startswith("learning: error:")
    assert not list(out.glob("runs*/*/*/state.json"))  # nothing trained


def test_sb3_actor_as_a_jax_function_and_the_compact_replay_buffer(tmp_path):
    torch.set_num_threads(1)
    env = gymnasium.make("MountainCarContinuous-v0")  # actions in [-1, 1], as our envs
    model = SAC("MlpPolicy", env, learning_starts=50, seed=0, device="cpu")
    model.learn(120)
    obs = np.random.default_rng(0).normal(size=(16, 2)).astype(np.float32)
    want = model.predict(obs, deterministic=True)[0]
    params = stacks.actor_params(model)
    got = np.stack([np.asarray(stacks.actor_action(params, o, None)) for o in obs])
    assert np.allclose(got, want, atol=1e-5)
    stacks.save_buffer(model.replay_buffer, tmp_path / "buffer.npz")
    other = SAC("MlpPolicy", env, seed=1, device="cpu")
    stacks.load_buffer(other.replay_buffer, tmp_path / "buffer.npz")
    a, b = model.replay_buffer, other.replay_buffer
    assert (b.pos, b.full) == (a.pos, a.full) == (120, False)
    for k in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_finished_only_trains_nothing_and_names_the_pending_runs(tmp_path, capsys):
    """``--finished-only`` reports the finished runs (none here) to ``learning_partial.*``,
    naming every pending (task, seed), and starts no run; other stacks are refused."""
    out = tmp_path / "bench"
    argv = ["--out", str(out), "--tasks", "RectExtract", "--seeds", "100", "101"]
    assert lb.main([*argv, "--finished-only"]) == 0
    doc = json.loads((out / "learning_partial.json").read_text())
    assert doc["partial"] is True and doc["tasks"] == []
    assert doc["pending"] == [{"task": "RectExtract", "seed": s} for s in (100, 101)]
    assert all(doc[k] for k in PROVENANCE)
    assert not (out / "runs").exists() and not (out / "learning.json").exists()
    capsys.readouterr()
    assert lb.main([*argv, "--finished-only", "--stack", "sb3"]) == 2
    assert "--finished-only reports our stack's runs only" in capsys.readouterr().err
