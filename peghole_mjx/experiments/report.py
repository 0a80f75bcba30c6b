"""Summary, CSV and figures of the compliance-centre experiment (like thesis Figs 5.1-5.4)."""

from __future__ import annotations

import csv
import datetime
import io
import platform
import time
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import mujoco
import numpy as np

from peghole_mjx.core.validation import reduction_pct
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import outputs
from peghole_mjx.experiments.compliance import (
    ANALYTIC_MAPPING,
    THESIS,
    ExperimentConfig,
    analytic_two_point_hook,
    config_dict,
    force_magnitude,
    peak_forces,
    two_point_interval,
)
from peghole_mjx.geometry.specs import PRESETS

#: curves.csv and the plots: forces binned on depth (keeps curves.csv < 100 kB), mm
DEPTH_BIN_MM = {"rect": 2.5, "dual": 1.0}


def depth_edges(preset: str) -> np.ndarray:
    spec = PRESETS[preset]
    n = max(1, round(spec.length_mm / DEPTH_BIN_MM[spec.kind]))
    return np.linspace(0.0, spec.length_mm, n + 1)


def _lc_key(L_C_m: float) -> str:
    return f"{L_C_m * 1e3:g}"


def _reduction(a: float, b: float) -> float:
    """``100 (1 - a / b)`` of two peak forces, NaN (not resolved) when either is below
    :data:`~peghole_mjx.core.validation.FORCE_FLOOR_N` (a percentage of 0.0004 N is noise)."""
    pct = reduction_pct(a, b)
    return float("nan") if pct is None else round(pct, 2)


def binned(res: dict, world: int, edges: np.ndarray) -> np.ndarray:
    """Max of the filtered force magnitude in each depth bin (NaN where no sample)."""
    mag = force_magnitude(res)[world]
    d = res["depth_mm"][world]
    idx = np.digitize(d, edges) - 1
    out = np.full(len(edges) - 1, np.nan)
    for i in range(len(edges) - 1):
        sel = idx == i
        if sel.any():
            out[i] = mag[sel].max()
    return out


def summarise(results: dict[str, dict], cfg: ExperimentConfig, runtime_s: float) -> dict:
    peak, red_top, red_ctr, pen, tp, order, analytic, cross = {}, {}, {}, {}, {}, {}, {}, {}
    pen_at: dict[str, dict] = {}
    nan_worlds = 0
    for preset, res in results.items():
        pk = peak_forces(res)
        nan_worlds += int(res["nan"].sum())
        lcs = sorted(set(res["L_C"].tolist()))
        means = {_lc_key(lc): float(np.nanmean(pk[res["L_C"] == lc])) for lc in lcs}
        peak[preset] = {k: round(v, 4) for k, v in means.items()}
        tip, ctr, top = (means[_lc_key(lc)] for lc in lcs)
        red_top[preset] = _reduction(tip, top)
        red_ctr[preset] = _reduction(tip, ctr)
        order[preset] = bool(tip < ctr < top)
        pen[preset] = round(float(np.max(res["penetration_mm"])), 5)
        if "penetration_at_depth_mm" in res:
            w = int(np.argmax(res["penetration_mm"]))
            pen_at[preset] = {
                "L_C_mm": round(float(res["L_C"][w]) * 1e3, 3),
                "tip_depth_mm": round(float(res["penetration_at_depth_mm"][w]), 3),
                "time_s": round(float(res["penetration_at_time_s"][w]), 4),
                "worlds_over_limit": int(
                    np.sum(res["penetration_mm"] > 0.25 * PRESETS[preset].radial_clearance_mm)
                ),
            }
        tp[preset], analytic[preset], cross[preset] = {}, {}, {}
        for lc in lcs:
            worlds = np.flatnonzero(res["L_C"] == lc)
            ivs = [two_point_interval(res, w) for w in worlds]
            hit = [iv for iv in ivs if iv is not None]
            sim_iv = [min(i[0] for i in hit), max(i[1] for i in hit)] if hit else None
            tp[preset][_lc_key(lc)] = sim_iv
            try:
                an = analytic_two_point_hook(
                    preset,
                    lc * 1e3,
                    cfg,
                    delta0_mm=res["delta0"][worlds] * 1e3,
                    beta0_rad=res["beta0"][worlds],
                    h0_mm=float(res.get("h0_mm", PRESETS[preset].hole_depth_mm)),
                )
            except Exception as exc:  # report, do not lose a finished run
                an = {"error": f"{type(exc).__name__}: {exc}"}
            analytic[preset][_lc_key(lc)] = an.get("interval_mm", an)
            cross[preset][_lc_key(lc)] = {
                "simulated": {
                    "interval_mm": sim_iv,
                    "worlds_with_two_point": len(hit),
                    "per_world": ivs,
                },
                "analytic": an,
                "errors": {
                    "delta0_mm": [round(float(v) * 1e3, 4) for v in res["delta0"][worlds]],
                    "beta0_deg": [round(float(np.degrees(v)), 4) for v in res["beta0"][worlds]],
                },
            }
    return {
        "peak_force_N": peak,
        "peak_force_std_N": {
            p: {
                _lc_key(lc): round(float(np.nanstd(peak_forces(r)[r["L_C"] == lc])), 4)
                for lc in sorted(set(r["L_C"].tolist()))
            }
            for p, r in results.items()
        },
        "reduction_tip_vs_top_pct": red_top,
        "reduction_tip_vs_centre_pct": red_ctr,
        "ordering_tip_lt_centre_lt_top": order,
        "thesis": THESIS,
        "max_penetration_mm": pen,
        "max_penetration_where": pen_at,
        "penetration_limit_mm": {
            p: round(0.25 * PRESETS[p].radial_clearance_mm, 5) for p in results
        },
        "two_point_depth_mm": tp,
        "analytic_two_point_depth_mm": analytic,
        "two_point_cross_check": cross,
        "analytic_mapping": ANALYTIC_MAPPING,
        "nan_worlds": nan_worlds,
        "worlds": int(sum(len(r["L_C"]) for r in results.values())),
        "config": config_dict(cfg),
        "runtime_s": round(runtime_s, 1),
        "device": f"{jax.devices()[0].platform}: {platform.processor() or platform.machine()}",
        "versions": {
            "mujoco": mujoco.__version__,
            "jax": jax.__version__,
            "python": platform.python_version(),
        },
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def write_outputs(results: dict[str, dict], summary: dict, out: Path) -> list[Path]:
    """``summary.json``, ``curves.csv`` and two figures in ``out``, each written atomically."""
    out.mkdir(parents=True, exist_ok=True)
    files = [outputs.write_json(out / "summary.json", summary, indent=2)]
    # curves.csv: per preset, L_C, repeat: depth-binned filtered force magnitude
    fh = io.StringIO()
    w = csv.writer(fh)
    w.writerow(["preset", "L_C_mm", "repeat", "depth_mm", "force_N"])
    for preset, res in results.items():
        edges = depth_edges(preset)
        mids = 0.5 * (edges[1:] + edges[:-1])
        counts: dict[float, int] = {}
        for wi, lc in enumerate(res["L_C"]):
            rep = counts.get(lc, 0)
            counts[lc] = rep + 1
            for dm, f in zip(mids, binned(res, wi, edges), strict=True):
                if np.isfinite(f):
                    w.writerow([preset, _lc_key(lc), rep, f"{dm:.2f}", f"{f:.4f}"])
    files.append(outputs.write_text(out / "curves.csv", fh.getvalue()))
    n = len(results)
    colors = ["tab:green", "tab:orange", "tab:blue"]  # tip, centre, top (thesis colours)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4), squeeze=False)
    for ax, (preset, res) in zip(axes[0], results.items(), strict=True):
        edges = depth_edges(preset)
        mids = 0.5 * (edges[1:] + edges[:-1])
        for c, lc in zip(colors, sorted(set(res["L_C"].tolist())), strict=True):
            curves = np.array([binned(res, wi, edges) for wi in np.flatnonzero(res["L_C"] == lc)])
            ax.fill_between(
                mids, np.nanmin(curves, 0), np.nanmax(curves, 0), color=c, alpha=0.25, lw=0
            )
            ax.plot(mids, np.nanmean(curves, 0), color=c, lw=1.2, label=f"L_C = {lc * 1e3:g} mm")
        ax.set_xlabel("tip depth below the mouth (mm)")
        ax.set_ylabel("|F| (N), filtered")
        ax.set_title(preset)
        ax.invert_xaxis()
        ax.legend(fontsize=7)
    fig.tight_layout()
    files.append(outputs.write_png(fig, out / "force_depth.png", dpi=80))
    plt.close(fig)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.2), squeeze=False)
    for ax, (preset, res) in zip(axes[0], results.items(), strict=True):
        pk = peak_forces(res)
        lcs = sorted(set(res["L_C"].tolist()))
        ax.boxplot([pk[res["L_C"] == lc][np.isfinite(pk[res["L_C"] == lc])] for lc in lcs])
        ax.set_xticks(range(1, len(lcs) + 1), [f"{lc * 1e3:g}" for lc in lcs])
        ax.set_xlabel("L_C (mm)")
        ax.set_ylabel("peak |F| (N)")
        ax.set_title(preset)
    fig.tight_layout()
    files.append(outputs.write_png(fig, out / "peak_boxplot.png", dpi=80))
    plt.close(fig)
    return files


def output_bytes(cfg: ExperimentConfig) -> int:
    """An upper estimate of what :func:`write_outputs` writes, bytes: per preset curves.csv
    (< 100 kB) and its share of the figures, per world its part of summary.json."""
    presets = len(cfg.preset_names())
    return 2**20 + presets * 256 * 2**10 + presets * 3 * cfg.repeats * 2**10


def run_experiment(cfg: ExperimentConfig, out: str | Path) -> tuple[dict, list[Path]]:
    """Run the compliance-centre experiment ``cfg`` (every preset's batched pull), write its
    curves, figures and ``summary.json`` into ``out``; return the summary and the files.

    ``out`` is checked (a writable folder with room for the outputs) before the first
    simulation step; a run whose every world went NaN is a
    :class:`~peghole_mjx.experiments.compliance.DivergedError`, not a result."""
    out = outputs.check_out(out, output_bytes(cfg))
    t0 = time.time()
    results = {name: cx.Extraction(name, cfg).run() for name in cfg.preset_names()}
    cx.check_not_all_nan(
        np.concatenate([np.asarray(r["nan"], bool) for r in results.values()]),
        f"the compliance experiment ({', '.join(results)})",
        cx.nan_cause(cfg, x64=bool(jax.config.jax_enable_x64)),
    )
    summary = summarise(results, cfg, time.time() - t0)
    return summary, write_outputs(results, summary, out)
