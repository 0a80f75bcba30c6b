"""Learning curves in the style of the thesis's Figs 4.5-4.7, from runs' ``metrics.csv``.

Panels, each against env steps: (a) extraction force per episode (mean |F_z|, Fig 4.5),
(b) mean |F_xy| per episode (Fig 4.6), (c) discounted return (Fig 4.7), (d) eval success.
Training-episode statistics are drawn as lines, evaluation points as markers. Several runs
(e.g. RL vs RL + compliance strategy) share the axes, labelled from their configs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backend_bases import FigureCanvasBase
from scipy import stats

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.files import fileio
from peghole_mjx.training.config import env_setting, read_run_record
from peghole_mjx.training.logs import read_metrics, read_rows

PANELS = (
    ("mean_fz_N", "extraction force |F_z| per episode (N)", "Fig 4.5"),
    ("mean_fxy_N", "mean |F_xy| per episode (N)", "Fig 4.6"),
    ("mean_discounted_return", "discounted return", "Fig 4.7"),
    ("success_rate", "success rate", ""),
)


def t_interval(values: list[float], level: float = 0.95) -> list[float] | None:
    """The ``level`` Student-t interval of the mean of ``values`` (None for fewer than 2)."""
    v = np.asarray([x for x in values if math.isfinite(x)], float)
    if len(v) < 2:
        return None
    half = stats.t.ppf(0.5 + level / 2, len(v) - 1) * v.std(ddof=1) / math.sqrt(len(v))
    return [float(v.mean() - half), float(v.mean() + half)]


def run_label(run: Path) -> str:
    """``RL + CS`` or ``RL`` (compliance strategy on or off), with the env name."""
    meta, _ = read_run_record(run, what=str(run), full=False)
    cfg = meta["config"]
    cs = env_setting(cfg["env"], cfg.get("env_overrides", {}), "compliance_strategy")
    return f"{cfg['env']}: {'RL + CS' if cs else 'RL'}"


def _column(rows: list[dict[str, str]], key: str) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = [], []
    for r in rows:
        try:
            y = float(r.get(key, ""))
        except ValueError:
            continue
        if np.isfinite(y):
            xs.append(float(r["step"]))
            ys.append(y)
    return np.array(xs), np.array(ys)


def plot_curves(runs: list[Path], out: Path, title: str | None = None) -> Path:
    """One figure with the four panels for every run in ``runs``; returns ``out``."""
    matplotlib.use("Agg")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    for i, run in enumerate(runs):
        run = Path(run)
        rows = read_metrics(run)
        color = f"C{i}"
        label = run_label(run)
        for ax, (key, _, _) in zip(axes.flat, PANELS, strict=True):
            x, y = _column(rows, f"train/{key}")
            if len(x):
                ax.plot(x, y, color=color, lw=1.2, label=f"{label} (training episodes)")
            x, y = _column(rows, f"eval/{key}")
            if len(x):
                ax.plot(x, y, "o--", color=color, ms=4, lw=0.8, label=f"{label} (eval)")
    return _finish(fig, axes, title or "SAC learning curves", out)


def _finish(fig, axes, title: str, out: Path) -> Path:
    """Label the four panels, then write the figure atomically (a failed write keeps the
    old one)."""

    for ax, (_, ylabel, fig_ref) in zip(axes.flat, PANELS, strict=True):
        ax.set_ylabel(ylabel)
        if fig_ref:
            ax.set_title(f"cf. thesis {fig_ref}", fontsize=9, loc="right")
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("env steps")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title)
    return _save(fig, out)


def image_format(out: Path) -> str:
    """The image format of ``out`` by its suffix (none: PNG); a suffix matplotlib cannot
    write (``.txt``) is a :class:`UserInputError` naming the ones it can."""
    fmt = Path(out).suffix.lstrip(".").lower() or "png"
    known = FigureCanvasBase.get_supported_filetypes()
    if fmt not in known:
        raise UserInputError(
            f"--out {out}: .{fmt} is not an image format; use one of "
            f"{', '.join('.' + k for k in sorted(known))}"
        )
    return fmt


def _save(fig, out: Path) -> Path:
    """Write the figure atomically (a failed write keeps the old one) and close it."""
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with fileio.atomic_open(out, "wb") as fh:
        fig.savefig(fh, dpi=110, format=image_format(out))
    plt.close(fig)
    return out


def plot_seed_bands(runs: list[Path], out: Path, title: str | None = None) -> Path:
    """The four panels for multi-seed runs (``peghole train --seeds N``): the training
    episodes' statistics per chunk, mean over seeds with a 95 % Student-t band; returns ``out``."""
    matplotlib.use("Agg")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    for i, run in enumerate(runs):
        run = Path(run)
        path = run / "history.csv"
        if not path.exists():
            raise UserInputError(f"{run}: no history.csv (not a multi-seed training run)")
        rows = read_rows(path, ("seed", "step"))
        n_seeds = len({r["seed"] for r in rows})
        label = f"{run_label(run)}, {n_seeds} seeds"
        steps = sorted({int(r["step"]) for r in rows})
        for ax, (key, _, _) in zip(axes.flat, PANELS, strict=True):
            mean, lo, hi = [], [], []
            for s in steps:
                vals = [
                    float(r[f"train/{key}"])
                    for r in rows
                    if int(r["step"]) == s and r.get(f"train/{key}", "") not in ("", "nan")
                ]
                ci = t_interval(vals)
                mean.append(np.mean(vals) if vals else np.nan)
                lo.append(ci[0] if ci else np.nan)
                hi.append(ci[1] if ci else np.nan)
            # chunks in which no training episode ended are gaps: draw the others joined,
            # with markers, so an isolated chunk stays visible
            x, mean = np.asarray(steps), np.asarray(mean)
            ok = np.isfinite(mean)
            ax.plot(x[ok], mean[ok], color=f"C{i}", lw=1.4, marker="o", ms=3, label=label)
            lo, hi = np.asarray(lo), np.asarray(hi)
            band = np.isfinite(lo) & np.isfinite(hi)  # chunks with episodes of >= 2 seeds
            ax.fill_between(x[band], lo[band], hi[band], color=f"C{i}", alpha=0.25, lw=0)
    return _finish(fig, axes, title or "SAC training episodes: mean over seeds, 95 % band", out)


FINAL_PANELS = (
    ("success_rate", "success rate"),
    ("mean_fz_N", "mean |F_z| per episode (N)"),
    ("mean_time_s", "mean extraction time, successes (s)"),
)


def plot_final_evals(runs: list[Path], out: Path, title: str | None = None) -> Path:
    """The final evaluation of each seed of multi-seed runs (``seeds.json``): one dot per seed
    and the mean over seeds with its 95 % Student-t interval, per run; returns ``out``. It shows
    what the training curves cannot where the budget lets few training episodes end."""
    matplotlib.use("Agg")
    fig, axes = plt.subplots(1, len(FINAL_PANELS), figsize=(11, 3.8))
    labels = []
    for i, run in enumerate(runs):
        run = Path(run)
        path = run / "seeds.json"
        if not path.exists():
            raise UserInputError(f"{run}: no seeds.json (not a finished multi-seed run)")
        evals = json.loads(path.read_text())["final_eval"]
        labels.append(f"{run_label(run)}\n({len(evals)} seeds)")
        for ax, (key, _) in zip(axes, FINAL_PANELS, strict=True):
            vals = [float(e[key]) for e in evals if e.get(key) is not None]
            if not vals:  # not recorded by this run
                continue
            jitter = np.linspace(-0.12, 0.12, len(vals)) if len(vals) > 1 else np.zeros(1)
            ax.scatter(i + jitter, vals, color=f"C{i}", s=18, alpha=0.7)
            ci, mean = t_interval(vals), float(np.mean(vals))
            err = None if ci is None else [[mean - ci[0]], [ci[1] - mean]]
            ax.errorbar(i + 0.3, mean, yerr=err, fmt="D", color=f"C{i}", capsize=4, ms=5)
    for ax, (_, ylabel) in zip(axes, FINAL_PANELS, strict=True):
        ax.set_ylabel(ylabel)
        ax.set_xticks(range(len(labels)), labels, fontsize=8)
        ax.set_xlim(-0.5, len(labels) - 0.3)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(title or "Final evaluation per seed: dots, mean and 95 % t-interval")
    return _save(fig, out)
