"""Which friction model holds Coulomb friction at slow slides without the bounce?

The experiment and the envs relax each contact's frictional rows over 1 s
(``SimOptions.friction_timeconst``): with rows as stiff as the normal one, MuJoCo's convex
friction throws a sliding peg off the wall (docs/research/contact.md). The relaxation has a floor:
in
the thesis's tilted dual experiment (``benchmarks.studies.pull_speed --plan dual_tilt``) the
slow pull (0.5 mm/s) carries an effective friction coefficient of 0.095-0.17 instead of 0.266
under the tilt's tens of newtons, while Coulomb rows carry 0.26 but load both walls in only
80-92 % of the two-point steps (``--plan dual_tilt_coulomb``). This benchmark maps the friction
model between the two, in the MuJoCo C replica (float64, the experiment's scene and NumPy law), on
the same worlds:

- :data:`VARIANTS`: the frictional rows' time constant (1 s, the experiment's; 0.3, 0.1,
  0.03 s; as stiff as the normal row), ``impratio`` 10 (MuJoCo's documented lever against
  slip with elliptic cones; MJX-JAX has it), and MuJoCo's no-slip post-solve (10
  ``noslip_iterations``; MuJoCo C and MuJoCo Warp, not MJX-JAX);
- the worlds: the tilted dual experiment (dual-2, mu 0.266, K_lat 300 N/m, delta0 2 mm,
  beta0 0, theta0 -0.9 deg) at K_theta 100 and 30 N m/rad (where the 1 s rows fell furthest
  short), L_C at the tip and the top, the first :data:`REPEATS` of the sweep's 16 paired draws
  (seed 0), at 0.5 and 20 mm/s.

The rule that makes a variant **admissible** (:func:`admissible`) was fixed on 2026-11-29,
with the variants, before any of their results: at both speeds both wall sides loaded in
>= 90 % of the physics steps of the two-point windows (median over the worlds: issue 19's
bound); at 0.5 mm/s the effective friction coefficient within 10 % of mu (median) and the late
peak F_z within 15 % of the quasi-static oracle's in >= 80 % of the worlds (issue 19's
oracle bound); the deepest contact under 25 % of the radial clearance (25 um). Rows are
appended to ``<out>.parts.jsonl`` as each world finishes; a rerun resumes::

    python -m benchmarks.studies.friction_frontier             # 2 processes, ~25 min on 2 cores
    python -m benchmarks.studies.friction_frontier --diagnose  # one world: where the peak is from
    python -m benchmarks.studies.friction_frontier --repeats 2 --variants "Coulomb rows" \
        --out /tmp/f.json

Results: ``benchmarks/results/studies/friction_frontier.*``; the docs table
``friction_frontier`` is generated here.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import multiprocessing as mp
import time

import numpy as np
from tqdm import tqdm

from benchmarks.common import (
    STUDIES_RESULTS,
    fmt_ci,
    fmt_num,
    out_file,
    read_parts,
    run_to_parts,
    table,
)
from benchmarks.studies.c_replica import COLUMNS, ENGINE, EXPERIMENT, pull_c
from benchmarks.studies.pull_speed import (
    AT,
    cell,
    experiment_config,
    oracle_late_peaks,
    summarise,
    windows,
    world,
)
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import sweep as sw
from peghole_mjx.files.fileio import write_text
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.specs import MM

#: name -> (frictional rows' time constant s, None: as stiff as the normal row; mjOption
#: fields set on the model; which engines have the option)
VARIANTS: dict[str, tuple[float | None, dict[str, float], str]] = {
    "relaxed 1 s (the experiment's)": (1.0, {}, "C, MJX-JAX, Warp"),
    "relaxed 0.3 s": (0.3, {}, "C, MJX-JAX, Warp"),
    "relaxed 0.1 s": (0.1, {}, "C, MJX-JAX, Warp"),
    "relaxed 0.03 s": (0.03, {}, "C, MJX-JAX, Warp"),
    "Coulomb rows": (None, {}, "C, MJX-JAX, Warp"),
    "relaxed 1 s, impratio 10": (1.0, {"impratio": 10.0}, "C, MJX-JAX, Warp"),
    "Coulomb rows, impratio 10": (None, {"impratio": 10.0}, "C, MJX-JAX, Warp"),
    "relaxed 1 s, no-slip 10": (1.0, {"noslip_iterations": 10}, "C, Warp"),
    "Coulomb rows, no-slip 10": (None, {"noslip_iterations": 10}, "C, Warp"),
}
PLAN = "dual_tilt"
K_ROT = (100.0, 30.0)
SPEEDS_MM_S = (0.5, 20.0)
LCS = ("tip", "top")
#: draws per L_C: the first REPEATS of the sweep's 16 (pull_speed.REPEATS) paired draws
REPEATS = 4
TABLE_REPEATS = 16
#: the admissibility rule (fixed before any result; module docstring)
BOTH_WALLS_MIN = 0.90
MU_EFF_REL_TOL = 0.10
ORACLE_REL_TOL = 0.15
ORACLE_FRAC_MIN = 0.80
PENETRATION_BOUND_UM = 25.0


def worlds(repeats: int, seed: int = 0) -> list[tuple]:
    """(K_theta, L_C key, repeat, world, oracle late peak N) of every world of the map."""
    out = []
    for k in K_ROT:
        c = cell(k, 0.0, PLAN)
        tab = sw.cell_table(c, TABLE_REPEATS, seed)
        orc = oracle_late_peaks(c, tab)
        lcs = np.array(EXPERIMENT.setup("dual").lc_mm) * MM
        for at in LCS:
            idx = np.flatnonzero(np.isclose(tab["L_C"], lcs[AT[at]]))[:repeats]
            for r, i in enumerate(idx):
                out.append((k, at, r, world(tab, int(i)), float(orc[i])))
    return out


def _key(variant: str, k: float, v: float, at: str, r: int) -> str:
    return json.dumps([variant, k, v, at, r])


def _pull(variant: str, k: float, v: float, w: dict) -> tuple[np.ndarray, int, float]:
    """One world pulled at ``v`` mm/s with a :data:`VARIANTS` friction model (MuJoCo C)."""
    tcf, opt, _ = VARIANTS[variant]
    cfg = experiment_config("dual", v, None)
    # None: rows as stiff as the normal one (SimOptions' own meaning of None)
    sim = dataclasses.replace(cfg.sim_options(), friction_timeconst=tcf)
    cfg = dataclasses.replace(cfg, sim=sim)
    c = cell(k, 0.0, PLAN)
    return pull_c(c["preset"], c["mu"], w, v * MM, cfg, opt=opt)


def _job(args: tuple) -> dict:
    variant, k, v, at, r, w, oracle = args
    t0 = time.perf_counter()
    trace, settle, dt = _pull(variant, k, v, w)
    row = summarise(trace, settle, dt, cx.EARLY_MM["dual"])
    return {
        "key": _key(variant, k, v, at, r),
        "variant": variant,
        "k_rot_Nm_rad": k,
        "speed_mm_s": v,
        "at": at,
        "repeat": r,
        **row,
        "oracle_peak_fz_late_N": oracle,
        "wall_s": time.perf_counter() - t0,
    }


def summary(rows: list[dict], repeats: int) -> list[dict]:
    """Per (variant, K_theta, speed): the medians, the oracle agreement and the tip-vs-top
    reduction (paired over the repeats) beside the oracle's."""
    out = []
    for variant in VARIANTS:
        for k in K_ROT:
            for v in SPEEDS_MM_S:
                sel = [
                    r
                    for r in rows
                    if (r["variant"], r["k_rot_Nm_rad"], r["speed_mm_s"]) == (variant, k, v)
                ]
                if len(sel) < len(LCS) * repeats:
                    continue
                by = {(r["at"], r["repeat"]): r for r in sel}
                peak = np.array(
                    [[by[a, i]["peak_fz_late_N"] for i in range(repeats)] for a in LCS],
                    dtype=float,  # None (a NaN world) -> nan
                )
                orc = np.array(
                    [[by[a, i]["oracle_peak_fz_late_N"] for i in range(repeats)] for a in LCS]
                )
                both = [r["both_walls_frac_in_two_point"] for r in sel]
                both = [b for b in both if b is not None]
                rel = np.abs(peak / orc - 1.0)
                out.append(
                    {
                        "variant": variant,
                        "k_rot_Nm_rad": k,
                        "speed_mm_s": v,
                        "n_worlds": len(sel),
                        "mu_eff_median": float(np.median([r["mu_eff"] for r in sel])),
                        "mu_eff_min": float(np.min([r["mu_eff"] for r in sel])),
                        "both_walls_frac_median": float(np.median(both)) if both else None,
                        "peak_over_oracle_median": float(np.nanmedian(peak / orc)),
                        "oracle_within_15pct_frac": float(np.mean(rel <= ORACLE_REL_TOL)),
                        "penetration_um_max": float(max(r["penetration_um"] for r in sel)),
                        "reduction_tip_vs_top_pct": {
                            "value": sw.reduction_pct(peak[0], peak[-1]),
                            "ci95": sw.paired_bootstrap(peak[0], peak[-1]),
                            "oracle": sw.reduction_pct(orc[0], orc[-1]),
                        },
                        "wall_s_mean": float(np.mean([r["wall_s"] for r in sel])),
                        "engines": VARIANTS[variant][2],
                    }
                )
    return out


def admissible(cells: list[dict], mu: float) -> dict[str, dict]:
    """Per variant with every (K_theta, speed) cell: whether it meets the rule, and which
    conditions fail (the module docstring)."""
    out = {}
    for variant in VARIANTS:
        sel = [c for c in cells if c["variant"] == variant]
        if len(sel) < len(K_ROT) * len(SPEEDS_MM_S):
            continue
        fails = []
        for c in sel:
            tag = f"K_theta {c['k_rot_Nm_rad']:g}, {c['speed_mm_s']:g} mm/s"
            b = c["both_walls_frac_median"]
            if b is None or b < BOTH_WALLS_MIN:
                fails.append(f"both walls {b} < {BOTH_WALLS_MIN} ({tag})")
            if c["penetration_um_max"] > PENETRATION_BOUND_UM:
                fails.append(f"penetration {c['penetration_um_max']:.1f} um ({tag})")
            if c["speed_mm_s"] == min(SPEEDS_MM_S):
                if abs(c["mu_eff_median"] / mu - 1.0) > MU_EFF_REL_TOL:
                    fails.append(f"mu_eff {c['mu_eff_median']:.3f} ({tag})")
                if c["oracle_within_15pct_frac"] < ORACLE_FRAC_MIN:
                    fails.append(
                        f"oracle within 15 % in {c['oracle_within_15pct_frac']:.0%} ({tag})"
                    )
        out[variant] = {"admissible": not fails, "fails": fails}
    return out


#: the one-world diagnosis (``--diagnose``): which variants, and the world (K_theta, L_C, repeat)
DIAGNOSE_VARIANTS = ("relaxed 1 s (the experiment's)", "Coulomb rows", "relaxed 1 s, impratio 10")
DIAGNOSE_WORLD = (100.0, "top", 0)


def diagnose(variant: str, v: float = min(SPEEDS_MM_S)) -> dict:
    """Where the late peak comes from in one world (:data:`DIAGNOSE_WORLD`): the peak F_z, the
    tip depth at it, the summed normal force and effective friction coefficient over the
    20 ms windows around it (+-0.4 s) and at four instants of the pull, and the normal force
    and F_z when the pull starts (the errors ramped in, the 20 ms before)."""
    k, at, r = DIAGNOSE_WORLD
    w, oracle = next((w, o) for kk, a, rr, w, o in worlds(r + 1) if (kk, a, rr) == (k, at, r))
    trace, settle, dt = _pull(variant, k, v, w)
    col = {c: i for i, c in enumerate(COLUMNS)}
    n, w = windows(trace, dt)
    m = w.mean(1)
    fz, fn, ft = m[:, col["fz"]], m[:, col["f_normal"]], m[:, col["f_tangential"]]
    late = np.arange(len(m)) * n > settle
    i = int(np.argmax(np.where(late, fz, -np.inf)))
    win = slice(max(i - 20, 0), i + 21)
    at_frac = {
        f"{q:g}": {
            "fz_N": float(fz[j]),
            "normal_N": float(fn[j]),
            "mu": float(ft[j] / fn[j]),
            "tip_depth_mm": float(m[j, col["depth"]] / MM),
        }
        for q in (0.2, 0.4, 0.6, 0.8)
        if fn[j := int(q * len(m))] > 0
    }
    pre = slice(max(settle - n, 0), settle)  # the last 20 ms before the pull starts
    return {
        "variant": variant,
        "world": {"k_rot_Nm_rad": k, "at": at, "repeat": r},
        "normal_N_at_pull_start": float(trace[pre, col["f_normal"]].mean()),
        "fz_N_at_pull_start": float(trace[pre, col["fz"]].mean()),
        "speed_mm_s": v,
        "oracle_peak_fz_late_N": oracle,
        "peak_fz_N": float(fz[i]),
        "tip_depth_at_peak_mm": float(m[i, col["depth"]] / MM),
        "normal_N_at_peak": float(fn[i]),
        "mu_around_peak": float(ft[win].sum() / fn[win].sum()),
        "at_fraction_of_pull": at_frac,
    }


@table("friction_frontier")
def friction_frontier_table() -> str:
    """The friction models between relaxed and Coulomb rows, with the admissibility rule."""
    d = json.loads((STUDIES_RESULTS / "friction_frontier.json").read_text())
    slow, fast = min(c["speed_mm_s"] for c in d["cells"]), max(c["speed_mm_s"] for c in d["cells"])
    by = {(c["variant"], c["k_rot_Nm_rad"], c["speed_mm_s"]): c for c in d["cells"]}
    lines = [
        f"| variant | engines | K_theta N m/rad | mu_eff: {slow:g} / {fast:g} mm/s | both walls "
        f"loaded: {slow:g} / {fast:g} mm/s | late peak / oracle at {slow:g} mm/s (worlds within "
        f"15 %) | tip vs top % at {slow:g} mm/s [95 % CI] (oracle) | deepest contact um | "
        "admissible |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, v in d["variants"].items():
        for k in sorted({c["k_rot_Nm_rad"] for c in d["cells"]}, reverse=True):
            s_, f_ = by.get((name, k, slow)), by.get((name, k, fast))
            if s_ is None or f_ is None:
                continue
            red = s_["reduction_tip_vs_top_pct"]
            pen = max(s_["penetration_um_max"], f_["penetration_um_max"])
            adm = d["admissible"].get(name, {}).get("admissible")
            lines.append(
                f"| {name} | {v['engines']} | {k:g} | {s_['mu_eff_median']:.3f} / "
                f"{f_['mu_eff_median']:.3f} | {fmt_num(s_['both_walls_frac_median'], '.2f')} / "
                f"{fmt_num(f_['both_walls_frac_median'], '.2f')} | "
                f"{s_['peak_over_oracle_median']:.2f} "
                f"({s_['oracle_within_15pct_frac'] * 100:.0f} %) | "
                f"{fmt_ci(red)} ({red['oracle']:.1f}) | {pen:.1f} | {'yes' if adm else 'no'} |"
            )
    r = d["rule"]
    lines += [
        "",
        f"{d['preset']}, mu {d['mu']:g}, K_lat 300 N/m, delta0 2 mm, beta0 0, theta0 "
        f"{d['cell']['theta0_deg']:g} deg, L_C at the tip and the top, the first {d['repeats']} "
        f"paired draws of the sweep's 16 (seed 0); {d['engine'].split(';')[0]}; {d['device']}, "
        f"{d['date'][:10]}, {d['pulls_wall_s'] / 60:.0f} min of pulls (one core each). "
        f"Admissible: both walls loaded in >= {r['both_walls_min'] * 100:.0f} % of the two-point "
        f"steps at both speeds, and at {slow:g} mm/s mu_eff within "
        f"{r['mu_eff_rel_tol'] * 100:.0f} % of mu and "
        f"the late peak within {r['oracle_rel_tol'] * 100:.0f} % of the oracle in >= "
        f"{r['oracle_frac_min'] * 100:.0f} % of the worlds, the deepest contact under "
        f"{r['penetration_bound_um']:g} um (fixed {r['fixed']}).",
    ]
    return "\n".join(lines)


def main() -> int:
    """Pull every variant's worlds (resumable) and write the map, or ``--diagnose``."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=REPEATS, help="draws per L_C (<= 16)")
    ap.add_argument("--variants", default=None, help="VARIANTS names separated by ;")
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--out", type=out_file, default=STUDIES_RESULTS / "friction_frontier.json")
    ap.add_argument(
        "--diagnose",
        action="store_true",
        help="only the one-world diagnosis (DIAGNOSE_VARIANTS), into the --out JSON",
    )
    args = ap.parse_args()
    if args.diagnose:
        if not args.out.exists():
            raise SystemExit(f"{args.out} does not exist: run the map first")
        with mp.get_context("spawn").Pool(args.processes) as pool:
            rows = list(tqdm(pool.imap(diagnose, DIAGNOSE_VARIANTS), total=3, desc="diagnose"))
        doc = json.loads(args.out.read_text())
        doc["diagnosis"] = rows
        write_text(args.out, json.dumps(sw.clean_json(doc), indent=1, allow_nan=False) + "\n")
        for d in rows:
            print(json.dumps(d))
        return 0
    if not 2 <= args.repeats <= TABLE_REPEATS:
        raise SystemExit(f"--repeats must be 2..{TABLE_REPEATS} (paired intervals need two)")
    names = list(VARIANTS)
    if args.variants:
        names = [n.strip() for n in args.variants.split(";") if n.strip()]
        bad = [n for n in names if n not in VARIANTS]
        if bad or not names:
            raise SystemExit(f"unknown variant(s) {bad}; choose from {list(VARIANTS)}")
    mu = cell(K_ROT[0], 0.0, PLAN)["mu"]
    parts = args.out.with_suffix(".parts.jsonl")
    rows = read_parts(parts)
    todo = [
        (n, k, v, at, r, w, o)
        for n in names
        for v in SPEEDS_MM_S
        for k, at, r, w, o in worlds(args.repeats)
        if _key(n, k, v, at, r) not in rows
    ]
    todo.sort(key=lambda j: j[2])  # slow pulls first: the two processes finish together
    t0 = time.perf_counter()
    run_to_parts(_job, todo, parts, rows, args.processes, "friction")
    kept = [r for r in rows.values() if r["repeat"] < args.repeats]
    cells = summary(kept, args.repeats)
    old = json.loads(args.out.read_text()) if args.out.exists() else {}
    doc = {
        "preset": cell(K_ROT[0], 0.0, PLAN)["preset"],
        "mu": mu,
        "cell": {k: v for k, v in cell(K_ROT[0], 0.0, PLAN).items() if k != "k_rot_Nm_rad"},
        "engine": f"{ENGINE}; the experiment's scene and settings but the friction model",
        "variants": {
            n: {"friction_timeconst_s": t, "opt": o, "engines": e}
            for n, (t, o, e) in VARIANTS.items()
        },
        "rule": {
            "both_walls_min": BOTH_WALLS_MIN,
            "mu_eff_rel_tol": MU_EFF_REL_TOL,
            "oracle_rel_tol": ORACLE_REL_TOL,
            "oracle_frac_min": ORACLE_FRAC_MIN,
            "penetration_bound_um": PENETRATION_BOUND_UM,
            "fixed": "2026-11-29, with the variants, before any of their results",
        },
        "repeats": args.repeats,
        "cells": cells,
        "admissible": admissible(cells, mu),
        "worlds": sorted(kept, key=lambda r: r["key"]),
        "runtime_s": round(time.perf_counter() - t0, 1),
        "pulls_wall_s": round(sum(r["wall_s"] for r in kept), 1),
        **({"diagnosis": old["diagnosis"]} if "diagnosis" in old else {}),
        **provenance(),
    }
    write_text(args.out, json.dumps(sw.clean_json(doc), indent=1, allow_nan=False) + "\n")
    with args.out.with_suffix(".csv").open("w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["variant", "k_rot_Nm_rad", "speed_mm_s", "mu_eff_median",
                     "both_walls_frac_median", "peak_over_oracle_median",
                     "oracle_within_15pct_frac", "penetration_um_max",
                     "tip_vs_top_pct", "tip_vs_top_oracle_pct"])  # fmt: skip
        for c in cells:
            red = c["reduction_tip_vs_top_pct"]
            wr.writerow([c["variant"], c["k_rot_Nm_rad"], c["speed_mm_s"], c["mu_eff_median"],
                         c["both_walls_frac_median"], c["peak_over_oracle_median"],
                         c["oracle_within_15pct_frac"], c["penetration_um_max"],
                         red["value"], red["oracle"]])  # fmt: skip
    for n, a in doc["admissible"].items():
        print(f"{n}: {'admissible' if a['admissible'] else 'not: ' + '; '.join(a['fails'][:3])}")
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
