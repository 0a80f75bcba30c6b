"""Learning curves in the style of the thesis's Figs 4.5-4.7, from runs' ``metrics.csv``.

Panels, each against env steps: (a) extraction force per episode (mean |F_z|, Fig 4.5),
(b) mean |F_xy| per episode (Fig 4.6), (c) discounted return (Fig 4.7), (d) eval success.
Training-episode statistics are drawn as lines, evaluation points as markers. Several runs
(e.g. RL vs RL + compliance strategy) share the axes, labelled from their configs.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from peghole_mjx.errors import UserInputError

PANELS = (
    ("mean_fz_N", "extraction force |F_z| per episode (N)", "Fig 4.5"),
    ("mean_fxy_N", "mean |F_xy| per episode (N)", "Fig 4.6"),
    ("mean_discounted_return", "discounted return", "Fig 4.7"),
    ("success_rate", "success rate", ""),
)


def run_label(run: Path) -> str:
    """``RL + CS`` or ``RL`` (compliance strategy on or off), with the env name."""
    from peghole_mjx.training.config import read_run_record

    meta, _ = read_run_record(run, what=str(run), full=False)
    cfg = meta["config"]
    cs = bool(cfg.get("env_overrides", {}).get("compliance_strategy", False))
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


def read_metrics(run: Path, torn_tail: bool = False) -> list[dict[str, str]]:
    """The rows of a training run's ``metrics.csv`` (one per evaluation), as strings,
    schema-checked (:func:`read_rows`)."""
    path = Path(run) / "metrics.csv"
    if not path.exists():
        raise UserInputError(f"{run}: no metrics.csv (not a training run directory)")
    return read_rows(path, ("step",), torn_tail=torn_tail)


def read_rows(
    path: Path, required: tuple[str, ...], torn_tail: bool = False
) -> list[dict[str, str]]:
    """The rows of a CSV log a run appends to (``metrics.csv``, ``history.csv``), checked:
    UTF-8 text without NUL bytes, a header holding the ``required`` columns (no empty or
    repeated names), every row with the header's number of fields and a whole-number ``step``
    >= 0. A problem is a :class:`CorruptFileError` naming the file and the line.

    ``torn_tail``: the last line as a kill or a power cut can leave it (no final newline, or
    ending in NUL bytes) is dropped instead (``--resume``: that row is after the newest
    checkpoint, whose work is redone)."""
    from peghole_mjx.errors import CorruptFileError

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UserInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends in one
    if torn_tail:
        if lines and b"\0" in lines[-1] and not tail.strip(b"\0"):
            lines.pop()  # a row whose end a power cut replaced with NUL bytes
    elif tail:
        lines.append(tail)  # checked as any other line
    for i, line in enumerate(lines, 1):
        if b"\0" in line:
            raise CorruptFileError(
                f"{path} line {i}: NUL bytes (a damaged file, e.g. the tail a crash leaves)"
            )
    try:
        text = [line.decode().rstrip("\r") for line in lines]
    except UnicodeDecodeError as exc:
        raise CorruptFileError(f"{path}: not UTF-8 text ({exc.reason})") from None
    if not text or not text[0]:
        raise CorruptFileError(f"{path} line 1: no header")
    try:
        parsed = [(i, f) for i, f in enumerate(csv.reader(text), 1) if f]  # blank lines skipped
    except csv.Error as exc:
        raise CorruptFileError(f"{path}: not CSV ({exc})") from None
    header, body = parsed[0][1], parsed[1:]
    if any(not h for h in header) or len(set(header)) != len(header):
        raise CorruptFileError(f"{path} line 1: empty or repeated column names {header!r:.80}")
    missing = [c for c in required if c not in header]
    if missing:
        raise CorruptFileError(f"{path} line 1: the header lacks the columns {missing}")
    rows = []
    for i, fields in body:
        if len(fields) != len(header):
            raise CorruptFileError(
                f"{path} line {i}: {len(fields)} fields, the header has {len(header)}"
            )
        row = dict(zip(header, fields, strict=True))
        step = row.get("step")
        if step is not None and not (step.isascii() and step.isdigit()):
            raise CorruptFileError(f"{path} line {i}: step must be a whole number, got {step!r}")
        rows.append(row)
    return rows


def plot_curves(runs: list[Path], out: Path, title: str | None = None) -> Path:
    """One figure with the four panels for every run in ``runs``; returns ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    from matplotlib.backend_bases import FigureCanvasBase

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
    import matplotlib.pyplot as plt

    from peghole_mjx import fileio

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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from peghole_mjx.training.seeds import t_interval

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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from peghole_mjx.training.seeds import t_interval

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
