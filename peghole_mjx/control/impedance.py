"""Cartesian impedance law with an active compliance centre (ACC) for the iiwa, in JAX/MJX.

The compliance centre ``C`` is a point on the peg axis ``L_C`` above the peg tip (peg frame:
``z = tip_z - L_C``; the peg frame's z points from the mount to the tip). The law (thesis
Sec 2.4 / 3.2: the manipulator holds the peg by a lateral spring and a rotational spring at
``C``) commands the wrench at ``C``, expressed in the *compliance frame* (the commanded TCP
frame, orientation ``target.mat``)::

    F = K_t (x_des - x_C) + D_t (v_des - v_C) + F_ff
    M = K_r  rotvec(R_des R^T) - D_r omega + M_ff
    D_i = 2 zeta sqrt(K_i Lambda_ii),   Lambda = (J M^-1 J^T)^-1  (in the compliance frame)

clipped per axis to :class:`~peghole_mjx.control.limits.ControlLimits` (force threshold,
max Cartesian torque [3, 3, 1] N m), and maps it to joint torques::

    tau = J_C^T [F; M] + qfrc_bias + N^T (K_n (q_n - q) - D_n qdot)
    N^T = I - J^T Jbar^T,  Jbar = M^-1 J^T Lambda   (dynamically consistent null space)

``qfrc_bias`` is MuJoCo's gravity + Coriolis/centrifugal term (the peg's mass included); a
payload the law does not know of (``ImpedanceParams.load_error``, the weight its gravity
compensation leaves out) adds ``J_G^T f_load`` with ``J_G`` the translational Jacobian of the
peg's centre of mass; with
``compensate_passive`` the law also cancels the model's passive joint forces (``- qfrc_passive``:
the joint damping), as a joint-torque-sensing arm's inner loop does; ``tau`` is clipped to the
actuator ``ctrlrange`` read from the model. ``J_C`` is the 6 x nv Jacobian of the point ``C``
on the peg body (:mod:`peghole_mjx.control.kinematics`).

The tool frame is where the controller *believes* it: by default the peg body's frame at the
tip site; with a calibration error (``ImpedanceParams.tool_offset`` and ``tool_mat``, the
believed tool point and axes relative to the true ones, peg body frame) ``C`` lies ``L_C``
along the believed axis above the believed tip, and the rotation error is that of the believed
axes (``R tool_mat``). An offset along the axis is an ``L_C`` error of the same size.

Everything is a pure function of ``(mjx.Model, mjx.Data, Target, ImpedanceParams)`` pytrees, so
it jits, vmaps over worlds, and the stiffness may change at every control step (the RL's
compliance strategy). The quantities are those stored in ``mjx.Data`` by the last
``mjx.step`` (positions of the start of that step): a one-step (2 ms) measurement delay, as on a
real controller; at rest it is exact.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from peghole_mjx.control.kinematics import full_inertia, point_jacobian, rotvec_from_mat
from peghole_mjx.control.limits import GAINS, LIMITS, ControlLimits
from peghole_mjx.core._mjx import mjx
from peghole_mjx.geometry.mjcf import ACTUATORS, JOINTS


class Target(NamedTuple):
    """Commanded pose of the compliance centre: position (3,), rotation (3, 3), velocity (3,).

    World frame, SI. ``mat`` is also the compliance frame in which stiffness and limits act.
    """

    pos: jax.Array
    mat: jax.Array
    vel: jax.Array


class ImpedanceParams(NamedTuple):
    """Per-world, per-step parameters of the law (all arrays, so they vmap and may change).

    ``stiffness`` (6,): K_x, K_y, K_z (N/m), K_rx, K_ry, K_rz (N m/rad) in the compliance frame;
    ``damping_ratio`` (): zeta; ``L_C`` (): compliance centre above the tip, m;
    ``wrench_ff`` (6,): force/torque feed-forward in the compliance frame (N, N m);
    ``q_null`` (nv,): null-space posture; ``null_gains`` (2,): K_n, D_n.

    Optional (None: left out of the law's computation, which is then as without them):
    ``tool_offset`` (3,): the believed tool (tip) point minus the true one, peg body frame, m;
    ``tool_mat`` (3, 3): the believed tool axes in the true ones (the tool-frame calibration
    error); ``load_error`` (3,): the weight the law's gravity compensation leaves out, world
    frame, N (a payload heavier than the robot's load data: ``(m - m_nominal) g``), at the
    peg's centre of mass.
    """

    stiffness: jax.Array
    damping_ratio: jax.Array
    L_C: jax.Array
    wrench_ff: jax.Array
    q_null: jax.Array
    null_gains: jax.Array
    tool_offset: jax.Array | None = None
    tool_mat: jax.Array | None = None
    load_error: jax.Array | None = None


class ImpedanceOutput(NamedTuple):
    """What the law computed: joint torques and the (clipped) wrench, for logging and tests."""

    tau: jax.Array  # (nu,) joint torques after the actuator clip, N m
    wrench: jax.Array  # (6,) commanded wrench at C in the compliance frame, after the clip
    wrench_raw: jax.Array  # (6,) before the clip
    x_C: jax.Array  # (3,) world position of the compliance centre
    err: jax.Array  # (6,) pose error (position, rotation vector) in the compliance frame


def make_params(
    L_C_m: float | jax.Array,
    q_null,
    stiffness=None,
    damping_ratio=None,
    wrench_ff=None,
    null_gains=None,
    tool_offset=None,
    tool_mat=None,
    load_error=None,
) -> ImpedanceParams:
    """Parameters with the defaults of :data:`~peghole_mjx.control.limits.GAINS` (no tool-frame
    or load error unless given)."""
    f = jnp.float32 if not jax.config.jax_enable_x64 else jnp.float64
    stiffness = GAINS.stiffness if stiffness is None else stiffness
    zeta = GAINS.damping_ratio if damping_ratio is None else damping_ratio
    null = (
        (GAINS.null_stiffness_Nm_rad, GAINS.null_damping_Nms_rad)
        if null_gains is None
        else null_gains
    )
    return ImpedanceParams(
        stiffness=jnp.asarray(stiffness, f),
        damping_ratio=jnp.asarray(zeta, f),
        L_C=jnp.asarray(L_C_m, f),
        wrench_ff=jnp.zeros(6, f) if wrench_ff is None else jnp.asarray(wrench_ff, f),
        q_null=jnp.asarray(q_null, f),
        null_gains=jnp.asarray(null, f),
        tool_offset=None if tool_offset is None else jnp.asarray(tool_offset, f),
        tool_mat=None if tool_mat is None else jnp.asarray(tool_mat, f),
        load_error=None if load_error is None else jnp.asarray(load_error, f),
    )


def clip_wrench(w: jax.Array, limits: ControlLimits = LIMITS) -> jax.Array:
    """Per-axis clip of a compliance-frame wrench to the thesis's force/torque caps."""
    cap = jnp.asarray(limits.max_wrench, w.dtype)
    return jnp.clip(w, -cap, cap)


def rate_limit(
    prev: jax.Array, new: jax.Array, dt: float, max_speed: float = LIMITS.max_speed_m_s
) -> jax.Array:
    """Move a commanded position from ``prev`` towards ``new`` at no more than ``max_speed``."""
    step = new - prev
    n = jnp.linalg.norm(step)
    cap = max_speed * dt
    return prev + step * jnp.minimum(1.0, cap / jnp.maximum(n, 1e-12))


class ImpedanceController:
    """The law bound to one compiled robot scene (ids and limits resolved once, by name)."""

    def __init__(
        self,
        m: mujoco.MjModel,
        limits: ControlLimits = LIMITS,
        peg_body: str = "peg",
        tip_site: str = "peg_tip",
        compensate_passive: bool = False,
    ):
        self.limits = limits
        self.compensate_passive = bool(compensate_passive)
        self.body_id = m.body(peg_body).id
        site = m.site(tip_site)
        if site.bodyid[0] != self.body_id:
            raise ValueError(f"site {tip_site} is not on body {peg_body}")
        self.tip_local = np.asarray(site.pos, float).copy()  # in the peg body frame
        self.qadr = np.array([m.joint(j).qposadr[0] for j in JOINTS])
        self.dadr = np.array([m.joint(j).dofadr[0] for j in JOINTS])
        self.act = np.array([m.actuator(a).id for a in ACTUATORS])
        if not np.array_equal(m.actuator_trnid[self.act, 0], [m.joint(j).id for j in JOINTS]):
            raise ValueError("actuators must drive joint1..7 in order")
        self.ctrl_lo, self.ctrl_hi = (
            np.asarray(x, float) for x in m.actuator_ctrlrange[self.act].T
        )
        self.nv = m.nv

    @classmethod
    def from_model(cls, m: mujoco.MjModel, **kw) -> ImpedanceController:
        return cls(m, **kw)

    def centre_local(self, L_C: jax.Array) -> jax.Array:
        """Compliance centre in the peg body frame: on the axis, ``L_C`` above the tip."""
        tip = jnp.asarray(self.tip_local)
        return tip - jnp.array([0.0, 0.0, 1.0]) * L_C

    def centre_pose(
        self, d: mjx.Data, L_C: jax.Array, tool_offset=None, tool_mat=None
    ) -> tuple[jax.Array, jax.Array]:
        """World position of C and the rotation of the tool frame the law holds: the peg's,
        or with a calibration error (``tool_offset``, ``tool_mat``: see
        :class:`ImpedanceParams`) the believed one, C on its axis above its tip."""
        R = d.xmat[self.body_id]
        if tool_offset is None and tool_mat is None:
            return d.xpos[self.body_id] + R @ self.centre_local(L_C), R
        dtype = R.dtype
        off = jnp.zeros(3, dtype) if tool_offset is None else tool_offset
        Rt = jnp.eye(3, dtype=dtype) if tool_mat is None else tool_mat
        local = jnp.asarray(self.tip_local, dtype) + off - Rt[:, 2] * L_C
        return d.xpos[self.body_id] + R @ local, R @ Rt

    def __call__(
        self, m: mjx.Model, d: mjx.Data, target: Target, p: ImpedanceParams
    ) -> ImpedanceOutput:
        """Joint torques of the impedance law (see the module docstring)."""
        x_C, R = self.centre_pose(d, p.L_C, p.tool_offset, p.tool_mat)
        jacp, jacr = point_jacobian(m, d, x_C, self.body_id)  # (nv, 3) each
        J = jnp.concatenate([jacp.T, jacr.T])[:, self.dadr]  # (6, 7)
        qvel = d.qvel[self.dadr]
        q = d.qpos[self.qadr]
        Rc = target.mat
        T = jnp.zeros((6, 6), J.dtype).at[:3, :3].set(Rc.T).at[3:, 3:].set(Rc.T)
        J_loc = T @ J  # Jacobian in the compliance frame
        e_p = Rc.T @ (target.pos - x_C)
        e_r = Rc.T @ rotvec_from_mat(Rc @ R.T)
        err = jnp.concatenate([e_p, e_r])
        v_loc = J_loc @ qvel
        v_des = jnp.concatenate([Rc.T @ target.vel, jnp.zeros(3, J.dtype)])

        Mfull = full_inertia(m, d)[jnp.ix_(self.dadr, self.dadr)]
        Minv = jnp.linalg.inv(Mfull)
        Lam_inv = J_loc @ Minv @ J_loc.T
        Lam = jnp.linalg.inv(Lam_inv + 1e-9 * jnp.eye(6, dtype=J.dtype))
        K = p.stiffness
        D = 2.0 * p.damping_ratio * jnp.sqrt(K * jnp.clip(jnp.diag(Lam), 0.0))
        w_raw = K * err + D * (v_des - v_loc) + p.wrench_ff
        w = clip_wrench(w_raw, self.limits)

        tau_task = J_loc.T @ w
        Jbar = Minv @ J_loc.T @ Lam  # (7, 6)
        NT = jnp.eye(J.shape[1], dtype=J.dtype) - J_loc.T @ Jbar.T
        tau0 = p.null_gains[0] * (p.q_null - q) - p.null_gains[1] * qvel
        tau = tau_task + d.qfrc_bias[self.dadr] + NT @ tau0
        if p.load_error is not None:  # the payload's weight the compensation leaves out
            com = d.xipos[self.body_id]
            jacp_g, _ = point_jacobian(m, d, com, self.body_id)
            tau = tau + (jacp_g @ p.load_error)[self.dadr]
        if self.compensate_passive:
            tau = tau - d.qfrc_passive[self.dadr]
        tau = jnp.clip(tau, self.ctrl_lo, self.ctrl_hi)
        return ImpedanceOutput(tau=tau, wrench=w, wrench_raw=w_raw, x_C=x_C, err=err)

    def apply(
        self, m: mjx.Model, d: mjx.Data, target: Target, p: ImpedanceParams
    ) -> tuple[mjx.Data, ImpedanceOutput]:
        """Write the law's torques into ``d.ctrl`` (returns the new data and the output)."""
        out = self(m, d, target, p)
        return d.replace(ctrl=d.ctrl.at[self.act].set(out.tau)), out


def force_at_point(d: mjx.Data, body_id: int, force: jax.Array, point: jax.Array) -> jax.Array:
    """``xfrc_applied`` row (force, torque about the body COM) of a world force at a point."""
    torque = jnp.cross(point - d.xipos[body_id], force)
    return jnp.concatenate([force, torque])
