"""``peghole demo``: the whole pipeline once, with a short report.

What it does, step by step, and how a rerun reuses its complete stages:
:data:`peghole_mjx.cli.demo.DESCRIPTION` (``peghole demo --help``); the parser and the names
the demo writes are there too.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from peghole_mjx.cli.demo import DEMO_OUTPUTS, DEMO_STATE, REPORT_TITLE, STAGE_OUTPUTS
from peghole_mjx.cli.demo import add_parser as add_parser  # the group's parser (cli.GROUPS)
from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import dumps, load_json_object
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import outputs
from peghole_mjx.experiments import report as exp_report
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.mjcf import write_scenes
from peghole_mjx.geometry.specs import MM, PRESETS, get_preset
from peghole_mjx.policies import PRETRAINED
from peghole_mjx.sim.engines import engine_overrides
from peghole_mjx.training import evaluate as evaluate_mod
from peghole_mjx.training import run as run_mod
from peghole_mjx.training.config import load_train_config


def _step(name: str) -> float:
    print(f"\n== {name}", file=sys.stderr, flush=True)
    return time.perf_counter()


# ---------------------------------------------------------------------- the stages' work
# (module functions, so that tests replace them with quick stand-ins)
def _build_models(out: Path) -> None:
    for preset in ("rect-2", "dual-2"):
        scene, _, rep = write_scenes(get_preset(preset), out / preset)
        print(f"wrote {scene} (collision representation: {rep})", file=sys.stderr)


#: the demo's compliance preset; the cells it runs there: the quick experiment (the project's
#: default stiffness, K_theta 300 N m/rad, beta0 +0.1..+0.3 deg, where the quasi-static
#: oracle predicts R1 reversed) and the sweep's cell nearest R1 (K_theta 30 N m/rad, beta0 of
#: the thesis's sign; docs/research/compliance.md, 2026-11-29: 70.3 % simulated, 69.9 % oracle).
#: Both
#: run in one compiled MJX step (the stiffness and errors are per-world data); each cell's
#: summary and figures go to ``compliance/<folder>`` (the first: ``compliance/`` itself).
DEMO_PRESET = "rect-2"
DEMO_CELLS: dict[str, dict[str, Any]] = {
    "": {},
    "r1_regime": {"rotational_stiffness_Nm_rad": 30.0, "beta0_deg": (-0.3, -0.1)},
}
#: per-cell numbers of the compliance stage (read by the report)
CELLS_FILE = "cells.json"
#: the oracle's tip-vs-top reduction from which R1 counts as holding (the sweep's findings
#: count the cells where the oracle predicts >= 50 %), and below which (in size) the effect
#: counts as small (docs/research/compliance.md: the oracle's small cells are within 8 %), %
REGIME_HOLDS_PCT = 50.0
REGIME_SMALL_PCT = 10.0
#: the simulation "agrees" with the oracle within this many points (the sweep's findings' bound)
AGREE_POINTS = 10.0


def _cell_config(changes: dict[str, Any]) -> cx.ExperimentConfig:
    return dataclasses.replace(cx.ExperimentConfig.quick("rect"), **changes)


def _reductions(by_lc: list[np.ndarray]) -> dict[str, Any]:
    """Mean peak per L_C (tip, centre, top) and the tip-vs-top / tip-vs-centre reductions of
    the means, %, over the repeats finite at all three L_C (paired, as the sweep)."""
    ok = np.all(np.isfinite(np.stack(by_lc)), axis=0)
    tip, ctr, top = (np.asarray(v, float)[ok] for v in by_lc)

    def red(a: np.ndarray, ref: np.ndarray) -> float | None:
        return float(100.0 * (1.0 - a.mean() / ref.mean())) if ok.any() else None

    return {
        "peak_fz_N": [float(v.mean()) if ok.any() else None for v in (tip, ctr, top)],
        "tip_vs_top_pct": red(tip, top),
        "tip_vs_centre_pct": red(tip, ctr),
        "pairs": int(ok.sum()),
    }


def cell_oracle(cfg: cx.ExperimentConfig, preset: str = DEMO_PRESET) -> dict[str, Any]:
    """The quasi-static oracle (:mod:`peghole_mjx.analysis.oracle`, through
    :func:`~peghole_mjx.experiments.compliance.quasi_static`) for the worlds of ``cfg``: each
    world's peak extraction force after the first :data:`~.compliance.EARLY_MM` of the pull,
    reduced like the simulation's (:func:`_reductions`)."""
    table = cx.world_table(cfg, preset)
    h0 = PRESETS[preset].hole_depth_mm - cfg.sim_options().tip_gap_mm
    qs = cx.quasi_static(preset, PRESETS[preset].friction, table, h0)
    peaks = cx.quasi_static_peaks(qs, h0, cx.EARLY_MM[PRESETS[preset].kind])
    r = cfg.repeats
    return _reductions([peaks[k * r : (k + 1) * r] for k in range(3)])


def cell_record(name: str, cfg: cx.ExperimentConfig, res: dict, preset: str = DEMO_PRESET):
    """One row of the demo's compliance table: the cell's settings, the simulated reductions
    of ``res`` (:meth:`~.compliance.Extraction.run` of the cell's worlds), the oracle's and
    the thesis's, the contact's depth and the NaN worlds."""
    spec = PRESETS[preset]
    peaks = cx.peaks(res, cx.EARLY_MM[spec.kind])["fz"]
    r = cfg.repeats
    top_lc = cfg.setup(spec.kind).lc_mm[-1] * MM
    return {
        "name": name,
        "preset": preset,
        "mu": spec.friction,
        "k_rot_Nm_rad": cfg.rotational_stiffness_Nm_rad,
        "k_lat_N_m": cfg.lateral_stiffness_N_m,
        "beta0_deg": list(cfg.beta0_deg),
        "delta0_mm": list(cfg.delta0_mm),
        "repeats": r,
        "regime_KxLc2_over_Ktheta": cfg.lateral_stiffness_N_m
        * top_lc**2
        / cfg.rotational_stiffness_Nm_rad,
        "early_mm": cx.EARLY_MM[spec.kind],
        "sim": _reductions([peaks[k * r : (k + 1) * r] for k in range(3)]),
        "oracle": cell_oracle(cfg, preset),
        "thesis": {
            "tip_vs_top_pct": cx.THESIS["reduction_tip_vs_top_pct"],
            "tip_vs_centre_pct": cx.THESIS["reduction_tip_vs_centre_pct"],
        },
        "max_penetration_in_hole_mm": float(np.nanmax(res["penetration_in_hole_mm"])),
        "penetration_limit_mm": 0.25 * spec.radial_clearance_mm,
        "nan_worlds": int(np.sum(res["nan"])),
    }


def _run_experiment(out: Path) -> dict:
    """The compliance experiment of each :data:`DEMO_CELLS` cell on one compiled
    :class:`~.compliance.Extraction`; each cell's summary and figures (as ``peghole
    experiment compliance``) and ``cells.json`` (:func:`cell_record` per cell)."""
    cfgs = {folder: _cell_config(changes) for folder, changes in DEMO_CELLS.items()}
    need = sum(exp_report.output_bytes(c) for c in cfgs.values()) + (1 << 20)
    out = outputs.check_out(out, need)
    with prog.phase(f"building the {DEMO_PRESET} experiment scene (MuJoCo, MJX)"):
        extraction = cx.Extraction(DEMO_PRESET, cfgs[""])
    cells = []
    for folder, cfg in cfgs.items():
        t0 = time.time()
        res = extraction.run(table=cx.world_table(cfg, DEMO_PRESET))
        cx.check_not_all_nan(
            res["nan"], f"the demo's compliance cell {folder or 'default'}", cx.nan_cause(cfg)
        )
        summary = exp_report.summarise({DEMO_PRESET: res}, cfg, time.time() - t0)
        exp_report.write_outputs({DEMO_PRESET: res}, summary, out / folder)
        cells.append(cell_record(folder or "default", cfg, res))
    fileio.write_text(out / CELLS_FILE, dumps(cells, indent=2) + "\n")
    return {"cells": cells}


def _train(out: Path, cfg) -> dict:
    """Train the whole budget: the report states the FINAL policy's success (no early stop)."""
    return run_mod.TrainingRun(cfg, out, render=True).run()


def _evaluate(policy: str, episodes: int) -> dict:
    return evaluate_mod.evaluate(policy, episodes)


def _train_config(profile: str, engine: dict):
    """The demo's training config: RectExtract with training's defaults (RL + compliance
    strategy, the outcome reward, residual actions) and the profile's learner: on ``cpu`` the
    time-limit protocol's (a time-out a terminal failure, the time left observed; decided
    2026-12-06 by that protocol's rule, docs/research/time_limit.md)."""
    return load_train_config("RectExtract", profile, engine)


def training_task(cfg) -> str:
    """The demo training's task in words (for the report)."""
    over = cfg.env_overrides or {}
    cs = over.get("compliance_strategy", True)
    kind = over.get("reward_config.kind", "thesis")  # older records: eq (4.4)
    task = "RL + compliance strategy" if cs else "RL, compliance strategy off"
    actions = "residual actions" if over.get("action.residual", False) else "plain actions"
    timeout = ", time-out a failure" if over.get("reward_config.time_limit") == "failure" else ""
    return f"{task}, {kind} reward, {actions}{timeout}"


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
            if present and _is_demo_report(out / "report.md"):
                raise UserInputError(
                    f"{out} holds {', '.join(present)} but no {DEMO_STATE} (an older demo): "
                    "pass --force to delete them and start afresh, or choose another --out"
                )
            if present:  # --force would refuse it too (not a demo's folder): no such advice
                raise UserInputError(
                    f"{out} holds {', '.join(present)} but no {DEMO_STATE} or demo report: "
                    "not a demo's folder, nothing was changed; choose another --out"
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
        {
            "experiment": "compliance rect quick",
            "cells": {k or "default": dict(v) for k, v in DEMO_CELLS.items()},
        },
        "2/4 compliance experiment (rect-2, quick: K_theta 300 and 30 N m/rad)",
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
        "task": training_task(cfg),
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


def regime(oracle_tip_vs_top_pct: float | None) -> str:
    """The cell's regime of R1 from the oracle's tip-vs-top reduction: ``holds`` (>=
    :data:`REGIME_HOLDS_PCT`), ``weaker`` (R1's sign, smaller), ``small`` (within
    :data:`REGIME_SMALL_PCT` either way), ``reversed`` (the tip's peak above the top's), or
    ``unknown`` (no oracle value)."""
    x = oracle_tip_vs_top_pct
    if x is None or not math.isfinite(x):
        return "unknown"
    if x >= REGIME_HOLDS_PCT:
        return "holds"
    if x >= REGIME_SMALL_PCT:
        return "weaker"
    if x > -REGIME_SMALL_PCT:
        return "small"
    return "reversed"


def cell_label(cell: dict) -> str:
    """``rect-2, K_theta 300 N m/rad, beta0 +0.1..+0.3 deg``."""
    lo, hi = cell["beta0_deg"]
    return f"{cell['preset']}, K_theta {cell['k_rot_Nm_rad']:g} N m/rad, beta0 {lo:+g}..{hi:+g} deg"


def regime_sentence(cell: dict) -> str:
    """One sentence: the cell's regime per the oracle (:func:`regime`), why, and whether the
    simulation agrees with the oracle within :data:`AGREE_POINTS`."""
    o, s = cell["oracle"]["tip_vs_top_pct"], cell["sim"]["tip_vs_top_pct"]
    ratio = f"K_lat L_C,top^2 / K_theta = {cell['regime_KxLc2_over_Ktheta']:.3g}"
    th = cell["thesis"]["tip_vs_top_pct"]
    kind = regime(o)
    if kind == "holds":
        why = (
            f"R1 holds: the oracle puts the tip's peak {o:.1f} % below the top's (thesis "
            f"{th} %), the rotational spring being soft enough ({ratio}) for the compliance "
            "centre to set the peg's tilt"
        )
    elif kind == "weaker":
        why = (
            f"R1's ordering, weaker than the thesis's: the oracle puts the tip's peak {o:.1f} % "
            f"below the top's (thesis {th} %); with {ratio} the spring lets the compliance "
            "centre matter only a little"
        )
    elif kind == "small":
        why = (
            f"the effect is small: the oracle gives {o:+.1f} % (thesis {th} %), since with "
            f"{ratio} the peg keeps its commanded tilt and L_C barely matters"
        )
    elif kind == "reversed":
        why = (
            f"R1 is reversed: the oracle puts the tip's peak {-o:.1f} % above the top's (thesis "
            f"{th} % below), since with {ratio} the peg keeps its commanded tilt and with this "
            "sign of the angular error beta0 the top is the better compliance centre"
        )
    else:
        why = "no oracle value for this cell, so its regime is not known"
    if kind != "unknown" and s is not None and math.isfinite(s):
        agree = "agrees" if abs(s - o) <= AGREE_POINTS else "does not agree"
        why += f"; the simulation {agree} within {AGREE_POINTS:g} points ({s:+.1f} %)"
    return f"{cell_label(cell)}: {why}."


def compliance_table(cells: list[dict]) -> list[str]:
    """The demo's compliance table (markdown lines): per cell the simulated reductions of the
    mean peak extraction force beside the quasi-static oracle's for the same worlds and the
    thesis's (R1), the mean peaks, the contact depth and NaN worlds; then one regime sentence
    per cell (:func:`regime_sentence`)."""
    lines = [
        "| cell | K_lat L_C,top^2 / K_theta | tip vs top %: sim | oracle | thesis | "
        "tip vs centre %: sim | oracle | thesis | mean peak F_z N, tip / centre / top: sim | "
        "oracle | max penetration mm, tip in the hole (limit) | NaN worlds |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in cells:
        sim, orc, th = c["sim"], c["oracle"], c["thesis"]

        def peaks(d: dict) -> str:
            return " / ".join(_f(v, ".3g") for v in d["peak_fz_N"])

        lines.append(
            f"| {cell_label(c)} | {c['regime_KxLc2_over_Ktheta']:.3g} | "
            f"{_f(sim['tip_vs_top_pct'], '.1f')} | {_f(orc['tip_vs_top_pct'], '.1f')} | "
            f"{th['tip_vs_top_pct']} | "
            f"{_f(sim['tip_vs_centre_pct'], '.1f')} | {_f(orc['tip_vs_centre_pct'], '.1f')} | "
            f"{th['tip_vs_centre_pct']} | {peaks(sim)} | {peaks(orc)} | "
            f"{_f(c['max_penetration_in_hole_mm'], '.4f')} ({c['penetration_limit_mm']:.4f}) | "
            f"{c['nan_worlds']} |"
        )
    early = sorted({c["early_mm"] for c in cells})
    lines += [
        "",
        "Sim: the mean over the cell's repeats of each world's peak extraction force F_z after "
        f"the first {', '.join(f'{e:g}' for e in early)} mm of the pull (MJX, 20 mm/s); "
        "oracle: the same for the quasi-static oracle (`peghole_mjx/analysis/oracle.py`) in "
        "the same worlds; thesis: R1 (Sec 3.5). The regime, from the oracle:",
        "",
        *(f"- {regime_sentence(c)}" for c in cells),
    ]
    return lines


def _report(out: Path, tr: dict, ev: dict, timings: dict, profile: str) -> str:
    prov = provenance()
    cells = json.loads((out / "compliance" / CELLS_FILE).read_text())
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
        "## 2. Compliance-centre experiment (rect-2, quick)",
        "",
        "L_C at the tip, the centre and the top of the peg, "
        f"{cells[0]['repeats']} repeats each, in two cells: the project's default stiffness "
        "and the sweep's cell nearest the thesis's R1 (`peghole experiment sweep`, "
        "docs/research/compliance.md).",
        "",
        *(
            f"![force vs depth, {cell_label(c)}](compliance/{folder + '/' if folder else ''}"
            "force_depth.png)"
            for folder, c in zip(DEMO_CELLS, cells, strict=False)
        ),
        "",
        *compliance_table(cells),
        "",
        f"## 3. Training (RectExtract, {tr['task']}, profile {profile}, engine {tr['engine']})",
        "",
        f"{tr['env_steps']} env steps in {tr['wall_s']} s; eval return "
        f"{_f(tr['untrained_eval_return'], '.2f')} untrained -> "
        f"{_f(fe.get('mean_return', float('nan')), '.2f')}; "
        f"eval success {_f(fe.get('success_rate', float('nan')), '.2f')}. The final policy "
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
