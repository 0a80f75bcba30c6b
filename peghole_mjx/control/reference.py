"""The impedance law in NumPy: the tested reference twin of the JAX law, for MuJoCo C.

:func:`impedance_torque` is line for line the law of
:class:`peghole_mjx.control.impedance.ImpedanceController` (same clip, same 1e-9 regulariser of
the operational-space inertia, same dynamically consistent null-space projector; the module
docstring of :mod:`peghole_mjx.control.impedance` has the equations), on arrays that MuJoCo C
computes (``mj_jac``, ``mj_fullM``, ``qfrc_bias``). The MuJoCo C and PyBullet baselines of
``benchmarks/`` run it at every physics step, so they run the same controller as the MJX envs;
``tests/test_control.py`` checks it against the JAX law on random states.
:func:`impedance_torque_c` gathers those arrays from an ``MjData``.

The rotation helpers are :mod:`peghole_mjx.core.rotations`' (re-exported here), the NumPy
twins of :mod:`peghole_mjx.control.kinematics` (rotation vector = axis x angle, rad).
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from peghole_mjx.core.rotations import rot_from_rotvec, rotvec_from_mat

__all__ = [
    "impedance_torque",
    "impedance_torque_c",
    "rot_from_rotvec",
    "rot_z",
    "rotvec_from_mat",
    "tool_centre",
]


def rot_z(a: float) -> np.ndarray:
    """Rotation by ``a`` (rad) about z."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _t(a: np.ndarray) -> np.ndarray:
    return np.swapaxes(a, -1, -2)


def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Matrix times vector over leading batch dimensions."""
    return (A @ x[..., None])[..., 0]


def tool_centre(
    body_pos: np.ndarray,
    body_R: np.ndarray,
    tip_local: np.ndarray,
    L_C: float | np.ndarray,
    tool_offset: np.ndarray | None = None,
    tool_mat: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """World position of the compliance centre and the rotation of the tool frame the law
    holds: :meth:`~peghole_mjx.control.impedance.ImpedanceController.centre_pose` in NumPy.

    ``body_pos`` (..., 3) and ``body_R`` (..., 3, 3): the peg body's pose; ``tip_local`` (3,):
    the tip in the peg body frame; ``L_C`` (...): C above the tip, m. ``tool_offset`` (..., 3)
    and ``tool_mat`` (..., 3, 3): the believed tool point minus the true one and the believed
    axes in the true ones (peg body frame); None: no calibration error (the peg's own frame).
    """
    L_C = np.asarray(L_C, float)
    if tool_offset is None and tool_mat is None:
        centre = np.asarray(tip_local)[None, :] - np.array([0.0, 0.0, 1.0]) * L_C.reshape(-1, 1)
        centre = centre.reshape((*L_C.shape, 3))
        return body_pos + _mv(body_R, centre), body_R
    off = np.zeros(3) if tool_offset is None else np.asarray(tool_offset, float)
    Rt = np.eye(3) if tool_mat is None else np.asarray(tool_mat, float)
    local = np.asarray(tip_local) + off - Rt[..., :, 2] * L_C[..., None]
    return body_pos + _mv(body_R, local), body_R @ Rt


def impedance_torque(
    J: np.ndarray,
    M: np.ndarray,
    bias: np.ndarray,
    q: np.ndarray,
    qvel: np.ndarray,
    x_C: np.ndarray,
    R: np.ndarray,
    target_pos: np.ndarray,
    target_mat: np.ndarray,
    target_vel: np.ndarray,
    stiffness: np.ndarray,
    damping_ratio: float | np.ndarray,
    wrench_ff: np.ndarray,
    q_null: np.ndarray,
    null_gains: Sequence[float] | np.ndarray,
    max_wrench: Sequence[float],
    ctrl_lo: np.ndarray,
    ctrl_hi: np.ndarray,
    load_jacp: np.ndarray | None = None,
    load_error: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint torques (N m) and the clipped wrench (N, N m) of the Cartesian impedance law.

    ``J`` (6, n): world translational and rotational Jacobian of the compliance centre ``x_C``
    on the peg body, ``M`` (n, n) joint-space inertia, ``bias`` (n,) gravity + Coriolis
    torques, ``R`` the rotation of the tool frame the law holds (the peg body's, or the believed
    one: :func:`tool_centre`). ``load_error`` (3,): the weight the gravity compensation leaves
    out (world, N), through ``load_jacp`` (3, n), the translational Jacobian of the peg's
    centre of mass (both None: none). The rest as in
    :class:`peghole_mjx.control.impedance.ImpedanceController`.

    Every argument may carry the same leading batch dimensions (one world each: ``J`` (..., 6,
    n), ``damping_ratio`` (...,), ``null_gains`` (..., 2)); the MuJoCo C engine
    (:mod:`peghole_mjx.sim.engine_mujoco`) calls it once per physics step over all worlds.
    """
    Rc = np.asarray(target_mat)
    RcT = _t(Rc)
    n = J.shape[-1]
    # J in the compliance frame: both 3-row blocks rotated by Rc^T in one product
    J_loc = (RcT[..., None, :, :] @ J.reshape((*J.shape[:-2], 2, 3, n))).reshape(J.shape)
    J_locT = _t(J_loc)
    err = np.concatenate([_mv(RcT, target_pos - x_C), _mv(RcT, rotvec_from_mat(Rc @ _t(R)))], -1)
    v_loc = _mv(J_loc, qvel)
    v_des = np.concatenate([_mv(RcT, target_vel), np.zeros_like(err[..., 3:])], axis=-1)
    MinvJT = np.linalg.solve(M, J_locT)  # M^-1 J^T
    Lam = np.linalg.inv(J_loc @ MinvJT + 1e-9 * np.eye(6))
    K = np.asarray(stiffness, float)
    zeta = np.asarray(damping_ratio, float)[..., None]
    D = 2.0 * zeta * np.sqrt(K * np.clip(np.diagonal(Lam, axis1=-2, axis2=-1), 0.0, None))
    w_raw = K * err + D * (v_des - v_loc) + wrench_ff
    cap = np.asarray(max_wrench, float)
    w = np.clip(w_raw, -cap, cap)
    gains = np.asarray(null_gains, float)
    tau0 = gains[..., 0:1] * (q_null - q) - gains[..., 1:2] * qvel
    # J^T w + N^T tau0 with N^T = I - J^T Jbar^T, Jbar = M^-1 J^T Lambda (never formed)
    Jbar_T_tau0 = _mv(_t(Lam), _mv(_t(MinvJT), tau0))
    tau = _mv(J_locT, w - Jbar_T_tau0) + bias + tau0
    if load_error is not None:
        tau = tau + _mv(_t(load_jacp), load_error)
    return np.clip(tau, ctrl_lo, ctrl_hi), w


def impedance_torque_c(
    ctl,
    m: mujoco.MjModel,
    d: mujoco.MjData,
    L_C: float,
    target_pos: np.ndarray,
    target_mat: np.ndarray,
    target_vel: np.ndarray,
    stiffness: np.ndarray,
    damping_ratio: float,
    wrench_ff: np.ndarray,
    q_null: np.ndarray,
    null_gains: Sequence[float],
    max_wrench: Sequence[float] | None = None,
    tool_offset: np.ndarray | None = None,
    tool_mat: np.ndarray | None = None,
    load_error: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`impedance_torque` on a MuJoCo C state (``mj_forward`` done), compliance centre
    ``L_C`` (m) above the tip; ids, tip and torque limits from ``ctl``
    (:class:`~peghole_mjx.control.impedance.ImpedanceController`), the wrench caps
    ``max_wrench`` (N, N m) too unless given; ``tool_offset``, ``tool_mat`` and ``load_error``
    as in :class:`~peghole_mjx.control.impedance.ImpedanceParams`."""
    R = d.xmat[ctl.body_id].reshape(3, 3)
    if tool_offset is None and tool_mat is None:
        x_C = d.xpos[ctl.body_id] + R @ (ctl.tip_local - np.array([0.0, 0.0, L_C]))
    else:
        x_C, R = tool_centre(d.xpos[ctl.body_id], R, ctl.tip_local, L_C, tool_offset, tool_mat)
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, jacr, x_C, ctl.body_id)
    load_jacp = None
    if load_error is not None:
        load_jacp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, load_jacp, jr, d.xipos[ctl.body_id], ctl.body_id)
        load_jacp = load_jacp[:, ctl.dadr]
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    lim = ctl.limits
    if max_wrench is None:
        max_wrench = (*lim.max_force_N, *lim.max_torque_Nm)
    return impedance_torque(
        np.vstack([jacp, jacr])[:, ctl.dadr],
        M[np.ix_(ctl.dadr, ctl.dadr)],
        d.qfrc_bias[ctl.dadr],
        d.qpos[ctl.qadr],
        d.qvel[ctl.dadr],
        x_C,
        R,
        target_pos,
        target_mat,
        target_vel,
        stiffness,
        damping_ratio,
        wrench_ff,
        q_null,
        null_gains,
        max_wrench,
        ctl.ctrl_lo,
        ctl.ctrl_hi,
        load_jacp,
        load_error,
    )
