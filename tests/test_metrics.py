"""The episode statistics are declared once (envs/metrics.py) and every consumer derives them."""

from __future__ import annotations

import csv
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx.envs import metrics
from peghole_mjx.envs.rollout import RolloutResult, RolloutSummary

ROOT = Path(__file__).resolve().parents[1]

#: four finished episodes: a success, a jam, a NaN world, a timeout
EPISODES = {
    "success": np.array([1.0, 0.0, 0.0, 0.0], np.float32),
    "failure": np.array([0.0, 1.0, 1.0, 1.0], np.float32),
    "jammed": np.array([0.0, 1.0, 0.0, 0.0], np.float32),
    "nan": np.array([0.0, 0.0, 1.0, 0.0], np.float32),
    "overflow": np.zeros(4, np.float32),
    "extraction_time_s": np.array([7.5, 0.0, 0.0, 0.0], np.float32),
    "mean_fz_N": np.array([4.0, 2.0, 1.0, 3.0], np.float32),
    "peak_fz_N": np.array([9.0, 5.0, 1.0, 6.0], np.float32),
    "mean_fxy_N": np.array([1.0, 8.0, 0.0, 3.0], np.float32),
    "return": np.array([140.0, -3.0, -1.0, 2.0], np.float32),
    "discounted_return": np.array([20.0, -2.0, -1.0, 1.0], np.float32),
}
EXPECTED = {
    "episodes": 4,
    "success_rate": 0.25,
    "mean_time_s": 7.5,
    "mean_fz_N": 2.5,
    "peak_fz_N": 5.25,
    "mean_fxy_N": 3.0,
    "mean_return": 34.5,
    "mean_discounted_return": 4.5,
    "nan_worlds": 1,
    "jammed": 1,
    "overflow_worlds": 0,
    "timeouts": 1,
}


def test_rollout_summary_is_the_declared_statistics():
    res = RolloutResult(EPISODES, 0.0, 1.0, 4, 40)
    s = res.summary().as_dict()
    assert s == pytest.approx(EXPECTED)
    assert list(s) == [st.name for st in metrics.STATS]
    assert list(RolloutSummary.__dataclass_fields__) == list(s)


def test_training_totals_give_the_same_statistics_as_an_evaluation():
    done = jnp.array([True, True, True, True, False])
    ended = {k: jnp.concatenate([jnp.asarray(v), jnp.ones(1)]) for k, v in EPISODES.items()}
    totals = {k: float(v) for k, v in metrics.episode_totals(ended, done).items()}
    assert set(totals) == set(metrics.TOTAL_KEYS)
    train = metrics.summarize_totals(totals)
    assert list(train) == list(metrics.TRAIN_STATS)
    assert train == pytest.approx({k: EXPECTED[k] for k in metrics.TRAIN_STATS})
    assert metrics.summarize_totals({k: 0.0 for k in metrics.TOTAL_KEYS}) == {"episodes": 0}


def test_return_accumulation():
    acc = metrics.zero_returns(2)
    for r in (1.0, 2.0, 4.0):
        acc = metrics.accumulate_return(acc, jnp.full(2, r), 0.5)
    assert np.allclose(acc["return"], 7.0) and np.allclose(acc["discounted_return"], 3.0)


def test_metrics_csv_columns_match_the_committed_runs():
    """Committed metrics.csv files keep their columns (the derived order is the old one); the
    SB3 stacks' runs (``runs_seed/``, ``runs_sb3/``) write their own evaluation columns."""
    from peghole_mjx.training.run import METRIC_COLUMNS

    files = sorted(
        f
        for f in ROOT.glob("benchmarks/results/**/metrics.csv")
        if not any(part.startswith("runs_") for part in f.parts)
    )
    assert files
    for f in files:
        with f.open() as fh:
            assert tuple(next(csv.reader(fh))) == METRIC_COLUMNS, f
