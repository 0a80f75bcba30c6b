"""Why the simulated extraction departs from the quasi-static oracle at K_theta = 3 N m/rad.

The regime sweep (``peghole experiment sweep``) agrees with the oracle at K_theta 300 and
30 N m/rad but not at 3 N m/rad. This check pulls the rect-2 case where the gap is largest
(K_theta 3 N m/rad, K_lat 300 N/m, delta0 2 mm, beta0 -0.2 deg, mu 0.266, L_C at the top of the
peg, the sweep's first two repeats) in MJX under variants that change one suspect at a time:

* ``joint damping``: the arm model's joint damping (0.5 N m s/rad per joint) is not cancelled by
  the law, so at the pull speed it adds a tool torque comparable to a 3 N m/rad spring's; the
  variant cancels it (``ExperimentConfig.compensate_joint_damping``);
* ``float64``: float32 rounding;
* ``cone fix``: MJX's elliptic-cone Newton Hessian with its clamp removed
  (:mod:`peghole_mjx.sim.mjx_fixes`), against NaN worlds;
* ``step``: 1 ms against 0.5 ms;
* ``speed``: 20 mm/s against 5 mm/s (the oracle is quasi-static: a slower pull tests whether
  the arm's dynamics decide the force);
* ``off-axis 300``: only the tilt axis (y, the planar oracle's) soft, x and z at 300 N m/rad:
  whether the peg's out-of-plane rotation (which the planar oracle leaves out) matters;
* ``law zeta 3`` / ``contact damping 3``: the law's damping ratio (1 by default) or the
  contacts' (``SimOptions.contact_dampratio``, 1) three times higher: whether the rocking is
  underdamped.

Per variant and world: the late peak F_z (first 5 mm left out) beside the oracle's, the
fraction of physics steps with both wall sides loaded inside two-point windows (>= 0.9 is the
contact-check bound), NaN, penetration, run time. Writes
``benchmarks/results/studies/low_stiffness_check.json``; a variant already in the file is
skipped (resumable), ``--only NAME`` runs one::

    python -m benchmarks.studies.low_stiffness_check   # all variants, about 40 min on a free core

The docs table ``low_stiffness_check`` is generated here.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
from tqdm import tqdm

from benchmarks.common import STUDIES_RESULTS, out_file, table
from benchmarks.studies.c_replica import EXPERIMENT
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import sweep as sw
from peghole_mjx.files.fileio import write_text
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.mjcf import SimOptions

RESULTS = STUDIES_RESULTS
PRESET = "rect-2"
CELL = dict(
    preset=PRESET,
    mu=0.266,
    k_rot_Nm_rad=3.0,
    k_lat_N_m=300.0,
    delta0_mm=2.0,
    beta0_deg=-0.2,
    theta0_deg=0.0,
)
LC_MM = 150.0  # the top of the peg: where the oracle's peak is largest
REPEATS = 2


class Variant(NamedTuple):
    """One suspect changed: the law, the solver, the precision, the step, the pull speed."""

    compensate: bool = True  # the law cancels the arm's joint damping
    cone_fix: bool = True  # MJX's elliptic-cone Hessian fixed (peghole_mjx/sim/mjx_fixes.py)
    x64: bool = False
    timestep_s: float = 0.001
    speed_m_s: float = 0.02
    off_axis_Nm_rad: float | None = None  # K_theta about x and z (None: as about y)
    law_zeta: float | None = None  # the law's damping ratio (None: GAINS)
    contact_dampratio: float = SimOptions().contact_dampratio


VARIANTS = {
    "law and MJX as in the envs (1 ms, float32, 20 mm/s)": Variant(False, False),
    "joint damping cancelled": Variant(cone_fix=False),
    "joint damping cancelled, float64": Variant(cone_fix=False, x64=True),
    "joint damping cancelled, 0.5 ms": Variant(cone_fix=False, timestep_s=0.0005),
    "joint damping cancelled, 5 mm/s": Variant(cone_fix=False, speed_m_s=0.005),
    "joint damping cancelled, cone fix": Variant(),
    "joint damping cancelled, cone fix, 5 mm/s": Variant(speed_m_s=0.005),
    "joint damping cancelled, cone fix, off-axis 300": Variant(off_axis_Nm_rad=300.0),
    "joint damping cancelled, cone fix, law zeta 3": Variant(law_zeta=3.0),
    "joint damping cancelled, cone fix, contact damping 3": Variant(contact_dampratio=3.0),
}


def run_variant(name: str) -> dict:
    """Pull the check's worlds under variant ``name``; the row written to the JSON."""
    v = VARIANTS[name]
    jax.config.update("jax_enable_x64", v.x64)  # one variant per process (see main)
    sim = dataclasses.replace(
        SimOptions(),
        timestep=v.timestep_s,
        contact_timeconst=EXPERIMENT.setup("rect").contact_timeconst_s,
        contact_dampratio=v.contact_dampratio,
    )
    cfg = cx.ExperimentConfig(
        geometry="rect",
        sim=sim,
        speed_m_s=v.speed_m_s,
        compensate_joint_damping=v.compensate,
        fix_cone_hessian=v.cone_fix,
        off_axis_rotational_stiffness_Nm_rad=v.off_axis_Nm_rad,
        damping_ratio=v.law_zeta,
    )
    table = sw.cell_table(CELL, REPEATS, 0)
    sel = np.isclose(table["L_C"], LC_MM * 1e-3)
    table = {k: a[sel] for k, a in table.items()}
    t0 = time.perf_counter()
    ex = cx.Extraction(PRESET, cfg, mu=CELL["mu"])
    res = ex.run(progress=False, table=table)
    wall = time.perf_counter() - t0
    h0 = sw.h0_mm(PRESET, cfg)
    qs = cx.quasi_static(PRESET, CELL["mu"], table, h0)
    tp = res["two_point"]
    nw = len(table["L_C"])
    both = [float(np.mean(res["both_frac"][w][tp[w]])) if tp[w].any() else None for w in range(nw)]
    return {
        "variant": name,
        "compensate_joint_damping": v.compensate,
        "fix_cone_hessian": v.cone_fix,
        "float64": v.x64,
        "timestep_s": v.timestep_s,
        "speed_m_s": v.speed_m_s,
        "off_axis_rotational_stiffness_Nm_rad": v.off_axis_Nm_rad,
        "law_damping_ratio": v.law_zeta,
        "contact_dampratio": v.contact_dampratio,
        "peak_fz_late_N": _strict(cx.peaks(res, cx.EARLY_MM["rect"])["fz"]),
        "oracle_peak_fz_late_N": cx.quasi_static_peaks(qs, h0, cx.EARLY_MM["rect"]).tolist(),
        "both_walls_frac_in_two_point": both,
        "two_point_samples": tp.sum(1).tolist(),
        "nan": res["nan"].tolist(),
        "penetration_in_hole_um": (res["penetration_in_hole_mm"] * 1e3).tolist(),
        "wall_s": wall,
    }


def _strict(a: np.ndarray) -> list[float | None]:
    """A list for strict JSON: NaN (a NaN world) as null."""
    return [None if not np.isfinite(v) else float(v) for v in a]


def main() -> int:
    """Run every variant not yet in ``--out`` (each in its own process), or ``--only`` one."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=out_file, default=RESULTS / "low_stiffness_check.json")
    ap.add_argument("--only", choices=list(VARIANTS), help="run this variant only")
    args = ap.parse_args()
    if args.only is None:  # each variant in its own process (float64 is a process-wide flag)
        for name in tqdm(list(VARIANTS), desc="low-stiffness check"):
            if name not in _rows(args.out):
                cmd = [sys.executable, "-m", "benchmarks.studies.low_stiffness_check"]
                cmd += ["--out", str(args.out), "--only", name]
                subprocess.run(cmd, check=True)
        for r in _rows(args.out).values():
            print(
                f"{r['variant']:40s} sim {np.round(np.array(r['peak_fz_late_N'], float), 3)} "
                f"oracle {np.round(r['oracle_peak_fz_late_N'], 3)} "
                f"both walls {r['both_walls_frac_in_two_point']}"
            )
        return 0
    rows = _rows(args.out)
    if args.only not in rows:
        rows[args.only] = run_variant(args.only)
        doc = {
            "cell": CELL,
            "L_C_mm": LC_MM,
            "repeats": REPEATS,
            "rows": [rows[v] for v in VARIANTS if v in rows],
            **provenance(),
        }
        write_text(args.out, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return 0


def _rows(path: Path) -> dict[str, dict]:
    old = json.loads(path.read_text()) if path.exists() else {}
    return {r["variant"]: r for r in old.get("rows", [])}


# ----------------------------------------------------------------------------- docs tables
def per_world_text(r: dict) -> tuple[str, str, str]:
    """Per-world late peak, oracle peak and both-walls fraction of a check row, as text."""
    pk = " / ".join("NaN" if v is None else f"{v:.3f}" for v in r["peak_fz_late_N"])
    orc = " / ".join(f"{v:.3f}" for v in r["oracle_peak_fz_late_N"])
    both = " / ".join("-" if v is None else f"{v:.2f}" for v in r["both_walls_frac_in_two_point"])
    return pk, orc, both


@table("low_stiffness_check")
def low_stiffness_check_table() -> str:
    """Why K_theta = 3 N m/rad departs from the oracle: one row per variant."""
    d = json.loads((RESULTS / "low_stiffness_check.json").read_text())
    c = d["cell"]
    lines = [
        f"{c['preset']}, K_theta {c['k_rot_Nm_rad']:g} N m/rad, K_lat {c['k_lat_N_m']:g} N/m, "
        f"delta0 {c['delta0_mm']:g} mm, beta0 {c['beta0_deg']:+g} deg, mu {c['mu']:g}, "
        f"L_C {d['L_C_mm']:g} mm, {d['repeats']} worlds; {d['device']}, {d['date'][:10]}.",
        "",
        "| variant | late peak F_z N (per world) | oracle N | both walls loaded in two-point "
        "windows | NaN worlds |",
        "|---|---|---|---|---|",
    ]
    for r in d["rows"]:
        pk, orc, both = per_world_text(r)
        lines.append(f"| {r['variant']} | {pk} | {orc} | {both} | {sum(r['nan'])} |")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
