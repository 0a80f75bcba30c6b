"""Publish a training run's policy as a pretrained policy inside the package.

    python train/publish_policy.py RUN_DIR NAME [--checkpoint best|final|STEP] [--episodes 256]
                                                [--seed 0] [--screen 256] [--batch 256 --parts DIR]
                                                [--protocol FILE]

(NAME: rect, dual, rect_hard, dual_hard) copies the chosen policy into its ``PRETRAINED`` folder
(``peghole_mjx/policies/*``) with the run's ``metrics.csv``, ``curves.png`` and
``summary.json``, then evaluates it against the scripted baseline on fresh episodes
(``evaluation.json``: the same as ``peghole evaluate <name> --episodes N --json``).

``--checkpoint best`` (the default) takes the checkpoint whose training-time evaluation had
the highest success rate, ties broken by the lower mean extraction force |F_z| (the thesis's
R3 measure). Those evaluations use their own seeds (10000 + n), so the published evaluation
(seed 0) is independent of the selection. ``--screen N`` re-ranks the checkpoints the
training evaluations put near the top (success within 0.1 of the best) by the same rule on N
episodes of the policy alone (seed 20000; the training evaluations have only ``num_eval_envs``
episodes each, too few to tell 97 % from 99 % success). The choice is recorded in
``policy.json`` (``selection``). ``--candidates STEP ...`` screens those checkpoints only.
Each checkpoint's screen is kept in ``RUN_DIR/screen_seed20000_N.json`` (with the digest of
its parameters), so a rerun after an interrupted evaluation does not screen it again.

The published policy runs, and is evaluated, in exactly the env it was trained in: its
``env_overrides`` are the checkpoint's (the training config's, plus the pins of physics
defaults changed since training that a republished older policy carries). There is no
publish-time change of the env (the ``--deploy-set`` option was removed on 2026-11-29: the
dual policy it had published with a 0.5 N feed-forward bound, trained with 2 N, reported a
number no policy had been trained for). Other env settings are an evaluation option,
``peghole evaluate NAME --cross --set env.KEY=VALUE --out FILE``, which writes nothing into
the policy folder.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from peghole_mjx.training.selection import checkpoint_dir, choose_checkpoint, eval_rows

SCREEN_SEED = 20000  # screening episodes: disjoint from training evals (10000 + n) and seed 0
SCREEN_WITHIN = 0.1  # screen the checkpoints whose training-eval success is this close to the best


def screen_checkpoints(
    run: Path, episodes: int, candidates: list[int] | None = None
) -> tuple[Path, dict]:
    """Re-rank the near-best (or the ``candidates``) checkpoints of ``run`` on fresh episodes."""
    from peghole_mjx.envs.rollout import rollout
    from peghole_mjx.policies import load_policy
    from peghole_mjx.training.evaluate import params_sha256

    rows = eval_rows(run)
    near = max(float(r["eval/success_rate"]) for r in rows) - SCREEN_WITHIN
    if candidates is None:
        steps = [int(r["step"]) for r in rows if float(r["eval/success_rate"]) >= near]
    else:
        steps = [int(r["step"]) for r in rows if int(r["step"]) in candidates]
    if not steps:
        have = [int(r["step"]) for r in rows]
        raise SystemExit(f"none of the checkpoints {candidates} is in {run} (it has {have})")
    env, scores = None, []
    cache_file = run / f"screen_seed{SCREEN_SEED}_{episodes}.json"
    cache = json.loads(cache_file.read_text()) if cache_file.exists() else {}
    for step in steps:
        bundle = load_policy(checkpoint_dir(run, step))
        sha = params_sha256(bundle.params)
        if cache.get(str(step), {}).get("params_sha256") == sha:  # screened before: same result
            s = cache[str(step)]["summary"]
        else:
            env = env if env is not None else bundle.make_env()
            s = rollout(env, bundle.policy_fn(), episodes, seed=SCREEN_SEED, params=bundle.params)
            s = s.summary().as_dict()
            cache[str(step)] = {"params_sha256": sha, "summary": s}
            cache_file.write_text(json.dumps(cache, indent=2) + "\n")
        print(f"step {step:>8}: success {s['success_rate']:.3f}  F_z {s['mean_fz_N']:.3f} N")
        scores.append((s["success_rate"], -s["mean_fz_N"], step))
    _, _, best = max(scores)
    among = (
        f"the checkpoints at steps {candidates}"
        if candidates
        else f"checkpoints within {SCREEN_WITHIN} of the best training-eval success"
    )
    return checkpoint_dir(run, best), {
        "rule": f"highest success on {episodes} screening episodes (seed {SCREEN_SEED}) among "
        f"{among}, then lowest mean |F_z|",
        "step": best,
        "screen": {str(st): {"success_rate": sr, "mean_fz_N": -nf} for sr, nf, st in scores},
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("run", type=Path)
    from peghole_mjx.policies import PRETRAINED

    ap.add_argument("name", choices=sorted(PRETRAINED))
    ap.add_argument("--checkpoint", default="best", help="best | final | an env-step count")
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch", type=int, help="evaluate at most this many episodes at once")
    ap.add_argument(
        "--parts",
        type=Path,
        help="keep finished evaluation batches here (peghole evaluate --parts)",
    )
    ap.add_argument("--screen", type=int, default=0, help="screening episodes (0: no screening)")
    ap.add_argument(
        "--candidates", type=int, nargs="+", help="with --screen: screen these steps only"
    )
    ap.add_argument(
        "--protocol",
        type=Path,
        help="the declared protocol whose publication rule this follows (recorded in "
        "policy.json's selection and evaluation.json)",
    )
    args = ap.parse_args()
    if args.protocol is not None and not args.protocol.is_file():
        raise SystemExit(f"--protocol {args.protocol}: no such file")

    from peghole_mjx.files.provenance import commit, run_provenance
    from peghole_mjx.policies import PRETRAINED, check_as_trained, load_policy, upgrade_policy
    from peghole_mjx.sim.engines import engine_overrides
    from peghole_mjx.training.evaluate import evaluate, requested_config

    source_commit = commit()  # before the package's policy files are replaced (then dirty)
    if args.screen > 0:
        src, selection = screen_checkpoints(args.run, args.screen, args.candidates)
    else:
        src, selection = choose_checkpoint(args.run, args.checkpoint)
    meta = json.loads((src / "policy.json").read_text())
    if args.protocol is not None:
        selection = {**selection, "protocol": args.protocol.as_posix()}
    meta["selection"] = selection
    check_as_trained(meta, str(src))  # before the published policy is replaced
    dest = PRETRAINED[args.name]
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    shutil.copy2(src / "params.npz", dest / "params.npz")
    (dest / "policy.json").write_text(json.dumps(meta, indent=2) + "\n")
    upgrade_policy(dest)  # a checkpoint of an older policy format is published as the current
    for f in ("metrics.csv", "curves.png", "summary.json"):
        if (args.run / f).exists():
            shutil.copy2(args.run / f, dest / f)
    if not (dest / "curves.png").exists():  # a run ended before its finish(): plot its metrics
        from peghole_mjx.training.plots import plot_curves

        plot_curves([args.run], dest / "curves.png")
    res = evaluate(args.name, args.episodes, seed=args.seed, batch=args.batch, parts_dir=args.parts)
    # the config of the env the evaluation ran (its engine resolved), without building it again
    ran_on = engine_overrides(res["engine"])
    env_config = json.loads(requested_config(load_policy(args.name), ran_on).to_json())
    res.update(
        {
            "checkpoint_rule": selection["rule"],
            **({"protocol": selection["protocol"]} if "protocol" in selection else {}),
            "reward_kind": env_config["reward_config"]["kind"],
            "env_config": env_config,
            **run_provenance(["python", "train/publish_policy.py", *sys.argv[1:]]),
            "commit": source_commit,
            "config": "see env_config, episodes, seed, checkpoint_rule; env_config is the policy's "
            "full env config, the training settings are in policy.json beside it",
        }
    )
    (dest / "evaluation.json").write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps({"selection": selection, "force_reduction_pct": res["force_reduction_pct"]}))
    print(dest)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
