"""The compliance-centre experiment in MuJoCo C (float64), one world at a time.

A twin of :class:`peghole_mjx.experiments.compliance.Extraction` for checks that need double
precision, per-step traces or slow pulls at low cost: the same scene (``compile_scene`` with
the experiment's simulator options and collision representation), the NumPy twin of the
impedance law (:func:`peghole_mjx.control.reference.impedance_torque`), the same rest pose,
ramp and pull. Used by :mod:`benchmarks.studies.contact_diagnosis` and
:mod:`benchmarks.studies.pull_speed`.

MuJoCo C's multi-point CCD (on by default in MuJoCo 4) is off in every compiled scene
(``geometry.mjcf._set_options``): MJX collides convex meshes with its own routine, and with
multi-point CCD on the replica does not reproduce it on the dual meshes (two dual-2 worlds,
K_theta 3 N m/rad, beta0 -0.2 deg, L_C = top, 0.5 mm/s: late peaks 0.121 / 0.112 N with it,
0.168 / 0.177 N without; MJX float64 0.167 / 0.176 N, the quasi-static oracle 0.167 / 0.176 N;
2026-11-29). The rect scenes (boxes, edge capsules) do not use CCD: their traces are
identical either way.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from peghole_mjx.control.limits import GAINS, LIMITS
from peghole_mjx.control.reference import impedance_torque, rot_from_rotvec
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.geometry.mjcf import compile_scene
from peghole_mjx.geometry.specs import MM, PRESETS

#: trace columns of :func:`pull_c`, one row per physics step
COLUMNS = ("depth", "f_plus", "f_minus", "penetration", "f_tangential", "f_normal", "fz")
#: what the replica is, stored beside its results so that a result of another replica is redone
ENGINE = "MuJoCo C, float64, multi-point CCD off, NumPy impedance law"
#: the experiment's defaults; ``EXPERIMENT.setup(kind)`` holds each geometry's L_C positions,
#: step, contact time constant and representation (``compliance.GeometrySetup``)
EXPERIMENT = cx.ExperimentConfig()


def pull_c(
    preset: str,
    mu: float,
    world: dict[str, float],
    speed_m_s: float,
    cfg: cx.ExperimentConfig | None = None,
    damping_ratio: float | None = None,
    opt: dict[str, float] | None = None,
) -> tuple[np.ndarray, int, float]:
    """One world of the compliance experiment in MuJoCo C (float64): errors ramped in over
    the settling time, then a straight pull at ``speed_m_s`` until the tip is clear.

    ``world`` holds the :data:`~peghole_mjx.experiments.compliance.WORLD_KEYS` (SI, rad).
    Returns the per-step trace (:data:`COLUMNS`: tip depth m, normal force on the +x / -x
    wall sides N, largest penetration m, tangential and normal force sums N, extraction force
    = minus the contacts' vertical force on the peg N), the settling steps and the step.
    ``opt``: ``mjOption`` fields set on the compiled model (e.g. ``noslip_iterations``,
    ``impratio``), for diagnoses of options the experiment does not set."""
    cfg = cfg or cx.ExperimentConfig(geometry=PRESETS[preset].kind)
    spec = dataclasses.replace(PRESETS[preset], friction=mu)
    rep = cfg.representation_of(spec.kind)
    m = compile_scene(spec, sim=cfg.sim_options(), representation=rep)
    for k, v in (opt or {}).items():
        if not hasattr(m.opt, k):
            raise ValueError(f"unknown mjOption field {k!r}")
        setattr(m.opt, k, v)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("inserted").id)
    mujoco.mj_forward(m, d)
    joints = [m.joint(f"joint{i}") for i in range(1, 8)]
    qadr = np.array([j.qposadr[0] for j in joints])
    dadr = np.array([j.dofadr[0] for j in joints])
    act = np.array([m.actuator(f"joint{i}_motor").id for i in range(1, 8)])
    lo, hi = m.actuator_ctrlrange[act].T
    peg = m.body("peg").id
    L_C = float(world["L_C"])
    centre = m.site("peg_tip").pos.copy() - np.array([0.0, 0.0, L_C])
    q0 = d.qpos[qadr].copy()
    R0 = d.xmat[peg].reshape(3, 3).copy()
    x0 = d.xpos[peg] + R0 @ centre
    mouth = d.site("hole_mouth").xpos[2]
    tip = m.site("peg_tip").id
    kr, kl = float(world["k_rot"]), float(world["k_lat"])
    off = cfg.off_axis_rotational_stiffness_Nm_rad
    ko = kr if off is None else off
    stiff = np.array([kl, kl, cfg.axial_stiffness_N_m, ko, kr, ko])
    zeta = GAINS.damping_ratio if damping_ratio is None else damping_ratio
    dt = m.opt.timestep
    settle = round(cfg.settle_s / dt)
    n = settle + math.ceil((mouth - d.site_xpos[tip][2] + cfg.clear_mm * MM) / (speed_m_s * dt))
    # spring rest pose of the quasi-static model, as in compliance.Extraction.init_world
    dx_err = float(world["delta0"]) - L_C * math.sin(float(world["theta0"]))
    rot_err = -(float(world["beta0"]) + float(world["theta0"]))
    jacp, jacr, M = np.zeros((3, m.nv)), np.zeros((3, m.nv)), np.zeros((m.nv, m.nv))
    f6 = np.zeros(6)
    out = np.zeros((n, len(COLUMNS)))
    z = 0.0
    for t in range(n):
        a = min(t / settle, 1.0)
        vel = np.array([0.0, 0.0, speed_m_s if t >= settle else 0.0])
        z += vel[2] * dt
        pos = x0 + np.array([a * dx_err, 0.0, z])
        Rc = rot_from_rotvec(np.array([0.0, a * rot_err, 0.0])) @ R0
        R = d.xmat[peg].reshape(3, 3)
        xc = d.xpos[peg] + R @ centre
        mujoco.mj_jac(m, d, jacp, jacr, xc, peg)
        mujoco.mj_fullM(m, d, M)
        J = np.vstack([jacp, jacr])[:, dadr]
        bias = d.qfrc_bias[dadr]
        if cfg.compensate_joint_damping:
            bias = bias - d.qfrc_passive[dadr]
        tau, _ = impedance_torque(
            J, M[np.ix_(dadr, dadr)], bias, d.qpos[qadr], d.qvel[dadr], xc, R,
            pos, Rc, vel, stiff, zeta, np.zeros(6), q0,
            (GAINS.null_stiffness_Nm_rad, GAINS.null_damping_Nms_rad), LIMITS.max_wrench, lo, hi,
        )  # fmt: skip
        d.ctrl[act] = tau
        mujoco.mj_step(m, d)
        fp = fm = pen = ft = fn = fz = 0.0
        for i in range(d.ncon):
            c = d.contact[i]
            mujoco.mj_contactForce(m, d, i, f6)
            if f6[0] <= 0:
                continue
            own = m.geom_bodyid[c.geom1] == peg  # the normal points from geom1 to geom2
            sgn = 1.0 if own else -1.0
            frame = c.frame.reshape(3, 3)
            on_peg = -sgn * (frame.T @ f6[:3])  # world force of the contact on the peg
            pen = max(pen, -c.dist)
            nx = frame[0, 0] * sgn
            fp += f6[0] * (nx > 0.3)
            fm += f6[0] * (nx < -0.3)
            ft += math.hypot(f6[1], f6[2])
            fn += f6[0]
            fz -= on_peg[2]
        out[t] = (mouth - d.site_xpos[tip][2], fp, fm, pen, ft, fn, fz)
    return out, settle, dt
