"""Stuck joints: the scripted Ch 2-3 method and a policy on the same stuck-peg episodes.

The env is the policy's training env (its ``policy.json``) with a stuck joint: the peg starts
welded in its hole and the weld releases once the axial F/T force reaches the episode's
breakaway force (env config ``stuck`` group, docs/guide/stuck.md). A policy trained on the
stuck variant is evaluated as trained; any other policy (e.g. the published ``rect``) as a
cross evaluation with the stuck joint switched on, recorded in ``differs_from_training``.
``--breakaway LO HI`` changes the breakaway range, ``--engine`` the physics engine (both cross
evaluations). Both methods meet the same episodes (one seed: hole pose, pose errors, friction
and breakaway force are the same per episode).

Per method (:func:`method_summary`): success rate with its Wilson 95 % interval, failures by
cause, mean and peak |F_z|, mean extraction time (``benchmarks.evals.hard_variants.summarise``),
how many episodes broke the weld and when (``peghole_mjx.envs.metrics.stuck_summary``), and the
same per third of the breakaway range. Paired by episode, policy minus scripted, with 95 %
bootstrap intervals (:func:`paired`): success, mean and peak |F_z|, extraction time (episodes
both extract) and release time (episodes in which both break the weld).

Writes ``benchmarks/results/evals/stuck_<label>_<device>.json`` (device, versions, date) and
``.csv`` (one row per method and breakaway bin, ``all`` first). The finished slices of
``--batch`` episodes are kept under ``--parts`` (default ``runs/stuck_<label>_<device>/``): an
interrupted run, rerun, continues where it stopped, and a longer one reuses them::

    python -m benchmarks.evals.stuck --policy runs/stuck_rect/final_policy --label rect_stuck \\
        --episodes 256 --batch 64
    python -m benchmarks.evals.stuck --policy rect --episodes 16 --out /tmp/stuck_rect.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np

import peghole_mjx  # noqa: F401  (sets the XLA CPU flag before JAX starts)
from benchmarks.common import (
    EVALS_RESULTS,
    ROOT,
    device_label,
    fmt_num,
    out_file,
    rel,
    table,
    wilson,
    write_rows,
)
from benchmarks.evals.cross_engine import paired_difference
from benchmarks.evals.hard_variants import summarise
from peghole_mjx.core.validation import arg
from peghole_mjx.envs.metrics import stuck_summary
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import provenance
from peghole_mjx.policies import PRETRAINED, load_policy
from peghole_mjx.sim.engines import ENGINES
from peghole_mjx.training.evaluate import evaluate, requested_config

METHODS = ("policy", "scripted")
#: the breakaway range is split into this many bins of equal width for the per-bin rows
BINS = 3


def bins(lo: float, hi: float) -> list[tuple[float, float]]:
    """The breakaway bins ``[(lo, hi), ...]`` of the range (N); one bin for a fixed force."""
    if hi <= lo:
        return [(lo, hi)]
    edges = np.linspace(lo, hi, BINS + 1)
    return [(float(a), float(b)) for a, b in itertools.pairwise(edges)]


def _in_bin(b: np.ndarray, edge: tuple[float, float], last: bool) -> np.ndarray:
    lo, hi = edge
    return (b >= lo) & ((b <= hi) if last else (b < hi))


def _bin_entry(e: dict[str, np.ndarray], mask: np.ndarray, edge) -> dict:
    ok = e["success"][mask] > 0
    rel_ = e["released"][mask] > 0
    n, k = int(mask.sum()), int(ok.sum())
    mean = lambda x: round(float(x.mean()), 4) if x.size else None  # noqa: E731
    return {
        "breakaway_N": [round(edge[0], 3), round(edge[1], 3)],
        "episodes": n,
        "success_rate": round(k / n, 4) if n else None,
        "success_ci95": wilson(k, n) if n else None,
        "released": int(rel_.sum()),
        "mean_release_time_s": mean(e["release_time_s"][mask][rel_]),
        "mean_fz_N": mean(e["mean_fz_N"][mask]),
        "peak_fz_N": mean(e["peak_fz_N"][mask]),
        "mean_time_s": mean(e["extraction_time_s"][mask][ok]),
    }


def method_summary(e: dict[str, np.ndarray], breakaway: tuple[float, float]) -> dict:
    """One method's summary over its per-episode records (with the stuck joint's keys)."""
    out = {**summarise(e), **stuck_summary(e)}
    t = out["mean_release_time_s"]
    out["mean_release_time_s"] = None if np.isnan(t) else round(t, 4)
    out["release_rate"] = round(out["release_rate"], 4)
    out["mean_breakaway_N"] = round(out["mean_breakaway_N"], 4)
    edges = bins(*breakaway)
    b = np.asarray(e["breakaway_N"])
    out["by_breakaway"] = [
        _bin_entry(e, _in_bin(b, edge, i == len(edges) - 1), edge) for i, edge in enumerate(edges)
    ]
    return out


def paired(pol: dict[str, np.ndarray], scr: dict[str, np.ndarray]) -> dict:
    """Policy minus scripted on the same episodes, 95 % bootstrap intervals."""
    out = {
        "success": paired_difference(scr["success"] > 0, pol["success"] > 0),
        "mean_fz_N": paired_difference(scr["mean_fz_N"], pol["mean_fz_N"]),
        "peak_fz_N": paired_difference(scr["peak_fz_N"], pol["peak_fz_N"]),
    }
    for name, key, flag in (
        ("time_s", "extraction_time_s", "success"),
        ("release_time_s", "release_time_s", "released"),
    ):
        both = (scr[flag] > 0) & (pol[flag] > 0)
        out[f"{name}_episodes"] = int(both.sum())
        out[name] = paired_difference(scr[key][both], pol[key][both]) if both.sum() >= 2 else None
    return out


# ----------------------------------------------------------------------------- outputs
CSV_FIELDS = (
    "method",
    "bin",
    "breakaway_lo_N",
    "breakaway_hi_N",
    "episodes",
    "success_rate",
    "success_lo",
    "success_hi",
    "released",
    "mean_release_time_s",
    "mean_fz_N",
    "peak_fz_N",
    "mean_time_s",
    "engine",
    "seed",
    "device",
    "date",
)


def csv_rows(doc: dict) -> list[dict]:
    """One row per method and breakaway bin (``all`` first)."""
    rows = []
    lo, hi = doc["breakaway_N"]
    for who in METHODS:
        s = doc[who]
        entries = [("all", {**s, "breakaway_N": [lo, hi]})]
        entries += [(str(i), b) for i, b in enumerate(s["by_breakaway"])]
        for name, b in entries:
            ci = b["success_ci95"] or [None, None]
            values = [who, name, *b["breakaway_N"], b["episodes"], b["success_rate"], *ci]
            values += [b["released"], b["mean_release_time_s"], b["mean_fz_N"], b["peak_fz_N"]]
            values += [b["mean_time_s"], doc["engine"], doc["seed"], doc["device"], doc["date"]]
            rows.append(dict(zip(CSV_FIELDS, values, strict=True)))
    return rows


def _change(x: dict | None) -> str:
    return "-" if x is None else f"{x['mean']:+.3f} [{x['ci95'][0]:+.3f}, {x['ci95'][1]:+.3f}]"


@table("stuck")
def stuck_table() -> str:
    """The committed stuck-joint comparisons, one table per result file."""
    files = sorted(EVALS_RESULTS.glob("stuck_*.json"))
    if not files:
        return (
            "Not run yet: no `benchmarks/results/evals/stuck_<label>_<device>.json` is committed "
            "(`python -m benchmarks.evals.stuck --policy DIR --episodes 256`)."
        )
    lines = []
    for path in files:
        d = json.loads(path.read_text())
        lo, hi = d["breakaway_N"]
        lines += [
            f"`{d['label']}` ({d['env']}, engine {d['engine']}): {d['episodes']} episodes of "
            f"seed {d['seed']}, breakaway U({lo:g}, {hi:g}) N; {d['device']}, "
            f"{d['date'][:10]}; from [`{rel(path)}`]({rel(path)}).",
            "",
            "| method | success [95 %] | weld released | release s | mean F_z N | peak F_z N "
            "| time s |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for who in METHODS:
            s = d[who]
            a, b = s["success_ci95"]
            lines.append(
                f"| {who} | {s['success_rate']:.3f} [{a:.3f}, {b:.3f}] | {s['released']} | "
                f"{fmt_num(s['mean_release_time_s'], '.2f')} | {s['mean_fz_N']:#.3g} | "
                f"{s['peak_fz_N']:#.3g} | {fmt_num(s['mean_time_s'], '.2f')} |"
            )
        p = d["paired"]
        lines += [
            "",
            f"Policy minus scripted (same episodes, 95 % bootstrap): success "
            f"{_change(p['success'])}, mean F_z {_change(p['mean_fz_N'])} N, time "
            f"{_change(p['time_s'])} s ({p['time_s_episodes']} episodes both extract).",
            "",
        ]
    return "\n".join(lines).rstrip()


# ----------------------------------------------------------------------------- command
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--policy", required=True, help="a policy folder, or rect, dual, ...")
    ap.add_argument("--label", help="the result's name (default: the policy's name or folder)")
    ap.add_argument("--episodes", type=arg("episodes"), default=256)
    ap.add_argument("--seed", type=arg("seed"), default=0)
    ap.add_argument("--batch", type=arg("batch"), help="worlds at once (default: all episodes)")
    ap.add_argument("--engine", choices=ENGINES, help="default: the policy's training engine")
    ap.add_argument(
        "--breakaway",
        nargs=2,
        type=float,
        metavar=("LO_N", "HI_N"),
        help="the breakaway range (default: the policy's training env's, else the env default)",
    )
    ap.add_argument("--parts", type=Path, help="finished slices (resumable)")
    ap.add_argument("--out", type=out_file, help="JSON to write (the CSV beside it)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    bundle = load_policy(args.policy)
    trained = requested_config(bundle)
    over: dict = {}
    if not trained.stuck.enabled:
        over["stuck.enabled"] = True
    if args.breakaway:
        over["stuck.breakaway_N"] = tuple(args.breakaway)
    if args.engine and args.engine != trained.engine:
        over["engine"] = args.engine
    config = requested_config(bundle, over)  # checked (one line) before anything runs
    label = args.label or (args.policy if args.policy in PRETRAINED else Path(args.policy).name)
    dev = device_label(None if jax.default_backend() == "cpu" else jax.devices()[0].device_kind)
    parts = args.parts or ROOT / "runs" / f"stuck_{label}_{dev}"
    out = args.out or EVALS_RESULTS / f"stuck_{label}_{dev}.json"
    fileio.check_out_file(out)
    t0 = time.perf_counter()
    res = evaluate(
        bundle,
        args.episodes,
        seed=args.seed,
        progress=not args.no_progress,
        env_overrides=over or None,
        batch=args.batch,
        parts_dir=parts,
        cross=True,
        keep_episodes=True,
    )
    ep = {"policy": res["per_episode"]["policy"], "scripted": res["per_episode"]["baseline"]}
    ep = {who: {k: np.asarray(v, float) for k, v in e.items()} for who, e in ep.items()}
    breakaway = tuple(float(x) for x in config.stuck.breakaway_N)
    doc = {
        "benchmark": "stuck",
        "what": "stuck joint: policy and scripted baseline on the same episodes",
        "command": "python -m benchmarks.evals.stuck " + " ".join(argv or sys.argv[1:]),
        "label": label,
        "policy": str(bundle.path),
        "env": bundle.env_name,
        "engine": res["engine"],
        "episodes": args.episodes,
        "seed": args.seed,
        "batch": res["batch"],
        "breakaway_N": list(breakaway),
        "weld_timeconst_s": config.stuck.timeconst_s,
        "scripted": "fixed compliance at the tip, straight pull at 20 mm/s",
        "differs_from_training": res["differs_from_training"],
        **provenance(),
        "wall_s": round(time.perf_counter() - t0, 1),
        **{who: method_summary(ep[who], breakaway) for who in METHODS},
        "paired": paired(ep["policy"], ep["scripted"]),
    }
    fileio.write_text(out, json.dumps(doc, indent=2) + "\n")
    write_rows(out.with_suffix(".csv"), csv_rows(doc), CSV_FIELDS)
    for who in METHODS:
        s = doc[who]
        print(
            f"{who:9s} success {s['success_rate']:.3f} {s['success_ci95']}  released "
            f"{s['released']}/{s['episodes']} at {fmt_num(s['mean_release_time_s'], '.2f')} s  "
            f"mean F_z {s['mean_fz_N']:.2f} N  peak {s['peak_fz_N']:.2f} N  "
            f"time {fmt_num(s['mean_time_s'], '.2f')} s"
        )
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
