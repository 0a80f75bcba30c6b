"""Fidelity of the capsule representation of the dual parts against the exact mesh one.

``baseline``: the DualExtract scripted baseline (straight pull at 20 mm/s, the fixed stiffness)
in the env of the published dual policy (``peghole_mjx/policies/dual_extract/policy.json``:
200-step episodes, 25 mm/s pull limit, ...), on the capsule scene, ``--episodes`` episodes with
seed 0 in slices of 256 (the episodes' start states are those of the committed mesh-scene
evaluation: JAX's partitionable threefry keys are prefix-stable). It is compared with the mesh
scene's committed per-episode records of the same episodes
(``benchmarks/results/evals/dual_ffdeploy_cpu-2core/episodes1024.csv``, baseline columns):
success (Wilson 95 % interval), mean and peak |F_z| per episode (mean with a 95 % normal
interval), and the paired per-episode differences (mean, 95 % interval).

``jam``: the jammed (two-point) dual configuration of the quasi-static analysis (dual-2, the
analytic studies' compliance: K_x = 0.4 N/mm, K_theta = 300 N m/rad, delta0 = 2 mm at the
compliance centre, theta0 = -0.9 deg, L_C at the tip; friction 0.01): peg 2 touches the mouth
corner of hole 2 on one side and the wall of hole 2 with its opposite tip edge, about 90 N
each, 16-46 mm deep (``analysis.dual.oracle_body(spec, None, L_C)``, all eight candidate
contacts; ``analysis.oracle.solve``). The simulated counterpart (MuJoCo C, the capsule and the
mesh scene of ``build_scene(robot=False)``): the peg moves in the oracle's x-z plane only (a
slide along x, a slide along z, a hinge about y instead of the free joint), no gravity, the
compliance springs at the compliance centre applied as a body wrench every step, the depth
prescribed by a stiff z servo pulling out at 2 mm/s from 48 mm (timestep 0.1 ms for the
explicit 300 N m/rad spring; joint damping for quasi-static motion; Coulomb frictional rows,
MuJoCo C's multi-point CCD off as in every scene). At each compared depth
the contact normal forces are summed per oracle contact (peg, mouth or tip, side) and the
extraction force F_z read from the constraint force on the z slide; each is compared with the
oracle's lambda and F_z (relative difference). ``jam_envs_friction``: the same with the envs'
relaxed frictional rows (``SimOptions.friction_timeconst``).

Run ``python -m benchmarks.studies.capsule_fidelity baseline`` (about 5 minutes on 2 CPU cores)
and ``python -m benchmarks.studies.capsule_fidelity jam`` (``jam_envs_friction``, ``jam_mjx``,
``profile``); each writes its part of ``benchmarks/results/studies/capsule_fidelity.json``.
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import math
import sys
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from benchmarks.common import EVALS_RESULTS, ROOT, STUDIES_RESULTS, wilson
from peghole_mjx.analysis import dual, oracle
from peghole_mjx.core._mjx import mjx
from peghole_mjx.envs import load
from peghole_mjx.envs.rollout import episode_keys, rollout, scripted_policy
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.mjcf import SimOptions, block_top_z, build_scene
from peghole_mjx.geometry.parts import peg_tip_z_m
from peghole_mjx.geometry.specs import MM, PRESETS
from peghole_mjx.policies import load_policy

MESH_EPISODES = EVALS_RESULTS / "dual_ffdeploy_cpu-2core" / "episodes1024.csv"
#: pull speeds of ``jam_envs_friction`` (mm/s): the jam's own, and the scripted method's 20
ENVS_FRICTION_SPEEDS_MM_S = (2.0, 5.0, 20.0)
OUT = STUDIES_RESULTS / "capsule_fidelity.json"
METRICS = ("mean_fz_N", "peak_fz_N", "extraction_time_s")


def mean_ci(x: np.ndarray, z: float = 1.96) -> dict:
    x = np.asarray(x, float)
    m, se = float(x.mean()), float(x.std(ddof=1) / math.sqrt(len(x)))
    return {"mean": round(m, 5), "ci95": [round(m - z * se, 5), round(m + z * se, 5)], "n": len(x)}


def summarise(ep: dict[str, np.ndarray]) -> dict:
    ok = ep["success"] > 0
    out = {
        "episodes": len(ok),
        "success_rate": round(float(ok.mean()), 4),
        "success_ci95": wilson(int(ok.sum()), len(ok)),
    }
    for k in METRICS:
        vals = ep[k][ok] if k == "extraction_time_s" else ep[k]
        out[k] = mean_ci(vals)
    return out


def mesh_records(n: int) -> dict[str, np.ndarray]:
    with MESH_EPISODES.open() as f:
        rows = list(csv.DictReader(f))[:n]
    cols = ("success", *METRICS)
    return {c: np.array([float(r[f"baseline_{c}"]) for r in rows]) for c in cols}


def baseline(episodes: int, batch: int) -> dict:
    """Scripted baseline on the capsule scene vs the committed mesh-scene episodes."""
    bundle = load_policy("dual")
    over = {**bundle.env_overrides, "representation": "capsule"}

    env = load(bundle.env_name, config_overrides=over)
    t0 = time.perf_counter()
    res = rollout(env, scripted_policy(env), episodes, seed=0, batch=batch, progress=True)
    wall = time.perf_counter() - t0
    cap = {c: np.asarray(res.per_episode[c], float) for c in ("success", *METRICS)}
    mesh = mesh_records(episodes)
    both_ok = (cap["success"] > 0) & (mesh["success"] > 0)
    paired = {}
    for k in METRICS:
        sel = both_ok if k == "extraction_time_s" else np.ones_like(both_ok)
        paired[k] = mean_ci(cap[k][sel] - mesh[k][sel])
    s_cap, s_mesh = summarise(cap), summarise(mesh)

    def overlap(a, b):
        return a[0] <= b[1] and b[0] <= a[1]

    agree = {
        "success": overlap(s_cap["success_ci95"], s_mesh["success_ci95"]),
        **{k: overlap(s_cap[k]["ci95"], s_mesh[k]["ci95"]) for k in METRICS},
    }
    return {
        "env": bundle.env_name,
        "env_overrides": over,
        "seed": 0,
        "batch": batch,
        "capsule": s_cap,
        "mesh": s_mesh,
        "mesh_source": str(MESH_EPISODES.relative_to(ROOT)) + " (baseline columns)",
        "paired_difference_capsule_minus_mesh": paired,
        "intervals_overlap": agree,
        "capsule_nan_worlds": int((res.per_episode["nan"] > 0).sum()),
        "capsule_rollout_wall_s": round(wall, 1),
        "capsule_compile_s": round(res.compile_s, 1),
        "capsule_physics_steps_per_s": round(res.physics_steps_per_s, 1),
    }


#: the compared depths of the tip line below the mouth, mm (inside the oracle's two-point region)
JAM_DEPTHS_MM = (20.0, 25.0, 30.0, 35.0, 40.0)


def _planar_model(
    spec, rep: str, h0_mm: float, timestep: float, friction_timeconst: float | None = None
):
    """The free-peg scene with the peg in the x-z plane: slide x, slide z, hinge y.

    ``friction_timeconst``: the frictional rows' time constant (s; None: Coulomb rows as stiff
    as the normal one, MuJoCo's default). MuJoCo C's multi-point CCD is off, as in every scene
    (``geometry.mjcf._set_options``): with it on, C's mesh-mesh contact at the mouth edge reads
    F_z 37-105 % above the oracle; off, +3 to +4 % (2026-11-29)."""
    sim = SimOptions(timestep, friction_timeconst=friction_timeconst)
    s = build_scene(spec, robot=False, representation=rep, contact_cap=0, sim=sim)
    s.delete(s.joint("peg_free"))
    s.delete(s.key("mouth"))
    s.option.gravity = [0.0, 0.0, 0.0]
    peg = s.body("peg")
    tip = peg_tip_z_m(spec)
    peg.pos = [peg.pos[0], peg.pos[1], block_top_z(spec) - h0_mm * MM + tip]
    # body frame: x = world -x, z = world -z (half turn about y); axes given in the body frame
    slide = mujoco.mjtJoint.mjJNT_SLIDE
    peg.add_joint(name="x", type=slide, axis=[-1, 0, 0], damping=40.0)
    peg.add_joint(name="z", type=slide, axis=[0, 0, 1], damping=200.0)
    peg.add_joint(name="ry", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0], damping=0.5)
    s.add_actuator(
        name="z_servo",
        target="z",
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        gainprm=[2e5] + [0] * 9,
        biasprm=[0, -2e5, -2e3] + [0] * 7,
    )
    m = s.compile()
    m.opt.ccd_tolerance = 1e-10
    return m


def jam(
    speed_mm_s: float = 2.0,
    h0_mm: float = 48.0,
    timestep: float = 1e-4,
    settle_s: float = 0.3,
    friction_timeconst: float | None = None,
) -> dict:
    """Contact forces of the jammed dual configuration: capsule and mesh vs the oracle
    (``friction_timeconst``: see :func:`_planar_model`)."""
    spec = PRESETS["dual-2"]
    L_C = 0.0
    kw = dict(dual.DEFAULTS)
    body, _ = dual.oracle_body(spec, None, L_C, **kw)
    sol = oracle.solve(body, np.asarray(JAM_DEPTHS_MM))
    K_x = kw["K_x_N_per_mm"] / MM  # N/m
    K_th = kw["K_theta_Nmm_per_rad"] * MM  # N m/rad
    x_m, th_m = (
        float(v)
        for v in dual.common.rest_pose(L_C, kw["delta0_mm"], kw["beta0_rad"], kw["theta0_rad"])
    )
    out: dict = {
        "preset": "dual-2",
        "compliance": {**{k: float(v) for k, v in kw.items()}, "L_C_mm": L_C},
        "oracle": {
            f"{h:g}": {
                "contacts_N": {
                    sol.names[k]: round(float(sol.lam[i, k]), 3)
                    for k in np.flatnonzero(sol.active[i])
                },
                "F_z_N": round(float(sol.F_z[i]), 4),
                "theta_deg": round(float(np.degrees(sol.theta[i])), 4),
            }
            for i, h in enumerate(JAM_DEPTHS_MM)
        },
        "harness": {
            "timestep_s": timestep,
            "pull_speed_mm_s": speed_mm_s,
            "start_depth_mm": h0_mm,
            "settle_s": settle_s,
            "friction_timeconst_s": friction_timeconst,
        },
    }
    names = sol.names
    for rep in ("capsule", "mesh"):
        m = _planar_model(spec, rep, h0_mm, timestep, friction_timeconst)
        ccd = not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_MULTICCD
        out["harness"]["multiccd"] = bool(ccd)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        peg, tip_site = m.body("peg").id, m.site("peg_tip").id
        mouth = d.site("hole_mouth").xpos.copy()
        zdof = m.joint("z").dofadr[0]
        peg_geoms = {m.geom(f"peg{i}").id: i for i in (1, 2)}
        f6 = np.zeros(6)
        targets = sorted(JAM_DEPTHS_MM, reverse=True)
        t_pull0 = settle_s
        n_steps = int((settle_s + (h0_mm - min(targets) + 0.5) / speed_mm_s) / timestep)
        window: dict[str, list] = {}
        t0 = time.perf_counter()
        for _ in range(n_steps):
            t = d.time
            pulled = max(0.0, t - t_pull0) * speed_mm_s * MM
            d.ctrl[0] = -pulled  # joint z (body z = world -z): negative = out of the hole
            # compliance springs at C (L_C above the tip line's middle), oracle's sign convention
            R = d.xmat[peg].reshape(3, 3)
            up = -R[:, 2]
            tip = d.site_xpos[tip_site]
            th = math.atan2(-up[0], up[2])
            C = tip + L_C * MM * up
            x_C = (C[0] - mouth[0]) / MM
            Fx = -K_x * (x_C - x_m) * MM
            M_or = -K_th * (th - th_m)  # N m, oracle's rotation sense = about world -y
            F = np.array([Fx, 0.0, 0.0])
            torque = np.array([0.0, -M_or, 0.0]) + np.cross(C - d.xipos[peg], F)
            d.xfrc_applied[peg, :3] = F
            d.xfrc_applied[peg, 3:] = torque
            mujoco.mj_step(m, d)
            depth = (mouth[2] - d.site_xpos[tip_site][2]) / MM
            # record within 0.25 mm of each compared depth (averaged)
            for h in targets:
                if abs(depth - h) < 0.25 and d.time > settle_s:
                    sums = {n: 0.0 for n in names}
                    for i in range(d.ncon):
                        c = d.contact[i]
                        pg = peg_geoms.get(c.geom1) or peg_geoms.get(c.geom2)
                        if pg is None:
                            continue
                        mujoco.mj_contactForce(m, d, i, f6)
                        cx = c.pos[0] - mouth[0]
                        cz = c.pos[2] - mouth[2]
                        side_px = (cx - (-20.0 if pg == 1 else 20.0) * MM) > 0
                        if cz > -2 * MM:  # a hole's mouth corner on the peg's side
                            key = f"H{pg}{'R' if side_px else 'L'}-corner/P{pg}"
                        else:  # the peg's tip edge on the hole's wall
                            key = f"P{pg}{'R' if side_px else 'L'}-tip/H{pg}"
                        sums[key] += abs(f6[0])
                    window.setdefault(f"{h:g}", []).append(
                        (sums, float(d.qfrc_constraint[zdof]), math.degrees(th))
                    )
        wall = time.perf_counter() - t0
        res = {}
        for h in JAM_DEPTHS_MM:
            w = window.get(f"{h:g}", [])
            if not w:
                res[f"{h:g}"] = None
                continue
            sums = {n: float(np.mean([s[n] for s, _, _ in w])) for n in names}
            res[f"{h:g}"] = {
                "contacts_N": {n: round(v, 3) for n, v in sums.items() if v > 0.05},
                "F_z_N": round(float(np.mean([fz for _, fz, _ in w])), 4),
                # chatter: the spread of the extraction force over the 0.5 mm window, and of
                # the summed normal forces
                "F_z_std_N": round(float(np.std([fz for _, fz, _ in w])), 4),
                "normal_sum_std_N": round(float(np.std([sum(s.values()) for s, _, _ in w])), 4),
                "theta_deg": round(float(np.mean([a for _, _, a in w])), 4),
                "samples": len(w),
            }
        out[rep] = res
        out[f"{rep}_wall_s"] = round(wall, 1)
    # relative differences of the oracle's active contacts and F_z
    comp = {}
    for h in JAM_DEPTHS_MM:
        key = f"{h:g}"
        orc = out["oracle"][key]
        row = {}
        for rep in ("capsule", "mesh"):
            sim = out[rep].get(key)
            if sim is None:
                continue
            row[rep] = {
                n: round(sim["contacts_N"].get(n, 0.0) / lam - 1, 4)
                for n, lam in orc["contacts_N"].items()
            }
            row[rep]["F_z"] = round(sim["F_z_N"] / orc["F_z_N"] - 1, 4)
        if "capsule" in row and "mesh" in row:
            row["capsule_vs_mesh"] = {
                n: round(
                    out["capsule"][key]["contacts_N"].get(n, 0.0)
                    / max(out["mesh"][key]["contacts_N"].get(n, 0.0), 1e-9)
                    - 1,
                    4,
                )
                for n in orc["contacts_N"]
            }
        comp[key] = row
    out["relative_difference"] = comp
    worst = [
        abs(v)
        for row in comp.values()
        for rep in ("capsule", "mesh")
        for n, v in row.get(rep, {}).items()
        if n != "F_z"
    ]
    out["max_abs_relative_difference_contact_forces"] = round(max(worst), 4) if worst else None
    out["within_10_pct"] = bool(worst) and max(worst) <= 0.10
    return out


def jam_mjx(
    speed_mm_s: float = 10.0,
    h0_mm: float = 42.0,
    timestep: float = 1e-4,
    reps: tuple[str, ...] = ("capsule", "mesh"),
) -> dict:
    """The jam of :func:`jam` in MJX-JAX (one world, a jitted scan): the extraction force F_z
    (constraint force on the z slide) and the tilt at the compared depths, capsule and mesh,
    vs the oracle. (MJX's per-contact forces are not read here: F_z and the tilt carry the
    normal forces' balance.)"""
    spec = PRESETS["dual-2"]
    L_C = 0.0
    kw = dict(dual.DEFAULTS)
    body, _ = dual.oracle_body(spec, None, L_C, **kw)
    depths = [h for h in JAM_DEPTHS_MM if h < h0_mm - 1]
    sol = oracle.solve(body, np.asarray(depths))
    K_x, K_th = kw["K_x_N_per_mm"] / MM, kw["K_theta_Nmm_per_rad"] * MM
    x_m, th_m = (
        float(v)
        for v in dual.common.rest_pose(L_C, kw["delta0_mm"], kw["beta0_rad"], kw["theta0_rad"])
    )
    out: dict = {
        "engine": "mjx-jax (CPU)",
        "harness": {
            "timestep_s": timestep,
            "pull_speed_mm_s": speed_mm_s,
            "start_depth_mm": h0_mm,
            "friction_timeconst_s": None,
        },
        "oracle": {
            f"{h:g}": {
                "F_z_N": round(float(sol.F_z[i]), 4),
                "theta_deg": round(float(np.degrees(sol.theta[i])), 4),
            }
            for i, h in enumerate(depths)
        },
    }
    settle = 0.3
    n = int((settle + (h0_mm - min(depths) + 0.5) / speed_mm_s) / timestep)
    for rep in reps:
        m = _planar_model(spec, rep, h0_mm, timestep)
        d0 = mujoco.MjData(m)
        mujoco.mj_forward(m, d0)
        mouth = jnp.asarray(d0.site("hole_mouth").xpos)
        peg, tip_site, zdof = m.body("peg").id, m.site("peg_tip").id, int(m.joint("z").dofadr[0])
        mx = mjx.put_model(m, impl="jax")
        dx = mjx.put_data(m, d0, impl="jax")

        def step(d, _, mx=mx, mouth=mouth, peg=peg, tip_site=tip_site, zdof=zdof):
            pulled = jnp.maximum(0.0, d.time - settle) * speed_mm_s * MM
            R = d.xmat[peg]
            up = -R[:, 2]
            tip = d.site_xpos[tip_site]
            th = jnp.arctan2(-up[0], up[2])
            C = tip + L_C * MM * up
            Fx = -K_x * ((C[0] - mouth[0]) / MM - x_m) * MM
            F = jnp.array([Fx, 0.0, 0.0])
            torque = jnp.array([0.0, K_th * (th - th_m), 0.0]) + jnp.cross(C - d.xipos[peg], F)
            xfrc = d.xfrc_applied.at[peg].set(jnp.concatenate([F, torque]))
            d = mjx.step(mx, d.replace(ctrl=jnp.array([-pulled]), xfrc_applied=xfrc))
            depth = (mouth[2] - d.site_xpos[tip_site][2]) / MM
            return d, jnp.stack([depth, d.qfrc_constraint[zdof], jnp.degrees(th)])

        run = jax.jit(lambda d, step=step: jax.lax.scan(step, d, None, length=n))
        t0 = time.perf_counter()
        _, trace = run(dx)
        trace = np.asarray(trace)
        wall = time.perf_counter() - t0
        res = {}
        for h in depths:
            sel = np.abs(trace[:, 0] - h) < 0.25
            if not sel.any():
                res[f"{h:g}"] = None
                continue
            res[f"{h:g}"] = {
                "F_z_N": round(float(trace[sel, 1].mean()), 4),
                "F_z_std_N": round(float(trace[sel, 1].std()), 4),
                "theta_deg": round(float(trace[sel, 2].mean()), 4),
                "samples": int(sel.sum()),
            }
        out[rep] = res
        out[f"{rep}_wall_s"] = round(wall, 1)
        out[f"{rep}_finite"] = bool(np.isfinite(trace).all())
    out["relative_difference_F_z"] = {
        rep: {
            k: None if v is None else round(v["F_z_N"] / out["oracle"][k]["F_z_N"] - 1, 4)
            for k, v in out[rep].items()
        }
        for rep in reps
    }
    return out


def diagnose(data: dict) -> dict:
    """The extraction-force excess of each jam run (sim - oracle) against what a HORIZONTAL
    mouth-contact normal would add: ``lambda_mouth sin|theta|`` (the oracle's mouth corner
    presses on the tilted peg side, its normal perpendicular to the peg axis; a collision routine
    that returns the wall's face normal instead loses that tilt). MJX-JAX's capsule-box and
    MuJoCo C's mesh-mesh contact at the mouth edge show exactly that excess (normals read from
    a jammed state: MJX capsule-box (0.98, +-0.20, 0.0), MuJoCo C capsule-box z = -0.008)."""
    out = {}
    for part, reps in (("jam", ("capsule", "mesh")), ("jam_mjx", ("capsule", "mesh"))):
        j = data.get(part)
        if not j:
            continue
        rows = {}
        for h, orc in j["oracle"].items():
            lam = data["jam"]["oracle"][h]["contacts_N"].get("H2R-corner/P2", 0.0)
            th = math.radians(abs(orc["theta_deg"]))
            row = {"horizontal_mouth_normal_excess_N": round(lam * math.sin(th), 4)}
            for rep in reps:
                sim = j[rep].get(h)
                if sim:
                    row[f"{rep}_F_z_excess_N"] = round(sim["F_z_N"] - orc["F_z_N"], 4)
            rows[h] = row
        out[part] = rows
    return out


def _peg_contact_fz(m: mujoco.MjModel, d: mujoco.MjData, peg_geoms: set[int]) -> float:
    """The vertical (world z) contact force on the peg, summed over the contacts of ``d``."""
    f6 = np.zeros(6)
    fz = 0.0
    for i in range(d.ncon):
        c = d.contact[i]
        if c.geom1 not in peg_geoms and c.geom2 not in peg_geoms:
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        f_world = c.frame.reshape(3, 3).T @ f6[:3]  # on geom2, world frame
        fz += f_world[2] if c.geom2 in peg_geoms else -f_world[2]
    return float(fz)


def profile(episodes: int = 32, seed: int = 0) -> dict:
    """Where the baseline's extraction force differs: the scripted pull in the published dual
    policy's env on MuJoCo C (the env itself on its ``mujoco`` engine, a cross evaluation of the
    env: ``episodes`` episodes of ``seed``, ``episode_keys``), the vertical contact force on the
    peg summed over contacts at the start of every env step (the world's state written into an
    ``MjData`` by ``env.engine.to_mjdata`` with its friction scale, forward), averaged per
    phase of the pull: tip deeper than r below the mouth (the capsule's rounded end fully
    inside, both representations alike) and the last r before the tip leaves the mouth plus
    until success (the capsule's rounded end still in the hole, the mesh peg's flat tip
    already out).

    The committed ``profile`` section (2026-11-29, its ``engine`` entry naming ``mujoco-c``)
    came from the benchmarks' own MuJoCo C loop, retired on 2026-12-02 (a second copy of the
    env's step; its episodes started with the hole at its nominal pose and drew their own
    commanded errors, one world after the other). A rerun draws the env's own episode starts,
    so its episodes are others: 32 episodes on 2026-12-02 (not committed) gave capsule 0.076 N
    [0.054, 0.099] vs mesh 0.081 N [0.057, 0.104] (committed: 0.123 vs 0.129 N), the same
    finding."""
    bundle = load_policy("dual")
    out: dict = {"episodes": episodes, "seed": seed, "engine": "mujoco (the env's engine)"}
    for rep in ("capsule", "mesh"):
        over = {**bundle.env_overrides, "representation": rep, "engine": "mujoco"}
        env = load(bundle.env_name, config_overrides=over)
        r_mm = env.spec.peg_radii_mm[0]
        m = copy.copy(env.engine.model)
        fric0 = np.array(m.pair_friction)
        d = mujoco.MjData(m)
        peg_body = m.body("peg").id
        peg_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == peg_body}
        _, keys = episode_keys(seed, episodes)
        s = jax.jit(jax.vmap(env.reset))(keys)
        step = jax.jit(jax.vmap(env.step, in_axes=(0, None)))
        a = scripted_policy(env)(None, None)
        fscale = np.asarray(s.info["friction_scale"], float)
        sums = [{"deep": [], "exit": []} for _ in range(episodes)]
        live = np.ones(episodes, bool)
        success = np.zeros(episodes, bool)
        for _ in range(env.config.episode_length):
            data = jax.tree.map(np.asarray, s.data)
            depth = np.asarray(s.info["depth_mm"], float)
            for w in np.flatnonzero(live):
                m.pair_friction[:] = fric0 * fscale[w]
                env.engine.to_mjdata(jax.tree.map(lambda x, w=w: x[w], data), m, d)
                phase = "deep" if depth[w] > r_mm else "exit"
                sums[w][phase].append(abs(_peg_contact_fz(m, d, peg_geoms)))
            s = step(s, a)
            ended = live & (np.asarray(s.done) > 0)
            success[ended] = np.asarray(s.metrics["success"])[ended] > 0
            live &= ~ended
            if not live.any():
                break
        phases = {k: [float(np.mean(e[k])) if e[k] else 0.0 for e in sums] for k in sums[0]}
        per_episode = [float(np.mean(e["deep"] + e["exit"])) for e in sums]
        out[rep] = {
            "mean_abs_contact_fz_N": mean_ci(np.array(per_episode)),
            "phase_deep_mean_abs_contact_fz_N": mean_ci(np.array(phases["deep"])),
            "phase_exit_mean_abs_contact_fz_N": mean_ci(np.array(phases["exit"])),
            "exit_phase_depth_mm": f"< {r_mm:g} (= r) below the mouth until success",
            "success_rate": round(float(success.mean()), 4),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "part",
        choices=("baseline", "jam", "jam_envs_friction", "jam_mjx", "profile", "diagnose"),
        help="jam_envs_friction: the jam with the envs' relaxed frictional rows "
        "(SimOptions.friction_timeconst) instead of Coulomb rows",
    )
    ap.add_argument("--episodes", type=int, default=256)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)

    data = json.loads(OUT.read_text()) if OUT.exists() else {}
    if args.part == "diagnose":
        data["diagnosis"] = diagnose(data)
        OUT.write_text(json.dumps(data, indent=2, default=float) + "\n")
        print(json.dumps(data["diagnosis"], indent=2))
        return 0
    if args.part == "baseline":
        part = baseline(args.episodes, args.batch)
    elif args.part == "profile":
        part = profile()
    elif args.part == "jam_mjx":
        part = jam_mjx()
    elif args.part == "jam_envs_friction":
        ftc = SimOptions().friction_timeconst
        part = jam(friction_timeconst=ftc)
        # the same jam pulled faster: where the relaxed rows carry the oracle's friction again
        by_speed = {}
        for v in ENVS_FRICTION_SPEEDS_MM_S:
            same = v == part["harness"]["pull_speed_mm_s"]
            rel = (part if same else jam(v, friction_timeconst=ftc))["relative_difference"]
            by_speed[f"{v:g}"] = {
                rep: {h: row[rep]["F_z"] for h, row in rel.items()} for rep in ("capsule", "mesh")
            }
        part["F_z_relative_difference_by_speed_mm_s"] = by_speed
    else:
        part = jam()
    data[args.part] = {**provenance(), "note": args.note, **part}
    data["method"] = __doc__.split("\n\n", 1)[1].split("Run ``")[0].strip()
    OUT.write_text(json.dumps(data, indent=2, default=float) + "\n")
    print(json.dumps(part, indent=2, default=float))
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
