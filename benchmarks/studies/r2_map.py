"""Where does the quasi-static model predict R2? The oracle over the full dual grid.

R2 (thesis Sec 2.5.2, Fig 2.20): in the dual peg-hole the force peaks are lower as L_C goes to
the tip (tip < centre < top). Whether a simulation "shows R2 where the model predicts it" needs
the cells where the model predicts it, with the same draws and intervals as the simulation.
This map runs the quasi-static oracle (:func:`peghole_mjx.experiments.compliance.quasi_static`,
no simulation) on every cell of the regime sweep's full dual grid
(``sweep.GRIDS["dual"]["full"]``: dual-2 and dual-3, mu 0.01 and 0.266, K_theta, K_lat,
delta0, beta0 and the theta0 = -0.9 deg arm) and the sweep's paired worlds (16 draws, seed 0,
L_C at tip / centre / top). Per cell: the oracle's mean late peak F_z per L_C (first
``EARLY_MM`` of the pull left out, as the experiment's), the paired reductions tip vs top,
tip vs centre and centre vs top with 95 % bootstrap intervals, and a class:

* ``ordered``: R2's full ordering resolved by the model's own intervals (the lower ends of
  tip vs centre and centre vs top above 0);
* ``tip_below_top``: tip vs top resolved above 0, the centre not between;
* ``reversed``: tip vs top resolved below 0;
* ``unresolved``: the tip-vs-top interval contains 0.

and two flags where the experiment cannot follow the oracle: ``over_force_cap`` (a mean peak
above the law's axial force limit, ``LIMITS.max_force_N[2]``: the quasi-static peg wedges) and
``over_torque_cap`` (the initial rotational spring torque K_theta |beta0 + theta0| at the
largest draw above ``LIMITS.max_torque_Nm[1]``: the law clips it). Each finished cell is
appended to ``<out>.parts.jsonl`` (resumable)::

    python -m benchmarks.studies.r2_map          # 480 cells, about 10 min on one core
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from tqdm import tqdm

from benchmarks.common import (
    EVALS_RESULTS,
    STUDIES_RESULTS,
    fmt_ci,
    fmt_num,
    out_file,
    table,
    write_rows,
)
from benchmarks.evals.experiments import ordered
from benchmarks.studies.pull_speed import oracle_late_peaks
from peghole_mjx.control.limits import LIMITS
from peghole_mjx.experiments import sweep as sw
from peghole_mjx.files.fileio import write_text
from peghole_mjx.files.provenance import provenance

GRID = sw.GRIDS["dual"]["full"]
SEED = 0
CLASSES = ("ordered", "tip_below_top", "unresolved", "reversed")
#: the paired reductions kept per cell, in :func:`classify`'s argument order
REDUCTIONS = ("tip_vs_top", "tip_vs_centre", "centre_vs_top")


def _key(c: dict) -> str:
    return json.dumps(c, sort_keys=True)


def classify(tt_ci: list[float], tc_ci: list[float], ct_ci: list[float]) -> str:
    """R2 class of a cell from its paired intervals (tip vs top, tip vs centre, centre vs top)."""
    if ordered(tc_ci, ct_ci):
        return "ordered"
    if tt_ci[0] > 0:
        return "tip_below_top"
    if tt_ci[1] < 0:
        return "reversed"
    return "unresolved"


def map_cell(c: dict, repeats: int, seed: int = SEED) -> dict:
    """The oracle's R2 row of one grid cell."""
    tab = sw.cell_table(c, repeats, seed)
    tip, centre, top = oracle_late_peaks(c, tab).reshape(3, repeats)
    red = dict(zip(REDUCTIONS, ((tip, top), (tip, centre), (centre, top)), strict=True))
    row = {**c, "repeats": repeats}
    row["oracle_peak_fz_N"] = {"tip": tip.mean(), "centre": centre.mean(), "top": top.mean()}
    for name, (a, b) in red.items():
        row[f"{name}_pct"] = {"value": sw.reduction_pct(a, b), "ci95": sw.paired_bootstrap(a, b)}
    row["r2_class"] = classify(*(row[f"{n}_pct"]["ci95"] for n in red))
    peak = max(row["oracle_peak_fz_N"].values())
    row["over_force_cap"] = bool(not np.isfinite(peak) or peak > LIMITS.max_force_N[2])
    tilt = float(np.max(np.abs(tab["beta0"] + tab["theta0"])))  # the largest draw's, rad
    row["over_torque_cap"] = bool(c["k_rot_Nm_rad"] * tilt > LIMITS.max_torque_Nm[1])
    return sw.clean_json(row)


def summary(rows: list[dict]) -> list[dict]:
    """Per (preset, mu): how many cells fall in each class, within the caps and over them."""
    out = []
    for preset in GRID.presets:
        for mu in GRID.mu:
            sel = [r for r in rows if r["preset"] == preset and r["mu"] == mu]
            ok = [r for r in sel if not (r["over_force_cap"] or r["over_torque_cap"])]
            out.append(
                {
                    "preset": preset,
                    "mu": mu,
                    "cells": len(sel),
                    "within_caps": len(ok),
                    **{k: sum(r["r2_class"] == k for r in ok) for k in CLASSES},
                    "ordered_over_caps": sum(
                        r["r2_class"] == "ordered" for r in sel if r not in ok
                    ),
                }
            )
    return out


def write_figure(rows: list[dict], path: Path) -> Path:
    """One panel per (preset, mu): K_theta x K_lat (rows) against the arm x delta0 (columns),
    coloured by class, hatched over a cap."""
    colours = ("#1b7837", "#a6dba0", "#f0f0f0", "#c2a5cf")
    ys = [(k, kl) for k in GRID.k_rot_Nm_rad for kl in GRID.k_lat_N_m]
    arms = [(b, 0.0) for b in GRID.beta0_deg] + [(0.0, GRID.theta0_arm_deg)]
    xs = [(a, d) for a in arms for d in GRID.delta0_mm]
    fig = Figure(figsize=(12, 11))
    axes = fig.subplots(len(GRID.presets), len(GRID.mu), sharex=True, sharey=True, squeeze=False)
    for i, preset in enumerate(GRID.presets):
        for j, mu in enumerate(GRID.mu):
            ax = axes[i, j]
            img = np.full((len(ys), len(xs)), np.nan)
            for r in rows:
                if r["preset"] != preset or r["mu"] != mu:
                    continue
                y = ys.index((r["k_rot_Nm_rad"], r["k_lat_N_m"]))
                x = xs.index(((r["beta0_deg"], r["theta0_deg"]), r["delta0_mm"]))
                img[y, x] = CLASSES.index(r["r2_class"])
                if r["over_force_cap"] or r["over_torque_cap"]:
                    ax.text(x, y, "x", ha="center", va="center", fontsize=9)
            ax.imshow(img, cmap=ListedColormap(colours), vmin=-0.5, vmax=3.5, aspect="auto")
            ax.set_title(f"{preset}, mu {mu:g}")
            ax.set_xticks(range(len(xs)))
            labels = [(f"th0 {a[1]:g}" if a[1] else f"b0 {a[0]:+g}") + f"\nd0 {d:g}" for a, d in xs]
            ax.set_xticklabels(labels, fontsize=7)
            ax.set_yticks(range(len(ys)))
            ax.set_yticklabels([f"K_th {k:g} / K_lat {kl:g}" for k, kl in ys], fontsize=7)
    handles = [Patch(color=c, label=n) for c, n in zip(colours, CLASSES, strict=True)]
    handles.append(Patch(color="white", label="x: over the law's force or torque cap"))
    fig.legend(handles=handles, loc="lower center", ncol=5)
    fig.suptitle(
        "R2 (tip < centre < top) in the quasi-static oracle, 16 paired draws, 95 % intervals"
    )
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    fig.savefig(path, dpi=110)
    return path


# ----------------------------------------------------------------------------- docs tables
#: the pulls of the thesis's tilted dual experiment (``pull_speed --plan ...``): store, rows
TILT_STORES = (
    ("dual_tilt", "the experiment's"),
    ("dual_tilt_coulomb", "Coulomb"),
    ("dual_tilt_mu001", "the experiment's"),
    ("dual_tilt_mu001_k3", "the experiment's"),
    ("dual3_tilt_mu001", "the experiment's"),
)
#: the experiment itself on the tilted cells (``peghole experiment sweep --out ...``)
TILT_SWEEPS = ("dual_tilt", "dual_tilt_x64", "dual3_tilt_mu001")


@table("r2_map")
def r2_map_table() -> str:
    """Where the quasi-static oracle predicts R2 over the full dual grid, and the thesis's
    tilted dual experiment pulled in MuJoCo C (``pull_speed --plan dual_tilt``) and run in
    MJX beside the oracle."""
    lines = []
    path = STUDIES_RESULTS / "r2_map.json"
    if path.exists():
        m = json.loads(path.read_text())
        lines += [
            "| preset | mu | cells | within the law's caps | ordered | tip below top only | "
            "unresolved | reversed | ordered, over a cap |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for s in m["summary"]:
            lines.append(
                f"| {s['preset']} | {s['mu']:g} | {s['cells']} | {s['within_caps']} | "
                f"{s['ordered']} | {s['tip_below_top']} | {s['unresolved']} | "
                f"{s['reversed']} | {s['ordered_over_caps']} |"
            )
        lines += [
            "",
            f"Quasi-static oracle, {m['repeats']} paired draws per cell (seed {m['seed']}), "
            f"95 % paired bootstrap intervals; caps: axial force {m['force_cap_N']:g} N, "
            f"torque {m['torque_cap_Nm']:g} N m; {m['device']}, {m['date'][:10]}.",
        ]
    stores = [(STUDIES_RESULTS / f"pull_speed_{n}.json", rows) for n, rows in TILT_STORES]
    stores = [(json.loads(p.read_text()), rows) for p, rows in stores if p.exists()]

    def red(x: dict) -> str:
        lo, hi = x["oracle_ci95"]
        return f"{fmt_ci(x)} ({x['oracle']:.1f} [{lo:.1f}, {hi:.1f}])"

    def resolved(c: dict, ci: str) -> str:
        ok = ordered(c["reduction_tip_vs_centre_pct"][ci], c["reduction_centre_vs_top_pct"][ci])
        return "yes" if ok else "no"

    if stores:
        lines += [
            "",
            "| preset | K_theta N m/rad | pull mm/s | mu, frictional rows | mean peak F_z N: tip / "
            "centre / top (oracle) | tip vs top % [95 % CI] (oracle [its CI]) | tip vs centre | "
            "centre vs top | ordering resolved: simulation / oracle | two-point region mm: "
            "tip / centre / top (oracle) | both walls loaded, median |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
    notes = []
    for d, rows in stores:
        for c in d["cells"]:
            pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
            orc = " / ".join(f"{v:.3g}" for v in c["oracle_peak_fz_N"].values())
            tp = " / ".join(f"{v:.1f}" for v in c["two_point_mm"].values())
            otp = " / ".join(f"{v:.1f}" for v in c["oracle_two_point_mm"].values())
            both = c["both_walls_frac_median"]
            lines.append(
                f"| {d['preset']} | {c['k_rot_Nm_rad']:g} | {c['speed_mm_s']:g} | "
                f"{d['mu']:g}, {rows} | "
                f"{pk} ({orc}) | "
                f"{red(c['reduction_tip_vs_top_pct'])} | {red(c['reduction_tip_vs_centre_pct'])} "
                f"| {red(c['reduction_centre_vs_top_pct'])} | {resolved(c, 'ci95')} / "
                f"{resolved(c, 'oracle_ci95')} | {tp} ({otp}) | "
                f"{'-' if both is None else f'{both:.2f}'} |"
            )
        notes.append(
            f"{d['preset']}, mu {d['mu']:g}, {rows} rows: {d['settings']['repeats']} paired "
            f"repeats per L_C, "
            f"{d['device']}, "
            f"{d['date'][:10]}, {d['pulls_wall_s'] / 60:.0f} min of pulls (one core each)"
        )
    if stores:
        d = stores[0][0]
        lines += [
            "",
            f"K_lat 300 N/m, delta0 2 mm, beta0 0, theta0 {d['theta0_deg']:g} deg; "
            f"{d['engine'].split(';')[0]}; " + "; ".join(notes) + ".",
        ]
    # the experiment itself in MJX: float32 (the sweep's precision) and the float64 rerun
    sweeps = [EVALS_RESULTS / f / "compliance_sweep_dual.json" for f in TILT_SWEEPS]
    sweeps = [json.loads(p.read_text()) for p in sweeps if p.exists()]
    if sweeps:

        def sred(c: dict, n: str) -> str:
            x = c[f"reduction_{n}_pct"]
            return f"{fmt_ci(x)} ({c['quasi_static'][f'reduction_{n}_pct']:.1f})"

        lines += [
            "",
            "| preset, mu, precision | K_theta N m/rad | mean peak F_z N: tip / centre / top "
            "(oracle) | tip vs "
            "top % [95 % CI] (oracle) | tip vs centre | centre vs top | ordering resolved | "
            "deepest contact in two-point windows um (limit) | NaN worlds |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        notes = []
        for d in sweeps:
            x = d["settings"]
            prec = x.get("precision", "float32")
            for c in d["cells"]:
                pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
                orc = " / ".join(f"{v:.3g}" for v in c["quasi_static"]["peak_fz_N"].values())
                ok = ordered(
                    c["reduction_tip_vs_centre_pct"]["ci95"],
                    c["reduction_centre_vs_top_pct"]["ci95"],
                )
                pen = c.get("max_penetration_two_point_um")
                lines.append(
                    f"| {c['preset']}, {c['mu']:g}, {prec} | {c['k_rot_Nm_rad']:g} | "
                    f"{pk} ({orc}) | "
                    f"{sred(c, 'tip_vs_top')} | "
                    f"{sred(c, 'tip_vs_centre')} | {sred(c, 'centre_vs_top')} | "
                    f"{'yes' if ok else 'no'} | {fmt_num(pen, '.1f')} "
                    f"({c['penetration_limit_um']:.1f}) | {c['nan_worlds']} |"
                )
            notes.append(
                f"{d['cells'][0]['preset']}, mu {d['cells'][0]['mu']:g}, {prec}: "
                f"{sum(c['n_worlds'] for c in d['cells'])} worlds, "
                f"{x['experiment']['speed_m_s'] * 1e3:g} mm/s, {d['device']}, {d['date'][:10]}"
            )
        lines += [
            "",
            "The experiment itself (MJX-JAX, `peghole experiment sweep`), the tilted cells: "
            + "; ".join(notes)
            + ".",
        ]
    return "\n".join(lines)


def main() -> int:
    """Classify every cell of the full dual grid (resumable) and write the map."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=GRID.repeats)
    ap.add_argument("--out", type=out_file, default=STUDIES_RESULTS / "r2_map.json")
    args = ap.parse_args()
    if args.repeats < 2:
        raise SystemExit("--repeats must be >= 2 (intervals need two draws)")
    parts = args.out.with_suffix(".parts.jsonl")
    done = {}
    if parts.exists():
        for line in parts.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if r["row"]["repeats"] != args.repeats:
                    raise SystemExit(f"{parts} holds cells of another --repeats: move it away")
                done[r["key"]] = r["row"]
    cells = GRID.check().cells()
    with parts.open("a") as f:
        for c in tqdm([c for c in cells if _key(c) not in done], desc="R2 map"):
            row = map_cell(c, args.repeats)
            done[_key(c)] = row
            f.write(json.dumps({"key": _key(c), "row": row}) + "\n")
            f.flush()
    rows = [done[_key(c)] for c in cells]
    doc = {
        "what": "the quasi-static oracle's R2 class of every cell of the full dual grid",
        "seed": SEED,
        "repeats": args.repeats,
        "force_cap_N": LIMITS.max_force_N[2],
        "torque_cap_Nm": LIMITS.max_torque_Nm[1],
        "summary": summary(rows),
        "cells": rows,
        **provenance(),
    }
    write_text(args.out, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    flat = [
        {
            **{k: r[k] for k in ("preset", "mu", "k_rot_Nm_rad", "k_lat_N_m", "delta0_mm")},
            **{k: r[k] for k in ("beta0_deg", "theta0_deg", "r2_class")},
            **{f"oracle_{k}_N": v for k, v in r["oracle_peak_fz_N"].items()},
            **{f"{n}_pct": r[f"{n}_pct"]["value"] for n in REDUCTIONS},
            "over_force_cap": r["over_force_cap"],
            "over_torque_cap": r["over_torque_cap"],
        }
        for r in rows
    ]
    write_rows(args.out.with_suffix(".csv"), flat)
    print(write_figure(rows, args.out.with_suffix(".png")))
    for s in doc["summary"]:
        print(s)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
