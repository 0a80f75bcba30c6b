"""``peghole demo``: the whole pipeline once, with a short report.

Steps (each also a command of its own):

1. ``peghole models build`` for rect-2 and dual-2 (MJCF scenes with the iiwa);
2. ``peghole experiment compliance --geometry rect --quick`` (L_C at tip / centre / top);
3. ``peghole train --env RectExtract --profile cpu`` on the ``mujoco`` engine (MuJoCo C, the
   published rect policy's recipe: 100k env steps, a few minutes on 2 cores; ``--profile full``
   on MJX on a GPU, which trains to the GPU targets of docs/results.md);
4. ``peghole evaluate rect`` (the committed pretrained policy vs the scripted baseline);
5. ``report.md`` linking the figures.

On a 2-core CPU it takes about 10-15 minutes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from peghole_mjx.validation import arg


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="build models, run a quick experiment, train briefly, evaluate, write a report",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("peghole_demo"), help="output directory")
    p.add_argument(
        "--episodes",
        type=arg("episodes"),
        default=None,
        help="evaluation episodes (CPU 32, GPU 1024)",
    )
    p.add_argument(
        "--profile",
        choices=("auto", "quick", "cpu", "full"),
        default="auto",
        help="training profile: auto = full on a GPU (engine mjx), cpu on a CPU (engine "
        "mujoco); quick: a smoke run",
    )
    p.set_defaults(func=cmd_demo)


def _step(name: str) -> float:
    print(f"\n== {name}", file=sys.stderr, flush=True)
    return time.perf_counter()


def cmd_demo(args: argparse.Namespace) -> int:
    import jax

    from peghole_mjx.envs.engines import engine_overrides
    from peghole_mjx.errors import UserInputError
    from peghole_mjx.experiments.compliance import ExperimentConfig
    from peghole_mjx.experiments.report import run_experiment
    from peghole_mjx.geometry.mjcf import write_scenes
    from peghole_mjx.geometry.specs import get_preset
    from peghole_mjx.training.config import load_train_config
    from peghole_mjx.training.evaluate import evaluate
    from peghole_mjx.training.run import TrainingRun

    gpu = jax.default_backend() != "cpu"
    profile = ("full" if gpu else "cpu") if args.profile == "auto" else args.profile
    episodes = args.episodes or (1024 if gpu else 32)
    out = args.out
    if (out / "report.md").exists():
        raise UserInputError(f"{out} already holds a demo report: choose another --out")
    from peghole_mjx import fileio
    from peghole_mjx.validation import dumps

    fileio.check_out_dir(out)
    timings: dict[str, float] = {}

    t = _step("1/4 build the rect-2 and dual-2 scenes")
    for preset in ("rect-2", "dual-2"):
        scene, _, rep = write_scenes(get_preset(preset), out / "models" / preset)
        print(f"wrote {scene} (collision representation: {rep})", file=sys.stderr)
    timings["models"] = time.perf_counter() - t

    t = _step("2/4 compliance experiment (rect, quick)")
    run_experiment(ExperimentConfig.quick("rect"), out / "compliance")
    timings["experiment"] = time.perf_counter() - t

    engine = {f"env.{k}": v for k, v in engine_overrides("auto").items()}
    t = _step(f"3/4 train SAC on RectExtract (profile {profile}, engine {engine['env.engine']})")
    cfg = load_train_config("RectExtract", profile, engine, compliance_strategy=True)
    train_summary = TrainingRun(cfg, out / "train", render=True).run()
    print(f"evaluating the trained policy on {episodes} episodes", file=sys.stderr)
    train_summary["demo_eval"] = evaluate(str(out / "train"), episodes)
    train_summary["engine"] = engine["env.engine"]
    timings["training"] = time.perf_counter() - t

    t = _step(f"4/4 evaluate the pretrained rect policy ({episodes} episodes)")
    ev = evaluate("rect", episodes)
    fileio.write_text(out / "evaluation.json", dumps(ev, indent=2) + "\n")
    timings["evaluation"] = time.perf_counter() - t

    report = _report(out, train_summary, ev, timings, profile)
    fileio.write_text(out / "report.md", report)
    print(report)
    print(f"report: {out / 'report.md'}", file=sys.stderr)
    return 0


def _compliance_table(comp: dict) -> list[str]:
    """Mean peak force per L_C and the reductions beside the thesis's (R1)."""
    th = comp["thesis"]
    lines = [
        "| preset | mean peak F N at L_C (mm) | tip vs top % | tip vs centre % | "
        "max penetration mm (limit) | NaN worlds |",
        "|---|---|---|---|---|---|",
    ]
    for preset, peaks in comp["peak_force_N"].items():
        by_lc = ", ".join(f"{k}: {peaks[k]:.3f}" for k in sorted(peaks, key=float))
        lines.append(
            f"| {preset} | {by_lc} | {comp['reduction_tip_vs_top_pct'][preset]:.1f} "
            f"(thesis {th['reduction_tip_vs_top_pct']}) | "
            f"{comp['reduction_tip_vs_centre_pct'][preset]:.1f} "
            f"(thesis {th['reduction_tip_vs_centre_pct']}) | "
            f"{comp['max_penetration_mm'][preset]:.4f} ({comp['penetration_limit_mm'][preset]}) | "
            f"{comp['nan_worlds']} |"
        )
    return lines


def _report(out: Path, tr: dict, ev: dict, timings: dict, profile: str) -> str:
    from peghole_mjx.provenance import provenance

    prov = provenance()
    comp = json.loads((out / "compliance" / "summary.json").read_text())
    p, b, th = ev["policy"], ev["baseline"], ev["thesis"]
    fe = tr["final_eval"]
    lines = [
        "# peghole_mjx demo report",
        "",
        f"Device: {prov['device']}; {prov['date']}. Wall clock: "
        + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items())
        + ".",
        "",
        "## 1. Models",
        "",
        "Scenes written to `models/rect-2` and `models/dual-2` "
        "(open one with `python -m mujoco.viewer --mjcf models/rect-2/scene.xml`).",
        "",
        "## 2. Compliance-centre experiment (rect, quick)",
        "",
        "![force vs depth](compliance/force_depth.png)",
        "",
        *_compliance_table(comp),
        "",
        f"## 3. Training (RectExtract, RL + compliance strategy, profile {profile}, engine "
        f"{tr['engine']})",
        "",
        f"{tr['env_steps']} env steps in {tr['wall_s']} s; eval return "
        f"{tr['untrained_eval_return']:.2f} untrained -> "
        f"{fe.get('mean_return', float('nan')):.2f}; "
        f"eval success {fe.get('success_rate', float('nan')):.2f}. The trained policy on the "
        f"demo's {tr['demo_eval']['episodes']} evaluation episodes (seed 0): success "
        f"{tr['demo_eval']['policy']['success_rate']:.3f} (scripted baseline "
        f"{tr['demo_eval']['baseline']['success_rate']:.3f}), mean F_z "
        f"{tr['demo_eval']['policy']['mean_fz_N']:.2f} N against "
        f"{tr['demo_eval']['baseline']['mean_fz_N']:.2f} N.",
        "",
        "![learning curves](train/curves.png)",
        "",
        "![rollout](train/rollout.gif)",
        "",
        f"## 4. Pretrained rect policy vs the scripted baseline ({ev['episodes']} episodes)",
        "",
        "| | policy | baseline | thesis RL |",
        "|---|---|---|---|",
        f"| success rate | {p['success_rate']:.3f} | {b['success_rate']:.3f} | "
        f"{th['success_rate']} |",
        f"| mean time s | {p['mean_time_s']:.2f} | {b['mean_time_s']:.2f} | {th['mean_time_s']} |",
        f"| mean F_z N | {p['mean_fz_N']:.2f} | {b['mean_fz_N']:.2f} | |",
        f"| peak F_z N | {p['peak_fz_N']:.2f} | {b['peak_fz_N']:.2f} | "
        f"{th['peak_fz_N_policy']} vs {th['peak_fz_N_baseline']} |",
        f"| mean F_xy N | {p['mean_fxy_N']:.2f} | {b['mean_fxy_N']:.2f} | |",
        f"| force reduction % | {ev['force_reduction_pct']:.1f} | | {th['force_reduction_pct']} |",
        "",
    ]
    return "\n".join(lines)
