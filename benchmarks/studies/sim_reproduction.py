"""Do the committed MuJoCo C experiment results reproduce on the sim layer's engine?

Since 2026-12-06 the compliance experiment's ``mujoco`` engine steps its worlds on the sim
layer's :class:`peghole_mjx.sim.engine_mujoco.MujocoEngine` (one ``mujoco.batch`` of all
worlds, the engine's analytic Jacobian of C, its law with the passive forces cancelled, no
MuJoCo auto-reset) instead of its own per-world ``MjData`` loop (``mj_jac``, one world at a
time, auto-reset on). The same law, scene, schedule and contact rule: the float64 operations
differ in order only. This study reruns worlds of the committed pull-speed results
(``benchmarks/results/studies/pull_speed_<plan>.json``, written by the per-world loop) through
the study's own row function (:func:`benchmarks.studies.pull_speed.world_row`) and compares every
stored figure.

The rule, fixed 2026-12-06 before the run: a world **reproduces** when its late peak F_z is
within 1 % (relative) or 0.005 N (absolute) of the committed value, its deepest penetration
within 0.1 um, its effective friction coefficient within 0.002 and its count of late
two-point windows within 2. The worlds: the first :data:`REPEATS` of the 16 paired draws of
every cell of each plan in :data:`PLANS`, at the plan's 20 mm/s pull (the slow pulls take
50-100 s a world on the 2-core CPU and are not rerun)::

    python -m benchmarks.studies.sim_reproduction            # ~10 min on 2 cores
    python -m benchmarks.studies.sim_reproduction --repeats 1 --plans dual --out /tmp/r.json

Results: ``benchmarks/results/studies/sim_reproduction.json`` / ``.csv``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from tqdm import tqdm

from benchmarks.common import STUDIES_RESULTS, out_file, write_rows
from benchmarks.studies import pull_speed as ps
from peghole_mjx.files.provenance import commit, provenance

#: the plans whose committed rows are rerun (their results file: ``pull_speed_<plan>.json``)
PLANS = ("rect", "dual", "dual_tilt", "dual_tilt_mu001")
#: the first draws of each cell rerun
REPEATS = 4
#: the pull speed rerun, mm/s
SPEED_MM_S = 20.0
#: the reproduction rule (module docstring)
PEAK_REL, PEAK_ABS_N, PEN_UM, MU_EFF, TWO_POINT = 0.01, 0.005, 0.1, 0.002, 2
FIELDS = ("peak_fz_late_N", "penetration_um", "mu_eff", "two_point_windows")


def committed(plan: str) -> dict[str, dict]:
    """The committed world rows of a plan, by key."""
    path = STUDIES_RESULTS / f"pull_speed_{plan}.json"
    return {w["key"]: w for w in json.loads(path.read_text())["worlds"]}


def todo(plan: str, repeats: int) -> list[tuple]:
    """The study's jobs of ``plan`` at :data:`SPEED_MM_S` for the first ``repeats`` draws."""
    p = ps.PLANS[plan]
    cells = [ps.cell(k, b, plan) for k, b in p.cells]
    jobs = ps.jobs(cells, (SPEED_MM_S,), ps.REPEATS, 0, p.coulomb_rows)
    return [j for j in jobs if json.loads(j[0])[-1] < repeats]


def compare(new: dict, old: dict) -> dict:
    """The differences of one world's row and whether it reproduces (the module's rule)."""
    pn, po = new["peak_fz_late_N"], old["peak_fz_late_N"]
    d_peak = None if pn is None or po is None else pn - po
    ok_peak = (pn is None) == (po is None) and (
        d_peak is None or abs(d_peak) <= max(PEAK_ABS_N, PEAK_REL * abs(po))
    )
    d_pen = new["penetration_um"] - old["penetration_um"]
    d_mu = new["mu_eff"] - old["mu_eff"]
    d_tp = new["two_point_windows"] - old["two_point_windows"]
    ok = ok_peak and abs(d_pen) <= PEN_UM and abs(d_mu) <= MU_EFF and abs(d_tp) <= TWO_POINT
    return {
        "d_peak_fz_late_N": d_peak,
        "d_penetration_um": d_pen,
        "d_mu_eff": d_mu,
        "d_two_point_windows": d_tp,
        "reproduced": bool(ok),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", nargs="+", choices=PLANS, default=list(PLANS))
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--out", type=out_file, default=STUDIES_RESULTS / "sim_reproduction.json")
    args = ap.parse_args(argv)
    source = commit()  # before any work: the tree the run's code came from
    rows = []
    jobs = [(plan, j) for plan in args.plans for j in todo(plan, args.repeats)]
    old = {plan: committed(plan) for plan in args.plans}
    t0 = time.perf_counter()
    for plan, job in tqdm(jobs, desc="worlds", unit="world"):
        new = ps.world_row(job)
        ref = old[plan][job[0]]
        rows.append(
            {
                "plan": plan,
                "key": job[0],
                **{f"new_{k}": new[k] for k in FIELDS},
                **{f"committed_{k}": ref[k] for k in FIELDS},
                **compare(new, ref),
                "wall_s": new["wall_s"],
                "committed_wall_s": ref["wall_s"],
            }
        )
    n_ok = sum(r["reproduced"] for r in rows)
    peaks = [abs(r["d_peak_fz_late_N"]) for r in rows if r["d_peak_fz_late_N"] is not None]
    summary = {
        "worlds": len(rows),
        "reproduced": n_ok,
        "max_abs_d_peak_fz_late_N": max(peaks, default=None),
        "max_abs_d_penetration_um": max((abs(r["d_penetration_um"]) for r in rows), default=None),
        "max_abs_d_mu_eff": max((abs(r["d_mu_eff"]) for r in rows), default=None),
        "max_abs_d_two_point_windows": max(
            (abs(r["d_two_point_windows"]) for r in rows), default=None
        ),
        "outside_the_rule": [f"{r['plan']} {r['key']}" for r in rows if not r["reproduced"]],
        "wall_s_new": sum(r["wall_s"] for r in rows),
        "wall_s_committed": sum(r["committed_wall_s"] for r in rows),
    }
    doc = {
        "study": "sim_reproduction",
        "rule": {
            "peak_rel": PEAK_REL,
            "peak_abs_N": PEAK_ABS_N,
            "penetration_um": PEN_UM,
            "mu_eff": MU_EFF,
            "two_point_windows": TWO_POINT,
            "fixed": "2026-12-06, before the run",
        },
        "config": {
            "plans": args.plans,
            "repeats": args.repeats,
            "speed_mm_s": SPEED_MM_S,
            "study_repeats": ps.REPEATS,
            "seed": 0,
        },
        "engine": ps.ENGINE + "; stepped by the sim layer's MujocoEngine (mujoco.batch)",
        "committed_engine": "the experiment's per-world MjData loop (mj_jac, auto-reset on)",
        "summary": summary,
        "runtime_s": time.perf_counter() - t0,
        "command": "python -m benchmarks.studies.sim_reproduction " + " ".join(sys.argv[1:]),
        **provenance(),
        "commit": source,
        "rows": rows,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=2) + "\n")
    write_rows(out.with_suffix(".csv"), rows)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
