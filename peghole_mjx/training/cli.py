"""The parsers of ``peghole train``, ``peghole evaluate`` and ``peghole compare``; the commands
are in :mod:`peghole_mjx.training.commands`, imported when one runs (:mod:`peghole_mjx.core.lazy`:
``peghole --help`` does not import the learner)."""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg, key_value
from peghole_mjx.envs import ENV_NAMES
from peghole_mjx.envs.mesh_extract import absolute_task
from peghole_mjx.sim.engines import CLI_ENGINES, engine_overrides
from peghole_mjx.training.config import (
    MAX_SEEDS,
    TRAINING_ENV_DEFAULTS,
    TrainConfig,
    load_train_config,
)

COMMANDS = "peghole_mjx.training.commands"


def run_dir(text: str) -> Path:
    """A ``--out`` / ``--resume`` folder: an empty or blank path is refused (``Path("")`` is the
    current folder, where a run would write over whatever is there)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            "an empty path is not a run folder (it would be the current folder): give a folder"
        )
    return Path(text)


def seed_count(text: str) -> int:
    """``--seeds N``: a whole number in [1, ``MAX_SEEDS``] (a run of more seeds could not be
    read back: run.json's limit)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if not 1 <= n <= MAX_SEEDS:
        raise argparse.ArgumentTypeError(f"must be a whole number in [1, {MAX_SEEDS}], got {n}")
    return n


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``train``, ``evaluate`` and ``compare`` to ``sub``."""
    engine_help = (
        "physics engine: mjx (MuJoCo MJX), mjx-warp (MuJoCo Warp: CUDA GPU; a CPU runs one "
        "world slowly), mujoco (MuJoCo C on mujoco.batch threads), auto (mujoco where JAX "
        "has no GPU; on a CUDA GPU mjx-warp with warp-lang, else mjx)"
    )
    t = sub.add_parser(
        "train",
        help="train a SAC policy (Brax) on an extraction env",
        description="Brax SAC on an extraction env (RectExtract, DualExtract, their Hard variants) "
        "with evaluation, metrics.csv, TensorBoard logs and a checkpoint at every "
        "evaluation; writes learning curves, a rollout GIF and summary.json at the end. "
        "Hyperparameters: train/configs/<ENV>.json (profiles full | cpu | quick). Uses all "
        "local GPUs (pmap).",
    )
    t.add_argument("--env", choices=ENV_NAMES, help="required unless --resume")
    t.add_argument(
        "--compliance-strategy",
        choices=("on", "off"),
        default=None,
        help="on: the action also sets the lateral stiffness k_xy and the rotational stiffness "
        "K_theta (RL + CS, thesis Sec 4.2; docs/guide/training.md); off: fixed stiffness. "
        "A shorthand "
        "for --set env.compliance_strategy=true|false (default: "
        f"{'on' if TRAINING_ENV_DEFAULTS['compliance_strategy'] else 'off'}, "
        "training/config.py TRAINING_ENV_DEFAULTS)",
    )
    t.add_argument(
        "--engine",
        choices=CLI_ENGINES,
        default=None,
        help=engine_help + "; recorded in run.json and the policy (engine: provenance, not "
        "the task). "
        "Default auto; with --resume only the run's own engine",
    )
    t.add_argument(
        "--profile",
        choices=("full", "cpu", "quick"),
        default=None,
        help="hyperparameter profile (default full); with --resume only the run's own",
    )
    t.add_argument(
        "--quick",
        action="store_true",
        help="same as --profile quick (CPU smoke run); another --profile is refused",
    )
    t.add_argument(
        "--out",
        type=run_dir,
        help="run directory: a new or empty folder (required unless --resume)",
    )
    t.add_argument("--resume", type=run_dir, metavar="DIR", help="continue the run in DIR")
    t.add_argument(
        "--set",
        dest="overrides",
        type=key_value,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="hyperparameter override, e.g. --set num_envs=64; env.KEY=VALUE for the env config",
    )
    t.add_argument(
        "--distributed",
        action="store_true",
        help="experimental: one of several processes training one learner (jax.distributed; "
        "coordinator, "
        "process count and index from JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, "
        "JAX_PROCESS_ID or the cluster launcher); give each process its own --out",
    )
    t.add_argument(
        "--seeds",
        type=seed_count,
        default=None,
        metavar="N",
        help="train N seeds (seed, seed+1, ...) in one compiled call (make_train vmapped over "
        "the seeds' keys): per-seed policies, history.csv, seeds.json with 95 %% intervals over "
        "seeds and banded curves (training/seeds.py); resumable with --resume DIR",
    )
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument("--no-video", action="store_true", help="skip the final rollout GIF")
    t.add_argument(
        "--stop-at-success",
        type=arg("success_rate"),
        metavar="RATE",
        help="end the run at the first evaluation with at least this success rate "
        "(benchmarks/baselines/time_to_success.py uses 0.95)",
    )
    t.set_defaults(func=command(f"{COMMANDS}:cmd_train"))

    e = sub.add_parser(
        "evaluate",
        help="evaluate a policy against the scripted baseline on the same episodes",
        description="Runs the policy and the scripted fixed-compliance baseline (thesis Ch 2-3 "
        "method) on the same randomised episodes and reports success_rate, mean_time_s, "
        "mean_fz_N, peak_fz_N, mean_fxy_N for each, and the force reduction beside the "
        "thesis's R3-R5. CHECKPOINT: a policy directory, a training run directory, or a "
        "pretrained name (rect, dual, rect_hard, dual_hard); several are evaluated on the same "
        "episodes (the baseline run once per env), and --json / --out then give a list.",
    )
    e.add_argument("checkpoint", nargs="+")
    e.add_argument(
        "--env",
        choices=ENV_NAMES,
        help="the env the policy must have been trained on (refused in one line if not)",
    )
    e.add_argument(
        "--preset",
        help="evaluate on this preset; refused unless it is the policy's training preset, or "
        "--cross is given",
    )
    e.add_argument(
        "--set",
        dest="env_sets",
        type=key_value,
        action="append",
        default=[],
        metavar="env.KEY=VALUE",
        help="an env config entry for this evaluation, e.g. --set env.action.max_ff_xy_N=0.5 "
        "or --set 'env.geometry={\"peg_w_mm\": 59.8}'; refused unless it equals the training "
        "value, or --cross is given",
    )
    e.add_argument(
        "--cross",
        action="store_true",
        help="evaluate the policy in an env other than its training env (--preset, --set): "
        "the result records the differences (differs_from_training); written to --out only, "
        "never into a policy folder",
    )
    e.add_argument(
        "--engine",
        choices=CLI_ENGINES,
        default=None,
        help=engine_help + ". Default auto (a policy file from before 2026-12-05: the engine "
        "it recorded); any engine evaluates the policy as trained (the engine is not the task)",
    )
    e.add_argument(
        "--policy-only",
        action="store_true",
        help="skip the scripted baseline (no force reduction)",
    )
    e.add_argument("--episodes", type=arg("episodes"), default=256)
    e.add_argument("--seed", type=arg("seed"), default=0)
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.add_argument("--out", type=Path, help="also write the JSON object to this file")
    e.add_argument(
        "--batch",
        type=arg("batch"),
        metavar="N",
        help="run at most N episodes at once (default: all); the episodes are the same",
    )
    e.add_argument(
        "--parts",
        type=Path,
        metavar="DIR",
        help="save each finished batch in DIR; rerunning the same command loads them and "
        "runs only the rest (long evaluations survive an interruption)",
    )
    e.set_defaults(func=command(f"{COMMANDS}:cmd_evaluate"))

    c = sub.add_parser(
        "compare",
        help="plot the learning curves of several runs on shared axes (Figs 4.5-4.7)",
    )
    c.add_argument("runs", nargs="+", type=Path, help="training run directories")
    c.add_argument("--out", type=Path, required=True, help="PNG to write")
    c.set_defaults(func=command(f"{COMMANDS}:cmd_compare"))


def train_config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The :class:`TrainConfig` of a fresh ``peghole train``: ``load_train_config`` with the
    flags given (an unset ``--compliance-strategy`` leaves training's default,
    ``TRAINING_ENV_DEFAULTS``)."""
    if not args.env:
        raise UserInputError("--env and --out are required (or --resume DIR)")
    cs = None if args.compliance_strategy is None else args.compliance_strategy == "on"
    overrides = absolute_task(dict(args.overrides), "env.task")
    engine = getattr(args, "engine", None)
    if engine is not None:  # --engine and --set env.engine / env.impl must agree
        for key, value in engine_overrides(engine).items():
            if f"env.{key}" in overrides and overrides[f"env.{key}"] != value:
                raise UserInputError(
                    f"--engine {engine} and --set env.{key}={overrides[f'env.{key}']} "
                    "contradict each other: give one of them"
                )
    if "env.engine" not in overrides:
        eng = engine_overrides(engine or "auto")
        overrides = {**{f"env.{k}": v for k, v in eng.items()}, **overrides}
    return load_train_config(
        args.env,
        profile=chosen_profile(args),
        overrides=overrides,
        compliance_strategy=cs,
    )


def chosen_profile(args: argparse.Namespace) -> str:
    """The profile of ``--profile`` and ``--quick`` (default full); ``--quick`` with another
    ``--profile`` is refused in one line (decided 2026-12-04: contradicting flags are refused,
    neither wins)."""
    profile = getattr(args, "profile", None)
    if getattr(args, "quick", False):
        if profile not in (None, "quick"):
            raise UserInputError(
                f"--quick and --profile {profile} contradict each other: give one of them"
            )
        return "quick"
    return profile or "full"
