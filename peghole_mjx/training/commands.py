"""``peghole train``, ``peghole evaluate`` and ``peghole compare``: the commands (their parsers:
:mod:`peghole_mjx.training.cli`)."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
from pathlib import Path

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import dumps
from peghole_mjx.envs.mesh_extract import absolute_task
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import LOCK_NAME, RunLock
from peghole_mjx.files.provenance import run_provenance
from peghole_mjx.policies import check_recorded_params, load_policy, resolve_policy_path
from peghole_mjx.sim.engines import engine_overrides
from peghole_mjx.training import evaluate as evaluation
from peghole_mjx.training.cli import chosen_profile, train_config_from_args
from peghole_mjx.training.config import env_setting, read_run_record
from peghole_mjx.training.distributed import initialize
from peghole_mjx.training.logs import read_metrics
from peghole_mjx.training.plots import image_format, plot_curves
from peghole_mjx.training.run import TrainingRun, failed_start
from peghole_mjx.training.seeds import SeedsRun


def fresh_run_config(args: argparse.Namespace):
    """The config of a new run in ``--out`` (refused when ``--out`` already holds one)."""
    if not args.env or not args.out:
        raise UserInputError("--env and --out are required (or --resume DIR)")
    check_fresh_out(args.out)  # before the config, the lock or any compile: cheap
    cfg = train_config_from_args(args)
    fileio.check_out_dir(args.out)
    # a run that stopped before its first evaluation does not block its --out: the new run
    # replaces it, holding the run's lock (TrainingRun.prepare, SeedsRun.prepare)
    if (args.out / "run.json").exists() and not failed_start(args.out):
        raise UserInputError(
            f"{args.out} already holds a training run: use --resume {args.out} or a new --out"
        )
    return cfg


#: what a folder may hold and still take a new run though it has no run.json: the lock of a
#: run killed before it wrote run.json
_FRESH_OK = frozenset({LOCK_NAME})


def check_fresh_out(out: Path) -> None:
    """Refuse (one line) a ``--out`` for a new run that is not a new or empty folder nor a run
    folder of ours (it holds run.json): a new run never writes metrics.csv, summary.json or
    anything else over a folder of the user's (decided 2026-12-04)."""
    out = Path(out)
    if not out.is_dir() or (out / "run.json").is_file():
        return  # a file or a path under a file: check_out_dir's line; a run: fresh_run_config
    entries = sorted(p.name for p in out.iterdir() if p.name not in _FRESH_OK)
    if entries:
        raise UserInputError(
            f"--out {out} is not empty and is not a training run (no run.json): it holds "
            f"{fileio.describe_files(entries)}; give a new or empty folder, or --resume a run"
        )


def cmd_train(args: argparse.Namespace) -> int:
    """``peghole train``: a new run, ``--resume`` of one, or ``--seeds N`` (``_train_seeds``)."""
    progress = not args.no_progress
    if args.seeds is not None or (args.resume and _is_seeds_run(args.resume)):
        return _train_seeds(args, progress)
    if args.distributed:  # before anything of JAX runs
        initialize()
    if args.resume:
        over = dict(args.overrides)
        if args.env or set(over) - {"num_timesteps"}:
            raise UserInputError(
                "--resume takes the run's own config: drop --env and --set "
                "(only --set num_timesteps=N, to extend a run, is allowed)"
            )
        if not (args.resume / "run.json").exists():
            raise UserInputError(
                f"--resume: {args.resume / 'run.json'} not found (not a training run directory)"
            )
        check_resume_flags(args)
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
        with _no_empty_out_left(args.out):
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


@contextlib.contextmanager
def _no_empty_out_left(out: Path | None):
    """A new run's ``--out`` that did not exist is removed again when the command is refused
    or fails while the folder is still empty (the checks create it to probe it): a refusal
    leaves nothing behind. A folder that holds anything is left as it is."""
    existed = out is None or os.path.lexists(out)
    try:
        yield
    except BaseException:
        if not existed:
            with contextlib.suppress(OSError):
                out.rmdir()  # only an empty folder: never anything the run or the user wrote
        raise


def check_resume_flags(args: argparse.Namespace) -> None:
    """Refuse (one line naming the flag and the recorded value) ``--engine``,
    ``--compliance-strategy``, ``--profile``, ``--quick`` or ``--out`` given with ``--resume``
    when it differs from the run's own (a ``--set num_timesteps=N`` below the run's is
    refused by :meth:`TrainingRun.resume`, once N is checked).

    Decided 2026-12-04: a flag equal to the run's own value is accepted (it changes nothing,
    and the command that started a run still resumes it with ``--resume`` added); any other
    is refused, never silently ignored."""
    given = (args.engine, args.compliance_strategy, args.profile, args.out)
    if not args.quick and all(v is None for v in given):
        return  # nothing to compare: run.json is read under the run's lock
    _, cfg = read_run_record(args.resume)
    env, env_over = cfg.env, dict(cfg.env_overrides or {})

    def refuse(flag: str, what: str, recorded) -> None:
        raise UserInputError(
            f"--resume takes the run's own config: {flag} differs from the run's {what} "
            f"{recorded} (drop {flag.split()[0]})"
        )

    if args.engine is not None:
        for key, value in engine_overrides(args.engine).items():
            recorded = env_setting(env, env_over, key)
            if recorded != value:
                refuse(f"--engine {args.engine}", key, recorded)
    if args.compliance_strategy is not None:
        recorded = bool(env_setting(env, env_over, "compliance_strategy"))
        if recorded != (args.compliance_strategy == "on"):
            refuse(
                f"--compliance-strategy {args.compliance_strategy}",
                "compliance strategy",
                "on" if recorded else "off",
            )
    if args.quick or args.profile is not None:
        profile = chosen_profile(args)
        recorded = cfg.profile
        if profile != recorded:
            flag = "--quick" if args.quick else f"--profile {profile}"
            refuse(flag, "profile", recorded)
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        refuse(f"--out {args.out}", "folder", args.resume)


def _is_seeds_run(out: Path) -> bool:
    try:
        return "seeds" in json.loads((out / "run.json").read_text())
    except (OSError, ValueError, TypeError):
        return False


def _train_seeds(args: argparse.Namespace, progress: bool) -> int:
    """``peghole train --seeds N`` (or ``--resume`` of such a run): training/seeds.py."""
    if args.distributed or args.stop_at_success is not None:
        raise UserInputError("--seeds takes neither --distributed nor --stop-at-success")
    if args.resume:
        if args.env or args.overrides or args.seeds is not None:
            raise UserInputError("--resume takes the run's own config: drop --env, --set, --seeds")
        check_resume_flags(args)
        fileio.check_out_dir(args.resume, "--resume")
        run = SeedsRun.resume(args.resume, progress=progress)
        summary = run.run(resume=True)
    else:
        with _no_empty_out_left(args.out):
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
    """``peghole evaluate``: each policy and the scripted baseline on the same episodes."""
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
        res = evaluation.evaluate(
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
    if args.out:  # each result carries its device, versions, date, command, config and commit
        stamp = run_provenance(["peghole", *getattr(args, "argv", ["evaluate"])])
        stamp["config"] = {
            "episodes": args.episodes,
            "seed": args.seed,
            "batch": args.batch,
            "policy_only": bool(args.policy_only),
            "cross": bool(args.cross),
            "env_overrides": over or {},
        }
        record = [r | stamp for r in results] if len(results) > 1 else results[0] | stamp
        fileio.write_text(args.out, dumps(record, indent=2) + "\n")
    return 0


def _checked_policy(checkpoint: str, args: argparse.Namespace, over: dict):
    """The policy ``checkpoint`` loaded (its files checked: :func:`load_policy`) and the env
    it will be evaluated in checked against ``--env`` and its training env (``--cross``)."""
    # an edited params.npz of a recorded policy is refused (2026-12-04), before it is loaded
    check_recorded_params(resolve_policy_path(checkpoint))
    bundle = load_policy(checkpoint)
    if args.env and bundle.env_name != args.env:
        raise UserInputError(f"{checkpoint}: a policy for {bundle.env_name}, not for {args.env}")
    config = evaluation.requested_config(bundle, over or None)
    evaluation.check_requested_env(bundle, config, args.cross)
    return bundle


def _check_evaluate_outputs(args: argparse.Namespace, bundles: list) -> None:
    """``--parts`` a writable folder whose baseline slices are of these episodes, and room on
    disk for what the evaluation writes (estimated), before the first evaluation."""
    if args.parts:
        fileio.check_out_dir(args.parts, "--parts")
        batch = args.batch or args.episodes
        evaluation.check_parts_keys(args.parts, [b.env_name for b in bundles], args.seed, batch)
    need = evaluation.output_bytes(
        len(bundles), args.episodes, args.batch, bool(args.parts), bool(args.out)
    )
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
        over = {**engine_overrides(args.engine), **over}
    return absolute_task(over)


def _in_policy_folder(path: Path) -> bool:
    """``path`` is inside a folder that holds a policy (a ``policy.json``)."""
    return any((p / "policy.json").exists() for p in Path(path).resolve().parents)


def _print_evaluation(res: dict) -> None:
    p, b, th = res["policy"], res["baseline"], res["thesis"]
    print(
        f"{res['policy_path']}: {res['env']} ({res['preset'] or res.get('task')}, engine "
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
    stuck = res.get("stuck")  # a stuck joint: episodes whose weld released
    if stuck:
        base = "-" if stuck["baseline"] is None else str(stuck["baseline"]["released"])
        print(f"{'weld released':22s}{stuck['policy']['released']:>10d}{base:>10s}")
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
    """``peghole compare``: the learning curves of several runs on shared axes."""
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
