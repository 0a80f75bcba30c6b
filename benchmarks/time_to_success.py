"""Time to success of our stack (MJX + Brax SAC) on the seed stack's task, measured alike.

The counterpart of ``benchmarks/seed_stack.py``: the same task (RectExtract, rect-2, the 9-D
observation and the 6-D action of eq 4.3 with the fixed stiffness, i.e. the compliance
strategy off, the env's default 15 s episodes), the same success threshold (0.95) and the
same clock: training wall time (JIT compilation, replay prefill, env steps and gradient
updates) without the evaluations' time. It trains with the ``cpu`` profile of
``train/configs/RectExtract.json`` (``full`` on a GPU) and evaluates every ``--eval-every``
env steps on ``--eval-episodes`` episodes, stopping at the first evaluation that reaches
the threshold (or at ``--max-steps``). The time is known to the evaluation interval.

Writes ``benchmarks/results/train_rect_<device>.json`` (``cpu-2core``, ``gpu-h100``, ...), read by
``benchmarks/readme_tables.py`` and ``benchmarks/plot.py``. Run:
``python -m benchmarks.time_to_success`` (the training run goes to ``--out``).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from benchmarks.bench_common import RESULTS, device_label, utc_now

THRESHOLD = 0.95


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("runs/time_to_success_rect"))
    ap.add_argument("--profile", choices=("auto", "cpu", "full"), default="auto")
    ap.add_argument("--eval-every", type=int, default=3200, help="env steps between evals")
    ap.add_argument("--eval-episodes", type=int, default=32)
    ap.add_argument("--max-steps", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

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
    }
    cfg = load_train_config("RectExtract", profile, overrides, compliance_strategy=False)
    run = TrainingRun(cfg, args.out, progress=True, render=False, stop_at_success=THRESHOLD)
    summary = run.run(resume=False)

    with (args.out / "metrics.csv").open() as f:
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
    result = {
        "stack": "MJX + Brax SAC (peghole_mjx.training)",
        "task": "RectExtract (rect-2, 150 mm pull, 15 s limit), compliance strategy off",
        "device": device,
        "versions": prov["versions"],
        "date": utc_now(),
        "command": "python -m benchmarks.time_to_success"
        + ("" if args.profile == "auto" else f" --profile {args.profile}"),
        "profile": profile,
        "config": cfg.as_dict(),
        "success_threshold": THRESHOLD,
        "time_to_success_s": summary["time_to_95pct_success_train_s"],
        "time_to_success_with_eval_s": summary["time_to_95pct_success_s"],
        "env_steps_to_success": summary["step_at_95pct_success"],
        "reached_threshold": summary["time_to_95pct_success_s"] is not None,
        "final_success_rate": float(last["eval/success_rate"]),
        "train_wall_s": round(train_s, 1),
        "env_steps": int(last["step"]),
        "train_env_steps_per_s": round(int(last["step"]) / max(train_s, 1e-9), 1),
        "eval_episodes": args.eval_episodes,
        "eval_every_steps": args.eval_every,
        "curve": curve,
        "note": "training clock without evaluations, JIT compilation and replay prefill "
        "included; the time is known to the evaluation interval",
    }
    out = RESULTS / f"train_rect_{label}.json"
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("time_to_success_s", "env_steps", "device")}))
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
