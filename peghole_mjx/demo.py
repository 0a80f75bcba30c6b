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

Rerun in place: ``demo.json`` in the output folder records each stage as started and, once
complete, with the SHA-256 of every file it wrote. A rerun with the same ``--out`` reuses
every complete stage whose files still verify and whose settings (profile, engine, episodes)
are the same, and redoes the others (an interrupted stage is removed and run again); the
report is always rewritten. ``--force`` deletes the demo's earlier outputs and starts afresh.
A folder holding demo outputs that ``demo.json`` does not record (an older demo, other files)
is refused in one line unless ``--force``. The output folder is checked (writable, room for
the outputs) before any work.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from peghole_mjx import fileio
from peghole_mjx.validation import arg

#: the record of the demo's stages in ``--out``
DEMO_STATE = "demo.json"
#: stage -> what it writes inside ``--out`` (None: nothing, its result lives in ``demo.json``)
STAGE_OUTPUTS: dict[str, str | None] = {
    "models": "models",
    "experiment": "compliance",
    "training": "train",
    "training_eval": None,
    "evaluation": "evaluation.json",
}
#: every name the demo writes in ``--out`` (what ``--force`` deletes)
DEMO_OUTPUTS = (*(v for v in STAGE_OUTPUTS.values() if v), "report.md", DEMO_STATE)
#: first line of the demo's report (how ``--force`` tells an older demo's folder)
REPORT_TITLE = "# peghole_mjx demo report"


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
    p.add_argument(
        "--force",
        action="store_true",
        help="start afresh: delete the demo's earlier outputs in --out ("
        + ", ".join(DEMO_OUTPUTS)
        + ") instead of reusing its complete stages",
    )
    p.set_defaults(func=cmd_demo)


def _step(name: str) -> float:
    print(f"\n== {name}", file=sys.stderr, flush=True)
    return time.perf_counter()


# ---------------------------------------------------------------------- the stages' work
# (module functions, so that tests replace them with quick stand-ins)
def _build_models(out: Path) -> None:
    from peghole_mjx.geometry.mjcf import write_scenes
    from peghole_mjx.geometry.specs import get_preset

    for preset in ("rect-2", "dual-2"):
        scene, _, rep = write_scenes(get_preset(preset), out / preset)
        print(f"wrote {scene} (collision representation: {rep})", file=sys.stderr)


def _run_experiment(out: Path) -> None:
    from peghole_mjx.experiments.compliance import ExperimentConfig
    from peghole_mjx.experiments.report import run_experiment

    run_experiment(ExperimentConfig.quick("rect"), out)


def _train(out: Path, cfg) -> dict:
    from peghole_mjx.training.run import TrainingRun

    return TrainingRun(cfg, out, render=True).run()


def _evaluate(policy: str, episodes: int) -> dict:
    from peghole_mjx.training.evaluate import evaluate

    return evaluate(policy, episodes)


def _train_config(profile: str, engine: dict):
    from peghole_mjx.training.config import load_train_config

    return load_train_config("RectExtract", profile, engine, compliance_strategy=True)


def output_bytes(cfg) -> int:
    """A generous estimate of what the demo writes: scenes, figures, GIF and report (64 MiB)
    and the training run, whose two newest checkpoints hold the replay buffer (up to 64
    float32 per transition, counted three times)."""
    return 64 * 2**20 + 3 * int(cfg.max_replay_size) * 64 * 4


# ---------------------------------------------------------------------- the stage record
_sha256 = fileio.sha256_file


def _manifest(out: Path, name: str | None) -> dict[str, str]:
    """``{path relative to out: sha256}`` of every file of the stage output ``name``."""
    if name is None:
        return {}
    root = out / name
    files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
    return {str(p.relative_to(out)): _sha256(p) for p in files}


def _digest(record: dict) -> str:
    """A digest of a completed stage's files and data (a later stage's setting)."""
    text = json.dumps([record.get("files"), record.get("data")], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


class DemoState:
    """``demo.json``: each stage's settings, whether it completed, its files' SHA-256, its
    wall time and its result; written atomically before and after each stage."""

    def __init__(self, out: Path, stages: dict[str, dict]):
        self.out = out
        self.stages = stages

    @classmethod
    def open(cls, out: Path, force: bool) -> DemoState:
        """The record of ``out`` (empty for a fresh folder). Refused in one line, before any
        work: a damaged ``demo.json``, or demo outputs that it does not record (unless
        ``force``, which deletes the demo's earlier outputs)."""
        from peghole_mjx.errors import CorruptFileError, UserInputError
        from peghole_mjx.validation import load_json_object

        present = [n for n in DEMO_OUTPUTS if (out / n).exists() or (out / n).is_symlink()]
        state_file = out / DEMO_STATE
        if force:
            if present and not (state_file.exists() or _is_demo_report(out / "report.md")):
                raise UserInputError(
                    f"--force: {out} holds {', '.join(present)} but no demo.json or demo "
                    "report: not a demo's folder, nothing deleted; choose another --out"
                )
            for n in present:
                _remove(out / n)
            return cls(out, {})
        if not state_file.exists():
            if present:
                raise UserInputError(
                    f"{out} holds {', '.join(present)} but no {DEMO_STATE} (an older demo, or "
                    "other files): pass --force to delete them and start afresh, or choose "
                    "another --out"
                )
            return cls(out, {})
        data = load_json_object(
            state_file,
            lambda why: CorruptFileError(
                f"{state_file} is damaged ({why}): pass --force to start afresh"
            ),
        )
        stages = data.get("stages")
        if not isinstance(stages, dict) or not all(isinstance(r, dict) for r in stages.values()):
            raise CorruptFileError(
                f"{state_file} is not a demo record ('stages' must map each stage to an "
                "object): pass --force to start afresh"
            )
        unrecorded = [
            n for stage, n in STAGE_OUTPUTS.items() if n in present and stage not in stages
        ]
        if unrecorded:
            raise UserInputError(
                f"{out} holds {', '.join(unrecorded)}, which {DEMO_STATE} does not record as "
                "the demo's: pass --force to delete the demo's outputs and start afresh, or "
                "choose another --out"
            )
        return cls(out, {k: v for k, v in stages.items() if k in STAGE_OUTPUTS})

    def _save(self) -> None:
        from peghole_mjx.validation import dumps

        text = dumps({"demo": 1, "stages": self.stages}, indent=2) + "\n"
        fileio.write_text(self.out / DEMO_STATE, text)

    def reusable(self, stage: str, settings: dict) -> dict | None:
        """The record of ``stage`` if it completed with these settings and its files verify;
        None (the stage is run) otherwise, saying why when there was a record."""
        rec = self.stages.get(stage)
        if rec is None:
            return None
        why = None
        if rec.get("done") is not True:
            why = "interrupted before it completed"
        elif rec.get("settings") != json.loads(_dumps_safe(settings)):
            why = f"settings changed ({rec.get('settings')} -> {settings})"
        elif not isinstance(rec.get("files"), dict) or not isinstance(rec.get("data"), dict):
            why = "its record is incomplete"
        else:
            for rel, sha in rec["files"].items():
                path = self.out / rel
                if not path.is_file() or _sha256(path) != sha:
                    why = f"{rel} is missing or changed"
                    break
        if why is None:
            return rec
        print(f"demo: redoing the {stage} stage: {why}", file=sys.stderr, flush=True)
        return None

    def run(self, stage: str, settings: dict, title: str, work: Callable[[], dict | None]):
        """The record of ``stage``: reused (:meth:`reusable`), else run: its old output
        removed, the stage recorded as started, ``work()`` done, then recorded complete."""
        rec = self.reusable(stage, settings)
        if rec is not None:
            print(f"\n== {title}: complete, reused", file=sys.stderr, flush=True)
            return rec
        t = _step(title)
        name = STAGE_OUTPUTS[stage]
        if name is not None:
            _remove(self.out / name)  # recorded as this demo's (DemoState.open)
        self.stages[stage] = {"settings": settings, "done": False}
        self._save()
        data = work() or {}
        rec = {
            "settings": settings,
            "done": True,
            "wall_s": time.perf_counter() - t,
            "files": _manifest(self.out, name),
            "data": data,
        }
        self.stages[stage] = json.loads(_dumps_safe(rec))  # as a rerun will read it back
        self._save()
        return self.stages[stage]


def _dumps_safe(obj: Any) -> str:
    from peghole_mjx.validation import dumps

    return dumps(obj)


def _is_demo_report(path: Path) -> bool:
    try:
        with open(path) as f:
            return f.readline().strip() == REPORT_TITLE
    except (OSError, UnicodeDecodeError):
        return False


def _file_sha256(*paths: Path) -> str:
    return hashlib.sha256("".join(_sha256(p) for p in paths).encode()).hexdigest()[:16]


def cmd_demo(args: argparse.Namespace) -> int:
    import jax

    from peghole_mjx import fileio
    from peghole_mjx.envs.engines import engine_overrides
    from peghole_mjx.policies import PRETRAINED
    from peghole_mjx.validation import dumps

    gpu = jax.default_backend() != "cpu"
    profile = ("full" if gpu else "cpu") if args.profile == "auto" else args.profile
    episodes = args.episodes or (1024 if gpu else 32)
    out = args.out
    engine = {f"env.{k}": v for k, v in engine_overrides("auto").items()}
    cfg = _train_config(profile, engine)
    # before any work: the folder (writable, room) and what it already holds
    fileio.check_out_dir(out)
    state = DemoState.open(out, force=getattr(args, "force", False))
    fileio.check_room(out, output_bytes(cfg), "--out")

    models = state.run(
        "models",
        {"presets": ["rect-2", "dual-2"]},
        "1/4 build the rect-2 and dual-2 scenes",
        lambda: _build_models(out / "models"),
    )
    experiment = state.run(
        "experiment",
        {"experiment": "compliance rect quick"},
        "2/4 compliance experiment (rect, quick)",
        lambda: _run_experiment(out / "compliance"),
    )
    title = f"3/4 train SAC on RectExtract (profile {profile}, engine {engine['env.engine']})"
    training = state.run(
        "training",
        {"profile": profile, "engine": engine["env.engine"], "config": cfg.as_dict()},
        title,
        lambda: {"summary": _train(out / "train", cfg)},
    )

    def demo_eval() -> dict:
        print(f"evaluating the trained policy on {episodes} episodes", file=sys.stderr)
        return {"result": _evaluate(str(out / "train"), episodes)}

    training_eval = state.run(
        "training_eval",
        {"episodes": episodes, "training": _digest(training)},
        f"3/4 evaluate the trained policy ({episodes} episodes)",
        demo_eval,
    )
    rect = PRETRAINED["rect"]

    def pretrained_eval() -> dict:
        ev = _evaluate("rect", episodes)
        fileio.write_text(out / "evaluation.json", dumps(ev, indent=2) + "\n")
        return {"result": ev}

    evaluation = state.run(
        "evaluation",
        {
            "policy": "rect",
            "episodes": episodes,
            "policy_sha256": _file_sha256(rect / "policy.json", rect / "params.npz"),
        },
        f"4/4 evaluate the pretrained rect policy ({episodes} episodes)",
        pretrained_eval,
    )

    train_summary = {
        **training["data"]["summary"],
        "demo_eval": training_eval["data"]["result"],
        "engine": engine["env.engine"],
    }
    timings = {
        "models": models["wall_s"],
        "experiment": experiment["wall_s"],
        "training": training["wall_s"] + training_eval["wall_s"],
        "evaluation": evaluation["wall_s"],
    }
    report = _report(out, train_summary, evaluation["data"]["result"], timings, profile)
    fileio.write_text(out / "report.md", report)
    print(report)
    print(f"report: {out / 'report.md'}", file=sys.stderr)
    return 0


def _f(value: Any, spec: str) -> str:
    """``value`` formatted, or ``n/a`` for an undefined one (NaN, read back as null)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return format(value, spec)


def _compliance_table(comp: dict) -> list[str]:
    """Mean peak force per L_C and the reductions beside the thesis's (R1)."""
    th = comp["thesis"]
    lines = [
        "| preset | mean peak F N at L_C (mm) | tip vs top % | tip vs centre % | "
        "max penetration mm (limit) | NaN worlds |",
        "|---|---|---|---|---|---|",
    ]
    for preset, peaks in comp["peak_force_N"].items():
        by_lc = ", ".join(f"{k}: {_f(peaks[k], '.3f')}" for k in sorted(peaks, key=float))
        lines.append(
            f"| {preset} | {by_lc} | {_f(comp['reduction_tip_vs_top_pct'][preset], '.1f')} "
            f"(thesis {th['reduction_tip_vs_top_pct']}) | "
            f"{_f(comp['reduction_tip_vs_centre_pct'][preset], '.1f')} "
            f"(thesis {th['reduction_tip_vs_centre_pct']}) | "
            f"{_f(comp['max_penetration_mm'][preset], '.4f')} "
            f"({comp['penetration_limit_mm'][preset]}) | "
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
        REPORT_TITLE,
        "",
        f"Device: {prov['device']}; {prov['date']}. Wall clock: "
        + ", ".join(f"{k} {_f(v, '.0f')} s" for k, v in timings.items())
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
        f"{_f(tr['untrained_eval_return'], '.2f')} untrained -> "
        f"{_f(fe.get('mean_return', float('nan')), '.2f')}; "
        f"eval success {_f(fe.get('success_rate', float('nan')), '.2f')}. The trained policy "
        f"on the demo's {tr['demo_eval']['episodes']} evaluation episodes (seed 0): success "
        f"{_f(tr['demo_eval']['policy']['success_rate'], '.3f')} (scripted baseline "
        f"{_f(tr['demo_eval']['baseline']['success_rate'], '.3f')}), mean F_z "
        f"{_f(tr['demo_eval']['policy']['mean_fz_N'], '.2f')} N against "
        f"{_f(tr['demo_eval']['baseline']['mean_fz_N'], '.2f')} N.",
        "",
        "![learning curves](train/curves.png)",
        "",
        "![rollout](train/rollout.gif)",
        "",
        f"## 4. Pretrained rect policy vs the scripted baseline ({ev['episodes']} episodes)",
        "",
        "| | policy | baseline | thesis RL |",
        "|---|---|---|---|",
        f"| success rate | {_f(p['success_rate'], '.3f')} | {_f(b['success_rate'], '.3f')} | "
        f"{th['success_rate']} |",
        f"| mean time s | {_f(p['mean_time_s'], '.2f')} | {_f(b['mean_time_s'], '.2f')} | "
        f"{th['mean_time_s']} |",
        f"| mean F_z N | {_f(p['mean_fz_N'], '.2f')} | {_f(b['mean_fz_N'], '.2f')} | |",
        f"| peak F_z N | {_f(p['peak_fz_N'], '.2f')} | {_f(b['peak_fz_N'], '.2f')} | "
        f"{th['peak_fz_N_policy']} vs {th['peak_fz_N_baseline']} |",
        f"| mean F_xy N | {_f(p['mean_fxy_N'], '.2f')} | {_f(b['mean_fxy_N'], '.2f')} | |",
        f"| force reduction % | {_f(ev['force_reduction_pct'], '.1f')} | | "
        f"{th['force_reduction_pct']} |",
        "",
    ]
    return "\n".join(lines)
