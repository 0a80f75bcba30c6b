"""Cross-engine agreement: the scripted baseline on the same episodes on MJX and on MuJoCo C.

For each env (default: all four registered envs), the scripted Ch 2-3 method
(``peghole_mjx.envs.rollout.scripted_policy``) is rolled out on ``--episodes`` episodes of one
seed with ``engine=mjx`` (MJX-JAX, float32) and ``engine=mujoco`` (MuJoCo C through
``mujoco.batch``, float64). Both engines start from the same states (the reset's draw and IK
are the env's, shared), so the comparison is paired episode by episode.

Per env and engine: success rate (Wilson 95 %), failures by cause, mean and peak |F_z|, mean
time (``benchmarks.evals.hard_variants.summarise``). Per env: the paired differences mujoco - mjx of
mean |F_z|, peak |F_z| (bootstrap over episodes, 10 000 resamples, 95 %) and the share of
episodes whose outcome differs; ``agree`` is true when the two success intervals overlap.

``--engines mujoco`` runs the C engine only; the MJX side of an env is then read from the
committed scripted result of the same episodes (``hard_variants_<env>_<device>.json``: same
seed, episodes, batch and env config, MJX), and the comparison is unpaired (success
intervals, relative mean |F_z|); the entry names its source file.

``--policies rect,dual,rect_hard,dual_hard``: each published policy (trained on MJX) and the
scripted baseline evaluated on the ``mujoco`` engine (a cross evaluation, ``peghole evaluate
NAME --engine mujoco --cross``) on ``--episodes`` episodes of the seed, beside the policy's
committed MJX evaluation (``evaluation.json`` in its folder: seed 0, its own episode count; the
first episodes are the same, the comparison is unpaired).

Slices of ``--batch`` worlds are saved under ``--parts`` as they finish (resume: rerun the
command). Writes ``benchmarks/results/evals/cross_engine_<device>.json`` (+ ``.csv``, one row
per env and engine)::

    python -m benchmarks.evals.cross_engine --episodes 256
    python -m benchmarks.evals.cross_engine --envs RectExtract --episodes 16 --out /tmp/x.json
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import EVALS_RESULTS, cpu_label, out_file, rel, table, wilson, write_rows
from benchmarks.evals.hard_variants import run, summarise
from peghole_mjx.envs import ALL_ENVS
from peghole_mjx.files.provenance import provenance
from peghole_mjx.policies import load_policy
from peghole_mjx.training.evaluate import evaluate

ENGINES = ("mjx", "mujoco")
BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED = 10_000, 0


def paired_difference(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of ``b - a`` with its 95 % bootstrap interval (episodes resampled in pairs)."""
    d = np.asarray(b, float) - np.asarray(a, float)
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, len(d), (BOOTSTRAP_RESAMPLES, len(d)))
    lo, hi = np.percentile(d[idx].mean(1), [2.5, 97.5])
    return {"mean": round(float(d.mean()), 4), "ci95": [round(float(lo), 4), round(float(hi), 4)]}


def compare(ep: dict[str, dict[str, np.ndarray]]) -> dict:
    """The paired comparison of the two engines' per-episode arrays."""
    a, b = ep["mjx"], ep["mujoco"]
    s_a, s_b = summarise(a), summarise(b)
    lo = max(s_a["success_ci95"][0], s_b["success_ci95"][0])
    hi = min(s_a["success_ci95"][1], s_b["success_ci95"][1])
    return {
        "success_intervals_overlap": bool(lo <= hi),
        "outcome_differs_share": round(float(np.mean((a["success"] > 0) != (b["success"] > 0))), 4),
        "mean_fz_N_mujoco_minus_mjx": paired_difference(a["mean_fz_N"], b["mean_fz_N"]),
        "peak_fz_N_mujoco_minus_mjx": paired_difference(a["peak_fz_N"], b["peak_fz_N"]),
        "mean_fz_relative_pct": round(
            float(100 * (b["mean_fz_N"].mean() / a["mean_fz_N"].mean() - 1)), 2
        ),
    }


def committed_mjx(name: str, episodes: int, seed: int, batch: int) -> tuple[dict, str] | None:
    """The committed MJX scripted summary of these episodes (hard_variants), if one exists."""
    path = EVALS_RESULTS / f"hard_variants_{name}_{cpu_label()}.json"
    if not path.exists():
        return None
    ref = json.loads(path.read_text())
    same = (ref.get("episodes"), ref.get("seed"), ref.get("batch"), ref.get("overrides"))
    if same != (episodes, seed, batch, {}):
        return None
    keys = ("episodes", "success_rate", "success_ci95", "failure_rate", "failure_ci95")
    keys += ("failures_by_cause", "mean_fz_N", "peak_fz_N", "max_peak_fz_N", "mean_fxy_N")
    keys += ("fz_by_outcome_N", "mean_time_s", "date")
    return {k: ref[k] for k in keys if k in ref}, path.name


def compare_unpaired(a: dict, b: dict) -> dict:
    """Success intervals and mean |F_z| of two summaries (no per-episode arrays)."""
    lo = max(a["success_ci95"][0], b["success_ci95"][0])
    hi = min(a["success_ci95"][1], b["success_ci95"][1])
    return {
        "paired": False,
        "success_intervals_overlap": bool(lo <= hi),
        "mean_fz_relative_pct": round(100 * (b["mean_fz_N"] / a["mean_fz_N"] - 1), 2),
    }


def policy_on_c(name: str, episodes: int, seed: int, batch: int, parts: Path) -> dict:
    """A published policy and the baseline on the mujoco engine, beside its MJX evaluation."""
    bundle = load_policy(name)
    mjx_eval = json.loads((Path(bundle.path) / "evaluation.json").read_text())
    res = evaluate(
        bundle,
        episodes,
        seed=seed,
        batch=batch,
        parts_dir=parts / f"policy_{name}",
        env_overrides={"engine": "mujoco"},
        cross=True,
    )
    keep = ("success_rate", "mean_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N", "episodes")
    entry = {
        "env": res["env"],
        "mjx": {
            "source": f"{Path(bundle.path).name}/evaluation.json",
            "seed": mjx_eval["seed"],
            "policy": {k: mjx_eval["policy"][k] for k in keep},
            "baseline": {k: mjx_eval["baseline"][k] for k in keep},
            "force_reduction_pct": mjx_eval["force_reduction_pct"],
        },
        "mujoco": {
            "policy": {k: res["policy"][k] for k in keep},
            "baseline": {k: res["baseline"][k] for k in keep},
            "force_reduction_pct": res["force_reduction_pct"],
        },
    }
    a, b = entry["mjx"]["policy"], entry["mujoco"]["policy"]
    wa = wilson(round(a["success_rate"] * a["episodes"]), a["episodes"])
    wb = wilson(round(b["success_rate"] * b["episodes"]), b["episodes"])
    entry["mjx"]["policy"]["success_ci95"], entry["mujoco"]["policy"]["success_ci95"] = wa, wb
    entry["comparison"] = {
        "paired": False,
        "policy_success_intervals_overlap": bool(max(wa[0], wb[0]) <= min(wa[1], wb[1])),
        "policy_mean_fz_relative_pct": round(100 * (b["mean_fz_N"] / a["mean_fz_N"] - 1), 2),
        "force_reduction_pct_mjx_vs_mujoco": [
            round(entry["mjx"]["force_reduction_pct"], 2),
            round(entry["mujoco"]["force_reduction_pct"], 2),
        ],
    }
    return entry


# ----------------------------------------------------------------------------- docs tables
#: the committed comparison (2-core CPU) that the docs tables read
RESULT = EVALS_RESULTS / "cross_engine_cpu-2core.json"


@table("cross_engine")
def cross_engine_table() -> str:
    """The scripted baseline on both engines."""
    path = RESULT
    if not path.exists():
        return "Not measured yet: `python -m benchmarks.evals.cross_engine`."
    d = json.loads(path.read_text())
    out = [
        f"Scripted baseline, {d['episodes']} episodes of seed {d['seed']} on each engine, "
        f"{d['device']}, {d['date'][:10]} ([{path.name}]({rel(path)})):",
        "",
        "| env | engine | success [95 %] | mean F_z N | peak F_z N | time s | mujoco - mjx "
        "mean F_z N [95 %] | source |",
        "|---|---|---|---:|---:|---:|---|---|",
    ]
    for name, e in d["envs"].items():
        comp = e["comparison"]
        diff = comp.get("mean_fz_N_mujoco_minus_mjx")
        dtext = (
            f"{diff['mean']:+.3f} [{diff['ci95'][0]:+.3f}, {diff['ci95'][1]:+.3f}]"
            if diff
            else f"{comp['mean_fz_relative_pct']:+.1f} % (unpaired)"
        )
        for eng in ("mjx", "mujoco"):
            s = e[eng]
            lo, hi = s["success_ci95"]
            t = "-" if s.get("mean_time_s") is None else f"{s['mean_time_s']:.2f}"
            out.append(
                f"| {name} | {eng} | {s['success_rate']:.3f} [{lo:.3f}, {hi:.3f}] | "
                f"{s['mean_fz_N']:.3f} | {s['peak_fz_N']:.2f} | {t} | "
                f"{dtext if eng == 'mujoco' else ''} | {s.get('source', 'this run')} |"
            )
    return "\n".join(out)


@table("cross_engine_policies")
def cross_engine_policies() -> str:
    """Each published policy (trained on MJX) on both engines."""
    path = RESULT
    pol = json.loads(path.read_text()).get("policies", {}) if path.exists() else {}
    if not pol:
        return (
            "Not measured yet: `python -m benchmarks.evals.cross_engine --envs '' --policies ...`."
        )
    out = [
        "| policy | engine | episodes | success [95 %] | mean F_z N | time s | baseline success "
        "| reduction vs baseline % | source |",
        "|---|---|---:|---|---:|---:|---:|---:|---|",
    ]
    for name, e in pol.items():
        for eng in ("mjx", "mujoco"):
            p_, b = e[eng]["policy"], e[eng]["baseline"]
            lo, hi = p_["success_ci95"]
            src = e[eng].get("source", "this run (cross evaluation)")
            out.append(
                f"| {name} | {eng} | {p_['episodes']} | {p_['success_rate']:.3f} [{lo:.3f}, "
                f"{hi:.3f}] | {p_['mean_fz_N']:.3f} | {p_['mean_time_s']:.2f} | "
                f"{b['success_rate']:.3f} | {e[eng]['force_reduction_pct']:.1f} | {src} |"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--envs", default=",".join(ALL_ENVS), help="comma list of registered envs ('' for none)"
    )
    p.add_argument("--engines", default="mjx,mujoco", help="mjx,mujoco or mujoco (see above)")
    p.add_argument("--episodes", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--batch", type=int, default=64, help="worlds at once")
    p.add_argument(
        "--parts",
        type=Path,
        default=Path(os.environ.get("TMPDIR", "/tmp")) / "peghole_cross_engine",
        help="folder of the finished slices (resume)",
    )
    p.add_argument("--policies", default="", help="comma list of published policies (above)")
    p.add_argument(
        "--out", type=out_file, help="default: benchmarks/results/evals/cross_engine_<dev>.json"
    )
    args = p.parse_args(argv)
    names = [e.strip() for e in args.envs.split(",") if e.strip()] if args.envs else []
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    if engines not in (["mjx", "mujoco"], ["mujoco"]):
        p.error("--engines is mjx,mujoco or mujoco")
    unknown = sorted(set(names) - set(ALL_ENVS))
    if unknown or args.episodes < 2 or args.batch < 1:
        p.error(f"unknown envs {unknown}" if unknown else "--episodes >= 2 and --batch >= 1")
    out = args.out or EVALS_RESULTS / f"cross_engine_{cpu_label()}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "benchmark": "cross_engine",
        "method": "scripted (fixed compliance at the tip, straight pull at 20 mm/s)",
        "episodes": args.episodes,
        "seed": args.seed,
        "batch": args.batch,
        **provenance(),
        "envs": {},
    }
    for name in names:
        ep, entry = {}, {}
        ref = None
        if "mjx" not in engines:
            ref = committed_mjx(name, args.episodes, args.seed, args.batch)
            if ref is None:
                p.error(f"{name}: no committed MJX result of these episodes; run both engines")
            entry["mjx"] = {**ref[0], "source": ref[1]}
        for engine in engines:
            env, ep[engine], wall = run(
                name, {"engine": engine}, args.episodes, args.seed, args.batch, args.parts
            )
            entry[engine] = {"wall_s": round(wall, 1), **summarise(ep[engine])}
            print(json.dumps({"env": name, "engine": engine, **entry[engine]}), flush=True)
        entry["preset"], entry["representation"] = env.config.preset, env.representation
        entry["comparison"] = (
            compare(ep) if ref is None else compare_unpaired(entry["mjx"], entry["mujoco"])
        )
        result["envs"][name] = entry
        print(json.dumps({"env": name, **entry["comparison"]}), flush=True)
    result["policies"] = {}
    for name in [x.strip() for x in args.policies.split(",") if x.strip()]:
        pol = policy_on_c(name, args.episodes, args.seed, args.batch, args.parts)
        result["policies"][name] = pol
        print(json.dumps({"policy": name, **pol["comparison"]}), flush=True)
    if out.exists():  # entries of earlier runs of this file are kept unless rerun
        old = json.loads(out.read_text())
        for key in ("envs", "policies"):
            result[key] = {**old.get(key, {}), **result[key]}
    out.write_text(json.dumps(result, indent=2) + "\n")
    rows = [
        {"env": n, "engine": g, **_flat(e[g])} for n, e in result["envs"].items() for g in ENGINES
    ]
    write_rows(out.with_suffix(".csv"), rows)
    print(out)
    return 0


def _flat(s: dict) -> dict:
    keys = ("episodes", "success_rate", "mean_fz_N", "peak_fz_N", "mean_time_s", "wall_s")
    out = {k: s.get(k) for k in keys}
    out["source"] = s.get("source", "this run")
    out["success_lo"], out["success_hi"] = s["success_ci95"]
    out.update({f"fail_{c}": v for c, v in s["failures_by_cause"].items()})
    return out


if __name__ == "__main__":
    raise SystemExit(main())
