"""The learning benchmark: final policies over seeds, with intervals (one command, resumable).

    python -m benchmarks.evals.learning --out benchmarks/results/evals/learning_cpu-2core

For each task (default RectExtract, RectExtractHard, DualExtract, DualExtractHard) and each
seed (default 100-104: fresh seeds, the tuning seeds are 0-4), one SAC run
(:class:`peghole_mjx.training.run.TrainingRun`, ``--profile`` with ``--set`` changes; the
training default reward and learner) that evaluates ``--eval-episodes`` episodes every
``--eval-every`` env steps. Then its LAST policy (``final_policy``, never the best checkpoint)
and the scripted baseline run the same ``--final-episodes`` fresh episodes (seed
``--final-seed``, disjoint from the training evaluations' seeds).

Per task, in ``learning.json`` (and one row per task in ``learning.csv``):

* final success per seed; its interquartile mean (IQM: the mean of the middle half, rliable's
  aggregate) with a 95 % bootstrap interval over seeds (2000 resamples, percentile; within a
  task the stratified bootstrap of rliable is this one), the share of seeds at >= 95 %;
* collapse: each seed's final success against its best evaluated success (``>= best - 0.05``
  holds or not);
* env steps and training clock (compile and prefill in, evaluations out) to the first
  evaluation at >= 95 %: median and IQR over the seeds that reached it, and how many did;
  ``at_95_untrained``: how many of them were there at env step 0 (time 0 by construction);
* mean and peak F_z of the final policy minus the baseline's on the same episodes, per seed,
  with a 95 % Student-t interval over seeds;
* the untrained policy's evaluation (env step 0, the training evaluation's episodes): its
  success and mean F_z per seed and their means, beside the final policy's mean F_z;
* on residual envs (``action.residual``), the zero action (the untrained residual policy's
  deterministic action: the scripted pull with mid-range gains) on the final episodes
  (``zero_action``, one rollout per task, kept in ``zero_action_<task>_<N>_seed<S>.json``),
  and each final policy minus it, success and mean F_z, with 95 % t intervals over seeds:
  what learning added on the same episodes;
* the figure ``curves_<task>.png``: evaluation success against env steps, the seeds' mean and
  95 % band.

Every file carries device, versions, date, the command, the commit and each task's full
training config (env overrides, reward kind and engine included). The runs live under
``--out``/runs/TASK/seed_S; an interrupted benchmark started again with the same command
resumes each unfinished run from its checkpoint and skips finished runs and evaluations; a
rerun with other settings into the same folder is refused.

Stacks (``--stack``; each writes its own files, so the three sit in one ``--out``):

* ``ours`` (default): the above; ``learning.json``, ``learning.csv``, ``curves_<task>.png``,
  runs under ``runs/``. Updates per env step: ``grad_updates_per_step / num_envs`` (cpu
  profile: 16 / 32 = 0.5, batch 256).
* ``seed``: the thesis's pipeline rebuilt (``benchmarks/baselines/seed_stack.py``): the PyBullet
  env (its default config: eq 4.4, compliance strategy off, 0.1 m/s pull) + SB3 SAC with
  ``SAC_SETTINGS`` (gamma 0.99, ent_coef 0.2, buffer 100k, train_freq 50; SB3's defaults
  else: 1 update per 50 env steps, 0.02, batch 256). RectExtract and RectExtractHard only
  (default both; others are refused). Baseline: the same scripted straight pull (0.02 m/s) in
  the PyBullet env, on the same episodes (``pybullet_peghole.scripted_action``).
* ``sb3``: SB3 SAC with its defaults (``MlpPolicy``, 1 update per env step, batch 256, buffer
  1e6) on our Gymnasium adapter (``PegHoleGymEnv``: time-outs are truncations), the env of
  the ``--profile``'s training config (its env overrides), engine ``mujoco`` (``--engine auto``),
  gamma the env's reward discount (0.9995 for the outcome reward). Baseline: ``evaluate``'s.

``seed`` and ``sb3`` write ``learning_<stack>.json`` / ``.csv`` and ``curves_<stack>_<task>.png``,
their runs under ``runs_<stack>/``; the same budget (``--num-timesteps`` or the profile's), the
same evaluation schedule (``--eval-every`` env steps, ``--eval-episodes`` fresh deterministic
episodes, clock excluded), the same final evaluation and the same statistics. Their runs,
checkpoints and resumption: :mod:`benchmarks.evals.learning_stacks`. Only ``env.KEY=VALUE``
``--set`` changes apply to them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from scipy import stats as sps
from tqdm import tqdm

from benchmarks.common import EVALS_RESULTS, parse_overrides, rel, table, write_rows
from benchmarks.evals import learning_stacks as stacks
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.envs.reward import REWARD_KINDS
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import run_provenance
from peghole_mjx.sim.engines import engine_label, engine_overrides
from peghole_mjx.training.config import TrainConfig, load_train_config
from peghole_mjx.training.evaluate import evaluate
from peghole_mjx.training.logs import read_metrics
from peghole_mjx.training.run import TrainingRun

TASKS = ("RectExtract", "RectExtractHard", "DualExtract", "DualExtractHard")
SEEDS = (100, 101, 102, 103, 104)
#: the success rate that counts as solved (the issue's 95 %)
TARGET = 0.95
#: a final policy has collapsed when it is this far below its best evaluation
COLLAPSE_MARGIN = 0.05
BOOTSTRAP_RESAMPLES = 2000
CSV_FIELDS = (
    "task",
    "seeds",
    "final_success_iqm",
    "final_success_ci95_lo",
    "final_success_ci95_hi",
    "share_at_95",
    "seeds_collapsed",
    "steps_to_95_median",
    "clock_to_95_median_s",
    "reached_95",
    "at_95_untrained",
    "mean_fz_minus_baseline_N",
    "mean_fz_ci95_lo",
    "mean_fz_ci95_hi",
    "peak_fz_minus_baseline_N",
    "untrained_mean_fz_N",
    "final_mean_fz_N",
    "zero_action_success",
    "zero_action_mean_fz_N",
    "final_minus_zero_action_mean_fz_N",
    "engine",
    "reward_kind",
    "device",
    "date",
    "commit",
    "stack",
    "updates_per_env_step",
)


# ---------------------------------------------------------------------- statistics
def iqm(x) -> float:
    """The interquartile mean: the mean of the middle 50 % (25 % trimmed from each end)."""
    return float(sps.trim_mean(np.asarray(x, float), 0.25))


def bootstrap_ci(x, stat=iqm, n: int = BOOTSTRAP_RESAMPLES, seed: int = 0) -> list[float]:
    """95 % percentile bootstrap interval of ``stat`` over the units of ``x`` (the seeds)."""
    x = np.asarray(x, float)
    rng = np.random.default_rng(seed)
    draws = [stat(x[rng.integers(0, len(x), len(x))]) for _ in range(n)]
    return [float(np.percentile(draws, 2.5)), float(np.percentile(draws, 97.5))]


def t_ci(x) -> list[float] | None:
    """95 % Student-t interval of the mean of ``x`` (None for fewer than two values)."""
    x = np.asarray(x, float)
    if len(x) < 2:
        return None
    half = sps.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return [float(x.mean() - half), float(x.mean() + half)]


def first_at(rows: list[dict], target: float = TARGET) -> dict | None:
    """The first evaluation row of a ``metrics.csv`` at or above ``target`` success."""
    for r in rows:
        v = finite_or_none(r.get("eval/success_rate"))
        if v is not None and v >= target:
            return r
    return None


def finite_or_none(v) -> float | None:
    """``v`` as a finite float, None if it is empty, not a number or not finite (a CSV cell)."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _median_iqr(vals: list[float]) -> dict[str, Any] | None:
    if not vals:
        return None
    q1, med, q3 = np.percentile(vals, [25, 50, 75])
    return {"median": float(med), "iqr": [float(q1), float(q3)]}


def task_summary(task: str, per_seed: list[dict]) -> dict[str, Any]:
    """The task's statistics over its seeds (module text) from the per-seed records."""
    final = [s["final_success"] for s in per_seed]
    collapsed = [
        s["seed"] for s in per_seed if s["final_success"] < s["best_eval"] - COLLAPSE_MARGIN
    ]
    steps = [s["steps_to_95"] for s in per_seed if s["steps_to_95"] is not None]
    clock = [s["clock_to_95_s"] for s in per_seed if s["clock_to_95_s"] is not None]
    # a seed without a baseline on its episodes (none in its env) has no F_z difference
    based = [s for s in per_seed if s["baseline_mean_fz_N"] is not None]
    d_mean = [s["policy_mean_fz_N"] - s["baseline_mean_fz_N"] for s in based]
    d_peak = [s["policy_peak_fz_N"] - s["baseline_peak_fz_N"] for s in based]
    return {
        "task": task,
        "seeds": [s["seed"] for s in per_seed],
        "final_success": final,
        "final_success_iqm": iqm(final),
        "final_success_ci95": bootstrap_ci(final),
        "share_at_95": float(np.mean([v >= TARGET for v in final])),
        "seeds_collapsed": collapsed,
        "steps_to_95": _median_iqr(steps),
        "clock_to_95_s": _median_iqr(clock),
        "reached_95": len(steps),
        # seeds whose untrained evaluation (env step 0) was already >= 95 %: their time to
        # 95 % is 0 by construction and says nothing about learning speed
        "at_95_untrained": sum(
            1 for s in per_seed if (s.get("untrained_success") or 0.0) >= TARGET
        ),
        "mean_fz_minus_baseline_N": float(np.mean(d_mean)) if d_mean else None,
        "mean_fz_minus_baseline_ci95": t_ci(d_mean),
        "peak_fz_minus_baseline_N": float(np.mean(d_peak)) if d_peak else None,
        "peak_fz_minus_baseline_ci95": t_ci(d_peak),
        # the untrained policy's evaluation (env step 0; its own episodes, not the final
        # ones): what a residual policy's zero action already does before any learning
        "untrained_success_mean": _mean_of(per_seed, "untrained_success"),
        "untrained_mean_fz_N": _mean_of(per_seed, "untrained_mean_fz_N"),
        "final_mean_fz_N": _mean_of(per_seed, "policy_mean_fz_N"),
    }


def zero_action_summary(zero: dict | None, per_seed: list[dict]) -> dict[str, Any]:
    """The zero action's result on the final episodes (``zero``: a rollout summary, None on a
    non-residual env) and each final policy minus it (success, mean F_z) with t intervals."""
    if zero is None:
        return {"zero_action": None}
    d_success = [s["final_success"] - zero["success_rate"] for s in per_seed]
    d_fz = [s["policy_mean_fz_N"] - zero["mean_fz_N"] for s in per_seed]
    return {
        "zero_action": {
            k: zero[k] for k in ("success_rate", "mean_fz_N", "peak_fz_N", "mean_time_s")
        },
        "final_minus_zero_action_success": float(np.mean(d_success)),
        "final_minus_zero_action_success_ci95": t_ci(d_success),
        "final_minus_zero_action_mean_fz_N": float(np.mean(d_fz)),
        "final_minus_zero_action_mean_fz_ci95": t_ci(d_fz),
    }


def zero_action_eval(task: str, seed: int, args, out: Path) -> dict | None:
    """The zero action on the final episodes of ``task`` (its seed ``seed`` run's env; every
    seed's env is the same), or None when the env is not residual. Kept in
    ``zero_action_<task>_<N>_seed<S>.json`` under ``out``: the rollout runs once."""
    from peghole_mjx.envs.rollout import rollout
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training.evaluate import requested_config

    bundle = load_policy(str(_run_dir(out, task, seed) / "final_policy"))
    if not requested_config(bundle).action.residual:  # read from the config, no env built
        return None
    path = out / f"zero_action_{task}_{args.final_episodes}_seed{args.final_seed}.json"
    if path.exists():
        return json.loads(path.read_text())["summary"]
    env = bundle.make_env()
    zero = np.zeros(env.action_size, np.float32)
    res = rollout(
        env,
        lambda obs, rng: zero,
        args.final_episodes,
        seed=args.final_seed,
        label=f"zero action rollout ({task})",
    )
    summary = res.summary().as_dict()
    record = {
        "task": task,
        "what": "the residual env's zero action (the untrained residual policy's deterministic "
        "action) on the final episodes",
        "episodes": args.final_episodes,
        "seed": args.final_seed,
        "summary": summary,
        "env_config": json.loads(env.config.to_json()),
        "config": "see task, episodes, seed, env_config",
        **run_provenance(sys.argv),
    }
    fileio.write_text(path, dumps(record, indent=2) + "\n")
    return summary


def _mean_of(per_seed: list[dict], key: str) -> float | None:
    """The mean of ``key`` over the seeds that have it, None if none has."""
    values = [s[key] for s in per_seed if s.get(key) is not None]
    return float(np.mean(values)) if values else None


# ---------------------------------------------------------------------- runs
def seed_record(run_dir: Path, final: dict[str, Any]) -> dict[str, Any]:
    """One seed's record: its evaluations' curve, best and first >= 95 %, and its final
    policy's evaluation against the baseline (``final``: :func:`evaluate`'s result, or a
    stack's with the same ``policy``, ``baseline`` (None: no baseline) and ``episodes``).
    Every stack's run folder holds ``run.json`` (``config.seed``) and ``metrics.csv`` (one
    row per evaluation: ``step``, ``eval/success_rate``, ``train_wall_s``)."""
    rows = read_metrics(run_dir)
    curve = [
        (int(r["step"]), finite_or_none(r.get("eval/success_rate")))
        for r in rows
        if finite_or_none(r.get("eval/success_rate")) is not None
    ]
    hit = first_at(rows)
    # the untrained policy's evaluation (env step 0), where the run made one
    start = next((r for r in rows if r.get("step") == "0"), {})
    run_json = json.loads((run_dir / "run.json").read_text())
    cfg = run_json["config"]
    pol, base = final["policy"], final["baseline"]
    if base is None:
        base = {"success_rate": None, "mean_fz_N": None, "peak_fz_N": None}
    return {
        "seed": cfg["seed"],
        "run_commit": run_json.get("commit", "unknown: run.json written before runs recorded it"),
        "curve": curve,
        "best_eval": max((v for _, v in curve), default=0.0),
        "steps_to_95": int(hit["step"]) if hit else None,
        "clock_to_95_s": finite_or_none(hit.get("train_wall_s")) if hit else None,
        "final_success": float(pol["success_rate"]),
        "policy_mean_fz_N": float(pol["mean_fz_N"]),
        "policy_peak_fz_N": float(pol["peak_fz_N"]),
        "baseline_success": finite_or_none(base["success_rate"]),
        "baseline_mean_fz_N": finite_or_none(base["mean_fz_N"]),
        "baseline_peak_fz_N": finite_or_none(base["peak_fz_N"]),
        "final_episodes": int(final["episodes"]),
        "untrained_success": finite_or_none(start.get("eval/success_rate")),
        "untrained_mean_fz_N": finite_or_none(start.get("eval/mean_fz_N")),
    }


def train_config(task: str, seed: int, args):
    """The run's training config: the profile, the evaluation schedule, the ``--set``s."""
    over = {
        **{f"env.{k}": v for k, v in engine_overrides(args.engine).items()},
        "seed": seed,
        "eval_every": args.eval_every,
        "num_eval_envs": args.eval_episodes,
        **parse_overrides(args.sets),
    }
    if args.num_timesteps is not None:
        over["num_timesteps"] = args.num_timesteps
    return load_train_config(task, args.profile, over)


def _run_dir(out: Path, task: str, seed: int) -> Path:
    """Our stack's run folder of ``task`` and ``seed`` under ``out``."""
    return out / "runs" / task / f"seed_{seed}"


def run_seed(task: str, seed: int, args, out: Path) -> dict[str, Any]:
    """Train (or resume, or skip when finished) one seed and evaluate its final policy."""
    if args.stack != "ours":  # an SB3 stack: its run folder under runs_<stack>/
        cfg, run_dir, final = stacks.run_seed(args.stack, task, seed, args, out)
        return {"config": cfg, **seed_record(run_dir, final)}
    run_dir = _run_dir(out, task, seed)
    cfg = train_config(task, seed, args)
    if (run_dir / "run.json").exists():
        recorded = TrainConfig.from_dict(json.loads((run_dir / "run.json").read_text())["config"])
        if json.loads(dumps(recorded.as_dict())) != json.loads(dumps(cfg.as_dict())):
            raise UserInputError(
                f"{run_dir} holds a run of another config: rerun with the settings it was "
                "started with, or another --out"
            )
        if not (run_dir / "summary.json").exists():
            TrainingRun.resume(run_dir, render=False).run(resume=True)
    else:
        TrainingRun(cfg, run_dir, render=False).run()
    final_file = run_dir / f"final_eval_{args.final_episodes}_seed{args.final_seed}.json"
    if final_file.exists():
        final = json.loads(final_file.read_text())
    else:
        final = evaluate(str(run_dir / "final_policy"), args.final_episodes, seed=args.final_seed)
        fileio.write_text(final_file, dumps(final, indent=2) + "\n")
    return {"config": cfg.as_dict(), **seed_record(run_dir, final)}


def plot_task(task: str, per_seed: list[dict], path: Path, title: str | None = None) -> None:
    """Evaluation success against env steps: the seeds' mean and 95 % band (Student t over
    seeds, clipped to [0, 1]), each seed thin."""
    fig, ax = plt.subplots(figsize=(6, 3.5))
    steps = sorted({s for rec in per_seed for s, _ in rec["curve"]})
    grid = np.full((len(per_seed), len(steps)), np.nan)
    for i, rec in enumerate(per_seed):
        d = dict(rec["curve"])
        grid[i] = [d.get(s, np.nan) for s in steps]
        ax.plot(steps, grid[i], color="0.7", lw=0.8)
    mean = np.nanmean(grid, axis=0)
    n = np.sum(np.isfinite(grid), axis=0)
    sd = np.nanstd(grid, axis=0, ddof=1) if len(per_seed) > 1 else np.zeros_like(mean)
    half = sps.t.ppf(0.975, np.maximum(n - 1, 1)) * sd / np.sqrt(np.maximum(n, 1))
    ax.plot(steps, mean, color="C0", lw=2, label=f"mean of {len(per_seed)} seeds")
    # a success rate lies in [0, 1]: the t band is clipped there
    lo, hi = np.clip(mean - half, 0.0, 1.0), np.clip(mean + half, 0.0, 1.0)
    ax.fill_between(steps, lo, hi, color="C0", alpha=0.25, label="95 % band (t, clipped to [0, 1])")
    ax.axhline(TARGET, color="C3", ls="--", lw=1)
    ax.set(xlabel="env steps", ylabel="evaluation success", ylim=(-0.02, 1.02), title=title or task)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ----------------------------------------------------------------------------- docs tables
#: the residual protocol's result files (docs/research/residual.md): the four tasks, the shapes
RESIDUAL_FILES = (
    EVALS_RESULTS / "learning_residual_cpu-2core" / "learning.json",
    EVALS_RESULTS / "learning_residual_shapes_cpu-2core" / "cylinder" / "learning.json",
    EVALS_RESULTS / "learning_residual_shapes_cpu-2core" / "keyed" / "learning.json",
)


def _ci_text(ci: list[float] | None, fmt: str) -> str:
    return "-" if ci is None else f"[{ci[0]:{fmt}}, {ci[1]:{fmt}}]"


#: the one-update-per-env-step protocol's result file (docs/research/learner_settings.md): our
#: learner with SB3's learner settings on fresh seeds, beside the residual protocol's stacks
UTD1_FILE = EVALS_RESULTS / "learning_utd1_cpu-2core" / "learning.json"
#: the task-reward-critics protocol's result file (docs/research/learner_settings.md): the
#: one-update-per-env-step learner with critics whose target has no entropy bonus and learning
#: rates falling to zero, on fresh seeds
TASKQ_FILE = EVALS_RESULTS / "learning_taskq_cpu-2core" / "learning.json"
#: the more-worlds protocol's result file (docs/research/time_limit.md): the task-reward
#: critics' learner with eight times the worlds and env steps at the same gradient updates
WORLDS_FILE = EVALS_RESULTS / "learning_worlds_cpu-2core" / "learning.json"
#: the time-limit protocol's result file (docs/research/time_limit.md): the more-worlds learner
#: with a time-out as a terminal failure and the time left observed
TIMELIMIT_FILE = EVALS_RESULTS / "learning_timelimit_cpu-2core" / "learning.json"

#: the residual protocol's result file of each stack (one ``--out``: the stacks sit together)
STACK_FILES = {
    stack: EVALS_RESULTS
    / "learning_residual_cpu-2core"
    / ("learning.json" if stack == "ours" else f"learning_{stack}.json")
    for stack in stacks.STACKS
}


def censored_median_iqr(per_seed: list[dict], key: str) -> tuple[float, float, float]:
    """``(median, q1, q3)`` of ``key`` (``steps_to_95`` or ``clock_to_95_s``) over ALL seeds, a
    seed that never reached 95 % counted as infinitely late (``inf``), so that a median over
    the seeds that reached it alone does not flatter a stack. Order statistics (``nearest``):
    no interpolation with ``inf``."""
    vals = [math.inf if s[key] is None else float(s[key]) for s in per_seed]
    q1, med, q3 = np.percentile(vals, [25, 50, 75], method="nearest")
    return float(med), float(q1), float(q3)


def stack_setting(t: dict) -> str:
    """What a stack's task entry trained on: engine, reward kind, ``residual`` or ``plain``
    actions, and ``time-out a failure`` where the entry set ``reward_config.time_limit``
    so (the outcome reward's default is a truncation)."""
    over = t["config"].get("env_overrides", {})
    actions = "residual" if over.get("action.residual") else "plain"
    timeout = ", time-out a failure" if over.get("reward_config.time_limit") == "failure" else ""
    return f"{t['engine']}, {t['reward_kind']}, {actions}{timeout}"


def censored_text(v: float, fmt: str, censored: str) -> str:
    """One value of :func:`censored_median_iqr`: ``censored`` where it is ``inf``."""
    return censored if math.isinf(v) else f"{v:{fmt}}"


def to_95_text(t: dict, key: str, fmt: str, budget_text: str) -> str:
    """``median [q1, q3] (k of n)`` of :func:`censored_median_iqr`, a censored value shown as
    ``> budget``."""
    med, q1, q3 = (
        censored_text(v, fmt, f"> {budget_text}") for v in censored_median_iqr(t["per_seed"], key)
    )
    return f"{med} [{q1}, {q3}] ({t['reached_95']} of {len(t['seeds'])})"


@table("learning_stacks")
def stacks_table() -> str:
    """The three stacks of the residual protocol per task, from their result files."""
    lines = [
        "| stack | task | trained on (engine, reward, actions) | budget, env steps | updates / "
        "env step | seeds | final success IQM [95 % CI] | seeds >= 0.95 | collapsed | env "
        "steps to 95 %: median [IQR] "
        "(reached) | training clock to 95 %, s: median [IQR] (reached) | mean F_z minus "
        "baseline, N | file |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for stack, path in STACK_FILES.items():
        if not path.exists():
            lines.append(f"| {stack} | pending | | | | | | | | | | | `{rel(path)}` |")
            continue
        for t in json.loads(path.read_text())["tasks"]:
            n, budget = len(t["seeds"]), t["config"]["num_timesteps"]
            budget_text = f"{budget / 1e3:g}k"
            lines.append(
                f"| {stack} | {t['task']} | {stack_setting(t)} | {budget_text} | "
                f"{t['updates_per_env_step']:g} | {t['seeds'][0]}-{t['seeds'][-1]} | "
                f"{t['final_success_iqm']:.2f} {_ci_text(t['final_success_ci95'], '.2f')} | "
                f"{round(t['share_at_95'] * n)} of {n} | {len(t['seeds_collapsed'])} of {n} | "
                f"{to_95_text(t, 'steps_to_95', '.0f', budget_text)} | "
                f"{to_95_text(t, 'clock_to_95_s', '.3g', budget_text + ' steps')} | "
                f"{t['mean_fz_minus_baseline_N']:+.3g} "
                f"{_ci_text(t['mean_fz_minus_baseline_ci95'], '+.3g')} | "
                f"[`{path.name}`]({rel(path)}) |"
            )
    return "\n".join(lines)


@table("learning_residual")
def residual_table() -> str:
    """The residual benchmark per task (final policies over seeds) from its result files."""
    return benchmark_table(RESIDUAL_FILES)


@table("learning_utd1")
def utd1_table() -> str:
    """The one-update-per-env-step benchmark per task, from its result file."""
    return benchmark_table((UTD1_FILE,))


@table("learning_taskq")
def taskq_table() -> str:
    """The task-reward-critics benchmark per task, from its result file."""
    return benchmark_table((TASKQ_FILE,))


@table("learning_worlds")
def worlds_table() -> str:
    """The more-worlds benchmark per task, from its result file."""
    return benchmark_table((WORLDS_FILE,))


@table("learning_timelimit")
def timelimit_table() -> str:
    """The time-limit benchmark per task, from its result file (or its ``--finished-only``
    report while runs are pending)."""
    return benchmark_table((TIMELIMIT_FILE,))


def report_file(path: Path) -> Path | None:
    """A benchmark's report: ``path`` (``learning.json``, all runs finished), else the
    ``--finished-only`` report beside it (``learning_partial.json``), else None."""
    partial = path.with_name(f"{path.stem}_partial{path.suffix}")
    return path if path.exists() else partial if partial.exists() else None


def pending_seeds(doc: dict, task: str) -> list[int]:
    """The seeds of ``task`` a partial report names as not finished when it was written."""
    return [p["seed"] for p in doc.get("pending", []) if p["task"] == task]


def benchmark_table(paths: tuple[Path, ...]) -> str:
    """One row per task of each learning-benchmark file in ``paths`` (final policies over
    seeds, against the scripted baseline and the zero action)."""
    lines = [
        "| task | seeds | env steps; updates / env step | final success per seed | IQM [95 % CI] "
        "| seeds >= 0.95 | collapsed | mean F_z minus baseline, N | zero action: success / mean "
        "F_z | final minus zero action: success; mean F_z, N | file |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for declared in paths:
        path = report_file(declared)
        if path is None:
            lines.append(f"| pending | | | | | | | | | | `{rel(declared)}` |")
            continue
        doc = json.loads(path.read_text())
        for t in doc["tasks"]:
            name = t["task"]
            waiting = pending_seeds(doc, name)
            seeds = f"{t['seeds'][0]}-{t['seeds'][-1]}" + (
                f" (pending: {' '.join(map(str, waiting))})" if waiting else ""
            )
            if name == "MeshExtract":  # a shape: its folder names it
                name = f"MeshExtract ({path.parent.name})"
            n = len(t["seeds"])
            zero = t.get("zero_action")
            zero_cell = (
                "-" if zero is None else f"{zero['success_rate']:.3f} / {zero['mean_fz_N']:.3g} N"
            )
            learned = (
                "-"
                if zero is None
                else f"{t['final_minus_zero_action_success']:+.3f} "
                f"{_ci_text(t['final_minus_zero_action_success_ci95'], '+.3f')}; "
                f"{t['final_minus_zero_action_mean_fz_N']:+.3g} "
                f"{_ci_text(t['final_minus_zero_action_mean_fz_ci95'], '+.3g')}"
            )
            lines.append(
                f"| {name} | {seeds} | {t['config']['num_timesteps'] / 1e3:g}k; "
                f"{t['updates_per_env_step']:g} | "
                f"{' '.join(f'{v:.2f}' for v in t['final_success'])} | "
                f"{t['final_success_iqm']:.2f} {_ci_text(t['final_success_ci95'], '.2f')} | "
                f"{round(t['share_at_95'] * n)} of {n} | "
                f"{len(t['seeds_collapsed'])} of {n} | "
                f"{t['mean_fz_minus_baseline_N']:+.3g} "
                f"{_ci_text(t['mean_fz_minus_baseline_ci95'], '+.3g')} | {zero_cell} | "
                f"{learned} | [`{path.parent.name}/{path.name}`]({rel(path)}) |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, type=Path, help="results folder (runs inside)")
    p.add_argument(
        "--stack",
        choices=stacks.STACKS,
        default="ours",
        help="ours (default), seed (PyBullet + SB3 SAC, the thesis's settings) or sb3 (SB3 "
        "SAC's defaults on our Gymnasium adapter)",
    )
    p.add_argument(
        "--tasks", nargs="+", default=None, help=f"default {' '.join(TASKS)} (seed: Rect*)"
    )
    p.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    p.add_argument("--profile", default="cpu", help="training profile (default cpu)")
    p.add_argument(
        "--engine", default="auto", help="physics engine (default auto; sb3: auto is mujoco)"
    )
    p.add_argument("--num-timesteps", type=int, default=None, help="budget (default: profile's)")
    p.add_argument("--eval-every", type=int, default=1600, help="env steps between evaluations")
    p.add_argument("--eval-episodes", type=int, default=64, help="episodes per evaluation")
    p.add_argument("--final-episodes", type=int, default=256, help="final policy's episodes")
    p.add_argument("--final-seed", type=int, default=20_000, help="seed of the final episodes")
    p.add_argument("--set", dest="sets", action="append", help="KEY=VALUE training override")
    p.add_argument(
        "--reward",
        choices=REWARD_KINDS,
        default="outcome",
        help="the reward the learners train on (ours, sb3; default outcome, the protocol's; the "
        "seed stack pays eq (4.4) always)",
    )
    p.add_argument(
        "--finished-only",
        action="store_true",
        help="train nothing: report the seeds whose runs have finished (their final policies "
        "evaluated if not yet) to <stem>_partial.json/.csv, naming the pending ones (ours only)",
    )
    args = p.parse_args(argv)
    command = ["python", "-m", "benchmarks.evals.learning", *(argv or sys.argv[1:])]
    if args.tasks is None:
        allowed = stacks.STACK_TASKS.get(args.stack)
        args.tasks = list(allowed if allowed is not None else TASKS)
    args.command = command
    if args.stack != "seed" and not any(
        s.startswith("env.reward_config.kind=") for s in args.sets or []
    ):  # the protocol's reward, whatever training's default is
        args.sets = [*(args.sets or []), f"env.reward_config.kind={args.reward}"]
    try:
        stacks.check_args(args)
        if args.finished_only and args.stack != "ours":
            raise UserInputError("--finished-only reports our stack's runs only (--stack ours)")
        return _run(args, command)
    except UserInputError as exc:
        print(f"learning: error: {exc}", file=sys.stderr)
        return 2


def _run(args, command: list[str]) -> int:
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    # the provenance of the code that starts the runs (a commit made while they run is not
    # theirs); each run's own commit is in its run.json and per_seed's ``run_commit``
    prov = (
        run_provenance(command) if args.stack == "ours" else stacks.provenance(args.stack, command)
    )
    units = [(t, s) for t in args.tasks for s in args.seeds]
    pending = []
    if args.finished_only:  # a run has finished when it wrote its summary.json
        pending = [(t, s) for t, s in units if not (_run_dir(out, t, s) / "summary.json").exists()]
        units = [u for u in units if u not in pending]
    results: dict[str, list[dict]] = {t: [] for t, _ in units}
    for task, seed in tqdm(units, desc="learning benchmark (task x seed)", file=sys.stderr):
        results[task].append(run_seed(task, seed, args, out))
    tasks = []
    # ours keeps its file names (learning.json, curves_TASK.png); a stack its own beside them
    stem = "learning" if args.stack == "ours" else f"learning_{args.stack}"
    curves = "curves_" if args.stack == "ours" else f"curves_{args.stack}_"
    if args.finished_only:
        stem, curves = f"{stem}_partial", f"{curves}partial_"
    for task, per_seed in results.items():
        summary = task_summary(task, per_seed)
        if args.stack == "ours":
            zero = zero_action_eval(task, per_seed[0]["seed"], args, out)
            summary |= zero_action_summary(zero, per_seed)
        cfg = per_seed[0]["config"]
        over = cfg["env_overrides"]
        if args.stack == "ours":
            engine, kind = engine_label(over), over.get("reward_config.kind", "thesis")
            # one batched env step of num_envs worlds, then grad_updates_per_step SGD steps
            upe = cfg["grad_updates_per_step"] / cfg["num_envs"]
        else:
            engine, kind, upe = cfg["engine"], cfg["reward_kind"], cfg["updates_per_env_step"]
        summary |= {
            "engine": engine,
            "reward_kind": kind,
            "updates_per_env_step": upe,
            "config": {k: v for k, v in cfg.items() if k != "seed"},
            "per_seed": per_seed,
        }
        title = task if args.stack == "ours" else f"{task} ({args.stack})"
        plot_task(task, per_seed, out / f"{curves}{task}.png", title)
        tasks.append(summary)
    doc = {
        "benchmark": "learning",
        "stack": args.stack,
        "stack_description": stacks.STACK_NAMES[args.stack],
        "target_success": TARGET,
        "collapse_margin": COLLAPSE_MARGIN,
        "final_episodes": args.final_episodes,
        "final_seed": args.final_seed,
        "eval_every": args.eval_every,
        "eval_episodes": args.eval_episodes,
        "tasks": tasks,
        # --finished-only: the (task, seed) runs not finished when this file was written
        "partial": bool(args.finished_only),
        "pending": [{"task": t, "seed": s} for t, s in pending],
        # the provenance rule (benchmarks/provenance_rule.py): each task's full training config
        "config": "see tasks; each task's full training config is its entry's 'config'",
        **prov,
    }
    fileio.write_text(out / f"{stem}.json", dumps(doc, indent=2) + "\n")
    rows = []
    for t in tasks:
        ci, mci = t["final_success_ci95"], t["mean_fz_minus_baseline_ci95"] or [None, None]
        rows.append(
            {
                "task": t["task"],
                "seeds": " ".join(map(str, t["seeds"])),
                "final_success_iqm": t["final_success_iqm"],
                "final_success_ci95_lo": ci[0],
                "final_success_ci95_hi": ci[1],
                "share_at_95": t["share_at_95"],
                "seeds_collapsed": " ".join(map(str, t["seeds_collapsed"])),
                "steps_to_95_median": (t["steps_to_95"] or {}).get("median"),
                "clock_to_95_median_s": (t["clock_to_95_s"] or {}).get("median"),
                "reached_95": t["reached_95"],
                "at_95_untrained": t["at_95_untrained"],
                "mean_fz_minus_baseline_N": t["mean_fz_minus_baseline_N"],
                "mean_fz_ci95_lo": mci[0],
                "mean_fz_ci95_hi": mci[1],
                "peak_fz_minus_baseline_N": t["peak_fz_minus_baseline_N"],
                "untrained_mean_fz_N": t["untrained_mean_fz_N"],
                "final_mean_fz_N": t["final_mean_fz_N"],
                "zero_action_success": (t.get("zero_action") or {}).get("success_rate"),
                "zero_action_mean_fz_N": (t.get("zero_action") or {}).get("mean_fz_N"),
                "final_minus_zero_action_mean_fz_N": t.get("final_minus_zero_action_mean_fz_N"),
                "engine": t["engine"],
                "reward_kind": t["reward_kind"],
                "device": prov["device"],
                "date": prov["date"],
                "commit": prov["commit"],
                "stack": args.stack,
                "updates_per_env_step": t["updates_per_env_step"],
            }
        )
    write_rows(out / f"{stem}.csv", rows, CSV_FIELDS)
    print(f"wrote {out / f'{stem}.json'} and {out / f'{stem}.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
