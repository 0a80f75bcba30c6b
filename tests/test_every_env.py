"""Every command over every registered env (``peghole_mjx.envs.ALL_ENVS``), at the smallest size.

One test per env runs, in this process (``peghole_mjx.cli.main.main``), so that compiled graphs
are shared through the persistent compilation cache (tests/conftest.py):

1. ``peghole envs rollout --env E --policy scripted`` in the env a tiny ``--quick`` training
   run will use (its ``env_overrides`` given as ``--set``), so that step 3's baseline is the
   same compiled graph;
2. ``peghole train --env E --quick`` at the smallest size the config allows (:data:`TINY`);
3. ``peghole evaluate RUN`` (the policy just trained, against the scripted baseline);
4. the generalisation benchmark (``python -m benchmarks.evals.generalisation``) of that policy
   on its own preset (one cell: the same graphs as step 3);
5. ``peghole evaluate NAME --policy-only`` of the env's pretrained policy, on the CPU-default
   engine (``--engine auto --cross``: the published policies were trained on MJX, whose graph
   takes minutes to compile on a 2-core CPU).

Every command runs on the CPU-default engine (``auto``: MuJoCo C without a GPU). Each must exit
0 and report what it ran; the env's name, preset and episode counts are checked in the output.
"""

from __future__ import annotations

import json

import pytest

from benchmarks.evals import generalisation
from peghole_mjx.cli.main import main
from peghole_mjx.core.validation import loads
from peghole_mjx.envs import ALL_ENVS
from peghole_mjx.policies import PRETRAINED, load_policy
from peghole_mjx.sim.engines import engine_overrides
from peghole_mjx.training.config import load_train_config
from peghole_mjx.training.evaluate import requested_config

#: each env's commands compile their own graphs: dropped when its test ends (kept for the
#: module, the four envs' graphs held 2.8 GB in one worker, 2026-12-02)
pytestmark = pytest.mark.usefixtures("release_after")


#: the smallest training run: one call of 2 envs x 5 steps after a 10-transition prefill, one
#: evaluation of 2 episodes of 10 env steps, a 16 x 16 network
TINY = {
    "num_timesteps": 20,
    "num_envs": 2,
    "steps_per_call": 5,
    "eval_every": 20,
    "num_eval_envs": 2,
    "batch_size": 8,
    "grad_updates_per_step": 1,
    "min_replay_size": 10,
    "max_replay_size": 200,
    "hidden_layer_sizes": [16, 16],
    "env.episode_length": 10,
}
#: episodes of every rollout and evaluation: one batch shape for all of them, the training
#: run's evaluation episodes too (``num_eval_envs``), so that evaluating the trained policy
#: and the generalisation cell load the training's rollout graphs from the compilation cache
EPISODES = TINY["num_eval_envs"]
#: the pretrained policy of each env
PRETRAINED_OF = {load_policy(name).env_name: name for name in PRETRAINED}


def _sets(overrides: dict) -> list[str]:
    """``--set KEY=JSON`` for each entry (the CLIs parse VALUE as JSON)."""
    return [f"--set={k}={json.dumps(v)}" for k, v in overrides.items()]


def _json_out(capsys) -> dict:
    """The command's JSON (its last line of stdout); under ``--json`` nothing of its progress
    (labelled phases, bars) reaches stderr."""
    captured = capsys.readouterr()
    assert "compiling" not in captured.err and "rollout" not in captured.err, captured.err
    return loads(captured.out.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.parametrize("env", ALL_ENVS)
def test_every_command_runs_on_the_env(env, tmp_path, capsys):
    engine = {f"env.{k}": v for k, v in engine_overrides("auto").items()}
    cfg = load_train_config(env, "quick", {**engine, **TINY})

    # 1. scripted rollout in the training env
    argv = ["envs", "rollout", "--env", env, "--policy", "scripted"]
    argv += ["--episodes", str(EPISODES), "--json", *_sets(cfg.env_overrides)]
    assert main(argv) == 0
    rollout = _json_out(capsys)
    assert rollout["episodes"] == EPISODES
    assert rollout["engine"] == cfg.env_overrides["engine"]

    # 2. the tiniest quick training run
    run = tmp_path / "run"
    argv = ["train", "--env", env, "--quick", "--out", str(run), "--no-progress", "--no-video"]
    assert main([*argv, *_sets(TINY)]) == 0
    summary = json.loads((run / "summary.json").read_text())
    assert summary["env"] == env and summary["env_steps"] >= TINY["num_timesteps"]
    assert (run / "final_policy" / "policy.json").exists()
    capsys.readouterr()

    # 3. evaluate it against the scripted baseline
    assert main(["evaluate", str(run), "--episodes", str(EPISODES), "--json"]) == 0
    ev = _json_out(capsys)
    assert ev["env"] == env and ev["episodes"] == EPISODES
    assert ev["policy"]["episodes"] == ev["baseline"]["episodes"] == EPISODES
    assert ev["differs_from_training"] == {}

    # 4. the generalisation benchmark, one cell: the policy's own preset
    trained_preset = ev["preset"]
    out = tmp_path / "generalisation.json"
    argv = ["--policy", str(run), "--presets", trained_preset, "--no-custom", "--no-progress"]
    argv += ["--episodes", str(EPISODES), "--parts", str(tmp_path / "parts"), "--out", str(out)]
    assert generalisation.main(argv) == 0
    doc = json.loads(out.read_text())
    (cell,) = doc["cells"]
    assert doc["env"] == env and cell["cell"] == trained_preset and cell["trained_on"]
    assert cell["policy"]["episodes"] == cell["baseline"]["episodes"] == EPISODES
    capsys.readouterr()

    # 5. the env's pretrained policy, on the CPU-default engine
    name = PRETRAINED_OF[env]
    argv = ["evaluate", name, "--env", env, "--engine", "auto", "--cross", "--policy-only"]
    assert main([*argv, "--episodes", str(EPISODES), "--json"]) == 0
    pre = _json_out(capsys)
    assert pre["env"] == env and pre["policy"]["episodes"] == EPISODES
    assert pre["baseline"] is None and pre["engine"] == cfg.env_overrides["engine"]
    assert pre["preset"] == requested_config(load_policy(name)).preset
    assert set(pre["differs_from_training"]) <= {"engine", "impl", "mujoco_threads"}
