"""``make_train(env, cfg) -> train(key)`` and the multi-seed driver (``peghole train --seeds``).

One tiny config on the ``mujoco`` engine (the CPU default of ``peghole train``; the pure train
and the seeds driver are the same code on either engine); the vmapped two-seed run is compiled
once (module fixture) and reused."""

from __future__ import annotations

import json
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx.sim.engines import task_overrides
from peghole_mjx.training.config import load_train_config

TINY = {
    "num_envs": 4,
    "steps_per_call": 5,
    "eval_every": 20,
    "num_eval_envs": 4,
    "batch_size": 32,
    "grad_updates_per_step": 2,
    "min_replay_size": 20,
    "max_replay_size": 2000,
    "num_timesteps": 80,
    "env.episode_length": 25,
    "env.engine": "mujoco",
    # the reward whose time-outs are truncations (training's default pays eq (4.4))
    "env.reward_config.kind": "outcome",
}


def tiny_config():
    return load_train_config("RectExtract", "quick", TINY, compliance_strategy=True)


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree.leaves(tree)]


@pytest.fixture(scope="module")
def seeds_run(tmp_path_factory):
    from peghole_mjx.training.seeds import SeedsRun

    out = tmp_path_factory.mktemp("seeds") / "run"
    run = SeedsRun(tiny_config(), 2, out, progress=False)
    summary = run.run()
    return run, summary


def test_the_pure_train_counts_steps_like_a_training_run():
    from peghole_mjx.envs import load
    from peghole_mjx.training.functional import make_train

    cfg = tiny_config()
    train = make_train(load(cfg.env, config_overrides=cfg.env_overrides), cfg)  # not compiled
    per_call = cfg.num_envs * cfg.steps_per_call
    assert train.steps_per_call == per_call == 20
    assert train.prefill_calls == 1  # 20 rows >= min_replay_size
    assert train.learn_calls == 3  # 20 + 3 x 20 = num_timesteps


def test_train_of_key_is_pure_and_vmaps_over_seeds(seeds_run):
    """``jax.vmap(train)`` traces as one function of the keys (no compile here: the driver's
    pieces below run the same ``train.call``): a carry like the driver's and one history
    row per call and seed."""
    from peghole_mjx.training.functional import SEED_AXIS

    run, _ = seeds_run
    out = jax.eval_shape(jax.vmap(run.train, axis_name=SEED_AXIS), run.keys)
    t = run.train
    assert out.history["loss/critic"].shape == (2, t.prefill_calls + t.learn_calls)
    want = jax.eval_shape(run._init, run.keys)
    assert jax.tree.structure(out.carry) == jax.tree.structure(want)
    assert [x.shape for x in jax.tree.leaves(out.carry)] == [x.shape for x in jax.tree.leaves(want)]


def test_each_seed_of_a_call_is_its_own_run(seeds_run):
    """Seed 0 rerun beside another key for seed 1 ends bit-identical to the driver's seed 0
    (the seeds never mix); the two seeds differ; every learning call made its gradient
    updates and the prefill call none."""
    from peghole_mjx.policies import load_policy

    run, _ = seeds_run
    carry = run._init(run.keys.at[1].set(jax.random.PRNGKey(99)))
    losses = []
    for learn in np.asarray(run.train.learn_flags()):
        carry, hist = run._call(carry, jnp.asarray(learn))
        losses.append(np.asarray(hist["loss/critic"]))
    saved = [load_policy(run.out / f"seed_{k}" / "final_policy").params for k in range(2)]
    mine = jax.tree.map(lambda x: x[0], run.train.policy_params(carry))
    for a, b in zip(_leaves(mine), _leaves(saved[0]), strict=True):
        np.testing.assert_array_equal(a, b)
    gap = max(
        float(np.abs(a - b).max())
        for a, b in zip(_leaves(saved[0]), _leaves(saved[1]), strict=True)
    )
    assert gap > 1e-3
    cfg, t = run.cfg, run.train
    want = t.learn_calls * cfg.steps_per_call * cfg.grad_updates_per_step
    assert np.asarray(carry.ts.gradient_steps).tolist() == [want, want]
    assert (losses[0] == 0).all() and all((x != 0).all() for x in losses[1:])


def test_seeds_run_writes_per_seed_policies_history_and_intervals(seeds_run):
    from peghole_mjx.policies import load_policy

    run, summary = seeds_run
    assert summary["seeds"] == [0, 1]
    assert [r["seed"] for r in summary["final_eval"]] == [0, 1]
    assert all(r["episodes"] == TINY["num_eval_envs"] for r in summary["final_eval"])
    over = summary["final_eval_over_seeds"]["mean_return"]
    vals = [r["mean_return"] for r in summary["final_eval"]]
    assert over["mean"] == pytest.approx(np.mean(vals))
    lo, hi = over["ci95_t"]
    assert lo <= over["mean"] <= hi
    rows = run._rows()
    assert [(int(r["seed"]), int(r["step"])) for r in rows] == [
        (s, st) for st in (40, 60, 80) for s in (0, 1)
    ]
    for k in range(2):
        bundle = load_policy(run.out / f"seed_{k}" / "final_policy")
        assert bundle.meta["train_config"]["seed"] == k
        # the engine is provenance (policy.json "engine"), not the task
        assert bundle.env_overrides == task_overrides(run.cfg.env_overrides)
    assert (run.out / "curves.png").stat().st_size > 0
    assert json.loads((run.out / "seeds.json").read_text())["env_steps"] == 80


def test_seeds_run_resumes_bit_for_bit(seeds_run, tmp_path):
    """A copy of the run without its newest checkpoint (an interruption in the last chunk)
    resumes from the one before and ends with exactly the same policies and history."""
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training import checkpoints
    from peghole_mjx.training.seeds import SeedsRun

    run, _ = seeds_run
    copy = tmp_path / "run"
    shutil.copytree(run.out, copy, ignore=shutil.ignore_patterns("run.lock"))
    newest = checkpoints.checkpoint_dirs(copy / "checkpoints")[-1]
    shutil.rmtree(newest)
    shutil.rmtree(copy / "seed_0")
    resumed = SeedsRun.resume(copy, progress=False)
    resumed._init, resumed._call = run._init, run._call  # the same compiled functions
    resumed.run(resume=True)
    for k in range(2):
        a = load_policy(run.out / f"seed_{k}" / "final_policy").params
        b = load_policy(copy / f"seed_{k}" / "final_policy").params
        for x, y in zip(_leaves(a), _leaves(b), strict=True):
            np.testing.assert_array_equal(x, y)
    assert (copy / "history.csv").read_text() == (run.out / "history.csv").read_text()


def test_seeds_must_be_a_positive_whole_number(tmp_path):
    from peghole_mjx.core.errors import UserInputError
    from peghole_mjx.training.seeds import SeedsRun

    with pytest.raises(UserInputError, match="--seeds"):
        SeedsRun(tiny_config(), 0, tmp_path / "r", progress=False)


def test_t_interval_matches_the_textbook_value():
    from peghole_mjx.training.seeds import t_interval

    lo, hi = t_interval([1.0, 2.0, 3.0])  # mean 2, s 1, t(0.975, 2) = 4.3027
    assert (lo, hi) == pytest.approx((2 - 4.3027 / 3**0.5, 2 + 4.3027 / 3**0.5), abs=1e-3)
    assert t_interval([1.0]) is None
    assert jnp.isfinite(jnp.asarray(lo))


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--seeds", "0"], "--seeds: must be a whole number in [1, 4096], got 0"),
        (["--seeds", "2", "--distributed"], "--seeds takes neither --distributed"),
        (["--seeds", "2", "--stop-at-success", "0.9"], "--seeds takes neither"),
    ],
)
def test_cli_seeds_bad_input_is_one_line(tmp_path, capsys, extra, message):
    from peghole_mjx.cli.main import main

    try:  # argparse refuses a bad --seeds itself (exit 2 by SystemExit), the command the rest
        rc = main(
            ["train", "--env", "RectExtract", "--quick", "--out", str(tmp_path / "r"), *extra]
        )
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and message in err[0]
    assert not (tmp_path / "r" / "run.json").exists()


def test_cli_resume_of_a_seeds_run_takes_its_own_config(seeds_run, capsys):
    from peghole_mjx.cli.main import main

    run, _ = seeds_run
    rc = main(["train", "--resume", str(run.out), "--set", "num_envs=8"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--resume takes the run's own config" in err


def test_vmapped_learner_resets_only_on_steps_where_a_world_finished(seeds_run):
    """Two seeds vmapped in one call: a call of 5 env steps in which no world can finish
    (episode_length 25) makes no reset call on the host; the call that reaches the time limit
    makes at least one and at most one per step, and as many IK calls (the reset's start pose,
    solved on the host too). Without the seeds' named axis the reset's ``lax.cond`` becomes a
    select and resets every world at every step (5 calls here)."""
    run, _ = seeds_run
    timing = run.env.engine.timing
    carry = run._init(run.keys)
    n0, k0 = timing["init_calls"], timing["ik_calls"]
    carry, _ = run._call(carry, jnp.asarray(False))
    assert (timing["init_calls"], timing["ik_calls"]) == (n0, k0)
    for _ in range(4):  # steps 6 to 25: every world reaches the time limit at step 25
        carry, _ = run._call(carry, jnp.asarray(False))
    assert 1 <= timing["init_calls"] - n0 <= 5
    assert timing["ik_calls"] - k0 == timing["init_calls"] - n0


def test_a_time_out_is_bootstrapped_under_the_outcome_reward(seeds_run):
    """The replay rows of the time-limit step keep discount 1 (a truncation, bootstrapped from
    the true next observation, which differs from the fresh reset's); rows that ended by a
    terminal failure (cost <= -P) have discount 0; the truncation mask stays 0."""
    from peghole_mjx.envs.reward import failure_cost

    run, _ = seeds_run
    assert run.cfg.env_overrides["reward_config.kind"] == "outcome"
    carry = run._init(run.keys)
    for _ in range(5):  # 25 steps x 4 worlds = 100 rows per seed, the time limit at step 25
        carry, _ = run._call(carry, jnp.asarray(False))
    buf = run.train.trainer.buffer
    data = np.asarray(carry.buffer.data[0])  # seed 0's rows, in insertion order
    rows = buf._unflatten_fn(jnp.asarray(data[:100]))  # Brax's own row layout (vmapped)
    reward, discount = np.asarray(rows.reward), np.asarray(rows.discount)
    terminal = reward <= -failure_cost(run.env.config.reward_config) * 0.99
    np.testing.assert_array_equal(discount, np.where(terminal, 0.0, 1.0))
    assert not terminal[-4:].all()  # the time-limit step's rows: at least one truncation
    np.testing.assert_array_equal(np.asarray(rows.extras["state_extras"]["truncation"]), 0.0)
    last = np.asarray(rows.next_observation)[-4:]
    first = np.asarray(carry.env_state.obs[0])
    assert np.abs(last - first).max() > 0  # the true next observation, not the reset's


def test_actor_delay_holds_the_actor_and_temperature_while_the_critics_learn():
    """``actor_delay_updates`` 2: updates 1-2 move only the critics, update 3 the actor too."""
    from brax.training.types import Transition

    from peghole_mjx.envs import load
    from peghole_mjx.training.sac import AXIS, SACTrainer

    cfg = load_train_config(
        "RectExtract", "quick", {**TINY, "actor_delay_updates": 2}, compliance_strategy=True
    )
    trainer = SACTrainer(load(cfg.env, config_overrides=cfg.env_overrides), cfg)
    ts = trainer.learner_state(jax.random.PRNGKey(0))
    n, o, a = 32, trainer.obs_size, trainer.env.action_size
    ks = jax.random.split(jax.random.PRNGKey(1), 4)
    batch = Transition(
        observation=jax.random.normal(ks[0], (n, o)),
        action=jax.random.uniform(ks[1], (n, a), minval=-1.0, maxval=1.0),
        reward=jax.random.normal(ks[2], (n,)),
        discount=jnp.ones((n,)),
        next_observation=jax.random.normal(ks[3], (n, o)),
        extras={"state_extras": {"truncation": jnp.zeros((n,))}, "policy_extras": {}},
    )
    step = jax.jit(jax.vmap(trainer._sgd_step, axis_name=AXIS))
    one = jax.tree.map(lambda x: jnp.asarray(x)[None], ((ts, jax.random.PRNGKey(2)), batch))
    history = []
    for _ in range(3):
        (state, key), _ = step(*one)
        history.append(jax.tree.map(lambda x: x[0], state))
        one = ((state, key), one[1])
    for held in history[:2]:
        assert all(
            np.array_equal(x, y)
            for x, y in zip(_leaves(held.policy_params), _leaves(ts.policy_params), strict=True)
        )
        assert float(held.log_alpha) == float(ts.log_alpha)
        assert not all(
            np.array_equal(x, y)
            for x, y in zip(_leaves(held.q_params), _leaves(ts.q_params), strict=True)
        )
    moved = history[2]
    assert not all(
        np.array_equal(x, y)
        for x, y in zip(_leaves(moved.policy_params), _leaves(ts.policy_params), strict=True)
    )
    assert float(moved.log_alpha) != float(ts.log_alpha)
