"""``peghole envs``: run batched episodes of an environment with a policy."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from peghole_mjx import envs, policies
from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import arg, dumps, key_value
from peghole_mjx.envs import contacts as contacts_mod
from peghole_mjx.envs import rollout as rollout_mod
from peghole_mjx.envs.mesh_extract import absolute_task
from peghole_mjx.files import fileio
from peghole_mjx.geometry.specs import get_preset
from peghole_mjx.sim.engines import CLI_ENGINES, engine_label, engine_overrides
from peghole_mjx.training.evaluate import (
    check_requested_env,
    config_differences,
    requested_config,
)

#: ``--policy`` of the envs subcommands
POLICY_HELP = (
    f"scripted | random | a policy: pretrained name ({', '.join(policies.PRETRAINED)}), "
    "policy or run directory"
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "envs", help=f"batched extraction environments ({', '.join(envs.ENV_NAMES)})"
    )
    esub = p.add_subparsers(dest="envs_cmd", metavar="SUBCOMMAND", required=True)
    r = esub.add_parser(
        "rollout",
        help="run N episodes in one batch and report success, time and forces",
        description="Runs --episodes randomised episodes side by side (one batch), "
        "each until success or failure, and prints success rate, mean extraction time, mean "
        "and peak |F_z|, mean |F_xy|, plus compile time and steps/s. The scripted policy is "
        "the thesis's Ch 2-3 method (fixed compliance at the peg tip, straight pull).",
    )
    _env_arguments(r)
    r.add_argument("--episodes", type=arg("episodes"), default=64)
    r.add_argument("--json", action="store_true", help="print one JSON object")
    r.set_defaults(func=cmd_rollout)

    c = esub.add_parser(
        "contacts",
        help="record where and how hard the peg touches the hole in one episode",
        description="Runs one randomised episode (one world) and, after every env step, lists "
        "each active peg-hole contact: its point on the peg (mm, tip frame), its normal, its "
        "normal force and the hole geom touched, and which steps are in two-point contact. "
        "Writes contacts.csv, contacts.png (the points on the peg and the force on each wall "
        "over time) and summary.json to --out.",
    )
    _env_arguments(c)
    c.add_argument("--out", type=Path, required=True, help="output folder (created)")
    c.set_defaults(func=cmd_contacts)


def _env_arguments(q: argparse.ArgumentParser) -> None:
    """The options that choose the env, its config and the policy (every envs subcommand)."""
    q.add_argument("--env", required=True, choices=envs.ENV_NAMES)
    q.add_argument("--policy", default="scripted", help=POLICY_HELP)
    q.add_argument(
        "--engine",
        choices=CLI_ENGINES,
        default=None,
        help="physics engine: mjx (MuJoCo MJX), mjx-warp (MuJoCo Warp: CUDA GPU; a CPU runs "
        "it slowly), mujoco (MuJoCo C, mujoco.batch threads), auto (mujoco without a GPU; "
        "on a CUDA GPU mjx-warp with warp-lang, else mjx). "
        "Default auto (a policy file from before 2026-12-05: the engine it recorded); the "
        "engine is not part of the task, so any engine runs a policy as trained",
    )
    q.add_argument(
        "--cross",
        action="store_true",
        help="run a policy in an env other than its training env (--engine, --preset, --set), "
        "as evaluate --cross; without it such a run is refused",
    )
    q.add_argument("--seed", type=arg("seed"), default=0, help="the episodes' reset seed")
    q.add_argument("--preset", help="override the env's preset (same geometry kind)")
    q.add_argument(
        "--set",
        dest="overrides",
        type=key_value,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override, e.g. --set randomization.angular_error_deg=0.3",
    )


def scene_name(config) -> str:
    """The peg-hole of an env config as shown: its preset, or its task folder."""
    return config.preset or f"task {config.get('task', '')}"


def make_policy(env, name: str):
    """``scripted`` or ``random`` -> ``policy(obs, rng) -> action``."""
    if name == "scripted":
        return rollout_mod.scripted_policy(env)
    return rollout_mod.random_policy(env)


def _env_and_policy(args: argparse.Namespace, quiet: bool = False):
    """``(env, policy, params)`` of ``--env``, ``--policy``, ``--engine``, ``--preset`` and
    ``--set`` (``params`` None for scripted and random)."""
    overrides = absolute_task(dict(args.overrides))
    if args.preset and args.env in envs.TASK_ENVS:
        raise UserInputError(f"{args.env} takes its parts from a task folder: --set task=DIR")
    if args.preset:
        kind = get_preset(envs.get_default_config(args.env).preset).kind
        if get_preset(args.preset).kind != kind:
            raise UserInputError(f"preset {args.preset} does not fit {args.env} (a {kind} env)")
        overrides["preset"] = args.preset
    bundle, params = None, None
    if args.engine is not None or args.policy in ("scripted", "random"):
        overrides = {**engine_overrides(args.engine or "auto"), **overrides}
    if args.policy not in ("scripted", "random"):
        bundle = policies.load_policy(args.policy)
        if bundle.env_name != args.env:
            raise UserInputError(f"policy {args.policy} was trained on {bundle.env_name}")
        # as evaluate: another engine, preset or config entry only with --cross (nothing built)
        check_requested_env(bundle, requested_config(bundle, overrides), args.cross)
    try:
        with prog.phase(f"building the {args.env} env", enabled=not quiet):
            if bundle is not None:  # the env exactly as trained (plus --set)
                env = bundle.make_env(overrides)
            else:
                env = envs.load(args.env, config_overrides=overrides or None)
    except (KeyError, AttributeError) as exc:
        raise UserInputError(f"bad config override: {exc}") from None
    if bundle is not None:
        for key, (trained, now) in config_differences(bundle, env.config).items():
            # a --cross run in other settings: said, never written into the policy folder
            print(
                f"not the policy's training env: {key} = {now!r} (trained {trained!r})",
                file=sys.stderr,
            )
        policy, params = bundle.policy_fn(), bundle.params
    else:
        policy = make_policy(env, args.policy)
    return env, policy, params


def cmd_rollout(args: argparse.Namespace) -> int:
    env, policy, params = _env_and_policy(args, quiet=args.json)
    res = rollout_mod.rollout(
        env,
        policy,
        args.episodes,
        seed=args.seed,
        progress=not args.json,
        params=params,
        label=f"{args.policy} rollout",
    )
    summary = res.summary().as_dict()
    timing = {
        "compile_s": round(res.compile_s, 2),
        "env_steps_per_s": round(res.env_steps_per_s, 1),
        "physics_steps_per_s": round(res.physics_steps_per_s, 1),
    }
    if args.json:
        print(dumps({**summary, **timing, "engine": engine_label(env.config)}))
    else:
        print(
            f"{args.env} ({scene_name(env.config)}, engine {env.config.engine}), policy "
            f"{args.policy}, {summary['episodes']} episodes"
        )
        print(f"  success rate   {summary['success_rate']:.3f}")
        print(f"  mean time      {summary['mean_time_s']:.2f} s (successful episodes)")
        print(f"  mean |F_z|     {summary['mean_fz_N']:.2f} N")
        print(f"  peak |F_z|     {summary['peak_fz_N']:.2f} N (mean over episodes)")
        print(f"  mean |F_xy|    {summary['mean_fxy_N']:.2f} N")
        print(
            f"  failures       jammed {summary['jammed']}, timeouts {summary['timeouts']}, "
            f"NaN worlds {summary['nan_worlds']}, "
            f"contact-buffer overflows {summary['overflow_worlds']}"
        )
        print(
            f"  compile {timing['compile_s']} s (first {25} steps included); "
            f"{timing['env_steps_per_s']} env steps/s, "
            f"{timing['physics_steps_per_s']} physics steps/s",
            file=sys.stdout,
        )
    return 0


def cmd_contacts(args: argparse.Namespace) -> int:
    env, policy, params = _env_and_policy(args)
    if params is not None:
        learned = policy
        policy = lambda obs, rng: learned(params, obs, rng)  # noqa: E731
    fileio.check_out_dir(args.out)
    trace = contacts_mod.record_contacts(env, policy, seed=args.seed)
    trace.write_csv(args.out / "contacts.csv")
    title = f"{args.env} ({scene_name(env.config)}), policy {args.policy}, seed {args.seed}"
    contacts_mod.plot_contacts(trace, args.out / "contacts.png", title)
    summary = {"env": args.env, "policy": args.policy, "seed": args.seed, **trace.summary()}
    summary["engine"] = engine_label(env.config)
    fileio.write_text(args.out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(dumps(summary))
    print(f"wrote {args.out}/contacts.csv, contacts.png, summary.json", file=sys.stderr)
    return 0
