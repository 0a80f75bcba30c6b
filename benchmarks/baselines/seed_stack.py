"""The thesis's learning pipeline as a baseline: PyBullet RectExtract + Stable-Baselines3 SAC.

One environment (``benchmarks/baselines/pybullet_peghole.py``: the same observation, action,
reward, limits, randomisation and episode length as the registered env ``--env``, ``RectExtract``
(default, rect-2) or ``RectExtractHard`` (rect-3, +-4 deg commanded tilt error), its config
taken from ``peghole_mjx.envs.get_default_config``; peg-hole as boxes, the impedance law in
joint-torque control, compliance strategy off: 6-D action, fixed stiffness), trained by
SB3 SAC with the thesis's settings: ``MlpPolicy``, ``gamma 0.99``, ``ent_coef 0.2``,
``buffer_size 100_000``, ``train_freq 50``; every other setting is SB3's default
(``gradient_steps 1`` per ``train_freq``, ``batch_size 256``, ``learning_rate 3e-4``,
``learning_starts 100``), each exposed as an option. Torch runs on one CPU thread
(``--torch-threads``).

Mode: a fixed wall-clock budget (``--budget-s``). The clock counts training only (env steps
+ updates); every ``--eval-every-s`` of it, training pauses for ``--eval-episodes``
deterministic episodes, whose time is not counted. Reported: the success rate reached (last
evaluation, and the rolling rate of the last 20 training episodes) and the training wall clock
at which an evaluation first reached ``--threshold`` (default 0.95), or null if never.
The time to the threshold is known to the evaluation interval (15 s by default).
Writes ``benchmarks/results/baselines/seed_stack_<device>.json`` for RectExtract and
``seed_stack_<env>_<device>.json`` for another env (device, versions, date, note, load).

Needs the ``bench`` extra: ``pip install torch==2.13.0`` (CPU wheel) then
``pip install -e '.[bench]'``. Run: ``python -m benchmarks.baselines.seed_stack --budget-s 600
--stop-at-threshold`` (without ``--stop-at-threshold`` it trains for the whole budget).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import deque
from pathlib import Path

import numpy as np

from benchmarks.baselines.pybullet_peghole import env_config, make_gym_env
from benchmarks.common import (
    BASELINES_RESULTS,
    cpu_device,
    cpu_label,
    load_average,
    out_file,
    utc_now,
    versions_dict,
)
from peghole_mjx.core.errors import UserInputError

#: the thesis's SAC settings; everything else is SB3's default
SAC_SETTINGS = {
    "policy": "MlpPolicy",
    "gamma": 0.99,
    "ent_coef": 0.2,
    "buffer_size": 100_000,
    "train_freq": 50,
}


def evaluate(model, env, episodes: int) -> dict:
    """Deterministic episodes: success rate, mean return, mean length."""
    succ, rets, lens = [], [], []
    for _ in range(episodes):
        obs, _ = env.reset()
        ret, n, done, info = 0.0, 0, False, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, r, term, trunc, info = env.step(action)
            ret += r
            n += 1
            done = term or trunc
        succ.append(bool(info.get("is_success", False)))
        rets.append(ret)
        lens.append(n)
    return {
        "success_rate": float(np.mean(succ)),
        "mean_return": float(np.mean(rets)),
        "mean_length": float(np.mean(lens)),
    }


def make_callback(args, eval_env, log):
    """SB3 callback: the training clock without evaluations, evaluations, the budget stop."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Budget(BaseCallback):
        """Training clock (evaluations excluded), periodic evaluation, budget stop."""

        def __init__(self):
            super().__init__()
            self.paused = 0.0
            self.t0 = None
            self.next_eval = args.eval_every_s
            self.window: deque = deque(maxlen=20)
            self.episodes = 0
            self.time_to_threshold = None
            self.steps_to_threshold = None

        def train_s(self) -> float:
            return time.perf_counter() - self.t0 - self.paused

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _run_eval(self) -> None:
            t = time.perf_counter()
            res = evaluate(self.model, eval_env, args.eval_episodes)
            self.paused += time.perf_counter() - t
            point = {
                "train_s": round(self.train_s(), 1),
                "env_steps": int(self.num_timesteps),
                "episodes": self.episodes,
                "rolling_success_20": float(np.mean(self.window)) if self.window else 0.0,
                "eval": res,
                "eval_s": round(time.perf_counter() - t, 1),
            }
            log.append(point)
            print(json.dumps(point), flush=True)
            if self.time_to_threshold is None and res["success_rate"] >= args.threshold:
                self.time_to_threshold = point["train_s"]
                self.steps_to_threshold = point["env_steps"]

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if done:
                    self.episodes += 1
                    self.window.append(float(info.get("is_success", False)))
            s = self.train_s()
            if s >= self.next_eval:
                self._run_eval()
                self.next_eval += args.eval_every_s
                if self.time_to_threshold is not None and args.stop_at_threshold:
                    return False
            return s < args.budget_s

    return Budget()


#: the env whose results keep the original file names (committed before ``--env`` existed)
DEFAULT_ENV = "RectExtract"


def result_path(env: str, label: str) -> Path:
    """``seed_stack_<label>.json`` for RectExtract, ``seed_stack_<env>_<label>.json`` else."""
    return BASELINES_RESULTS / (
        f"seed_stack_{label}.json" if env == DEFAULT_ENV else f"seed_stack_{env}_{label}.json"
    )


def result_files(env: str = DEFAULT_ENV, results: Path = BASELINES_RESULTS) -> list[Path]:
    """The committed seed-stack training results for ``env`` (any device), read from each
    file's own ``stack`` and ``env`` fields (files before ``--env`` existed are RectExtract's),
    so other PyBullet results beside them (``seed_stack_dual_hull.json``) are never taken."""
    out = []
    for p in sorted(results.glob("seed_stack_*.json")):
        d = json.loads(p.read_text())
        if "stack" in d and d.get("env", DEFAULT_ENV) == env:
            out.append(p)
    return out


def task_line(env: str, config) -> str:
    """One line naming the task from the env's config (preset, tilt error, episode)."""
    r = config.randomization
    return (
        f"{env} ({config.preset}, commanded tilt error +-{r.angular_error_deg:g} deg, "
        f"{config.episode_length * config.ctrl_dt:g} s limit), compliance strategy off"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default=DEFAULT_ENV, help="RectExtract or RectExtractHard")
    ap.add_argument("--budget-s", type=float, default=600.0, help="training wall clock, s")
    ap.add_argument("--threshold", type=float, default=0.95, help="success rate to reach")
    ap.add_argument("--eval-every-s", type=float, default=15.0, help="training s between evals")
    ap.add_argument("--eval-episodes", type=int, default=20, help="95 %% needs 19 of 20")
    ap.add_argument("--stop-at-threshold", action="store_true")
    ap.add_argument("--gradient-steps", type=int, default=1, help="SB3 default: 1")
    ap.add_argument("--batch-size", type=int, default=256, help="SB3 default: 256")
    ap.add_argument("--learning-rate", type=float, default=3e-4, help="SB3 default: 3e-4")
    ap.add_argument("--learning-starts", type=int, default=100, help="SB3 default: 100")
    ap.add_argument(
        "--torch-threads",
        type=int,
        default=1,
        help="torch CPU threads (1: a small MLP gains nothing from more, and on a busy CPU "
        "2 threads made each policy call 30x slower here)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--note", default="")
    ap.add_argument("--out", type=out_file, default=None, help="default: result_path(env, device)")
    args = ap.parse_args(argv)
    out = args.out or result_path(args.env, cpu_label())
    try:
        config = env_config(args.env)
    except UserInputError as exc:
        print(f"seed_stack: error: {exc}", file=sys.stderr)
        return 2

    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(args.torch_threads)
    env = make_gym_env(args.env, seed=args.seed)
    eval_env = make_gym_env(args.env, seed=10_000 + args.seed)
    model = SAC(
        SAC_SETTINGS["policy"],
        env,
        gamma=SAC_SETTINGS["gamma"],
        ent_coef=SAC_SETTINGS["ent_coef"],
        buffer_size=SAC_SETTINGS["buffer_size"],
        train_freq=SAC_SETTINGS["train_freq"],
        gradient_steps=args.gradient_steps,
        batch_size=args.batch_size,
        learning_rate=args.learning_rate,
        learning_starts=args.learning_starts,
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    log: list[dict] = []
    cb = make_callback(args, eval_env, log)
    load0 = load_average()
    t0 = time.perf_counter()
    model.learn(total_timesteps=10**9, callback=cb, progress_bar=False)
    wall = time.perf_counter() - t0
    train_s = cb.train_s()
    if not log or log[-1]["env_steps"] != model.num_timesteps:
        cb._run_eval()  # the success rate reached at the end of the budget
    final = log[-1]
    result = {
        "stack": "PyBullet + Stable-Baselines3 SAC (the thesis's pipeline, rebuilt)",
        "env": args.env,
        "task": task_line(args.env, config),
        "env_config": config.to_dict(),
        "device": cpu_device(),
        "versions": versions_dict(),
        "date": utc_now(),
        "note": (
            args.note
            or "CPU possibly contended: other jobs may share the cores (load averages recorded)"
        ),
        "load_average_before": load0,
        "load_average_after": load_average(),
        "command": "python -m benchmarks.baselines.seed_stack " + " ".join(sys.argv[1:]),
        "sac": {
            **SAC_SETTINGS,
            "gradient_steps": args.gradient_steps,
            "batch_size": args.batch_size,
            "learning_rate": args.learning_rate,
            "learning_starts": args.learning_starts,
            "torch_threads": torch.get_num_threads(),
            "seed": args.seed,
        },
        "budget_s": args.budget_s,
        "success_threshold": args.threshold,
        "train_wall_s": round(train_s, 1),
        "total_wall_s_with_eval": round(wall, 1),
        "env_steps": int(model.num_timesteps),
        "train_env_steps_per_s": round(model.num_timesteps / max(train_s, 1e-9), 1),
        "episodes": cb.episodes,
        "final_success_rate": final["eval"]["success_rate"],
        "best_success_rate": max(pt["eval"]["success_rate"] for pt in log),
        "final_rolling_success_20": final["rolling_success_20"],
        "time_to_success_s": cb.time_to_threshold,
        "env_steps_to_success": cb.steps_to_threshold,
        "reached_threshold": cb.time_to_threshold is not None,
        "eval_episodes": args.eval_episodes,
        "curve": log,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2, default=list) + "\n")
    reached = (
        f"reached at {cb.time_to_threshold} s"
        if cb.time_to_threshold is not None
        else "not reached"
    )
    print(
        f"seed stack: {result['env_steps']} env steps in {result['train_wall_s']} s of training, "
        f"success {result['final_success_rate']:.2f} (threshold {args.threshold}: {reached}); "
        f"wrote {out}"
    )
    env.close()
    eval_env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
