"""The policy trace: each episode's outcome and commands up to the step it ended."""

import subprocess
import sys

import numpy as np
import pytest

from benchmarks.studies import policy_trace as pt


def _arrays(steps=4, n=3):
    per_step = {
        "done": np.zeros((steps, n), bool),
        "fxy_N": np.ones((steps, n)),
        "fz_N": np.arange(steps * n, dtype=float).reshape(steps, n),
        "k_xy": np.full((steps, n), 300.0),
        "k_rot": np.full((steps, n), 100.0),
        "ff": np.zeros((steps, n, 3)),
        "offset_mm": np.zeros((steps, n)),
        "pull": np.full((steps, n), 0.5),
        "depth_mm": np.full((steps, n), 140.0),
    }
    ended = {k: np.zeros(n) for k in ("success", "failure", "jammed", "nan", "overflow")}
    return per_step, ended


def test_rows_end_at_each_episodes_first_done_and_flag_the_feed_forward_bound():
    per_step, ended = _arrays()
    # episode 0 jams at step 2 pressing x at the 20 N bound; episode 1 succeeds at step 1
    # (the ff is at the bound only after it ended); episode 2 runs to the end
    per_step["done"][2:, 0] = True
    per_step["ff"][1:, 0, 0] = -20.0
    per_step["fxy_N"][2, 0] = 19.5
    per_step["done"][1:, 1] = True
    per_step["ff"][2:, 1, 1] = 20.0
    ended["jammed"][0] = ended["failure"][0] = 1
    ended["success"][1] = 1
    ended["failure"][2] = 1
    rows = pt.episode_rows(per_step, ended, ff_bound_xy=20.0, ctrl_dt=0.02)
    assert [r["outcome"] for r in rows] == ["jam", "success", "timeout"]
    assert [r["end_s"] for r in rows] == [0.06, 0.04, 0.08]
    assert [r["ff_xy_at_bound_end"] for r in rows] == [True, False, False]
    assert rows[0]["fxy_end_N"] == 19.5 and rows[0]["ff_xy_end_N"] == [-20.0, 0.0]
    # means over the steps up to the end only: episode 1's f_z is 1 and 4 (steps 0, 1)
    assert rows[1]["mean_fz_N"] == 2.5
    summary = pt.summarise(rows)
    assert summary["jam"] == {**summary["jam"], "n": 1, "ff_xy_at_bound_end": 1}
    assert summary["timeout"]["end_s"] == 0.08


def test_a_component_just_under_the_bound_is_not_at_it():
    per_step, ended = _arrays(n=1)
    per_step["ff"][:, 0, 0] = 0.98 * 20.0
    ended["failure"][0] = 1
    (row,) = pt.episode_rows(per_step, ended, ff_bound_xy=20.0, ctrl_dt=0.02)
    assert not row["ff_xy_at_bound_end"] and row["ff_xy_max_N"] == pytest.approx(19.6)


def test_an_unknown_policy_is_one_line_and_exit_2():
    res = subprocess.run(
        [sys.executable, "-m", "benchmarks.studies.policy_trace", "--policy", "no_such_policy"],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "no_such_policy" in res.stderr
