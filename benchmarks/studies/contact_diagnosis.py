"""Why a tilted rect peg chattered instead of holding two-point contact: MuJoCo C evidence.

The standard tilted case of ``peghole experiment contact-check`` (rect-2, L_C at the tip,
K_theta 300 N m/rad, delta0 2 mm, beta0 -0.2 deg, mu 0.266, 20 mm/s) is pulled in MuJoCo C,
float64, with the NumPy twin of the impedance law
(``peghole_mjx.control.reference.impedance_torque``), under
contact settings that differ one at a time:

* ``friction``: the frictional rows as stiff as the normal one (MuJoCo's default) or relaxed
  over 1 s (``solreffriction``). MuJoCo's convex friction model gives a sliding contact a
  separating normal velocity of about ``mu * v_slide``; with stiff frictional rows the pulled
  peg bounces off the walls in single-step impulses;
* ``representation``: peg box against wall boxes, or edge capsules (geometry/edges.py);
* the step size.

Per variant: the fraction of physics steps with both wall sides loaded inside the 20 ms
two-point windows, the peak per-step side force over its window mean (median and p95), the
largest penetration, and the effective friction coefficient (tangential / normal force summed
over the contacts). A second part takes one state of the MJX rollout (box representation) and
lists the contacts that MuJoCo C and MJX-JAX find from it (``--mjx``).

Writes ``benchmarks/results/studies/contact_diagnosis.json``::

    python -m benchmarks.studies.contact_diagnosis            # MuJoCo C variants (about 1 min)
    python -m benchmarks.studies.contact_diagnosis --mjx      # plus the MJX-vs-C contact comparison
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from tqdm import tqdm

from benchmarks.common import STUDIES_RESULTS, out_file
from benchmarks.studies.c_replica import pull_c
from peghole_mjx.core._mjx import mjx
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.mjcf import SimOptions

#: name -> (step s, friction time constant s or None, representation, contact time constant)
VARIANTS = {
    "box, stiff friction, 0.25 ms": (0.00025, None, "box", None),
    "box, stiff friction, 1 ms": (0.001, None, "box", None),
    "box, friction 1 s, 0.25 ms": (0.00025, 1.0, "box", None),
    "box, friction 1 s, 1 ms": (0.001, 1.0, "box", None),
    "box, friction 1 s, 2 ms": (0.002, 1.0, "box", None),
    "edges, stiff friction, 1 ms": (0.001, None, "edges", None),
    "edges, friction 1 s, 1 ms": (0.001, 1.0, "edges", None),
    "edges, friction 1 s, 1 ms, contact 10 ms": (0.001, 1.0, "edges", 0.01),
    "edges, friction 1 s, 2 ms, contact 10 ms": (0.002, 1.0, "edges", 0.01),
}


def pull(
    preset: str, dt: float, tcf: float | None, rep: str, tc: float | None, speed: float = 0.02
) -> dict[str, np.ndarray]:
    """The standard case in MuJoCo C (:func:`benchmarks.c_replica.pull_c`, the law without
    joint-damping cancellation); per physics step: tip depth, side forces, penetration,
    tangential and normal force sums."""
    sim = dataclasses.replace(
        SimOptions(), timestep=dt, friction_timeconst=tcf, contact_timeconst=tc
    )
    cfg = cx.ExperimentConfig(sim=sim, representation=rep, compensate_joint_damping=False)
    trace, settle, dt = pull_c(preset, cc.STANDARD_MU, cc.STANDARD_CASE, speed, cfg)
    return {"trace": trace[:, :6], "settle": settle, "dt": dt}


def summarise(run: dict) -> dict:
    """The contact-check metrics of one C trace (20 ms windows after the settling time)."""
    dt, tr = run["dt"], run["trace"][run["settle"] :]
    k = round(0.02 / dt)
    n = len(tr) // k * k
    w = tr[:n].reshape(-1, k, tr.shape[1])
    fp, fm = w[:, :, 1].mean(1), w[:, :, 2].mean(1)
    tp = cx.two_point_windows(fp, fm)
    both = ((w[:, :, 1] > cx.LOADED_N) & (w[:, :, 2] > cx.LOADED_N)).mean(1)
    ratio = np.maximum(
        w[:, :, 1].max(1) / np.maximum(fp, 1e-12), w[:, :, 2].max(1) / np.maximum(fm, 1e-12)
    )
    return {
        "two_point_windows": int(tp.sum()),
        "windows": len(tp),
        "both_frac": float(both[tp].mean()) if tp.any() else None,
        "peak_ratio_median": float(np.median(ratio[tp])) if tp.any() else None,
        "peak_ratio_p95": float(np.percentile(ratio[tp], 95)) if tp.any() else None,
        "penetration_um": float(tr[:, 3].max() * 1e6),
        "mu_eff": float(tr[:, 4].sum() / max(tr[:, 5].sum(), 1e-12)),
    }


def mjx_vs_c(preset: str = "rect-2", t0_s: float = 0.3, t1_s: float = 0.6) -> dict:
    """MJX-JAX and MuJoCo C contacts from the same states of an MJX rollout (box
    representation, friction relaxed over 1 s, 1 ms step), one state every 10 ms between
    ``t0_s`` and ``t1_s``: per state, the normal force that each finds on the +x and -x wall
    sides, and the count of states where C finds a loaded side that MJX misses."""
    cfg = cx.ExperimentConfig(
        sim=dataclasses.replace(SimOptions(), timestep=0.001, friction_timeconst=1.0),
        representation="box",
        chunk_steps=400,
    )
    ex = cx.Extraction(preset, cfg, mu=cc.STANDARD_MU)
    tab = {k: jnp.asarray(v) for k, v in cc.STANDARD_CASE.items()}
    carry = ex.init_world(*(tab[k] for k in cx.WORLD_KEYS))

    def advance(c, t0, n):
        return jax.lax.scan(lambda c, t: (ex.step(c, t)[0], None), c, t0 + jnp.arange(n))[0]

    first = jax.jit(functools.partial(advance, n=round(t0_s / ex.dt)))
    every = jax.jit(functools.partial(advance, n=round(0.01 / ex.dt)))
    fwd = jax.jit(mjx.forward)
    peg = ex.m.body("peg").id
    carry = first(carry, jnp.asarray(0))
    t = round(t0_s / ex.dt)
    states = []
    f6 = np.zeros(6)
    while t * ex.dt < t1_s - 1e-9:
        dx = fwd(ex.mx, carry[0])
        con = dx._impl.contact
        addr, force = np.asarray(con.efc_address), np.asarray(dx._impl.efc_force)
        sides = {"mjx": [0.0, 0.0], "c": [0.0, 0.0]}
        for i in range(len(addr)):
            if addr[i] >= 0 and float(con.dist[i]) < 0:
                own = ex.m.geom_bodyid[int(con.geom1[i])] == peg
                nx = float(con.frame[i, 0, 0]) * (1 if own else -1)
                sides["mjx"][0 if nx > 0 else 1] += float(force[addr[i]])
        d = mjx.get_data(ex.m, carry[0])
        mujoco.mj_forward(ex.m, d)
        for i in range(d.ncon):
            c = d.contact[i]
            mujoco.mj_contactForce(ex.m, d, i, f6)
            nx = c.frame[0] * (1 if ex.m.geom_bodyid[c.geom1] == peg else -1)
            sides["c"][0 if nx > 0 else 1] += float(f6[0])
        states.append({"time_s": round(t * ex.dt, 3), **sides})
        carry = every(carry, jnp.asarray(t))
        t += round(0.01 / ex.dt)
    missed = sum(
        any(s["c"][k] > cx.LOADED_N and s["mjx"][k] <= cx.LOADED_N for k in (0, 1)) for s in states
    )
    return {
        "preset": preset,
        "representation": "box",
        "states": states,
        "states_where_mjx_misses_a_side_c_loads": missed,
        "note": "side forces N as [+x, -x]; MJX: mjx.forward, C: mj_forward, same qpos/qvel/ctrl",
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="rect-2")
    ap.add_argument("--mjx", action="store_true", help="also compare MJX and C contacts")
    ap.add_argument(
        "--mjx-only",
        action="store_true",
        help="only (re)run the MJX-vs-C comparison into the existing --out file",
    )
    ap.add_argument("--out", type=out_file, default=STUDIES_RESULTS / "contact_diagnosis.json")
    args = ap.parse_args()
    if args.mjx_only:
        doc = json.loads(args.out.read_text())
        doc["mjx_vs_c_same_state"] = {**mjx_vs_c(args.preset), **provenance()}
        args.out.write_text(json.dumps(doc, indent=1))
        print(args.out)
        return 0
    rows = []
    for name, (dt, tcf, rep, tc) in tqdm(VARIANTS.items(), desc="MuJoCo C variants"):
        t0 = time.perf_counter()
        r = summarise(pull(args.preset, dt, tcf, rep, tc))
        r.update(
            variant=name,
            timestep_ms=dt * 1e3,
            friction_timeconst_s=tcf,
            representation=rep,
            contact_timeconst_s=tc,
            wall_s=time.perf_counter() - t0,
        )
        rows.append(r)
        print(json.dumps(r), flush=True)
    doc = {"preset": args.preset, "case": cc.case_dict(), "engine": "MuJoCo C, float64",
           "variants": rows, **provenance()}  # fmt: skip
    if args.mjx:
        doc["mjx_vs_c_same_state"] = mjx_vs_c(args.preset)
    args.out.write_text(json.dumps(doc, indent=1))
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
