"""Per-episode comparison of a policy with the scripted baseline on the same episodes.

    python -m benchmarks.evals.paired_reduction export POLICY_PARTS BASELINE_PARTS \
        --out EPISODES.csv
    python -m benchmarks.evals.paired_reduction export POLICY_PARTS [BASELINE_PARTS] \
        --baseline-csv EARLIER.csv --out EPISODES.csv
    python -m benchmarks.evals.paired_reduction analyse EPISODES.csv --chosen-on 64 \
        --out PAIRED.json

``export`` writes the per-episode records that ``peghole evaluate --parts DIR`` saved
(``DIR/policy-<sha>-<cfg>/`` and ``DIR/baseline/``) as one CSV row per episode. With
``--baseline-csv`` the baseline's columns come from an earlier export of the same env, seed and
batch (the scripted baseline is deterministic and its episodes are prefix-stable, so a policy
evaluated ``--policy-only`` pairs with it); a ``BASELINE_PARTS`` given as well (e.g. the first
slice rerun) must reproduce that file's first rows bit for bit, else the export stops. Rerun
the check: a setting the baseline ignores (``BASELINE_IGNORED_CONFIG``, e.g. ``obs``) still
changes the compiled program, and in the dual scene that changed the float32 rounding of every
episode (2026-11-30: up to 0.0058 N of a 0.1 N mean F_z). ``analyse`` gives
the mean-|F_z| reduction (the thesis's R3 measure, as ``peghole evaluate``) over all episodes,
per slice, on the episodes not used to choose the policy (``--chosen-on N``: episodes 0 to
N-1 of this seed were), a paired bootstrap interval (episodes resampled, policy and baseline
together) and the share of episodes where the policy's mean |F_z| is the lower; and the
reduction with its bootstrap interval over the episodes both succeed in (``both_succeed``:
the interval resamples those episodes only).

The docs table ``pretrained`` (the published policies' evaluations, ``evaluation.json`` beside
each, with the paired intervals committed under ``benchmarks/results/evals/<name>_cpu-2core/``)
is generated here.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

import numpy as np

from benchmarks.common import EVALS_RESULTS, ROOT, fmt_num, out_file, rel, table
from peghole_mjx.files.provenance import utc_now
from peghole_mjx.training.evaluate import force_reduction_pct

COLUMNS = ("success", "extraction_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N")
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0


def load_parts(folder: Path) -> dict[str, np.ndarray]:
    """The episodes of a ``--parts`` slice folder, in episode order."""
    files = sorted(Path(folder).glob("episodes_*.npz"))  # named by first episode, zero-padded
    if not files:
        raise SystemExit(f"{folder} holds no episodes_*.npz slices")
    loaded = [np.load(f) for f in files]
    return {k: np.concatenate([z[k] for z in loaded]) for k in COLUMNS}


def load_baseline_csv(path: Path) -> dict[str, np.ndarray]:
    """The ``baseline_<column>`` columns of an earlier ``export``, in episode order."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows or any(f"baseline_{c}" not in rows[0] for c in COLUMNS):
        raise SystemExit(f"{path} has no baseline_<column> rows of an export")
    if [int(r["episode"]) for r in rows] != list(range(len(rows))):
        raise SystemExit(f"{path}: episodes are not 0, 1, 2, ... in order")
    return {c: np.array([float(r[f"baseline_{c}"]) for r in rows], np.float32) for c in COLUMNS}


def export(
    policy_dir: Path, baseline_dir: Path | None, out: Path, baseline_csv: Path | None = None
) -> None:
    """One CSV row per episode: ``policy_<column>`` and ``baseline_<column>``."""
    if baseline_dir is None and baseline_csv is None:
        raise SystemExit("give BASELINE_PARTS, --baseline-csv, or both")
    pol = load_parts(policy_dir)
    n = len(pol["mean_fz_N"])
    if baseline_csv is None:
        base = load_parts(baseline_dir)
    else:
        base = load_baseline_csv(baseline_csv)
        if len(base["mean_fz_N"]) < n:
            raise SystemExit(
                f"{n} policy episodes but {baseline_csv} holds {len(base['mean_fz_N'])}"
            )
        base = {c: v[:n] for c, v in base.items()}
        if baseline_dir is not None:  # a rerun prefix must reproduce the file
            rerun = load_parts(baseline_dir)
            k = min(n, len(rerun["mean_fz_N"]))
            for c in COLUMNS:
                bad = np.flatnonzero(rerun[c][:k].astype(np.float32) != base[c][:k])
                if bad.size:
                    i = int(bad[0])
                    raise SystemExit(
                        f"{baseline_dir} episode {i} {c} = {rerun[c][i]} but {baseline_csv} "
                        f"has {base[c][i]}: not the same baseline episodes"
                    )
    if len(base["mean_fz_N"]) != n:
        raise SystemExit(f"{n} policy episodes but {len(base['mean_fz_N'])} baseline episodes")
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            ["episode", *(f"policy_{c}" for c in COLUMNS), *(f"baseline_{c}" for c in COLUMNS)]
        )
        for i in range(n):
            w.writerow([i, *(pol[c][i] for c in COLUMNS), *(base[c][i] for c in COLUMNS)])


def reduction_pct(policy_fz: np.ndarray, baseline_fz: np.ndarray) -> float:
    """Mean-|F_z| reduction of the policy vs the baseline, % (``peghole evaluate``'s own)."""
    return float(
        force_reduction_pct({"mean_fz_N": policy_fz.mean()}, {"mean_fz_N": baseline_fz.mean()})
    )


def paired_bootstrap(p: np.ndarray, b: np.ndarray) -> dict:
    """95 % interval of the reduction, episodes resampled with policy and baseline together."""
    n = len(p)
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, n, (BOOTSTRAP_RESAMPLES, n))
    boot = 100.0 * (1.0 - p[idx].mean(1) / b[idx].mean(1))
    return {
        "resamples": BOOTSTRAP_RESAMPLES,
        "seed": BOOTSTRAP_SEED,
        "reduction_pct_95": [float(x) for x in np.percentile(boot, [2.5, 97.5])],
    }


def analyse(
    episodes_csv: Path, chosen_on: int = 0, slice_size: int = 256, evaluated_on: str = ""
) -> dict:
    """The reductions of the module docstring from an ``export`` CSV."""
    with open(episodes_csv) as f:
        rows = list(csv.DictReader(f))
    p = np.array([float(r["policy_mean_fz_N"]) for r in rows])
    b = np.array([float(r["baseline_mean_fz_N"]) for r in rows])
    both = np.array(
        [float(r["policy_success"]) > 0 and float(r["baseline_success"]) > 0 for r in rows]
    )
    n = len(p)
    slices = range(0, n, slice_size)
    return {
        "episodes_csv": episodes_csv.name,
        "episodes": n,
        "policy_mean_fz_N": float(p.mean()),
        "baseline_mean_fz_N": float(b.mean()),
        "reduction_pct": reduction_pct(p, b),
        f"reduction_pct_per_{slice_size}": [
            reduction_pct(p[s : s + slice_size], b[s : s + slice_size]) for s in slices
        ],
        "chosen_on_episodes": chosen_on,
        # None when every episode was used to choose the policy (none left out)
        "reduction_pct_not_chosen_on": (
            reduction_pct(p[chosen_on:], b[chosen_on:]) if chosen_on < len(p) else None
        ),
        "bootstrap": paired_bootstrap(p, b),
        "share_of_episodes_policy_lower": float((p < b).mean()),
        "both_succeed": {
            "episodes": int(both.sum()),
            "policy_mean_fz_N": float(p[both].mean()) if both.any() else float("nan"),
            "baseline_mean_fz_N": float(b[both].mean()) if both.any() else float("nan"),
            "reduction_pct": reduction_pct(p[both], b[both]) if both.any() else float("nan"),
            "bootstrap": paired_bootstrap(p[both], b[both]) if both.any() else None,
        },
        "evaluated_on": evaluated_on,  # the device of the rollouts (this analysis is NumPy)
        "date": utc_now(),
    }


# ----------------------------------------------------------------------------- docs tables
#: the published policies: (name, folder under peghole_mjx/policies), rect first
POLICIES = ROOT / "peghole_mjx" / "policies"
PUBLISHED = (
    ("rect", "rect_extract"),
    ("rect_hard", "rect_extract_hard"),
    ("dual", "dual_extract"),
    ("dual_hard", "dual_extract_hard"),
)


def _eval_row(label: str, r: dict, thesis: str) -> str:
    return (
        f"| {label} | {r['success_rate']:.3f} | {fmt_num(r['mean_time_s'], '.2f')} | "
        f"{r['mean_fz_N']:#.3g} | {r['peak_fz_N']:#.3g} | {r['mean_fxy_N']:#.3g} | {thesis} |"
    )  # 3 significant digits: the dual forces are hundredths of a newton


def _batch_flag(ev: dict) -> str:
    """``--batch N`` when the evaluation ran in slices (older files record no batch)."""
    batch = ev.get("batch", ev["episodes"])
    return f" --batch {batch}" if batch < ev["episodes"] else ""


def paired_files(name: str, evaluation: dict) -> list[Path]:
    """The committed paired analyses (``paired*.json``) of the published policy ``name`` that
    analyse the episodes of its ``evaluation``: the same number of episodes and the same policy
    mean F_z (to 1e-5). An analysis of an earlier policy published under the same name stays in
    the record but is not shown beside a later one."""

    def same(path: Path) -> bool:
        paired = json.loads(path.read_text())
        return paired.get("episodes") == evaluation["episodes"] and math.isclose(
            paired.get("policy_mean_fz_N", math.nan),
            evaluation["policy"]["mean_fz_N"],
            rel_tol=1e-5,
        )

    return [p for p in sorted(EVALS_RESULTS.glob(f"{name}_cpu-2core/paired*.json")) if same(p)]


def how_trained(ev: dict, pol: dict) -> list[str]:
    """A published policy's learner settings in words, where they are not the thesis's: its
    residual actions (``policy.json``'s env overrides) and its reward (``evaluation.json``
    records the kind since 2026-12-06). The one description for the docs tables."""
    words = []
    if pol.get("env_overrides", {}).get("action.residual"):
        words.append("residual actions")
    if "reward_kind" in ev:
        words.append(f"reward {ev['reward_kind']}")
    return words


@table("pretrained")
def pretrained() -> str:
    """The committed pretrained policies' evaluations (``evaluation.json`` beside each)."""
    lines = []
    for name, sub in PUBLISHED:
        path = POLICIES / sub / "evaluation.json"
        if not path.exists():
            lines += [f"`{name}`: pending (no committed policy yet).", ""]
            continue
        ev = json.loads(path.read_text())
        pol = json.loads((POLICIES / sub / "policy.json").read_text())
        th = ev["thesis"]
        prov = pol.get("provenance", {})
        rect = name.startswith("rect")
        none = "no thesis result (R6: the dual RL study was not possible in PyBullet)"
        lines += [
            f"`{name}` ({ev['env']}, {ev['preset']}, compliance strategy "
            f"{'on' if ev['compliance_strategy'] else 'off'}, "
            f"{''.join(w + ', ' for w in how_trained(ev, pol))}trained for "
            f"{pol['env_steps']} env steps on {prov.get('device', '?')}, published: "
            f"{pol.get('selection', {}).get('rule', '?')}; "
            f"evaluated as trained on {ev['episodes']} "
            f"randomised episodes, seed {ev['seed']}, from "
            f"[`{rel(path)}`]({rel(path)}); "
            f"`peghole evaluate {name} --episodes {ev['episodes']}{_batch_flag(ev)}"
            f"{f' --seed {seed}' if (seed := ev['seed']) else ''} --json` "
            "reproduces it):",
            "",
            "| policy | success | mean time s | mean F_z N | peak F_z N | mean F_xy N | thesis |",
            "|---|---|---|---|---|---|---|",
            _eval_row(
                "SAC (ours)",
                ev["policy"],
                f"R4: {th['success_rate']} success, {th['mean_time_s']} s; "
                f"R5: peak F_z <= {th['peak_fz_N_policy']} N"
                if rect
                else none,
            ),
            _eval_row(
                "scripted baseline (Ch 2-3 method)",
                ev["baseline"],
                f"R5: peak F_z > {th['peak_fz_N_baseline']} N" if rect else none,
            ),
            "",
            f"Mean extraction force of the policy vs the baseline: "
            f"**{-ev['force_reduction_pct']:+.1f} %** "
            f"({'lower' if ev['force_reduction_pct'] > 0 else 'higher'}; thesis R3, rect: "
            f"{-th['force_reduction_pct']:+.1f} %; target: at least 29.6 % lower).",
            "",
        ]
        lines += _both_succeed(name, ev)
    return "\n".join(lines).rstrip()


def _both_succeed(name: str, evaluation: dict) -> list[str]:
    """The paired reductions over all episodes and over the episodes both succeed in, where a
    paired analysis is committed."""
    lines = []
    for path in paired_files(name, evaluation):
        paired = json.loads(path.read_text())
        both = paired.get("both_succeed")
        if both:
            lo_all, hi_all = paired["bootstrap"]["reduction_pct_95"]
            lo, hi = both["bootstrap"]["reduction_pct_95"]
            lines += [
                f"Paired bootstrap 95 % intervals ([`{rel(path)}`]"
                f"({rel(path)})): over all {paired['episodes']} episodes "
                f"{-paired['reduction_pct']:+.1f} % [{-hi_all:+.1f}, {-lo_all:+.1f}]; over the "
                f"{both['episodes']} episodes both succeed in "
                f"{-both['reduction_pct']:+.1f} % [{-hi:+.1f}, {-lo:+.1f}].",
                "",
            ]
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    ex = sub.add_parser("export", help="per-episode CSV from --parts slice folders")
    ex.add_argument("policy_dir", type=Path)
    ex.add_argument("baseline_dir", type=Path, nargs="?")
    ex.add_argument(
        "--baseline-csv",
        type=Path,
        help="baseline columns from an earlier export (same env, seed, batch)",
    )
    ex.add_argument("--out", type=out_file, required=True)
    an = sub.add_parser("analyse", help="reductions, bootstrap interval, per-episode share")
    an.add_argument("episodes_csv", type=Path)
    an.add_argument("--chosen-on", type=int, default=0, help="episodes used to choose the policy")
    an.add_argument("--slice", type=int, default=256)
    an.add_argument("--evaluated-on", default="", help="device of the evaluation's rollouts")
    an.add_argument("--out", type=out_file, required=True)
    args = ap.parse_args()
    if args.cmd == "export":
        export(args.policy_dir, args.baseline_dir, args.out, args.baseline_csv)
    else:
        res = analyse(args.episodes_csv, args.chosen_on, args.slice, args.evaluated_on)
        args.out.write_text(json.dumps(res, indent=2) + "\n")
        print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
