"""Which checkpoint of a training run is its policy: the published rule.

``choose_checkpoint(run, "best")`` takes the checkpoint whose training-time evaluation had the
highest success rate, ties broken by the lower mean extraction force |F_z| (the thesis's R3
measure); ``"final"`` the run's last policy; a step number that step's checkpoint. Used by
``train/publish_policy.py`` and by the studies that evaluate a run as it would be published
(``benchmarks/evals/task_policies.py``, ``benchmarks/evals/transfer.py`` via a folder).
"""

from __future__ import annotations

from pathlib import Path

from peghole_mjx.training.logs import read_metrics

KEEP = ("eval/episodes", "eval/success_rate", "eval/mean_time_s", "eval/mean_fz_N")


def eval_rows(run: Path) -> list[dict[str, str]]:
    """The evaluation rows of a run's ``metrics.csv`` (step > 0)."""
    return [r for r in read_metrics(run) if int(r["step"]) > 0]


def checkpoint_dir(run: Path, step: int) -> Path:
    """The policy folder of a run's checkpoint at ``step`` (the last one is ``final_policy``)."""
    path = run / "checkpoints" / f"step_{step:010d}"
    if not (path / "policy.json").exists():  # the last eval's checkpoint is the final policy
        path = run / "final_policy"
    return path


#: the ``selection.rule`` of a published run's last policy (``--checkpoint final``)
FINAL_RULE = "final policy of the run"


def choose_checkpoint(run: Path, which: str) -> tuple[Path, dict]:
    """The policy directory of ``which`` (best | final | a step number) and why it was chosen."""
    if which == "final":
        return run / "final_policy", {"rule": FINAL_RULE}
    rows = eval_rows(run)
    if which == "best":
        row = max(rows, key=lambda r: (float(r["eval/success_rate"]), -float(r["eval/mean_fz_N"])))
        rule = "highest training-eval success, then lowest mean |F_z|"
    else:
        row = next(r for r in rows if int(r["step"]) == int(which))
        rule = f"step {which}"
    step = int(row["step"])
    return checkpoint_dir(run, step), {
        "rule": rule,
        "step": step,
        **{k: float(row[k]) for k in KEEP},
    }
