"""Parameter studies of the thesis (Figs 2.11-2.18 and 3.12-3.42): CSV + PNG per family.

Each family evaluates the closed-form two-point regions (vectorised over the whole sweep) with
the thesis's parameter values and writes ``fig_<ID>.csv`` (one row per parameter combination:
boundary depths and region length) and ``fig_<ID>.png``. Depths are measured downward from the
hole mouth (``h = 0``); the plots draw the mouth and the initial depth ``h0``.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from peghole_mjx.analysis import common, dual, rect
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.files import fileio
from peghole_mjx.geometry.specs import get_preset

DEG = math.pi / 180.0
#: Rotational stiffness of the sensitivity panels (comparable to K_x L^2): shows the
#: compliance-centre effect that the thesis's 30e4 N mm/rad suppresses (docs/research/analysis.md).
SENS_K_THETA_DUAL = 1e3
SENS_RECT = {"K_theta_Nmm_per_rad": 5e3, "K_phi_Nmm_per_rad": 5e3}


@dataclass
class Panel:
    title: str
    x_label: str
    x: np.ndarray
    curves: list[tuple[str, np.ndarray, np.ndarray]]  # (label, h_lo, h_hi)


@dataclass
class Family:
    id: str
    title: str
    build: Callable[[], tuple[list[Panel], list[dict]]]
    h0: float


def _row(base: dict, h_lo, h_hi, length) -> dict:
    def num(v):
        v = float(v)
        return "" if not math.isfinite(v) else round(v, 6)

    return {**base, "h_start_mm": num(h_lo), "h_end_mm": num(h_hi), "region_length_mm": num(length)}


# ---------------------------------------------------------------------------------------- dual


def _sweep(
    model, region_fn, key: tuple[str, object], figure: str, x_name: str, x, fixed: dict, label: str
) -> tuple[tuple[str, np.ndarray, np.ndarray], list[dict]]:
    """One curve of a region figure: ``region_fn`` of ``model`` (dual or rect) swept over ``x``.

    ``key`` names the contact state (dual "category" or rect "case") and its value; every
    other argument takes ``model.DEFAULTS`` overridden by ``fixed``. Returns the curve
    (label, h_lo, h_hi) and one CSV row per point.
    """
    point = {**model.DEFAULTS, **fixed, x_name: x}  # every argument, x swept
    args = dict(point)
    L_C = args.pop("L_C_mm")
    reg = region_fn(model.FIGURE_PRESET, key[1], L_C, **args)
    lo, hi, ln = (np.broadcast_to(a, x.shape) for a in (reg.h_lo, reg.h_hi, reg.length))
    rows = []
    for i in range(x.size):
        vals = {
            k: (float(x.flat[i]) if k == x_name else float(np.asarray(v))) for k, v in point.items()
        }
        base = {
            "figure": figure,
            "geometry": model.FIGURE_PRESET,
            key[0]: key[1],
            "curve": label,
            **{k: round(v, 9) for k, v in vals.items()},
        }
        rows.append(_row(base, lo.flat[i], hi.flat[i], ln.flat[i]))
    return (label, lo, hi), rows


def _dual_sweep(figure: str, category: str, x_name: str, x, fixed: dict, label: str):
    """A dual-peg two-point-contact region (Figs 2.11-2.18) of state ``category``."""
    return _sweep(
        dual, dual.two_point_region, ("category", category), figure, x_name, x, fixed, label
    )


def _dual_2_11():
    panels, rows = [], []
    x = np.linspace(0.0, 50.0, 51)
    for cat, sub in zip(("5", "10", "9"), "abc", strict=True):
        curve, r = _dual_sweep("2.11" + sub, cat, "L_C_mm", x, {"L_C_mm": 0.0}, "region")
        panels.append(Panel(f"2.11{sub}: {dual.CATEGORY_NAMES[cat]}", "L_C (mm)", x, [curve]))
        rows += r
    for cat, sub in zip(("5", "10", "9"), "abc", strict=True):  # not in the thesis
        curve, r = _dual_sweep(
            "2.11" + sub + "-sens",
            cat,
            "L_C_mm",
            x,
            {"L_C_mm": 0.0, "K_theta_Nmm_per_rad": SENS_K_THETA_DUAL},
            "K_theta = 1e3 N mm/rad",
        )
        panels.append(
            Panel(
                f"sensitivity (not in thesis): state {cat}, K_theta = 1e3 N mm/rad",
                "L_C (mm)",
                x,
                [curve],
            )
        )
        rows += r
    return panels, rows


def _dual_2_12_14():
    panels, rows = [], []
    x = np.linspace(0.0, 3.0, 31)
    for fig, cat in (("2.12", "5"), ("2.13", "9"), ("2.14", "10")):
        for Lc, sub in zip((0.0, 25.0, 50.0), "abc", strict=True):
            curve, r = _dual_sweep(fig + sub, cat, "delta0_mm", x, {"L_C_mm": Lc}, "region")
            panels.append(
                Panel(f"{fig}{sub}: state {cat}, L_C = {Lc:g} mm", "delta0 (mm)", x, [curve])
            )
            rows += r
    return panels, rows


def _dual_2_15():
    panels, rows = [], []
    x = np.linspace(-1.0, 1.0, 41) * DEG
    for cat, sub in zip(("5", "10", "9"), "abc", strict=True):
        curve, r = _dual_sweep(
            "2.15" + sub, cat, "beta0_rad", x, {"L_C_mm": 50.0, "delta0_mm": 1.0}, "region"
        )
        panels.append(
            Panel(f"2.15{sub}: state {cat}, L_C = 50 mm, delta0 = 1 mm", "beta0 (rad)", x, [curve])
        )
        rows += r
    return panels, rows


def _dual_2_16_18():
    panels, rows = [], []
    x = np.linspace(0.0, 50.0, 51)
    sets = (
        ("K_x = 0.2 N/mm", {"K_x_N_per_mm": 0.2}),
        ("K_x = 0.6 N/mm", {"K_x_N_per_mm": 0.6}),
        ("K_theta = 15e4 N mm/rad", {"K_theta_Nmm_per_rad": 15e4}),
        ("K_theta = 45e4 N mm/rad", {"K_theta_Nmm_per_rad": 45e4}),
    )
    for fig, cat in (("2.16", "5"), ("2.17", "9"), ("2.18", "10")):
        curves = []
        for (label, fixed), sub in zip(sets, "abcd", strict=True):
            curve, r = _dual_sweep(fig + sub, cat, "L_C_mm", x, {"L_C_mm": 0.0, **fixed}, label)
            curves.append(curve)
            rows += r
        panels.append(Panel(f"{fig}: state {cat}, stiffness", "L_C (mm)", x, curves))
    return panels, rows


# ---------------------------------------------------------------------------------------- rect


def _rect_sweep(figure: str, case: int, x_name: str, x, fixed: dict, label: str):
    """A rectangular-peg two-contact region (Figs 3.12-3.42) of ``case``."""
    return _sweep(rect, rect.two_contact_region, ("case", case), figure, x_name, x, fixed, label)


def _rect_3_12():
    panels, rows = [], []
    x = np.linspace(0.0, 150.0, 61)
    for case, sub in zip((1, 2, 3), "abc", strict=True):
        curve, r = _rect_sweep("3.12" + sub, case, "L_C_mm", x, {"L_C_mm": 0.0}, "region")
        panels.append(
            Panel(f"3.12{sub}: case {case}, {rect.CASE_NAMES[case]}", "L_C (mm)", x, [curve])
        )
        rows += r
    for case, sub in zip((1, 2, 3), "abc", strict=True):  # not in the thesis
        curve, r = _rect_sweep(
            "3.12" + sub + "-sens",
            case,
            "L_C_mm",
            x,
            {"L_C_mm": 0.0, **SENS_RECT},
            "K_theta = K_phi = 5e3 N mm/rad",
        )
        panels.append(
            Panel(
                f"sensitivity (not in thesis): case {case}, K_theta = K_phi = 5e3",
                "L_C (mm)",
                x,
                [curve],
            )
        )
        rows += r
    return panels, rows


def _rect_error_family(
    first_fig: int, params: tuple[tuple[str, str], ...], x: np.ndarray, x_label_unit: str
):
    panels, rows = [], []
    fig = first_fig
    for pname, plabel in params:
        for case in (1, 2, 3):
            curves = []
            for Lc in (0.0, 75.0, 150.0):
                curve, r = _rect_sweep(
                    f"3.{fig}", case, pname, x, {"L_C_mm": Lc}, f"L_C = {Lc:g} mm"
                )
                curves.append(curve)
                rows += r
            panels.append(
                Panel(f"3.{fig}: case {case}, {plabel}", f"{plabel} ({x_label_unit})", x, curves)
            )
            fig += 1
    return panels, rows


def _rect_3_13_18():
    return _rect_error_family(
        13, (("delta_x_mm", "delta_X"), ("delta_y_mm", "delta_Y")), np.linspace(0.0, 3.0, 31), "mm"
    )


def _rect_3_19_27():
    return _rect_error_family(
        19,
        (
            ("delta_theta_rad", "delta_theta"),
            ("delta_phi_rad", "delta_phi"),
            ("delta_psi_rad", "delta_psi"),
        ),
        np.linspace(-1.0, 1.0, 41) * DEG,
        "rad",
    )


def _rect_3_28_42():
    panels, rows = [], []
    x = np.linspace(0.0, 150.0, 61)
    fig = 28
    studies = (
        ("K_x_N_per_mm", "K_X", (0.2, 0.3, 0.4, 0.6), "N/mm"),
        ("K_y_N_per_mm", "K_Y", (0.2, 0.3, 0.4, 0.6), "N/mm"),
        ("K_theta_Nmm_per_rad", "K_theta", (15e4, 30e4, 45e4), "N mm/rad"),
        ("K_phi_Nmm_per_rad", "K_phi", (15e4, 30e4, 45e4), "N mm/rad"),
        ("K_psi_Nmm_per_rad", "K_psi", (15e4, 30e4, 45e4), "N mm/rad"),
    )
    for pname, plabel, values, unit in studies:
        for case in (1, 2, 3):
            curves = []
            for v in values:
                curve, r = _rect_sweep(
                    f"3.{fig}",
                    case,
                    "L_C_mm",
                    x,
                    {"L_C_mm": 0.0, pname: v},
                    f"{plabel} = {v:g} {unit}",
                )
                curves.append(curve)
                rows += r
            panels.append(Panel(f"3.{fig}: case {case}, {plabel}", "L_C (mm)", x, curves))
            fig += 1
    return panels, rows


def _h0(preset: str) -> float:
    return get_preset(preset).hole_depth_mm


FAMILIES: dict[str, Family] = {
    "2.11": Family(
        "2.11",
        "Dual: two-point region vs compliance-centre location",
        _dual_2_11,
        _h0(dual.FIGURE_PRESET),
    ),
    "2.12-2.14": Family(
        "2.12-2.14",
        "Dual: effect of the initial lateral error",
        _dual_2_12_14,
        _h0(dual.FIGURE_PRESET),
    ),
    "2.15": Family(
        "2.15", "Dual: effect of the initial angular error", _dual_2_15, _h0(dual.FIGURE_PRESET)
    ),
    "2.16-2.18": Family(
        "2.16-2.18", "Dual: effect of the stiffness", _dual_2_16_18, _h0(dual.FIGURE_PRESET)
    ),
    "3.12": Family(
        "3.12",
        "Rect: two-contact region vs compliance-centre location",
        _rect_3_12,
        _h0(rect.FIGURE_PRESET),
    ),
    "3.13-3.18": Family(
        "3.13-3.18",
        "Rect: effect of the initial lateral errors",
        _rect_3_13_18,
        _h0(rect.FIGURE_PRESET),
    ),
    "3.19-3.27": Family(
        "3.19-3.27",
        "Rect: effect of the initial angular errors",
        _rect_3_19_27,
        _h0(rect.FIGURE_PRESET),
    ),
    "3.28-3.42": Family(
        "3.28-3.42", "Rect: effect of the stiffness", _rect_3_28_42, _h0(rect.FIGURE_PRESET)
    ),
}


def resolve(fig_id: str) -> list[str]:
    """Family ids for ``fig_id``: a family id, ``all``, or a single figure inside a family
    (``2.13`` -> ``2.12-2.14``)."""
    fig_id = fig_id.strip()
    if fig_id == "all":
        return list(FAMILIES)
    if fig_id in FAMILIES:
        return [fig_id]
    try:
        chap, num = (int(p) for p in fig_id.split("."))
    except ValueError:
        chap = num = -1
    for fid in FAMILIES:
        lo, _, hi = fid.partition("-")
        lc, ln = (int(p) for p in lo.split("."))
        hc, hn = (int(p) for p in (hi or lo).split("."))
        if chap == lc == hc and ln <= num <= hn:
            return [fid]
    raise UserInputError(f"unknown figure {fig_id!r}; choose one of {', '.join(FAMILIES)} or all")


def _plot(path: Path, fam: Family, panels: list[Panel]) -> None:
    matplotlib.use("Agg")

    n = len(panels)
    ncol = 3 if n % 3 == 0 else min(n, 4)
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.1 * nrow), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, p in zip(axes.flat, panels, strict=False):
        for k, (label, lo, hi) in enumerate(p.curves):
            c = colors[k % len(colors)]
            ax.fill_between(p.x, lo, hi, color=c, alpha=0.18 if len(p.curves) > 1 else 0.35, lw=0)
            ax.plot(p.x, lo, color=c, lw=1.4, label=label)
            ax.plot(p.x, hi, color=c, lw=1.4, ls="--")
        ax.axhline(0.0, color="k", lw=1.2)
        ax.axhline(fam.h0, color="0.4", lw=0.8, ls=":")
        ax.text(p.x[0], 0.0, " hole mouth (h = 0)", va="bottom", fontsize=7)
        ax.text(
            p.x[0], fam.h0, f" initial depth h0 = {fam.h0:g} mm", va="top", fontsize=7, color="0.3"
        )
        ax.set_ylim(fam.h0 * 1.08, -fam.h0 * 0.1)  # depth grows downward
        ax.set_xlim(p.x[0], p.x[-1])
        ax.set_title(p.title, fontsize=8)
        ax.set_xlabel(p.x_label, fontsize=8)
        ax.set_ylabel("depth below mouth h (mm)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if all(np.all(~np.isfinite(lo)) for _, lo, _ in p.curves):
            ax.text(
                0.5,
                0.5,
                "no two-point contact",
                transform=ax.transAxes,
                ha="center",
                fontsize=8,
                color="0.3",
            )
        ax.legend(fontsize=6, loc="lower right")
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(
        f"Fig {fam.id}: {fam.title}\nshaded: two-point contact region; solid: "
        "shallow boundary, dashed: deep boundary",
        fontsize=9,
    )
    fig.tight_layout()

    with fileio.atomic_open(path, "wb") as fh:  # a failed write keeps the old figure
        fig.savefig(fh, dpi=110 if n <= 6 else 80, format="png")
    plt.close(fig)


def family_paths(fig_id: str, out_dir: str | Path) -> tuple[Path, Path]:
    """The CSV and PNG :func:`write_family` writes for ``fig_id`` into ``out_dir``."""
    stem = "fig_" + fig_id.replace(".", "_")
    return Path(out_dir) / f"{stem}.csv", Path(out_dir) / f"{stem}.png"


def write_family(fig_id: str, out_dir: str | Path) -> tuple[Path, Path]:
    """Evaluate one family and write its CSV and PNG into ``out_dir``."""
    fam = FAMILIES[fig_id]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    panels, rows = fam.build()
    csv_path, png_path = family_paths(fig_id, out)
    keys: list[str] = []
    for r in rows:
        for k in r:
            if k not in keys:
                keys.append(k)

    with fileio.atomic_open(csv_path, "w") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    _plot(png_path, fam, panels)
    return csv_path, png_path


__all__ = ["FAMILIES", "common", "resolve", "write_family"]
