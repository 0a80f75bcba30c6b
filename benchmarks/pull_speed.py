"""Is the compliance-centre experiment quasi-static? The regime-sweep cells pulled slower.

The quasi-static oracle has no inertia and no damping; the simulated experiment pulls at
20 mm/s through the impedance law (damping ratio 1) and MuJoCo's soft contacts. At
K_theta = 300 and 30 N m/rad the sweep agrees with the oracle; at 3 N m/rad it does not, and
the peg rocks between the walls (docs/compliance.md). The thesis does not state the pull
speed of its Ch 2-3 experiments, so this check maps the regime-sweep cells over it: per cell
(rect-2, mu 0.266, K_lat 300 N/m, delta0 2 mm, beta0 with a fixed sign) and pull speed, the
sweep's paired worlds (:func:`peghole_mjx.experiments.sweep.cell_table`: L_C at the tip / centre
/ top x repeats, the same error draws for every L_C) are pulled in **MuJoCo C, float64**, with
the NumPy twin of the impedance law (:func:`peghole_mjx.control.reference.impedance_torque`)
and the experiment's scene and settings (``ExperimentConfig``: 1 ms step, 10 ms contact time
constant, frictional rows relaxed over 1 s, edge capsules, joint damping cancelled). MuJoCo C
runs one world 5-20x faster than MJX on this CPU, which makes slow pulls affordable.

Per world: the late peak F_z (the extraction force as the sum of the contact forces on the
peg, 20 ms means, Savitzky-Golay filtered like the sweep's, the first 5 mm left out) beside the
oracle's, and the fraction of physics steps with both wall sides loaded inside two-point
windows. Per cell and speed: the tip-vs-top and tip-vs-centre reductions with paired 95 %
bootstrap intervals beside the oracle's. Rows are appended to ``--out`` as each world
finishes; a rerun skips the worlds already there (resumable)::

    python -m benchmarks.pull_speed                     # the default grid, 2 processes
    python -m benchmarks.pull_speed --speeds 20,5 --repeats 4 --out /tmp/ps.json
    python -m benchmarks.pull_speed --mjx     # MJX spot checks (float64 and float32)
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter
from tqdm import tqdm

from benchmarks.bench_common import RESULTS
from benchmarks.c_replica import COLUMNS, pull_c
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import sweep as sw
from peghole_mjx.fileio import write_text
from peghole_mjx.geometry.specs import MM
from peghole_mjx.provenance import provenance

PRESET = "rect-2"
MU = 0.266
#: (K_theta N m/rad, beta0 deg) of the cells mapped: the two K_theta = 3 N m/rad cells where
#: the sweep departs from the oracle, the K_theta = 30 N m/rad cell nearest R1 and the
#: project's default (300 N m/rad)
CELLS = ((3.0, -0.2), (3.0, 0.2), (30.0, -0.2), (300.0, -0.2))
SPEEDS_MM_S = (20.0, 2.0)
REPEATS = 16


def cell(k_rot: float, beta0: float) -> dict:
    """The regime-sweep cell (same keys as :meth:`Grid.cells`)."""
    return {
        "preset": PRESET,
        "mu": MU,
        "k_rot_Nm_rad": k_rot,
        "k_lat_N_m": 300.0,
        "delta0_mm": 2.0,
        "beta0_deg": beta0,
        "theta0_deg": 0.0,
    }


def summarise(trace: np.ndarray, settle: int, dt: float, skip_mm: float) -> dict:
    """Late peak F_z (20 ms means, Savitzky-Golay filtered, the first ``skip_mm`` of the pull
    left out), both-walls fraction inside two-point windows, penetration."""
    k = round(cx.ExperimentConfig().record_every_s / dt)
    n = len(trace) // k * k
    w = trace[:n].reshape(-1, k, trace.shape[1])
    col = {c: i for i, c in enumerate(COLUMNS)}
    mean = w.mean(1)
    fz = mean[:, col["fz"]]
    if len(fz) >= cx.SG_WINDOW:
        fz = savgol_filter(fz, cx.SG_WINDOW, cx.SG_ORDER)
    t = (np.arange(len(w)) + 1) * k * dt
    pulled_mm = (trace[0, col["depth"]] - mean[:, col["depth"]]) / MM
    late = (t > settle * dt) & (pulled_mm > skip_mm)
    tp = cx.two_point_windows(mean[:, col["f_plus"]], mean[:, col["f_minus"]]) & late
    loaded = w[:, :, [col["f_plus"], col["f_minus"]]] > cx.LOADED_N
    both = loaded.all(-1).mean(1)
    finite = bool(np.all(np.isfinite(trace)))
    return {
        "peak_fz_late_N": float(np.max(np.where(late, fz, -np.inf))) if finite else None,
        "both_walls_frac_in_two_point": float(both[tp].mean()) if tp.any() else None,
        "two_point_windows": int(tp.sum()),
        "penetration_um": float(trace[:, col["penetration"]].max() / MM * 1e3),
        "mu_eff": float(
            trace[:, col["f_tangential"]].sum() / max(trace[:, col["f_normal"]].sum(), 1e-12)
        ),
    }


def _job(args: tuple) -> dict:
    key, c, speed_mm_s, world, oracle = args
    t0 = time.perf_counter()
    trace, settle, dt = pull_c(c["preset"], c["mu"], world, speed_mm_s * MM)
    row = summarise(trace, settle, dt, cx.EARLY_MM["rect"])
    return {"key": key, **row, "oracle_peak_fz_late_N": oracle, "wall_s": time.perf_counter() - t0}


def jobs(cells: list[dict], speeds: tuple[float, ...], repeats: int, seed: int) -> list[tuple]:
    """Every world of every (cell, speed): (key, cell, speed mm/s, world, oracle late peak)."""
    cfg = cx.ExperimentConfig(geometry="rect")
    h0 = sw._h0_mm(PRESET, cfg)
    out = []
    for c in cells:
        tab = sw.cell_table(c, repeats, seed)
        qs = cx.quasi_static(c["preset"], c["mu"], tab, h0)
        orc = cx.quasi_static_peaks(qs, h0, cx.EARLY_MM["rect"])
        for v in speeds:
            for i in range(len(tab["L_C"])):
                world = {k: float(tab[k][i]) for k in cx.WORLD_KEYS}
                key = json.dumps([c["k_rot_Nm_rad"], c["beta0_deg"], v, world["L_C"], i % repeats])
                out.append((key, c, v, world, float(orc[i])))
    return out


def reductions(rows: dict[str, dict], c: dict, v: float, repeats: int) -> dict | None:
    """Paired reductions of one (cell, speed) from its finished worlds (None if incomplete)."""
    lcs = np.array(cx.LC_MM["rect"]) * MM
    sim = np.full((3, repeats), np.nan)
    orc = np.full((3, repeats), np.nan)
    both = []
    for j, lc in enumerate(lcs):
        for r in range(repeats):
            key = json.dumps([c["k_rot_Nm_rad"], c["beta0_deg"], v, float(lc), r])
            if key not in rows:
                return None
            p = rows[key]["peak_fz_late_N"]
            sim[j, r] = np.nan if p is None else p
            orc[j, r] = rows[key]["oracle_peak_fz_late_N"]
            if rows[key]["both_walls_frac_in_two_point"] is not None:
                both.append(rows[key]["both_walls_frac_in_two_point"])
    ok = np.all(np.isfinite(sim), axis=0)
    tip, centre, top = sim[0, ok], sim[1, ok], sim[2, ok]
    out = {
        "k_rot_Nm_rad": c["k_rot_Nm_rad"],
        "beta0_deg": c["beta0_deg"],
        "speed_mm_s": v,
        "n_repeats": int(ok.sum()),
        "peak_fz_N": dict(zip(("tip", "centre", "top"), np.nanmean(sim, 1).tolist(), strict=True)),
        "oracle_peak_fz_N": dict(zip(("tip", "centre", "top"), orc.mean(1).tolist(), strict=True)),
        "both_walls_frac_median": float(np.median(both)) if both else None,
    }
    for name, ref, oref in (("top", top, orc[2]), ("centre", centre, orc[1])):
        out[f"reduction_tip_vs_{name}_pct"] = {
            "value": sw.reduction_pct(tip, ref),
            "ci95": sw.paired_bootstrap(tip, ref),
            "oracle": sw.reduction_pct(orc[0], oref),
        }
    return out


#: MJX spot checks (K_theta, beta0, speed mm/s, precision): the sweep's first two repeats at
#: L_C = top, to show that MJX agrees with the MuJoCo C replica
MJX_CHECKS = (
    (3.0, -0.2, 20.0, "float64"),
    (3.0, -0.2, 2.0, "float64"),
    (3.0, -0.2, 2.0, "float32"),
    (30.0, -0.2, 20.0, "float64"),
    (30.0, -0.2, 2.0, "float64"),
)
MJX_REPEATS = 2


def mjx_check(k_rot: float, beta0: float, speed_mm_s: float, precision: str) -> dict:
    """The experiment itself (:class:`~peghole_mjx.experiments.compliance.Extraction`, MJX)
    on the first :data:`MJX_REPEATS` worlds of the cell at L_C = top. Run it in a fresh
    process: float64 is a process-wide JAX flag."""
    import jax

    jax.config.update("jax_enable_x64", precision == "float64")
    c = cell(k_rot, beta0)
    cfg = cx.ExperimentConfig(geometry="rect", speed_m_s=speed_mm_s * MM)
    tab = sw.cell_table(c, MJX_REPEATS, 0)
    sel = np.isclose(tab["L_C"], cx.LC_MM["rect"][-1] * MM)
    tab = {k: v[sel] for k, v in tab.items()}
    t0 = time.perf_counter()
    res = cx.Extraction(PRESET, cfg, mu=MU).run(progress=False, table=tab)
    h0 = sw._h0_mm(PRESET, cfg)
    qs = cx.quasi_static(PRESET, MU, tab, h0)
    tp = res["two_point"]
    return {
        "k_rot_Nm_rad": k_rot,
        "beta0_deg": beta0,
        "speed_mm_s": speed_mm_s,
        "precision": precision,
        "L_C_mm": cx.LC_MM["rect"][-1],
        "peak_fz_late_N": cx.peaks(res, cx.EARLY_MM["rect"])["fz"].tolist(),
        "oracle_peak_fz_late_N": cx.quasi_static_peaks(qs, h0, cx.EARLY_MM["rect"]).tolist(),
        "both_walls_frac_in_two_point": [
            float(np.mean(res["both_frac"][w][tp[w]])) if tp[w].any() else None
            for w in range(len(tp))
        ],
        "nan": res["nan"].tolist(),
        "wall_s": time.perf_counter() - t0,
    }


def run_mjx_checks(out: Path) -> None:
    """Every :data:`MJX_CHECKS` row not yet in ``out``, each in its own process."""
    import subprocess
    import sys

    for chk in tqdm(MJX_CHECKS, desc="MJX checks"):
        doc = json.loads(out.read_text()) if out.exists() else {"rows": []}
        have = {tuple(r[k] for k in ("k_rot_Nm_rad", "beta0_deg", "speed_mm_s", "precision"))
                for r in doc["rows"]}  # fmt: skip
        if chk in have:
            continue
        arg = ",".join(str(x) for x in chk)
        cmd = [sys.executable, "-m", "benchmarks.pull_speed", "--mjx-one", arg, "--out", str(out)]
        subprocess.run(cmd, check=True)


def _mjx_one(arg: str, out: Path) -> None:
    k, b, v, prec = arg.split(",")
    row = mjx_check(float(k), float(b), float(v), prec)
    doc = json.loads(out.read_text()) if out.exists() else {"rows": []}
    doc["rows"].append(row)
    doc.update(engine="MJX-JAX (the experiment), first two repeats at L_C = top", **provenance())
    write_text(out, json.dumps(sw.clean_json(doc), indent=1, allow_nan=False) + "\n")
    print(json.dumps(row))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speeds", default=",".join(f"{v:g}" for v in SPEEDS_MM_S), help="mm/s")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS / "pull_speed_rect.json")
    ap.add_argument(
        "--mjx", action="store_true", help="run the MJX spot checks (into <out>_mjx.json) only"
    )
    ap.add_argument("--mjx-one", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.mjx_one:
        _mjx_one(args.mjx_one, args.out)
        return 0
    if args.mjx:
        run_mjx_checks(args.out.with_name(args.out.stem + "_mjx.json"))
        return 0
    speeds = tuple(float(s) for s in args.speeds.split(",") if s.strip())
    if not speeds or any(v <= 0 for v in speeds):
        raise SystemExit("--speeds must be positive mm/s values")
    if args.repeats < 2:
        raise SystemExit("--repeats must be >= 2 (intervals need two draws)")
    cells = [cell(k, b) for k, b in CELLS]
    parts = args.out.with_suffix(".parts.jsonl")
    rows = {}
    if parts.exists():
        for line in parts.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                rows[r["key"]] = r
    todo = [j for j in jobs(cells, speeds, args.repeats, args.seed) if j[0] not in rows]
    # slow pulls first: the longest jobs start early and the two processes finish together
    todo.sort(key=lambda j: j[2])
    t0 = time.perf_counter()
    with mp.get_context("spawn").Pool(args.processes) as pool, parts.open("a") as f:
        for r in tqdm(pool.imap_unordered(_job, todo), total=len(todo), desc="pull speed"):
            rows[r["key"]] = r
            f.write(json.dumps(r) + "\n")
            f.flush()
    summary = [
        s for c in cells for v in speeds if (s := reductions(rows, c, v, args.repeats)) is not None
    ]
    doc = {
        "preset": PRESET,
        "mu": MU,
        "engine": "MuJoCo C, float64, NumPy impedance law; the experiment's scene and settings",
        "settings": {
            "experiment": cx.config_dict(cx.ExperimentConfig(geometry="rect")),
            "repeats": args.repeats,
            "seed": args.seed,
            "skip_mm": cx.EARLY_MM["rect"],
        },
        "cells": summary,
        "worlds": sorted(rows.values(), key=lambda r: r["key"]),
        "runtime_s": round(time.perf_counter() - t0, 1),
        **provenance(),
    }
    write_text(args.out, json.dumps(sw.clean_json(doc), indent=1, allow_nan=False) + "\n")
    for s in summary:
        top = s["reduction_tip_vs_top_pct"]
        print(
            f"K_theta {s['k_rot_Nm_rad']:g} beta0 {s['beta0_deg']:+g} {s['speed_mm_s']:g} mm/s: "
            f"tip vs top {top['value']:.1f} % {top['ci95']} (oracle {top['oracle']:.1f}), "
            f"both walls {s['both_walls_frac_median']}"
        )
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
