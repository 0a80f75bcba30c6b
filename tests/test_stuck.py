"""Stuck joints (env config ``stuck``): a breakaway weld between the peg and the hole.

Off by default and then absent from the scene and the state; on, a weld whose breakaway force
is above the law's 60 N axial cap never releases and the scripted pull fails, a low one
releases at the first step and the scripted pull extracts; both engines release at the same
control step; bad values are refused in one line; the study command runs end to end.

One stuck env per engine (RectExtract, 3 worlds) serves every physics test: its worlds' drawn
breakaway forces are replaced in the reset state (``info["breakaway_N"]``), so one compiled
step covers a low, a middle and an unbreakable weld."""

from __future__ import annotations

import functools
import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from benchmarks.evals import stuck as study
from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.config import apply_overrides
from peghole_mjx.envs.metrics import STUCK_METRICS
from peghole_mjx.envs.randomization import breakaway_draw, randomization_fn
from peghole_mjx.envs.rollout import scripted_policy
from peghole_mjx.envs.stuck import WELD_NAME
from peghole_mjx.sim.engine_mujoco import STATE_SPEC

ON = {"stuck.enabled": True, "mujoco_threads": 2}
#: per world: released at the first step (the pull's first step reads ~6 N), mid-range, and
#: above the law's 60 N axial cap (never)
BREAKAWAY_N = (1.0, 30.0, 200.0)


@functools.cache
def compiled(engine: str = "mujoco", over: tuple = tuple(ON.items())):
    env = envs.load("RectExtract", config_overrides={"engine": engine, **dict(over)})
    return env, jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))


def start(engine: str = "mujoco", over: tuple = tuple(ON.items())):
    """The stuck env's reset state of 3 worlds with :data:`BREAKAWAY_N` put in."""
    env, reset, step = compiled(engine, over)
    s = reset(jax.random.split(jax.random.PRNGKey(4), len(BREAKAWAY_N)))
    b = jnp.asarray(BREAKAWAY_N, jnp.float32)
    return env, step, s.replace(info={**s.info, "breakaway_N": b})


@functools.cache
def scripted_episode(engine: str = "mujoco", steps: int | None = None):
    """The scripted pull from :func:`start`: every step's metrics (NumPy), the state at each
    world's first ``done`` (or the last), and the env."""
    env, step, s = start(engine)
    a = jnp.tile(scripted_policy(env)(None, None), (len(BREAKAWAY_N), 1))
    steps = steps or env.config.episode_length
    history, first_done = [], [None] * len(BREAKAWAY_N)
    for t in range(steps):
        s = step(s, a)
        history.append({k: np.asarray(v) for k, v in s.metrics.items()})
        for w in range(len(BREAKAWAY_N)):
            if first_done[w] is None and s.done[w] > 0:
                first_done[w] = t
        if all(d is not None for d in first_done):
            break
    return env, history, first_done, s


def _leaves_equal(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_off_by_default_no_weld_and_its_entries_change_nothing():
    """Every env defaults to no stuck joint: no equality in the scene, no stuck keys in the
    state; with it off, its other entries leave the states bit for bit as they were."""
    for name in envs.ALL_ENVS:
        assert envs.get_default_config(name).stuck.enabled is False
    base = {"mujoco_threads": 2}
    changed = {**base, "stuck.breakaway_N": (5.0, 6.0), "stuck.timeconst_s": 0.02}
    runs = []
    for over in (base, changed):
        env, reset, step = compiled("mujoco", tuple(over.items()))
        assert env.mj_model.neq == 0 and env._weld is None
        s = reset(jax.random.split(jax.random.PRNGKey(2), 2))
        out = [s]
        for _ in range(3):
            s = step(s, jnp.full((2, env.action_size), 0.3))
            out.append(s)
        assert not set(STUCK_METRICS) & (set(s.info) | set(s.metrics))
        runs.append(out)
    _leaves_equal(runs[0], runs[1])


def test_the_weld_holds_the_inserted_pose_at_the_start():
    """The weld's pose is the inserted keyframe's: no constraint violation there, and every
    reset (a moved hole, the IK's start) starts active and within a micrometre of it."""
    env, _, s = start()
    m = env.mj_model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    i = m.equality(WELD_NAME).id
    weld = mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert d.eq_active[i] == 1 and np.abs(d.efc_pos[d.efc_type == weld]).max() < 1e-9
    for w in range(len(BREAKAWAY_N)):
        env.engine.to_mjdata(jax.tree.map(lambda x, w=w: x[w], s.data), m, d)
        assert d.eq_active[i] == 1 and np.abs(d.efc_pos[d.efc_type == weld]).max() < 1e-6
    np.testing.assert_array_equal(s.metrics["released"], 0.0)


def test_an_unbreakable_weld_holds_and_a_low_one_releases_at_once():
    """Scripted pull (20 mm/s, the law's caps): the 1 N weld releases at the first step and the
    peg is extracted; the 30 N one releases when |F_z| reaches 30 N and the peg is extracted;
    the 200 N one never releases, |F_z| rises to the law's 60 N cap, the peg stays within
    0.05 mm of its start and the episode fails at the time limit."""
    env, h, first_done, s = scripted_episode()
    m = {k: np.stack([x[k] for x in h]) for k in h[0]}  # (steps, worlds)
    low, mid, never = range(3)
    assert m["release_time_s"][first_done[low], low] == pytest.approx(env.config.ctrl_dt)
    for w in (low, mid):
        assert m["success"][first_done[w], w] == 1 and m["released"][first_done[w], w] == 1
    # the 30 N weld: released at the step whose substeps reach 30 N (the averaged reading of
    # that step is below it, the step before's too)
    k = int(np.argmax(m["released"][:, mid]))
    assert m["release_time_s"][-1, mid] == pytest.approx((k + 1) * env.config.ctrl_dt)
    assert m["fz_N"][k - 1, mid] < 30.0 and 0.5 < (k + 1) * env.config.ctrl_dt < 1.0
    # the 200 N weld
    assert first_done[never] == env.config.episode_length - 1
    assert m["released"][:, never].max() == 0 and m["success"][-1, never] == 0
    assert m["failure"][-1, never] == 1 and m["jammed"][-1, never] == 0
    assert m["peak_fz_N"][-1, never] == pytest.approx(60.0, abs=0.5)
    assert np.ptp(m["depth_mm"][:, never]) < 0.05
    # the MuJoCo C state row carries the switch: off in the released worlds, on in the other
    d = mujoco.MjData(env.mj_model)
    i = env.mj_model.equality(WELD_NAME).id
    for w, on in ((low, 0), (never, 1)):
        row = np.asarray(s.data.state[w]).view(np.float64)
        mujoco.mj_setState(env.mj_model, d, row, STATE_SPEC)
        assert d.eq_active[i] == on


@pytest.mark.slow  # compiles the MJX step
def test_both_engines_release_at_the_same_control_step():
    """The same episode starts, pulls and breakaway forces on MJX (float32) and MuJoCo C
    (float64): each weld releases at the same control step on both (measured 2026-12-02)."""
    steps = 40  # past the 30 N weld's release (~0.6 s: 6 N at the first step, then 40 N/s)
    out = {}
    for engine in ("mujoco", "mjx"):
        env, step, s = start(engine)
        a = jnp.tile(scripted_policy(env)(None, None), (len(BREAKAWAY_N), 1))
        for _ in range(steps):
            s = step(s, a)
        out[engine] = (np.asarray(s.metrics["released"]), np.asarray(s.metrics["release_time_s"]))
    np.testing.assert_array_equal(out["mujoco"][0], [1, 1, 0])
    np.testing.assert_array_equal(out["mujoco"][0], out["mjx"][0])
    np.testing.assert_array_equal(out["mujoco"][1], out["mjx"][1])


def test_the_breakaway_draw_is_uniform_in_its_range_and_leaves_the_other_draws():
    c = apply_overrides(envs.get_default_config("RectExtract"), {"stuck.breakaway_N": (25, 35)})
    keys = jax.random.split(jax.random.PRNGKey(0), 256)
    b = np.asarray(jax.vmap(lambda k: breakaway_draw(k, c.stuck))(keys))
    assert b.min() >= 25 and b.max() <= 35 and b.std() == pytest.approx(10 / 12**0.5, rel=0.15)
    np.testing.assert_array_equal(b, jax.vmap(lambda k: breakaway_draw(k, c.stuck))(keys))
    draw = jax.vmap(lambda k: randomization_fn(k, c.randomization, 300.0))(keys)
    assert draw.breakaway_N is None  # the weld's draw is the stuck group's, made by the env


@pytest.mark.parametrize(
    ("over", "needle"),
    [
        ({"stuck.breakaway_N": (0.0, 10.0)}, "stuck.breakaway_N"),
        ({"stuck.breakaway_N": (50.0, 20.0)}, r"stuck.breakaway_N must be a range \(lo, hi\)"),
        ({"stuck.breakaway_N": (10.0, 2000.0)}, "stuck.breakaway_N"),
        ({"stuck.breakaway_N": 30.0}, "stuck.breakaway_N must be a list of 2 numbers"),
        ({"stuck.timeconst_s": 0.0}, "stuck.timeconst_s"),
        ({"stuck.enabled": 1}, "stuck.enabled must be true or false"),
        ({"stuck.force": 1.0}, "unknown env config key 'stuck.force'"),
    ],
)
def test_bad_stuck_values_are_refused_in_one_line(over, needle):
    with pytest.raises(UserInputError, match=needle) as err:
        apply_overrides(envs.get_default_config("RectExtract"), over)
    assert "\n" not in str(err.value)


def test_the_study_command_runs_end_to_end_and_resumes(tmp_path, capsys, monkeypatch):
    """The published ``rect`` policy (not trained stuck: a cross evaluation) and the scripted
    baseline on 2 stuck episodes on the mujoco engine: JSON and CSV written, the docs table
    built from them; a rerun loads the saved slices and gives the same numbers."""
    out = tmp_path / "stuck_rect.json"
    argv = ["--policy", "rect", "--episodes", "2", "--engine", "mujoco", "--no-progress"]
    argv += ["--breakaway", "20", "25", "--parts", str(tmp_path / "parts"), "--out", str(out)]
    assert study.main(argv) == 0
    doc = json.loads(out.read_text())
    assert {"device", "versions", "date", "label", "breakaway_N", "paired"} <= set(doc)
    assert doc["differs_from_training"]["stuck.enabled"] == [False, True]
    for who in study.METHODS:
        s = doc[who]
        assert s["episodes"] == 2 and len(s["success_ci95"]) == 2
        assert sum(b["episodes"] for b in s["by_breakaway"]) == 2
        assert 20.0 <= s["mean_breakaway_N"] <= 25.0
    assert doc["scripted"]["released"] == 2  # the scripted pull breaks every weld below 60 N
    rows = out.with_suffix(".csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * (1 + study.BINS)
    monkeypatch.setattr(study, "EVALS_RESULTS", tmp_path)
    assert "| scripted | " in study.stuck_table()
    first = {who: doc[who] for who in study.METHODS}
    assert study.main(argv) == 0  # every slice loaded, none run again
    again = json.loads(out.read_text())
    assert {who: again[who] for who in study.METHODS} == first
    assert not list((tmp_path / "parts").rglob("*.damaged"))
    capsys.readouterr()
