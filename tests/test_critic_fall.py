"""The fall read-out of benchmarks/evals/critic_fall.py on hand-made evaluation rows."""

import pytest

from benchmarks.evals.critic_fall import fall


def _rows(evals):
    return [
        {"step": str(s), "eval/success_rate": str(v), "loss/critic": "" if c is None else str(c)}
        for s, v, c in evals
    ]


def test_the_fall_is_the_first_evaluation_below_the_best_minus_the_margin_after_it():
    rows = _rows([(0, 0.8, None), (1600, 1.0, 0.01), (3200, 0.96, 0.02), (4800, 0.5, 3.0),
                  (6400, 1.0, 5.0), (8000, 0.9, 9.0)])  # fmt: skip
    f = fall(rows)
    assert (f["best"], f["best_step"], f["loss_at_best"]) == (1.0, 1600, 0.01)
    # 0.96 is within 0.05 of the best: not a fall; 0.5 is
    assert (f["fall_step"], f["fall_success"], f["loss_at_fall"]) == (4800, 0.5, 3.0)
    assert (f["last"], f["last_loss"]) == (0.9, 9.0)
    assert f["first_episode_step"] is None and f["train_episodes"] == 0 and f["q_end"] is None


def test_training_episodes_and_the_critics_estimate_are_read_from_the_rows():
    rows = _rows([(0, 0.8, None), (1600, 1.0, 0.01), (3200, 0.9, 0.02), (4800, 1.0, 0.03)])
    for row, episodes, actor in zip(rows, ("", "0", "3", "2"), ("", "-1.5", "-4", ""), strict=True):
        row["train/episodes"], row["loss/actor"] = episodes, actor
    f = fall(rows)
    assert (f["first_episode_step"], f["train_episodes"], f["q_end"]) == (3200, 5, 4.0)


def test_a_run_that_never_falls_has_no_fall_and_a_missing_loss_reads_as_none():
    f = fall(_rows([(0, 0.5, None), (1600, 0.7, 0.1), (3200, 0.9, None)]))
    assert f["best_step"] == 3200 and f["loss_at_best"] is None
    assert f["fall_step"] is None and f["fall_success"] is None


def test_rows_without_an_evaluation_are_refused():
    with pytest.raises(ValueError, match="no evaluation rows"):
        fall([{"step": "0", "eval/success_rate": "", "loss/critic": ""}])
