"""The built-in irregular parts as trained tasks: a policy per shape against the scripted method.

The study's rules were declared before its runs in
``benchmarks/results/evals/task_policies_decisions.txt``. Per built-in shape
(``peghole_mjx/geometry/shapes.py``) and setting (``nominal``: the MeshExtract env's
randomisation; ``hard``: the commanded tilt error of RectExtractHard, 4 deg):

1. the task folder (``peghole task builtin SHAPE --clearance-mm C``; reused when present);
2. ``hard`` only: the scripted baseline alone on ``--episodes`` episodes; the hard policy is
   trained only where the scripted method fails in at least :data:`HARD_FAILURE` of them;
3. the policy: ``peghole train --env MeshExtract --engine mujoco --profile cpu --set
   env.task=DIR`` (plus the tilt for ``hard``) into ``runs/task_policies/<shape>_<setting>``,
   resumed with ``--resume`` when an unfinished run is there;
4. the checkpoint the published rule picks (:func:`peghole_mjx.training.selection
   .choose_checkpoint`), evaluated with the scripted baseline on the same ``--episodes``
   episodes (seed 0, its training env): success with Wilson 95 % intervals, mean and peak
   |F_z|, paired differences policy minus scripted (95 % bootstrap) and the declared verdict
   (:func:`verdict`).

    python -m benchmarks.evals.task_policies --episodes 256

Each finished (shape, setting) is appended to ``runs/task_policies/rows.jsonl``: an
interrupted sweep, rerun, goes on where it stopped. Writes
``benchmarks/results/evals/task_policies_<device>.json`` and ``.csv`` (device, versions, date);
the docs table ``task_policies`` (docs/guide/tasks.md) is generated from it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import EVALS_RESULTS, ROOT, cpu_label, out_file, rel, table, write_rows
from benchmarks.evals.cross_engine import paired_difference
from benchmarks.evals.hard_variants import summarise
from peghole_mjx import envs
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.envs.task_make import make_builtin
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry import task as tf
from peghole_mjx.geometry.shapes import BUILTINS
from peghole_mjx.policies import load_policy
from peghole_mjx.training.evaluate import evaluate
from peghole_mjx.training.selection import choose_checkpoint

OUT = EVALS_RESULTS / f"task_policies_{cpu_label()}.json"
DECISIONS = EVALS_RESULTS / "task_policies_decisions.txt"
#: the settings: env config overrides on top of the task (``hard``: RectExtractHard's tilt)
SETTINGS = {
    "nominal": {},
    "hard": {"randomization.angular_error_deg": 4.0},
}
#: the scripted failure share at the hard setting from which a hard policy is trained
HARD_FAILURE = 0.2
PROFILE = "cpu"


def verdict(d_success: dict, d_mean_fz: dict) -> str:
    """The declared verdict of a paired comparison (policy minus scripted): ``better`` if the
    success interval lies above 0, or contains 0 and the mean |F_z| interval lies below 0;
    ``worse`` the mirror; otherwise ``no difference resolved``."""
    lo, hi = d_success["ci95"]
    if lo > 0:
        return "better"
    if hi < 0:
        return "worse"
    flo, fhi = d_mean_fz["ci95"]
    if fhi < 0:
        return "better"
    if flo > 0:
        return "worse"
    return "no difference resolved"


def task_folder(tasks: Path, shape: str, clearance_mm: float) -> Path:
    """The shape's task folder, built once."""
    folder = tasks / shape
    if not (folder / tf.MANIFEST).is_file():
        make_builtin(shape, clearance_mm, folder, progress=True)
    return folder


def scripted_probe(folder: Path, overrides: dict, episodes: int, seed: int) -> dict:
    """The scripted baseline alone on ``episodes`` episodes of the task at ``overrides``."""
    env = envs.load(
        "MeshExtract", config_overrides={"task": str(folder), "engine": "mujoco", **overrides}
    )
    res = rollout(env, scripted_policy(env), episodes, seed=seed, progress=False)
    ep = {k: np.asarray(v) for k, v in res.per_episode.items()}
    return summarise(ep)


def train(folder: Path, overrides: dict, run: Path) -> float:
    """Train (or finish) the shape's policy run; its training wall clock, s."""
    if not (run / "summary.json").is_file():
        cmd = [sys.executable, "-m", "peghole_mjx.cli.main", "train"]
        if (run / "run.json").is_file():
            cmd += ["--resume", str(run)]
        else:
            cmd += ["--env", "MeshExtract", "--engine", "mujoco", "--profile", PROFILE]
            cmd += ["--out", str(run), "--set", f"env.task={folder}", "--no-video"]
            cmd += [f"--set=env.{k}={json.dumps(v)}" for k, v in overrides.items()]
        subprocess.run(cmd, check=True)
    return float(json.loads((run / "summary.json").read_text())["wall_s"])


def compare(folder: Path, run: Path, episodes: int, seed: int) -> dict:
    """The chosen checkpoint and the scripted baseline on the same episodes: summaries, paired
    differences and the verdict."""
    path, selection = choose_checkpoint(run, "best")
    res = evaluate(
        load_policy(path), episodes, seed=seed, progress=False, keep_episodes=True, batch=64
    )
    ep = {
        who: {k: np.asarray(v, float) for k, v in res["per_episode"][src].items()}
        for who, src in (("policy", "policy"), ("scripted", "baseline"))
    }
    s, p = ep["scripted"], ep["policy"]
    diff = {
        "success": paired_difference(s["success"] > 0, p["success"] > 0),
        "mean_fz_N": paired_difference(s["mean_fz_N"], p["mean_fz_N"]),
        "peak_fz_N": paired_difference(s["peak_fz_N"], p["peak_fz_N"]),
    }
    return {
        "policy_path": rel(path) if path.is_relative_to(ROOT) else str(path),
        "selection": selection,
        "policy": summarise(p),
        "scripted": summarise(s),
        "policy_minus_scripted": diff,
        "force_reduction_pct": res["force_reduction_pct"],
        "verdict": verdict(diff["success"], diff["mean_fz_N"]),
    }


def shape_setting(shape: str, setting: str, args) -> dict:
    """One row: the hard probe where it applies, then training and the comparison."""
    folder = task_folder(args.tasks, shape, args.clearance_mm)
    over = SETTINGS[setting]
    row = {"key": f"{shape}/{setting}", "shape": shape, "setting": setting, "overrides": over}
    if setting == "hard":
        probe = scripted_probe(folder, over, args.episodes, args.seed)
        row["scripted_probe"] = probe
        if probe["failure_rate"] < HARD_FAILURE:
            row["trained"] = False
            row["why_not"] = (
                f"scripted fails {probe['failure_rate']:.1%} < {HARD_FAILURE:.0%} at this setting"
            )
            return row
    run = args.runs / f"{shape}_{setting}"
    row["trained"] = True
    row["run"] = str(run)
    row["train_wall_s"] = train(folder, over, run)
    t0 = time.perf_counter()
    row.update(compare(folder, run, args.episodes, args.seed))
    row["eval_wall_s"] = round(time.perf_counter() - t0, 1)
    jax.clear_caches()
    return row


CSV_FIELDS = (
    "shape",
    "setting",
    "trained",
    "scripted_success",
    "policy_success",
    "d_success",
    "d_success_lo",
    "d_success_hi",
    "scripted_mean_fz_N",
    "policy_mean_fz_N",
    "d_mean_fz_N",
    "d_mean_fz_lo",
    "d_mean_fz_hi",
    "verdict",
    "train_wall_s",
    "device",
    "date",
)


def csv_row(r: dict) -> dict:
    """A row of the CSV (one per shape and setting)."""
    out = {k: r.get(k) for k in ("shape", "setting", "trained", "train_wall_s", "verdict")}
    s = r.get("scripted") or r.get("scripted_probe") or {}
    out["scripted_success"] = s.get("success_rate")
    out["scripted_mean_fz_N"] = s.get("mean_fz_N")
    if r.get("trained"):
        d = r["policy_minus_scripted"]
        out["policy_success"] = r["policy"]["success_rate"]
        out["policy_mean_fz_N"] = r["policy"]["mean_fz_N"]
        out["d_success"], (out["d_success_lo"], out["d_success_hi"]) = (
            d["success"]["mean"],
            d["success"]["ci95"],
        )
        out["d_mean_fz_N"], (out["d_mean_fz_lo"], out["d_mean_fz_hi"]) = (
            d["mean_fz_N"]["mean"],
            d["mean_fz_N"]["ci95"],
        )
    return {k: out.get(k) for k in CSV_FIELDS}


def _rate(s: dict) -> str:
    lo, hi = s["success_ci95"]
    return f"{s['success_rate']:.3f} [{lo:.3f}, {hi:.3f}]"


def _diff(d: dict, fmt: str = "+.3f") -> str:
    return f"{d['mean']:{fmt}} [{d['ci95'][0]:{fmt}}, {d['ci95'][1]:{fmt}}]"


@table("task_policies")
def task_policies_table() -> str:
    """One row per shape and setting: scripted and policy success and force, paired."""
    if not OUT.exists():
        return f"Not run yet: no `{rel(OUT)}` is committed."
    data = json.loads(OUT.read_text())
    lines = [
        f"{data['device']}, {data['date'][:10]}, diametral clearance {data['clearance_mm']:g} mm, "
        f"{data['episodes']} episodes per row (seed {data['seed']}, engine mujoco); rules "
        f"declared before the runs: [`{DECISIONS.name}`]({rel(DECISIONS)}); results "
        f"[`{OUT.name}`]({rel(OUT)}).",
        "",
        "| shape | setting | scripted success [95 %] | policy success [95 %] | "
        "success, policy - scripted | mean F_z N scripted / policy | mean F_z, policy - "
        "scripted (N) | verdict | training s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        if not r.get("trained"):
            s = r["scripted_probe"]
            lines.append(
                f"| {r['shape']} | {r['setting']} | {_rate(s)} | not trained: {r['why_not']} "
                f"| - | {s['mean_fz_N']:.2f} / - | - | - | - |"
            )
            continue
        s, p, d = r["scripted"], r["policy"], r["policy_minus_scripted"]
        lines.append(
            f"| {r['shape']} | {r['setting']} | {_rate(s)} | {_rate(p)} | {_diff(d['success'])} "
            f"| {s['mean_fz_N']:.2f} / {p['mean_fz_N']:.2f} | {_diff(d['mean_fz_N'], '+.2f')} "
            f"| {r['verdict']} | {r['train_wall_s']:.0f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    ap.add_argument("--clearance-mm", type=float, default=0.1)
    ap.add_argument("--episodes", type=int, default=256, help="evaluation episodes per row")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shapes", default=",".join(BUILTINS), help="comma list (default: all six)")
    ap.add_argument("--settings", default=",".join(SETTINGS), help="comma list of settings")
    ap.add_argument("--tasks", type=Path, help="folder of the task folders")
    ap.add_argument("--runs", type=Path, default=ROOT / "runs" / "task_policies")
    ap.add_argument("--out", type=out_file, default=OUT)
    args = ap.parse_args(argv)
    args.tasks = args.tasks or ROOT / "runs" / f"tasks_builtin_c{args.clearance_mm:g}"
    shapes = [s.strip() for s in args.shapes.split(",") if s.strip()]
    settings = [s.strip() for s in args.settings.split(",") if s.strip()]
    bad = [s for s in shapes if s not in BUILTINS] + [s for s in settings if s not in SETTINGS]
    if bad:
        ap.error(
            f"unknown shapes or settings {bad}: shapes {list(BUILTINS)}, settings {list(SETTINGS)}"
        )
    args.runs.mkdir(parents=True, exist_ok=True)
    store = args.runs / f"rows_e{args.episodes}_s{args.seed}_c{args.clearance_mm:g}.jsonl"
    done = {}
    if store.exists():
        for line in store.read_text().splitlines():
            try:
                r = json.loads(line)
            except ValueError:  # a line cut short by a kill: its row runs again
                continue
            done[r["key"]] = r
    rows = []
    todo = [(sh, st) for st in settings for sh in shapes]
    for shape, setting in tqdm(todo, desc="task policies", unit="row", file=sys.stderr):
        row = done.get(f"{shape}/{setting}")
        if row is None:
            row = shape_setting(shape, setting, args)
            with store.open("a") as f:
                f.write(json.dumps(row) + "\n")
        rows.append(row)
        print(json.dumps({k: row.get(k) for k in ("key", "verdict", "why_not")}), flush=True)
        meta = {
            **provenance(),
            "command": "python -m benchmarks.evals.task_policies " + " ".join(argv or sys.argv[1:]),
            "clearance_mm": args.clearance_mm,
            "episodes": args.episodes,
            "seed": args.seed,
            "profile": PROFILE,
            "hard_failure_threshold": HARD_FAILURE,
            "decisions": rel(DECISIONS),
            "rows": rows,
        }
        args.out.write_text(json.dumps(meta, indent=2) + "\n")
        write_rows(
            args.out.with_suffix(".csv"),
            ({**csv_row(r), "device": meta["device"], "date": meta["date"]} for r in rows),
            CSV_FIELDS,
        )
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
