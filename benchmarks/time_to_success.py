"""Time to success of our stack (MJX + Brax SAC) on the seed stack's task, measured alike.

The counterpart of ``benchmarks/seed_stack.py``: the same task (``--env``: RectExtract, rect-2,
by default, or RectExtractHard, rect-3 with +-4 deg commanded tilt error; the 9-D observation
and the 6-D action of eq 4.3 with the fixed stiffness, i.e. the compliance strategy off, the
env's default 15 s episodes), the same success threshold (0.95) and the same clock: training
wall time (JIT compilation, replay prefill, env steps and gradient updates) without the
evaluations' time. It trains with the ``cpu`` profile of ``train/configs/<env>.json``
(``full`` on a GPU) and evaluates every ``--eval-every`` env steps on ``--eval-episodes``
episodes, stopping at the first evaluation that reaches the threshold, at ``--max-steps``, or
once the training clock reaches ``--budget-s`` (after a last evaluation). The time is known to
the evaluation interval.

Writes ``benchmarks/results/train_rect_<device>.json`` for RectExtract (``cpu-2core``,
``gpu-h100``, ...) and ``train_<env>_<device>.json`` for another env, read by
``benchmarks/readme_tables.py`` and ``benchmarks/plot.py``. Run:
``python -m benchmarks.time_to_success`` (the training run goes to ``--out``).

:func:`compare` sets the two stacks side by side: the threshold (0.95, or the best success
the seed stack reached if it never reached 0.95), each stack's time to it, and the ratio.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

from benchmarks.bench_common import RESULTS, device_label, load_average, utc_now
from benchmarks.hard_variants import parse_overrides
from benchmarks.seed_stack import DEFAULT_ENV, task_line

THRESHOLD = 0.95


def result_path(env: str, label: str, engine: str = "mjx") -> Path:
    """``train_rect_<label>.json`` for RectExtract, ``train_<env>_<label>.json`` else; with
    ``engine`` other than mjx, ``..._<engine>_<label>.json``."""
    name = "train_rect" if env == DEFAULT_ENV else f"train_{env}"
    if engine != "mjx":
        name = f"{name}_{engine}"
    return RESULTS / f"{name}_{label}.json"


def _points(result: dict) -> list[tuple[float, float]]:
    """(training clock s, evaluation success rate) of a result's curve, either stack."""
    pts = []
    for p in result.get("curve", []):
        if "eval" in p:  # seed stack (benchmarks/seed_stack.py)
            pts.append((float(p["train_s"]), float(p["eval"]["success_rate"])))
        else:  # ours
            pts.append((float(p["train_wall_s"]), float(p["eval_success_rate"])))
    return pts


def first_time_at(points: list[tuple[float, float]], threshold: float) -> float | None:
    """Training clock of the first evaluation at or above ``threshold`` (None: never)."""
    return next((t for t, s in points if s >= threshold), None)


def compare(seed: dict, ours: dict, target: float = THRESHOLD) -> dict:
    """Time to success of both stacks at one threshold, and the ratio seed stack / ours.

    The threshold is ``target`` if the seed stack's evaluations reached it, else the best
    success rate they reached (``rule`` says which); None when the seed stack never
    succeeded in an evaluation. ``ratio`` > 1: ours is faster; None when either stack did not
    reach the threshold (``verdict`` says which).
    """
    seed_pts, our_pts = _points(seed), _points(ours)
    best_seed = max((s for _, s in seed_pts), default=0.0)
    best_ours = max((s for _, s in our_pts), default=0.0)
    if best_seed >= target:
        threshold, rule = target, f"{target:g} (reached by the seed stack)"
    elif best_seed > 0.0:
        threshold = best_seed
        rule = f"the seed stack's best success {best_seed:g} (it never reached {target:g})"
    else:
        threshold, rule = None, "none: the seed stack never succeeded in an evaluation"
    t_seed = first_time_at(seed_pts, threshold) if threshold is not None else None
    t_ours = first_time_at(our_pts, threshold) if threshold is not None else None
    if threshold is None:
        verdict = "no comparison: the seed stack never succeeded in an evaluation"
    elif t_ours is None:
        verdict = f"ours never reached {threshold:g} within its budget"
    else:
        verdict = f"both reached {threshold:g}"
    ratio = t_seed / t_ours if t_seed is not None and t_ours else None
    return {
        "threshold": threshold,
        "rule": rule,
        "seed_best_success": best_seed,
        "ours_best_success": best_ours,
        "seed_time_s": t_seed,
        "ours_time_s": t_ours,
        "ratio_seed_over_ours": ratio,
        "verdict": verdict,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--env", default=DEFAULT_ENV, help="RectExtract or RectExtractHard")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/...)")
    ap.add_argument("--profile", choices=("auto", "cpu", "full"), default="auto")
    ap.add_argument(
        "--engine",
        choices=("mjx", "mujoco"),
        default="mjx",
        help="physics engine of the env (docs/engines.md); mujoco writes train_..._mujoco_...",
    )
    ap.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a training config override (Python literal value), declared before the run",
    )
    ap.add_argument("--eval-every", type=int, default=3200, help="env steps between evals")
    ap.add_argument("--eval-episodes", type=int, default=32)
    ap.add_argument("--max-steps", type=int, default=200_000)
    ap.add_argument(
        "--budget-s", type=float, default=None, help="training clock budget, s (default: none)"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--note", default="", help="added to the result's note (e.g. CPU load)")
    args = ap.parse_args(argv)
    from benchmarks.pybullet_peghole import PYBULLET_ENVS

    if args.env not in PYBULLET_ENVS:  # the task must be one the seed stack rebuilds
        print(
            f"time_to_success: error: the seed-stack task is one of {list(PYBULLET_ENVS)}, "
            f"not {args.env!r}",
            file=sys.stderr,
        )
        return 2
    out_dir = args.out or Path(
        "runs/time_to_success_rect"
        if args.env == DEFAULT_ENV
        else f"runs/time_to_success_{args.env}"
    )
    if args.engine != "mjx":
        out_dir = out_dir.with_name(f"{out_dir.name}_{args.engine}")

    import jax

    from peghole_mjx.control import LIMITS
    from peghole_mjx.provenance import provenance
    from peghole_mjx.training.config import load_train_config
    from peghole_mjx.training.run import TrainingRun

    gpu = jax.default_backend() != "cpu"
    profile = ("full" if gpu else "cpu") if args.profile == "auto" else args.profile
    overrides = {
        "eval_every": args.eval_every,
        "num_eval_envs": args.eval_episodes,
        "num_timesteps": args.max_steps,
        "seed": args.seed,
        # the task measured so far: the action's full speed limit (the cpu/full profiles
        # train the published policy at 25 mm/s)
        "env.action.max_speed_m_s": LIMITS.max_speed_m_s,
        "env.engine": args.engine,
    }
    overrides.update(parse_overrides(args.sets))
    cfg = load_train_config(args.env, profile, overrides, compliance_strategy=False)
    load0 = load_average()
    run = TrainingRun(
        cfg,
        out_dir,
        progress=True,
        render=False,
        stop_at_success=THRESHOLD,
        budget_train_s=args.budget_s,
    )
    summary = run.run(resume=False)

    with (out_dir / "metrics.csv").open() as f:
        rows = list(csv.DictReader(f))
    curve = [
        {
            "step": int(r["step"]),
            "train_wall_s": round(float(r["train_wall_s"]), 1),
            "wall_s": round(float(r["wall_s"]), 1),
            "eval_success_rate": float(r["eval/success_rate"]),
        }
        for r in rows
    ]
    prov = provenance()
    device = prov["device"]
    label = device_label(jax.devices()[0].device_kind if gpu else None)
    last = rows[-1]
    train_s = float(last["train_wall_s"])
    command = (
        "python -m benchmarks.time_to_success"
        + "".join(
            f" {flag} {value}"
            for flag, value, default in (
                ("--env", args.env, DEFAULT_ENV),
                ("--profile", args.profile, "auto"),
                ("--engine", args.engine, "mjx"),
                ("--budget-s", args.budget_s, None),
                ("--max-steps", args.max_steps, 200_000),
                ("--eval-every", args.eval_every, 3200),
                ("--eval-episodes", args.eval_episodes, 32),
            )
            if value != default
        )
        + "".join(f" --set {item}" for item in args.sets)
    )
    note = (
        "training clock without evaluations, JIT compilation and replay prefill "
        "included; the time is known to the evaluation interval"
    )
    result = {
        "stack": "MJX + Brax SAC (peghole_mjx.training)",
        "env": args.env,
        "task": task_line(args.env, run.env.config),
        "device": device,
        "versions": prov["versions"],
        "date": utc_now(),
        "command": command,
        "profile": profile,
        "engine": args.engine,
        "updates_per_env_step": cfg.grad_updates_per_step / cfg.num_envs,
        "config": cfg.as_dict(),
        "budget_s": args.budget_s,
        "success_threshold": THRESHOLD,
        "time_to_success_s": summary["time_to_95pct_success_train_s"],
        "time_to_success_with_eval_s": summary["time_to_95pct_success_s"],
        "env_steps_to_success": summary["step_at_95pct_success"],
        "reached_threshold": summary["time_to_95pct_success_s"] is not None,
        "final_success_rate": float(last["eval/success_rate"]),
        "best_success_rate": max(p["eval_success_rate"] for p in curve),
        "train_wall_s": round(train_s, 1),
        "env_steps": int(last["step"]),
        "train_env_steps_per_s": round(int(last["step"]) / max(train_s, 1e-9), 1),
        "eval_episodes": args.eval_episodes,
        "eval_every_steps": args.eval_every,
        "load_average_before": load0,
        "load_average_after": load_average(),
        "curve": curve,
        "note": f"{note}; {args.note}" if args.note else note,
    }
    out = result_path(args.env, label, args.engine)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("time_to_success_s", "env_steps", "device")}))
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
