"""The learning benchmark's statistics (benchmarks/evals/learning.py) against hand-computed
values (its runs are :class:`TrainingRun` and :func:`evaluate`, tested in their own files)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.evals import learning as lb


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
