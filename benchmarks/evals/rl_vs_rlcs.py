"""RL vs RL + compliance strategy: the comparison of the thesis's Fig 4.5 (claim C4.1).

Reads two finished (or stopped) training runs of the same env, one trained with
``--compliance-strategy on`` and one with ``off`` (same profile and seed), and writes

* ``benchmarks/results/evals/rl_vs_rlcs_<env>[_<tag>]_<device>.json``: every evaluation of both
  runs (success, mean/peak |F_z|, mean |F_xy|, discounted return), the training-episode force
  statistics over the run, and the verdict on C4.1 ("RL + CS gives lower, steadier F_z over
  training than RL without it");
* ``benchmarks/results/evals/rl_vs_rlcs_<env>[_<tag>]_<device>.png``: the learning curves of
  both runs (Figs 4.5-4.7 panels, :func:`peghole_mjx.training.plots.plot_curves`).

Usage::

    peghole train --env RectExtract --compliance-strategy on  --profile cpu \
        --set env.reward_config.kind=thesis --set env.action.residual=false \
        --set actor_delay_updates=0 --out runs/rect_cs
    peghole train --env RectExtract --compliance-strategy off --profile cpu \
        --set env.reward_config.kind=thesis --set env.action.residual=false \
        --set actor_delay_updates=0 --out runs/rect_nocs

The C4 claims are about the thesis's reward, eq (4.4), and its plain actions: its runs set
``env.reward_config.kind=thesis``, ``env.action.residual=false`` and no critic burn-in (stated
whatever training's defaults are; the committed C4 runs trained eq (4.4) with plain actions,
docs/research/rl_vs_rlcs.md).
    python -m benchmarks.evals.rl_vs_rlcs --cs runs/rect_cs --no-cs runs/rect_nocs

With multi-seed runs (``peghole train ... --seeds N``, ``history.csv`` + ``seeds.json``) the
result holds every seed's training statistics and final evaluation, the means over seeds with
95 % Student-t intervals, and verdicts from intervals: C4.1 (RL + CS lower and steadier F_z
over training: the 95 % Welch interval of RL minus RL + CS above zero for the per-seed mean
and for the per-seed standard deviation of the training episodes' F_z) and C4.2 (the mean
|F_xy| per episode falls during training: per seed, first chunk minus last chunk, its 95 %
t-interval above zero); the plot has a band per arm
(:func:`peghole_mjx.training.plots.plot_seed_bands`), and ``..._final.png`` shows each seed's
final evaluation (:func:`peghole_mjx.training.plots.plot_final_evals`).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from scipy import stats

from benchmarks.common import EVALS_RESULTS, device_label, rel, table, utc_now, versions_dict
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.training.plots import (
    plot_curves,
    plot_final_evals,
    plot_seed_bands,
    read_metrics,
)
from peghole_mjx.training.seeds import t_interval

#: evaluation columns of metrics.csv copied into the result (without the ``eval/`` prefix)
EVAL_KEYS = (
    "success_rate",
    "mean_time_s",
    "mean_fz_N",
    "peak_fz_N",
    "mean_fxy_N",
    "mean_discounted_return",
)


def _float(x: str | None) -> float:
    try:
        return float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return float("nan")


def run_record(run: Path) -> dict:
    """Config, evaluations and training-force statistics of one run."""
    rows = read_metrics(run)  # a clear error if ``run`` is not a training run
    meta = json.loads((run / "run.json").read_text())
    cfg = meta["config"]
    evals = [
        {"step": int(float(r["step"])), **{k: _float(r.get(f"eval/{k}")) for k in EVAL_KEYS}}
        for r in rows
    ]
    # training-episode |F_z| after the first evaluation (the random-policy phase excluded)
    train_fz = np.array([_float(r.get("train/mean_fz_N")) for r in rows[1:]])
    train_fz = train_fz[np.isfinite(train_fz)]
    learned = [e for e in evals if e["step"] > 0]
    return {
        "run": str(run),
        "compliance_strategy": bool(cfg.get("env_overrides", {}).get("compliance_strategy")),
        "env": cfg["env"],
        "profile": cfg.get("profile"),
        "seed": cfg.get("seed"),
        "env_steps": evals[-1]["step"] if evals else 0,
        "evaluations": evals,
        "train_mean_fz_N": float(train_fz.mean()) if len(train_fz) else float("nan"),
        "train_std_fz_N": float(train_fz.std()) if len(train_fz) else float("nan"),
        "train_windows": len(train_fz),  # metrics rows (evaluation intervals) averaged
        "eval_mean_fz_N": float(np.nanmean([e["mean_fz_N"] for e in learned]))
        if learned
        else float("nan"),
        "eval_mean_success": float(np.nanmean([e["success_rate"] for e in learned]))
        if learned
        else float("nan"),
    }


#: file-name stem of each env
SHORT = {
    "RectExtract": "rect",
    "DualExtract": "dual",
    "RectExtractHard": "rect_hard",
    "DualExtractHard": "dual_hard",
}


def is_seeds_run(run: Path) -> bool:
    """Whether ``run`` is a ``--seeds`` run (it has ``history.csv``)."""
    return (Path(run) / "history.csv").exists()


def seeds_record(run: Path) -> dict:
    """Per-seed training statistics and final evaluations of a ``--seeds`` run."""
    run = Path(run)
    try:
        summary = json.loads((run / "seeds.json").read_text())
        with (run / "history.csv").open() as f:
            rows = list(csv.DictReader(f))
    except FileNotFoundError as exc:
        raise UserInputError(f"{run}: not a finished multi-seed run ({exc.filename})") from None
    per_seed = []
    for ev in summary["final_eval"]:
        mine = [r for r in rows if int(r["seed"]) == ev["seed"]]
        fz = np.array([_float(r.get("train/mean_fz_N")) for r in mine])
        fxy = np.array([_float(r.get("train/mean_fxy_N")) for r in mine])
        fz, fxy = fz[np.isfinite(fz)], fxy[np.isfinite(fxy)]
        per_seed.append(
            {
                "seed": ev["seed"],
                "train_mean_fz_N": float(fz.mean()) if len(fz) else float("nan"),
                "train_std_fz_N": float(fz.std()) if len(fz) else float("nan"),
                "train_mean_fxy_N": float(fxy.mean()) if len(fxy) else float("nan"),
                "train_fxy_first_minus_last_N": float(fxy[0] - fxy[-1])
                if len(fxy) > 1
                else float("nan"),
                "train_curve": [
                    {"step": int(r["step"]), **{k: _float(r.get(f"train/{k}")) for k in EVAL_KEYS}}
                    for r in mine
                ],
                "final_eval": {k: ev.get(k) for k in (*EVAL_KEYS, "episodes", "jammed")},
            }
        )

    def over(key, src=None):
        vals = [float((s[src] if src else s)[key]) for s in per_seed]
        finite = [v for v in vals if np.isfinite(v)]
        return {
            "mean": float(np.mean(finite)) if finite else float("nan"),
            "ci95_t": t_interval(vals),
        }

    return {
        "run": str(run),
        "compliance_strategy": bool(summary["compliance_strategy"]),
        "env": summary["env"],
        "profile": summary["profile"],
        "seeds": summary["seeds"],
        "env_steps": summary["env_steps"],
        "eval_episodes_per_seed": summary["eval_episodes_per_seed"],
        "per_seed": per_seed,
        "over_seeds": {
            "train_mean_fz_N": over("train_mean_fz_N"),
            "train_std_fz_N": over("train_std_fz_N"),
            "train_mean_fxy_N": over("train_mean_fxy_N"),
            "train_fxy_first_minus_last_N": over("train_fxy_first_minus_last_N"),
            **{f"final_{k}": over(k, "final_eval") for k in ("success_rate", "mean_fz_N")},
            "final_mean_fxy_N": over("mean_fxy_N", "final_eval"),
        },
    }


def welch_interval(a: list[float], b: list[float], level: float = 0.95) -> list[float] | None:
    """The ``level`` Welch interval of mean(a) - mean(b) (None with fewer than 2 each)."""
    a = np.asarray([x for x in a if np.isfinite(x)], float)
    b = np.asarray([x for x in b if np.isfinite(x)], float)
    if len(a) < 2 or len(b) < 2:
        return None
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    se = np.sqrt(va + vb)
    if se == 0:
        return [float(a.mean() - b.mean())] * 2
    dof = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    half = stats.t.ppf(0.5 + level / 2, dof) * se
    d = a.mean() - b.mean()
    return [float(d - half), float(d + half)]


def _above_zero(ci: list[float] | None) -> bool:
    return bool(ci is not None and ci[0] > 0)


def seeds_verdicts(cs: dict, rl: dict) -> dict:
    """C4.1 and C4.2 from the per-seed statistics of the two arms."""

    def col(rec, key):
        return [s[key] for s in rec["per_seed"]]

    lower = welch_interval(col(rl, "train_mean_fz_N"), col(cs, "train_mean_fz_N"))
    steadier = welch_interval(col(rl, "train_std_fz_N"), col(cs, "train_std_fz_N"))
    c41 = _above_zero(lower) and _above_zero(steadier)
    fxy = {
        arm: rec["over_seeds"]["train_fxy_first_minus_last_N"]
        for arm, rec in (("rl_cs", cs), ("rl", rl))
    }

    def final(rec, key):
        return [_float(s["final_eval"].get(key)) for s in rec["per_seed"]]

    return {
        # not a thesis claim: the arms' final policies compared on their evaluation episodes
        # (informative where the budget lets few training episodes end)
        "final_eval_rl_minus_cs_ci95": {
            key: welch_interval(final(rl, key), final(cs, key))
            for key in ("success_rate", "mean_fz_N", "mean_time_s")
        },
        "c4_1": {
            "claim": "RL + CS gives lower, steadier F_z over training than RL without it (Fig 4.5)",
            "rl_minus_cs_train_mean_fz_N_ci95": lower,
            "rl_minus_cs_train_std_fz_N_ci95": steadier,
            "verdict": "confirmed" if c41 else "not confirmed",
        },
        "c4_2": {
            "claim": "the mean |F_xy| per episode falls during training (Fig 4.6)",
            "first_minus_last_chunk_fxy_N": fxy,
            "verdict": {
                arm: "confirmed" if _above_zero(v["ci95_t"]) else "not confirmed"
                for arm, v in fxy.items()
            },
        },
    }


def _check_arms(cs: dict, rl: dict) -> None:
    if not cs["compliance_strategy"] or rl["compliance_strategy"]:
        raise SystemExit("--cs needs a run with the CS on, --no-cs one with it off")
    if cs["env"] != rl["env"]:
        raise SystemExit(f"the runs train different envs: {cs['env']} vs {rl['env']}")


def _write(args, cs: dict, rl: dict, extra: dict) -> tuple[Path, dict, str]:
    """Write the result JSON (common header, both arms, ``extra``); its stem, the result and
    the device label."""
    label = device_label(None if args.device in (None, "cpu") else args.device)
    tag = f"_{args.tag}" if args.tag else ""
    stem = args.results / f"rl_vs_rlcs_{SHORT[cs['env']]}{tag}_{label}"
    result = {
        "benchmark": "rl_vs_rlcs",
        "env": cs["env"],
        "device": label,
        "date": utc_now(),
        "versions": versions_dict(("mujoco", "mjx", "jax")),
        "note": args.note,
        "rl_cs": cs,
        "rl": rl,
        **extra,
    }
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    return stem, result, label


def main_seeds(args) -> int:
    """The comparison of two ``--seeds`` runs (one per arm)."""
    try:
        cs, rl = seeds_record(args.cs), seeds_record(args.no_cs)
    except UserInputError as e:
        raise SystemExit(str(e)) from None
    _check_arms(cs, rl)
    stem, result, label = _write(args, cs, rl, seeds_verdicts(cs, rl))
    plot_seed_bands(
        [args.cs, args.no_cs],
        stem.with_suffix(".png"),
        title=f"{cs['env']}: RL vs RL + CS, {len(cs['seeds'])} seeds, 95 % bands ({label})",
    )
    plot_final_evals(
        [args.cs, args.no_cs],
        stem.with_name(stem.name + "_final.png"),
        title=f"{cs['env']}: final policies per seed, mean and 95 % t-interval ({label})",
    )
    print(
        json.dumps(
            {
                "c4_1": result["c4_1"]["verdict"],
                "c4_2": result["c4_2"]["verdict"],
                "out": str(stem.with_suffix(".json")),
            }
        )
    )
    return 0


# ----------------------------------------------------------------------------- docs tables
def result_files() -> list[Path]:
    """The committed comparisons (``rl_vs_rlcs_*.json``), sorted by name."""
    return sorted(EVALS_RESULTS.glob("rl_vs_rlcs_*.json"))


@table("rl_vs_rlcs")
def rl_vs_rlcs_table() -> str:
    """RL vs RL + CS learning runs (thesis Fig 4.5, C4.1), one block per result file."""
    paths = result_files()
    if not paths:
        return "Pending: run `python -m benchmarks.evals.rl_vs_rlcs`."
    lines = []
    for path in paths:
        d = json.loads(path.read_text())
        a, b = d["rl_cs"], d["rl"]
        if "per_seed" in a:
            lines += _rl_vs_rlcs_seeds(d, path)
            continue
        lines += [
            f"{d['env']} on {d['device']} ({d['date'][:10]}), profile `{a['profile']}`, seed "
            f"{a['seed']}; from [`{rel(path)}`]({rel(path)}) and "
            f"its `.png`. {d['note']}".rstrip(),
            "",
            "| run | env steps | training episodes: mean F_z N (std over the run's windows) "
            "| evaluations: mean success | evaluations: mean F_z N | last eval: success, F_z N |",
            "|---|---|---|---|---|---|",
        ]
        for label, r in (("RL + CS", a), ("RL", b)):
            last = r["evaluations"][-1]
            lines.append(
                f"| {label} | {r['env_steps']} | {r['train_mean_fz_N']:.2f} "
                f"({r['train_std_fz_N']:.2f}, {r['train_windows']} windows) | "
                f"{r['eval_mean_success']:.3f} | "
                f"{r['eval_mean_fz_N']:.2f} | {last['success_rate']:.3f}, {last['mean_fz_N']:.2f} |"
            )
        c = d["c4_1"]
        lines += [
            "",
            f"C4.1 ({c['claim']}): lower {'yes' if c['lower'] else 'no'}, steadier "
            f"{'yes' if c['steadier'] else 'no'}: **{c['verdict']}**; training-episode force "
            f"{d['force_reduction_train_pct']:.1f} % lower with the CS.",
            "",
        ]
    return "\n".join(lines).rstrip()


def _mean_ci(v: dict, fmt: str = ".2f") -> str:
    ci = v.get("ci95_t")
    return f"{v['mean']:{fmt}}" + (f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]" if ci else "")


def fmt_interval(v: list[float] | None) -> str:
    """``[lo, hi]`` to two decimals, ``n/a`` for None."""
    return "n/a" if v is None else f"[{v[0]:.2f}, {v[1]:.2f}]"


def _rl_vs_rlcs_seeds(d: dict, path: Path) -> list[str]:
    """The multi-seed comparison: means over seeds with 95 % t-intervals, and the verdicts."""
    a = d["rl_cs"]
    lines = [
        f"{d['env']} on {d['device']} ({d['date'][:10]}), profile `{a['profile']}`, seeds "
        f"{a['seeds']} per arm, {a['env_steps']} env steps each; from "
        f"[`{rel(path)}`]({rel(path)}) and its `.png` (bands: 95 % "
        f"over seeds). {d['note']}".rstrip(),
        "",
        "| arm | training: mean F_z N | training: std of F_z N | training: mean F_xy N "
        "| training: F_xy first - last chunk N | final eval success | final eval F_z N |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, r in (("RL + CS", d["rl_cs"]), ("RL", d["rl"])):
        o = r["over_seeds"]
        lines.append(
            f"| {label} | {_mean_ci(o['train_mean_fz_N'])} | {_mean_ci(o['train_std_fz_N'])} "
            f"| {_mean_ci(o['train_mean_fxy_N'])} "
            f"| {_mean_ci(o['train_fxy_first_minus_last_N'])} "
            f"| {_mean_ci(o['final_success_rate'], '.3f')} | {_mean_ci(o['final_mean_fz_N'])} |"
        )
    c1, c2 = d["c4_1"], d["c4_2"]
    ci = fmt_interval
    lines += [
        "",
        f"C4.1 ({c1['claim']}): RL minus RL + CS, mean F_z "
        f"{ci(c1['rl_minus_cs_train_mean_fz_N_ci95'])} N, its std "
        f"{ci(c1['rl_minus_cs_train_std_fz_N_ci95'])} N (95 % Welch): **{c1['verdict']}**. "
        f"C4.2 ({c2['claim']}): RL + CS **{c2['verdict']['rl_cs']}**, RL "
        f"**{c2['verdict']['rl']}**.",
        "",
    ]
    fin = d.get("final_eval_rl_minus_cs_ci95")
    if fin:  # results written before 2026-11-30 lack it
        lines += [
            "Final policies, RL minus RL + CS (95 % Welch over seeds; not a thesis claim): "
            f"success {ci(fin['success_rate'])}, mean F_z {ci(fin['mean_fz_N'])} N, "
            f"mean time {ci(fin['mean_time_s'])} s.",
            "",
        ]
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cs", type=Path, required=True, help="run trained with the CS on")
    p.add_argument("--no-cs", type=Path, required=True, help="run trained with the CS off")
    p.add_argument("--device", default=None, help="GPU name, e.g. 'H100' (default: this CPU)")
    p.add_argument("--note", default="", help="free-text conditions, stored in the JSON")
    p.add_argument("--tag", default="", help="file-name tag of a variant, e.g. 'slow'")
    p.add_argument("--results", type=Path, default=EVALS_RESULTS, help="output folder")
    args = p.parse_args(argv)
    if is_seeds_run(args.cs) or is_seeds_run(args.no_cs):
        return main_seeds(args)

    try:
        cs, nocs = run_record(args.cs), run_record(args.no_cs)
    except UserInputError as e:
        raise SystemExit(str(e)) from None
    _check_arms(cs, nocs)
    lower = cs["train_mean_fz_N"] < nocs["train_mean_fz_N"]
    steadier = cs["train_std_fz_N"] < nocs["train_std_fz_N"]
    extra = {
        "force_reduction_train_pct": 100.0 * (1 - cs["train_mean_fz_N"] / nocs["train_mean_fz_N"]),
        "c4_1": {
            "claim": "RL + CS gives lower, steadier F_z over training than RL without it (Fig 4.5)",
            "lower": bool(lower),
            "steadier": bool(steadier),
            "verdict": "confirmed" if lower and steadier else "not confirmed",
        },
    }
    stem, result, label = _write(args, cs, nocs, extra)
    plot_curves(
        [args.cs, args.no_cs],
        stem.with_suffix(".png"),
        title=f"{cs['env']}: RL vs RL + compliance strategy ({label})",
    )
    print(
        json.dumps(
            {
                "rl_cs_train_fz": round(cs["train_mean_fz_N"], 3),
                "rl_train_fz": round(nocs["train_mean_fz_N"], 3),
                "c4_1": result["c4_1"]["verdict"],
                "out": str(stem.with_suffix(".json")),
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
