"""``peghole train``, ``peghole evaluate`` and ``peghole compare``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from peghole_mjx import fileio
from peghole_mjx.errors import UserInputError
from peghole_mjx.validation import arg


def _override(text: str) -> tuple[str, object]:
    from peghole_mjx.envs.cli import _override as parse

    return parse(text)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from peghole_mjx.envs import ALL_ENVS
    from peghole_mjx.envs.engines import CLI_ENGINES
    from peghole_mjx.training.config import default

    engine_help = (
        "physics engine: mjx (MuJoCo MJX), mjx-warp (MuJoCo Warp, CUDA), mujoco (MuJoCo C on "
        "mujoco.batch threads), auto (mujoco where JAX has no GPU, else mjx)"
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
    t.add_argument("--env", choices=ALL_ENVS, help="required unless --resume")
    t.add_argument(
        "--compliance-strategy",
        choices=("on", "off"),
        default=None,
        help="on: the action also sets the lateral stiffness k_xy and the rotational stiffness "
        "K_theta (RL + CS, thesis Sec 4.2; docs/training.md); off: fixed stiffness (default: "
        f"{'on' if default('compliance_strategy') else 'off'}, TrainConfig.compliance_strategy)",
    )
    t.add_argument(
        "--engine",
        choices=CLI_ENGINES,
        default="auto",
        help=engine_help + "; recorded in run.json and the policy (env_overrides.engine). "
        "Default auto",
    )
    t.add_argument("--profile", choices=("full", "cpu", "quick"), default="full")
    t.add_argument("--quick", action="store_true", help="same as --profile quick (CPU smoke run)")
    t.add_argument("--out", type=Path, help="run directory (required unless --resume)")
    t.add_argument("--resume", type=Path, metavar="DIR", help="continue the run in DIR")
    t.add_argument(
        "--set",
        dest="overrides",
        type=_override,
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
        type=int,
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
        "(benchmarks/time_to_success.py uses 0.95)",
    )
    t.set_defaults(func=cmd_train)

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
        choices=ALL_ENVS,
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
        type=_override,
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
        help=engine_help + ". Default: the engine the policy was trained on; another is a "
        "cross evaluation (--cross)",
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
    e.set_defaults(func=cmd_evaluate)

    c = sub.add_parser(
        "compare",
        help="plot the learning curves of several runs on shared axes (Figs 4.5-4.7)",
    )
    c.add_argument("runs", nargs="+", type=Path, help="training run directories")
    c.add_argument("--out", type=Path, required=True, help="PNG to write")
    c.set_defaults(func=cmd_compare)


def train_config_from_args(args: argparse.Namespace):
    """The :class:`TrainConfig` of a fresh ``peghole train``: ``load_train_config`` with the
    flags given (an unset ``--compliance-strategy`` leaves TrainConfig's default)."""
    from peghole_mjx.training.config import load_train_config

    if not args.env:
        raise UserInputError("--env and --out are required (or --resume DIR)")
    from peghole_mjx.envs.engines import engine_overrides

    cs = None if args.compliance_strategy is None else args.compliance_strategy == "on"
    overrides = dict(args.overrides)
    if "env.engine" not in overrides:  # --set env.engine=... wins over --engine
        eng = engine_overrides(getattr(args, "engine", None) or "auto")
        overrides = {**{f"env.{k}": v for k, v in eng.items()}, **overrides}
    return load_train_config(
        args.env,
        profile="quick" if args.quick else args.profile,
        overrides=overrides,
        compliance_strategy=cs,
    )


def fresh_run_config(args: argparse.Namespace):
    """The config of a new run in ``--out`` (refused when ``--out`` already holds one)."""
    if not args.env or not args.out:
        raise UserInputError("--env and --out are required (or --resume DIR)")
    from peghole_mjx.training.run import failed_start

    cfg = train_config_from_args(args)
    fileio.check_out_dir(args.out)
    # a run that stopped before its first evaluation does not block its --out: the new run
    # replaces it, holding the run's lock (TrainingRun.prepare, SeedsRun.prepare)
    if (args.out / "run.json").exists() and not failed_start(args.out):
        raise UserInputError(
            f"{args.out} already holds a training run: use --resume {args.out} or a new --out"
        )
    return cfg


def cmd_train(args: argparse.Namespace) -> int:
    from peghole_mjx.training.lock import RunLock
    from peghole_mjx.training.run import TrainingRun

    progress = not args.no_progress
    if args.seeds is not None or (args.resume and _is_seeds_run(args.resume)):
        return _train_seeds(args, progress)
    if args.distributed:  # before anything of JAX runs
        from peghole_mjx.training.distributed import initialize

        initialize()
    if args.resume:
        over = dict(args.overrides)
        if args.env or set(over) - {"num_timesteps"}:
            raise UserInputError(
                "--resume takes the run's own config: drop --env and --set "
                "(only --set num_timesteps=N, to extend or end a run, is allowed)"
            )
        if not (args.resume / "run.json").exists():
            raise UserInputError(
                f"--resume: {args.resume / 'run.json'} not found (not a training run directory)"
            )
        with RunLock(args.resume) as lock:  # before anything of the run is read or written
            fileio.check_out_dir(args.resume, "--resume")
            run = TrainingRun.resume(
                args.resume,
                progress=progress,
                render=not args.no_video,
                num_timesteps=over.get("num_timesteps"),
            )
            run.lock = lock
            run.stop_at_success = args.stop_at_success
            summary = run.run(resume=True)
    else:
        cfg = fresh_run_config(args)
        with RunLock(args.out) as lock:
            run = TrainingRun(
                cfg,
                args.out,
                progress=progress,
                render=not args.no_video,
                stop_at_success=args.stop_at_success,
            )
            run.lock = lock
            summary = run.run(resume=False)
    fe = summary["final_eval"]
    untrained = summary["untrained_eval_return"]
    print(
        f"{summary['env']}: {summary['env_steps']} env steps in {summary['wall_s']} s; "
        f"eval success {_num(fe.get('success_rate'), '.3f')}, "
        f"return {_num(fe.get('mean_return'), '.2f')} "
        f"(untrained {_num(untrained, '.2f')}); outputs in {run.out}"
    )
    return 0


def _is_seeds_run(out: Path) -> bool:
    try:
        return "seeds" in json.loads((out / "run.json").read_text())
    except (OSError, ValueError, TypeError):
        return False


def _train_seeds(args: argparse.Namespace, progress: bool) -> int:
    """``peghole train --seeds N`` (or ``--resume`` of such a run): training/seeds.py."""
    from peghole_mjx.training.seeds import SeedsRun

    if args.distributed or args.stop_at_success is not None:
        raise UserInputError("--seeds takes neither --distributed nor --stop-at-success")
    if args.resume:
        if args.env or args.overrides or args.seeds is not None:
            raise UserInputError("--resume takes the run's own config: drop --env, --set, --seeds")
        fileio.check_out_dir(args.resume, "--resume")
        run = SeedsRun.resume(args.resume, progress=progress)
        summary = run.run(resume=True)
    else:
        cfg = fresh_run_config(args)
        run = SeedsRun(cfg, args.seeds, args.out, progress=progress)
        summary = run.run(resume=False)
    over = summary["final_eval_over_seeds"]
    for key in ("success_rate", "mean_fz_N", "mean_fxy_N"):
        ci = over.get(key, {}).get("ci95_t")
        ci_text = f" [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else ""
        print(f"{key}: mean over seeds {_num(over.get(key, {}).get('mean'), '.3g')}{ci_text}")
    print(f"{summary['env']}: {len(summary['seeds'])} seeds; outputs in {run.out}")
    return 0


def _num(v, fmt: str) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def cmd_evaluate(args: argparse.Namespace) -> int:
    from peghole_mjx.training.evaluate import evaluate
    from peghole_mjx.validation import dumps

    over = _env_sets(args)
    if args.out:  # checked before the evaluation, written after the result is printed
        fileio.check_out_file(args.out)
        if args.cross and _in_policy_folder(args.out):
            raise UserInputError(
                f"--out {args.out}: a cross evaluation is not written into a policy folder "
                "(its evaluation.json is the evaluation as trained)"
            )
    # every policy, its env and the outputs are checked before the first evaluation
    bundles = [_checked_policy(c, args, over) for c in args.checkpoint]
    _check_evaluate_outputs(args, bundles)
    baselines: dict = {}
    results = []
    for checkpoint, bundle in zip(args.checkpoint, bundles, strict=True):
        policy = bundle if args.env else checkpoint  # (the bundle: loaded once)
        res = evaluate(
            policy,
            args.episodes,
            seed=args.seed,
            progress=not args.json,
            batch=args.batch,
            parts_dir=args.parts,
            policy_only=args.policy_only,
            baselines=baselines,
            env_overrides=over or None,
            cross=args.cross,
        )
        results.append(res)
        if not args.json:
            _print_evaluation(res)
    res = results[0] if len(results) == 1 else results
    if args.json:
        print(dumps(res), flush=True)
    if args.out:
        fileio.write_text(args.out, dumps(res, indent=2) + "\n")
    return 0


def _checked_policy(checkpoint: str, args: argparse.Namespace, over: dict):
    """The policy ``checkpoint`` loaded (its files checked: :func:`load_policy`) and the env
    it will be evaluated in checked against ``--env`` and its training env (``--cross``)."""
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training.evaluate import check_requested_env, requested_config

    bundle = load_policy(checkpoint)
    if args.env and bundle.env_name != args.env:
        raise UserInputError(f"{checkpoint}: a policy for {bundle.env_name}, not for {args.env}")
    check_requested_env(bundle, requested_config(bundle, over or None), args.cross)
    return bundle


def _check_evaluate_outputs(args: argparse.Namespace, bundles: list) -> None:
    """``--parts`` a writable folder whose baseline slices are of these episodes, and room on
    disk for what the evaluation writes (estimated), before the first evaluation."""
    from peghole_mjx.training.evaluate import check_parts_keys, output_bytes

    if args.parts:
        fileio.check_out_dir(args.parts, "--parts")
        batch = args.batch or args.episodes
        check_parts_keys(args.parts, [b.env_name for b in bundles], args.seed, batch)
    need = output_bytes(len(bundles), args.episodes, args.batch, bool(args.parts), bool(args.out))
    for path, what in ((args.parts, "--parts"), (args.out, "--out")):
        if path:
            fileio.check_room(path, need, what)


def _env_sets(args: argparse.Namespace) -> dict:
    """``--preset`` and ``--set env.KEY=VALUE`` as env config overrides."""
    over = {}
    for key, value in args.env_sets:
        if not key.startswith("env."):
            raise UserInputError(f"--set {key}=...: evaluate takes env config keys, env.KEY=VALUE")
        over[key[len("env.") :]] = value
    if args.preset:
        over["preset"] = args.preset
    if getattr(args, "engine", None):
        from peghole_mjx.envs.engines import engine_overrides

        over = {**engine_overrides(args.engine), **over}
    return over


def _in_policy_folder(path: Path) -> bool:
    """``path`` is inside a folder that holds a policy (a ``policy.json``)."""
    return any((p / "policy.json").exists() for p in Path(path).resolve().parents)


def _print_evaluation(res: dict) -> None:
    p, b, th = res["policy"], res["baseline"], res["thesis"]
    print(
        f"{res['policy_path']}: {res['env']} ({res['preset']}, engine "
        f"{res.get('engine', 'mjx')}), {res['episodes']} episodes, seed {res['seed']}"
    )
    for key, (trained, now) in res.get("differs_from_training", {}).items():
        print(f"  cross evaluation: {key} = {now!r} (trained {trained!r})")
    print(f"{'':22s}{'policy':>10s}{'baseline':>10s}{'thesis RL':>11s}")
    rows = [
        ("success rate", "success_rate", "{:.3f}", th["success_rate"]),
        ("mean time s", "mean_time_s", "{:.2f}", th["mean_time_s"]),
        ("mean |F_z| N", "mean_fz_N", "{:.2f}", None),
        ("peak |F_z| N", "peak_fz_N", "{:.2f}", th["peak_fz_N_policy"]),
        ("mean |F_xy| N", "mean_fxy_N", "{:.2f}", None),
    ]
    for name, key, fmt, thesis in rows:
        t = "" if thesis is None else fmt.format(thesis)
        base = "-" if b is None else fmt.format(b[key])
        print(f"{name:22s}{fmt.format(p[key]):>10s}{base:>10s}{t:>11s}")
    red = res["force_reduction_pct"]
    if red is None:
        return
    red_s = "nan" if math.isnan(red) else f"{red:.1f} %"
    print(
        f"force reduction vs baseline: {red_s} (thesis R3: {th['force_reduction_pct']} %)",
        flush=True,
    )


#: bytes ``compare`` may write (a 11 x 7.5 inch figure at 110 dpi, any format), refused below
COMPARE_OUT_BYTES = 8 << 20


def cmd_compare(args: argparse.Namespace) -> int:
    from peghole_mjx.training.config import read_run_record
    from peghole_mjx.training.plots import image_format, plot_curves, read_metrics

    image_format(args.out)  # a suffix matplotlib cannot write is refused before any work
    fileio.check_out_file(args.out)
    fileio.check_room(args.out.parent if str(args.out.parent) else ".", COMPARE_OUT_BYTES)
    for r in args.runs:  # every run read and checked before the figure is drawn
        if not (r / "metrics.csv").exists():
            raise UserInputError(f"{r}: no metrics.csv (not a training run directory)")
        read_metrics(r)
        read_run_record(r, what=str(r), full=False)
    out = plot_curves(args.runs, args.out, title="RL vs RL + compliance strategy")
    print(out, file=sys.stdout)
    return 0
