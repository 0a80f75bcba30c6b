"""The mid-run fall of a learner, beside its critic's loss (docs/research/critic_fall.md).

Under one update per env step our SAC runs on the Hard tasks reach 1.00 evaluation success
within a few thousand env steps and then fall; this module reads each run's ``metrics.csv``
(one row per evaluation) and reports, per run, where the fall began and what the critic's loss
did before it: the first evaluation at the run's best success, the first later evaluation more
than :data:`benchmarks.evals.learning.COLLAPSE_MARGIN` below that best (the fall), the critic's
loss at both, and the final evaluation. Nothing is trained or simulated here.

``@table("critic_fall")`` lists the finished runs (``summary.json`` written) of
:data:`RUN_GROUPS`.
"""

from __future__ import annotations

from benchmarks.common import EVALS_RESULTS, table
from benchmarks.evals.learning import COLLAPSE_MARGIN, finite_or_none
from peghole_mjx.training.logs import read_metrics

_BENCH = EVALS_RESULTS / "learning_residual_cpu-2core"
#: the run folders read, as (label, folder holding seed_* runs): the tuning probes
#: (RectExtractHard) and the Hard tasks of the one-update-per-env-step, task-reward-critics and
#: more-worlds and time-limit benchmarks
_UTD1 = EVALS_RESULTS / "learning_utd1_cpu-2core" / "runs"
_TASKQ = EVALS_RESULTS / "learning_taskq_cpu-2core" / "runs"
_WORLDS = EVALS_RESULTS / "learning_worlds_cpu-2core" / "runs"
_TIMELIMIT = EVALS_RESULTS / "learning_timelimit_cpu-2core" / "runs"
RUN_GROUPS = (
    (
        "probe, mlp critic: RectExtractHard",
        _BENCH / "probe_sb3_settings" / "runs" / "RectExtractHard",
    ),
    (
        "probe, layernorm critic: RectExtractHard",
        _BENCH / "probe_layernorm" / "runs" / "RectExtractHard",
    ),
    ("probe, tau 0.001: RectExtractHard", _BENCH / "probe_tau" / "runs" / "RectExtractHard"),
    ("1 update/step protocol: RectExtractHard", _UTD1 / "RectExtractHard"),
    ("1 update/step protocol: DualExtractHard", _UTD1 / "DualExtractHard"),
    ("task-reward critics protocol: RectExtractHard", _TASKQ / "RectExtractHard"),
    ("task-reward critics protocol: DualExtractHard", _TASKQ / "DualExtractHard"),
    (
        "probe, 256 worlds: RectExtractHard",
        _TASKQ.parent / "probe_more_worlds" / "runs" / "RectExtractHard",
    ),
    ("more-worlds protocol: RectExtractHard", _WORLDS / "RectExtractHard"),
    ("more-worlds protocol: DualExtractHard", _WORLDS / "DualExtractHard"),
    (
        "probe, time-out a failure: RectExtractHard",
        _WORLDS.parent / "probe_time_limit" / "runs" / "RectExtractHard",
    ),
    ("time-limit protocol: RectExtractHard", _TIMELIMIT / "RectExtractHard"),
    ("time-limit protocol: DualExtractHard", _TIMELIMIT / "DualExtractHard"),
)


def fall(rows: list[dict]) -> dict:
    """Where a run's evaluations fell: ``best`` (the highest success), ``best_step`` (its first
    evaluation), ``fall_step`` (the first later evaluation below ``best - COLLAPSE_MARGIN``,
    None if none), the critic's loss at both (``loss_at_best``, ``loss_at_fall``) and the last
    evaluation's success and loss (``last``, ``last_loss``); the env step of the first row that
    counts a finished training episode (``first_episode_step``, None if none), the training
    episodes counted in all (``train_episodes``), and minus the last logged actor loss
    (``q_end``: the critics' ``min Q - alpha log pi`` over a batch, None if never logged)."""
    num = finite_or_none
    evals = [
        (int(r["step"]), num(r.get("eval/success_rate")), num(r.get("loss/critic"))) for r in rows
    ]
    evals = [e for e in evals if e[1] is not None]
    if not evals:
        raise ValueError("no evaluation rows")
    best = max(e[1] for e in evals)
    i = next(k for k, e in enumerate(evals) if e[1] == best)
    later = [e for e in evals[i + 1 :] if e[1] < best - COLLAPSE_MARGIN]
    down = later[0] if later else None
    return {
        "best": best,
        "best_step": evals[i][0],
        "loss_at_best": evals[i][2],
        "fall_step": None if down is None else down[0],
        "fall_success": None if down is None else down[1],
        "loss_at_fall": None if down is None else down[2],
        "last": evals[-1][1],
        "last_loss": evals[-1][2],
        "first_episode_step": next(
            (int(r["step"]) for r in rows if (num(r.get("train/episodes")) or 0) > 0), None
        ),
        "train_episodes": int(sum(num(r.get("train/episodes")) or 0 for r in rows)),
        "q_end": next(
            (-v for r in reversed(rows) if (v := num(r.get("loss/actor"))) is not None), None
        ),
    }


def _g(v: float | None, fmt: str) -> str:
    return "-" if v is None else f"{v:{fmt}}"


def _k(step: int | None) -> str:
    return "none" if step is None else f"{step / 1e3:.1f}k"


@table("critic_fall")
def fall_table() -> str:
    """Per committed run of :data:`RUN_GROUPS`: its best evaluation, where it fell, and the
    critic's loss at both."""
    lines = [
        "| run | seed | best eval success (env steps) | critic loss there | first fall below "
        "best - 0.05 (env steps) | critic loss there | last eval success | critic loss at "
        "the end | first training episode ended (env steps) | training episodes | minus the "
        "actor loss at the end | run folder (under benchmarks/results/evals) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, folder in RUN_GROUPS:
        runs = sorted(
            (p for p in folder.glob("seed_*/metrics.csv") if (p.parent / "summary.json").exists()),
            key=lambda p: int(p.parent.name[5:]),
        )
        for path in runs:
            f = fall(read_metrics(path.parent))
            where = (
                "none"
                if f["fall_step"] is None
                else f"{f['fall_success']:.2f} ({f['fall_step'] / 1e3:.1f}k)"
            )
            lines.append(
                f"| {label} | {path.parent.name[5:]} | {f['best']:.2f} "
                f"({f['best_step'] / 1e3:.1f}k) | {_g(f['loss_at_best'], '.3g')} | {where} | "
                f"{_g(f['loss_at_fall'], '.3g')} | {f['last']:.2f} | "
                f"{_g(f['last_loss'], '.3g')} | {_k(f['first_episode_step'])} | "
                f"{f['train_episodes']} | {_g(f['q_end'], '.3g')} | "
                f"`{path.parent.relative_to(EVALS_RESULTS)}` |"
            )
    return "\n".join(lines)
