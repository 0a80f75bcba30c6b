"""The ``mujoco`` engine: MuJoCo C through ``mujoco.batch`` (MuJoCo >= 4.0), for CPUs.

The env stays pure and jit-able: a world's physics state is MuJoCo's ``mjSTATE_INTEGRATION``
row (float64), carried in the env ``State`` bit for bit as twice as many uint32 words (JAX
runs in float32), plus the readings the task uses. A step enters the jitted code through
``jax.pure_callback`` with ``vmap_method="broadcast_all"``: under ``vmap`` (one or several
nested levels: worlds, training seeds) the callback receives every world of the call at once
and steps them on one ``mujoco.batch.Batch`` thread pool. So Brax training, rollouts, the
Gymnasium adapter and resume work on this engine unchanged.

Per physics substep, over all worlds as array operations (never a Python loop over worlds):
the Jacobian of the compliance centre from the bound joint axes and anchors (every joint of
the iiwa is a hinge on the chain to the peg: ``jacp = axis x (x_C - anchor)``,
``jacr = axis``, as ``mj_jac``), the joint-space inertia from the bound sparse ``M``, then the
NumPy twin of the impedance law (:func:`peghole_mjx.control.reference.impedance_torque`, tested
equal to the JAX law), written into ``ctrl``, and one ``Batch.step``. As in MJX, the law reads
the positions of the start of the last physics step (``mj_step``'s derived fields) with the
velocities after it.

Per-world randomisation reaches the C engine through per-simulation model fields
(``Batch.expand("pair_friction")``; with a payload draw also ``body_mass`` and
``body_inertia`` of the peg, without ``Batch.set_const``: the constants MuJoCo derives from the
masses at compile time, such as ``body_invweight0``, stay the nominal model's, as on MJX, whose
per-world model fields are replaced the same way). A world whose step raises in MuJoCo
(``SimulationError.ids``) or ends non-finite is returned with ``finite`` false: the env ends its
episode and counts it (``metrics["nan"]``); the batch goes on. ``mjDSBL_AUTORESET`` is set, so
MuJoCo never silently resets a diverging world to its defaults.
"""

from __future__ import annotations

import copy
import functools
import math
import os
import threading
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

try:  # MuJoCo >= 4.0 (pyproject allows 3.3): without it the engine refuses to start, in one line
    from mujoco import batch as mj_batch
except ImportError:
    mj_batch = None

from peghole_mjx.control import ImpedanceController, ImpedanceParams
from peghole_mjx.control.reference import impedance_torque, tool_centre
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.rotations import rotvec_from_mat
from peghole_mjx.sim.engines import ContactForces, FTReading, Readout, SceneIds, Sense

STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


@struct.dataclass
class CData:
    """One world's MuJoCo C state in the env ``State``: the integration state row (float64 as
    uint32 pairs) and the readings of its last call (float32)."""

    state: jax.Array  # (2 * nstate,) uint32: the mjSTATE_INTEGRATION row's float64 bits
    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    peg_pos: jax.Array  # (3,)
    peg_mat: jax.Array  # (3, 3)
    flange_pos: jax.Array  # (3,)
    flange_mat: jax.Array  # (3, 3)
    ok: jax.Array  # () bool: finite and no MuJoCo error in the call that made it


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis (3), bit for bit, without its axis bookkeeping (a third
    of its time on (64, 7, 3) arrays: it runs at every physics substep)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def available_threads() -> int:
    """The CPUs this process may run on (the ``threads`` default, 0)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


class _Pool:
    """One ``mujoco.batch.Batch`` of ``nsim`` worlds with the fields the engine binds."""

    def __init__(
        self,
        model: mujoco.MjModel,
        nsim: int,
        nthread: int,
        persistent: bool = False,
        passive: bool = False,
    ):
        #: ``persistent``: one MjData per world kept between calls, so that a world's contacts
        #: and constraint forces of its last step can be read
        #: (:meth:`MujocoEngine.contact_forces`); ``passive``: bind ``qfrc_passive`` (an
        #: output field, copied out after every call: only for a law that cancels it)
        self.batch = b = mj_batch.Batch(model, nsim, nthread=nthread, persistent=persistent)
        self.state = b.state
        self.qpos, self.qvel, self.ctrl = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl")
        self.xpos, self.xmat = b.bind("xpos"), b.bind("xmat")
        self.xanchor, self.xaxis = b.bind("xanchor"), b.bind("xaxis")
        self.site_xpos, self.site_xmat = b.bind("site_xpos"), b.bind("site_xmat")
        self.M, self.bias = b.bind("M"), b.bind("qfrc_bias")
        self.passive = b.bind("qfrc_passive") if passive else None
        self.sensordata = b.bind("sensordata")
        self.pair_friction = b.expand("pair_friction") if model.npair else None
        self.body_mass = self.body_inertia = self.xipos = None

    def scale_mass(self, body: int, scale: np.ndarray | None) -> None:
        """Body ``body``'s mass and inertia times ``scale`` (n,) per world (None: nominal);
        the fields are expanded on the first call (a pool without a payload draw never is)."""
        if scale is None and self.body_mass is None:
            return
        if self.body_mass is None:
            m = self.batch.model
            self._mass0, self._inertia0 = np.array(m.body_mass), np.array(m.body_inertia)
            self.body_mass = self.batch.expand("body_mass")
            self.body_inertia = self.batch.expand("body_inertia")
            self.xipos = self.batch.bind("xipos")
        s = np.ones(self.batch.nsim) if scale is None else np.asarray(scale, float)
        self.body_mass[:] = self._mass0
        self.body_inertia[:] = self._inertia0
        self.body_mass[:, body] = self._mass0[body] * s
        self.body_inertia[:, body] = self._inertia0[body] * s[:, None]


class MujocoEngine:
    """MuJoCo C on a ``mujoco.batch`` thread pool, behind ``jax.pure_callback``.

    :attr:`ctrl_log` (None by default) is an opt-in record of the applied joint torques: a list
    assigned to it receives one ``(n, nu)`` copy of ``ctrl`` per physics substep of every step
    call (host side, so it fills as the jitted step runs; no effect on the physics)."""

    name = "mujoco"
    #: the step and reset call the host (``jax.pure_callback``): JAX 0.10.2 does not keep a
    #: graph holding one in its persistent compilation cache
    host_callbacks = True

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        ctrl: ImpedanceController,
        ids: SceneIds,
        n_substeps: int,
        threads: int = 0,
    ):
        if mj_batch is None:
            raise UserInputError(
                "engine 'mujoco' needs MuJoCo >= 4.0 (mujoco.batch); installed "
                f"{mujoco.__version__}"
            )
        if not isinstance(threads, int) or isinstance(threads, bool) or threads < 0:
            raise UserInputError(
                f"mujoco_threads must be an integer >= 0 (0: all CPUs), got {threads!r}"
            )
        m = copy.copy(mj_model)
        # a diverging world keeps its NaN state (the env ends its episode), as in MJX
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self.model = m
        self.ctrl = ctrl
        self.ids = ids
        self.n_substeps = int(n_substeps)
        self.threads = int(threads) or available_threads()
        self._check_chain(m, ctrl)
        self.nstate = mujoco.mj_stateSize(m, STATE_SPEC)
        # where eq_active starts in the state row (the components before it in the spec's bit
        # order), and a float64 1.0 / 0.0 as the row's uint32 word pairs (set_eq_active)
        before = int(STATE_SPEC) & (int(mujoco.mjtState.mjSTATE_EQ_ACTIVE) - 1)
        self._eq_active_adr = mujoco.mj_stateSize(m, before)
        self._on_words = np.array([1.0]).view(np.uint32)
        self._pair_friction0 = np.array(m.pair_friction, float)
        self._q_default = np.array(m.qpos0, float)
        d0 = mujoco.MjData(m)  # the model's defaults, as mjx.make_data's
        self._mocap_pos0, self._mocap_quat0 = d0.mocap_pos.copy(), d0.mocap_quat.copy()
        # M (CSR, lower triangle) -> full (nv, nv)
        rows = np.repeat(np.arange(m.nv), m.M_rownnz)
        self._m_rows, self._m_cols = rows, np.asarray(m.M_colind)
        self._jnt = np.asarray(m.dof_jntid)[ctrl.dadr]  # the joint of each arm dof
        # the arm's dofs are all the model's, in order (checked): no gathers in the law
        self._all_dofs = np.array_equal(ctrl.dadr, np.arange(m.nv)) and np.array_equal(
            ctrl.qadr, np.arange(m.nq)
        )
        self._pools: dict[int, _Pool] = {}
        self._lock = threading.Lock()
        #: host seconds spent in the substep callbacks and, within them, in ``Batch.step``
        #: (the physics alone), read by benchmarks/perf/throughput.py; the number of substep
        #: calls and of reset calls (``init_calls``: the learner resets only where needed)
        self.timing = {"callback_s": 0.0, "batch_step_s": 0.0, "calls": 0, "init_calls": 0}
        self.timing |= {"ik_calls": 0}  # the reset's IK calls (solve_ik), counted alike
        #: opt-in torque record: set it to a list and every physics substep appends a copy of
        #: the worlds' ``ctrl`` as applied, ``(n, nu)`` with the call's worlds flattened in
        #: order (benchmarks/perf/engines.py replays them open loop in ``mujoco.rollout``,
        #: benchmarks/perf/contact_caps.py step by step to count contacts); None: off
        self.ctrl_log: list[np.ndarray] | None = None
        fd = np.dtype(np.float32)
        n_sub = self.n_substeps
        self._reading_shapes = (
            jax.ShapeDtypeStruct((n_sub, 3, 3), fd),
            jax.ShapeDtypeStruct((n_sub, 3), fd),
            jax.ShapeDtypeStruct((n_sub, 3), fd),
        )

    # ------------------------------------------------------------------ model checks
    @staticmethod
    def _check_chain(m: mujoco.MjModel, ctrl: ImpedanceController) -> None:
        """The analytic Jacobian needs every dof to be a hinge on the chain to the peg body."""
        if m.nv != len(ctrl.dadr) or np.any(m.jnt_type != mujoco.mjtJoint.mjJNT_HINGE):
            raise UserInputError(
                "engine 'mujoco' needs a scene whose only joints are the arm's 7 hinges"
            )
        chain, b = set(), ctrl.body_id
        while b > 0:
            chain.add(int(b))
            b = int(m.body_parentid[b])
        if not all(int(j) in chain for j in m.jnt_bodyid):
            raise UserInputError("engine 'mujoco': a joint is not on the chain to the peg body")

    # ------------------------------------------------------------------ host side
    def _pool(self, n: int) -> _Pool:
        pool = self._pools.get(n)
        if pool is None:
            pool = self._pools[n] = _Pool(
                self.model, n, self.threads, passive=self.ctrl.compensate_passive
            )
        return pool

    def pool(self, qpos: np.ndarray) -> _Pool:
        """A persistent pool of ``len(qpos)`` worlds at joint positions ``qpos`` (n, nq), the
        mocap bodies at the model's defaults, zero velocity, forward done: the start of a
        scripted client's worlds (the experiments: :meth:`law_step`, :meth:`contact_forces`)."""
        qpos = np.atleast_2d(np.asarray(qpos, float))
        n = qpos.shape[0]
        p = _Pool(
            self.model, n, self.threads, persistent=True, passive=self.ctrl.compensate_passive
        )
        p.batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
        p.qpos[:] = qpos
        self._run(p, p.batch.forward)
        return p

    def full_inertia(self, M: np.ndarray) -> np.ndarray:
        """(n, nv, nv) joint-space inertia from the bound CSR ``M`` rows (n, nM)."""
        n = M.shape[0]
        full = np.zeros((n, self.model.nv, self.model.nv))
        full[:, self._m_rows, self._m_cols] = M
        full[:, self._m_cols, self._m_rows] = M
        return full

    def centre_jacobian(self, p: _Pool, x_C: np.ndarray) -> np.ndarray:
        """(n, 6, nv) Jacobian of the world points ``x_C`` (n, 3) on the peg body."""
        axis = p.xaxis[:, self._jnt]  # (n, nj, 3)
        jacp = _cross(axis, x_C[:, None, :] - p.xanchor[:, self._jnt])
        return np.concatenate([np.swapaxes(jacp, 1, 2), np.swapaxes(axis, 1, 2)], axis=1)

    def _law(self, p: _Pool, pos, mat, vel, prm) -> tuple[np.ndarray, np.ndarray]:
        """The law's joint torques and clipped wrench of every world of ``p`` (n, nu), (n, 6)."""
        ctl, body = self.ctrl, self.ctrl.body_id
        R = p.xmat[:, body].reshape(-1, 3, 3)
        x_C, R = tool_centre(
            p.xpos[:, body],
            R,
            ctl.tip_local,
            prm["L_C"],
            prm.get("tool_offset"),
            prm.get("tool_mat"),
        )
        J, M = self.centre_jacobian(p, x_C), self.full_inertia(p.M)
        bias, q, qvel = p.bias, p.qpos, p.qvel
        if ctl.compensate_passive:  # as the JAX law: the passive joint forces cancelled
            bias = bias - p.passive
        load = prm.get("load_error")
        J_g = None if load is None else self.centre_jacobian(p, p.xipos[:, body])[:, :3]
        if not self._all_dofs:
            d, qa = ctl.dadr, ctl.qadr
            J, M, bias, q, qvel = J[:, :, d], M[:, d][:, :, d], bias[:, d], q[:, qa], qvel[:, d]
            J_g = None if J_g is None else J_g[:, :, d]
        return impedance_torque(
            J,
            M,
            bias,
            q,
            qvel,
            x_C,
            R,
            pos,
            mat,
            vel,
            prm["stiffness"],
            prm["damping_ratio"],
            prm["wrench_ff"],
            prm["q_null"],
            prm["null_gains"],
            ctl.limits.max_wrench,
            ctl.ctrl_lo,
            ctl.ctrl_hi,
            J_g,
            load,
        )

    def _law_step(self, p: _Pool, pos, mat, vel, prm) -> tuple[np.ndarray, np.ndarray, float]:
        """The law, then one ``Batch.step`` of every world of ``p``: (ok per world, the law's
        wrench (n, 6), the step's seconds)."""
        tau, wrench = self._law(p, pos, mat, vel, prm)
        p.ctrl[:, self.ctrl.act] = np.where(np.isfinite(tau), tau, 0.0)
        if self.ctrl_log is not None:
            self.ctrl_log.append(np.array(p.ctrl))
        t0 = time.perf_counter()
        ok = self._run(p, p.batch.step)
        return ok, wrench, time.perf_counter() - t0

    def law_step(self, p: _Pool, pos, mat, vel, prm: dict) -> tuple[np.ndarray, np.ndarray]:
        """One physics step of every world of a :meth:`pool` with the law applied before it
        (targets per world: ``pos`` (n, 3), ``mat`` (n, 3, 3), ``vel`` (n, 3); ``prm``: the
        law's parameters as arrays (n, ...) by ``ImpedanceParams`` field). A world that raises
        in MuJoCo or ends non-finite keeps its last finite state and is returned not ok, as
        the experiments' MJX path does. Returns (ok (n,), the law's wrench (n, 6))."""
        before = np.array(p.state)
        ok, wrench, _ = self._law_step(p, pos, mat, vel, prm)
        ok &= np.isfinite(p.qpos).all(1) & np.isfinite(p.qvel).all(1)
        if not ok.all():
            bad = np.flatnonzero(~ok)
            p.state[bad] = before[bad]
            self._run(p, functools.partial(p.batch.forward, ids=bad))
        return ok, wrench

    def contact_forces(self, p: _Pool, world: int, data: mujoco.MjData) -> ContactForces:
        """The contacts of world ``world``'s last step in a :meth:`pool` (``data``: an MjData of
        the model to read it into), MuJoCo C's ``mj_contactForce`` per contact: a contact
        carrying no normal force has every entry 0; ``tangential`` (N) and ``peg_force_z``
        (the world-z force of the contact on the peg, N) are set."""
        m, peg = self.model, self.ctrl.body_id
        p.batch.get_data(world, data)
        k = data.ncon
        fn, nx, dist, ft, fz = (np.zeros(k) for _ in range(5))
        own = np.zeros(k, bool)
        f6 = np.zeros(6)
        for i in range(k):
            c = data.contact[i]
            mujoco.mj_contactForce(m, data, i, f6)
            if f6[0] <= 0:
                continue
            own[i] = m.geom_bodyid[c.geom1] == peg
            frame = c.frame.reshape(3, 3)
            on_peg = -(1.0 if own[i] else -1.0) * (frame.T @ f6[:3])  # world, on the peg
            fn[i], nx[i], dist[i] = f6[0], frame[0, 0], c.dist
            ft[i], fz[i] = math.hypot(f6[1], f6[2]), on_peg[2]
        return ContactForces(fn, nx, own, dist, fn > 0, ft, fz)

    def _outputs(self, p: _Pool, ok: np.ndarray):
        i = self.ids
        ok = ok & np.isfinite(p.qpos).all(1) & np.isfinite(p.qvel).all(1)
        f32 = np.float32
        return (
            np.ascontiguousarray(p.state).view(np.uint32).copy(),
            p.qpos.astype(f32),
            p.qvel.astype(f32),
            p.xpos[:, i.peg_body].astype(f32),
            p.xmat[:, i.peg_body].reshape(-1, 3, 3).astype(f32),
            p.site_xpos[:, i.flange_site].astype(f32),
            p.site_xmat[:, i.flange_site].reshape(-1, 3, 3).astype(f32),
            ok,
        )

    def _run(self, p: _Pool, call) -> np.ndarray:
        """Run ``call()`` on the pool; the worlds MuJoCo raised in are returned not ok."""
        ok = np.ones(p.batch.nsim, bool)
        try:
            call()
        except mj_batch.SimulationError as exc:
            ok[np.asarray(exc.ids)] = False
        return ok

    def _host_ik(self, point_local, iterations, q0, pos_target, mat_target):
        """:meth:`solve_ik` on the host: the Newton steps of
        :func:`peghole_mjx.control.kinematics.newton_ik` in float64, MuJoCo C's kinematics
        (``Batch.forward`` to the position stage) and the engine's analytic Jacobian, all worlds
        of the call at once; the minimum-norm step (``pinv``) as MJX's ``lstsq``."""
        lead = pos_target.shape[:-1]
        q = np.asarray(q0, float).reshape(-1, q0.shape[-1])
        pos = np.asarray(pos_target, float).reshape(-1, 3)
        mat = np.asarray(mat_target, float).reshape(-1, 3, 3)
        local, body = np.asarray(point_local, float), self.ids.peg_body
        with self._lock:
            self.timing["ik_calls"] += 1
            p = self._pool(q.shape[0])
            p.batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
            p.qpos[:] = self._q_default
            for _ in range(iterations):
                p.qpos[:, self.ids.qadr] = q
                p.batch.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
                R = p.xmat[:, body].reshape(-1, 3, 3)
                x = p.xpos[:, body] + R @ local
                err = np.concatenate([pos - x, rotvec_from_mat(mat @ np.swapaxes(R, 1, 2))], 1)
                J = self.centre_jacobian(p, x)
                q = q + (np.linalg.pinv(J) @ err[..., None])[..., 0]
        return q.astype(np.float32).reshape(lead + q.shape[1:])

    def solve_ik(
        self,
        q0: jax.Array,
        pos_target: jax.Array,
        mat_target: jax.Array,
        point_local,
        iterations: int,
    ) -> jax.Array:
        """Arm joint angles that put ``point_local`` (peg body frame) at ``pos_target`` with
        the peg body's rotation ``mat_target``: ``iterations`` Newton steps from ``q0`` in
        MuJoCo C (float64), on the host (no MJX graph: the twin of
        :meth:`peghole_mjx.sim.engines.MjxEngine.solve_ik`)."""
        q0 = jnp.broadcast_to(q0, pos_target.shape[:-1] + q0.shape[-1:])
        return jax.pure_callback(
            functools.partial(self._host_ik, tuple(float(v) for v in point_local), int(iterations)),
            jax.ShapeDtypeStruct(q0.shape, np.dtype(np.float32)),
            q0,
            pos_target,
            mat_target,
            vmap_method="broadcast_all",
        )

    def _host_init(self, q_arm, hole_pos, hole_quat, *mass_scale):
        lead = q_arm.shape[:-1]
        q_arm = np.asarray(q_arm, float).reshape(-1, q_arm.shape[-1])
        n = q_arm.shape[0]
        with self._lock:
            self.timing["init_calls"] += 1
            p = self._pool(n)
            p.batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
            p.qpos[:] = self._q_default
            p.qpos[:, self.ids.qadr] = q_arm
            mp, mq = p.batch.bind("mocap_pos"), p.batch.bind("mocap_quat")
            mp[:] = self._mocap_pos0
            mq[:] = self._mocap_quat0
            mp[:, self.ids.hole_mocap] = np.asarray(hole_pos, float).reshape(n, 3)
            mq[:, self.ids.hole_mocap] = np.asarray(hole_quat, float).reshape(n, 4)
            if p.pair_friction is not None:
                p.pair_friction[:] = self._pair_friction0
            scale = np.asarray(mass_scale[0], float).reshape(n) if mass_scale else None
            p.scale_mass(self.ids.peg_body, scale)
            ok = self._run(p, p.batch.forward)
            out = self._outputs(p, ok)
        return tuple(o.reshape(lead + o.shape[1:]) for o in out)

    def _host_substeps(self, names, with_mass, state, targets, mat, vel, fscale, *rest):
        """``rest``: the per-world mass scale when ``with_mass``, then the law's parameters
        named ``names`` (the fields of ImpedanceParams that are not None)."""
        t_call = time.perf_counter()
        lead = state.shape[:-1]
        state = np.asarray(state).reshape(-1, state.shape[-1])
        n = state.shape[0]

        def flat(x, tail):
            return np.asarray(x, float).reshape((n, *tail))

        targets = flat(targets, targets.shape[len(lead) :])
        mat, vel = flat(mat, (3, 3)), flat(vel, (3,))
        mscale, prm_leaves = (flat(rest[0], ()), rest[1:]) if with_mass else (None, rest)
        prm = {k: flat(v, v.shape[len(lead) :]) for k, v in zip(names, prm_leaves, strict=True)}
        i = self.ids
        n_sub = self.n_substeps
        rmat = np.zeros((n, n_sub, 3, 3), np.float32)
        rf = np.zeros((n, n_sub, 3), np.float32)
        rt = np.zeros((n, n_sub, 3), np.float32)
        with self._lock:
            p = self._pool(n)
            p.state[:] = np.ascontiguousarray(state).view(np.float64)
            if p.pair_friction is not None:
                p.pair_friction[:] = self._pair_friction0 * np.asarray(fscale, float).reshape(
                    n, 1, 1
                )
            p.scale_mass(i.peg_body, mscale)
            ok = self._run(p, p.batch.forward)
            t_step = 0.0
            for k in range(n_sub):
                ok_k, _, dt_step = self._law_step(p, targets[:, k], mat, vel, prm)
                ok &= ok_k
                t_step += dt_step
                rmat[:, k] = p.site_xmat[:, i.ft_site].reshape(-1, 3, 3)
                rf[:, k] = p.sensordata[:, i.force_adr : i.force_adr + 3]
                rt[:, k] = p.sensordata[:, i.torque_adr : i.torque_adr + 3]
            out = self._outputs(p, ok)
            t = self.timing
            t["batch_step_s"] += t_step
            t["callback_s"] += time.perf_counter() - t_call
            t["calls"] += 1
        out = (*out, rmat, rf, rt)
        return tuple(o.reshape(lead + o.shape[1:]) for o in out)

    # ------------------------------------------------------------------ JAX side
    def _data_shapes(self):
        m, f32 = self.model, np.dtype(np.float32)
        S = jax.ShapeDtypeStruct
        return (
            S((2 * self.nstate,), np.dtype(np.uint32)),
            S((m.nq,), f32),
            S((m.nv,), f32),
            S((3,), f32),
            S((3, 3), f32),
            S((3,), f32),
            S((3, 3), f32),
            S((), np.dtype(bool)),
        )

    def init_data(
        self, q_arm: jax.Array, hole_pos: jax.Array, hole_quat: jax.Array, mass_scale=None
    ) -> CData:
        """The state with the arm joints at ``q_arm`` and the hole mocap at its pose, forward
        (with the peg's mass and inertia times ``mass_scale`` when given)."""
        extra = () if mass_scale is None else (mass_scale,)
        out = jax.pure_callback(
            self._host_init,
            self._data_shapes(),
            q_arm,
            hole_pos,
            hole_quat,
            *extra,
            vmap_method="broadcast_all",
        )
        return CData(*out)

    def readout(self, data: CData) -> Readout:
        return Readout(
            peg_pos=data.peg_pos,
            peg_mat=data.peg_mat,
            flange_pos=data.flange_pos,
            flange_mat=data.flange_mat,
            finite=data.ok,
            overflow=jnp.zeros((), jnp.float32),
        )

    def substeps(
        self,
        data: CData,
        targets: jax.Array,
        target_mat: jax.Array,
        target_vel: jax.Array,
        params: ImpedanceParams,
        friction_scale: jax.Array,
        sense: Sense,
        mass_scale: jax.Array | None = None,
    ):
        """The control step's substeps in MuJoCo C; returns ``(data, wrenches (n_sub, 6))``.
        ``mass_scale``: the peg's mass and inertia factor of the world (None: nominal)."""
        names = tuple(k for k, v in params._asdict().items() if v is not None)
        extra = () if mass_scale is None else (mass_scale,)
        out = jax.pure_callback(
            functools.partial(self._host_substeps, names, mass_scale is not None),
            (*self._data_shapes(), *self._reading_shapes),
            data.state,
            targets,
            target_mat,
            target_vel,
            friction_scale,
            *extra,
            *(getattr(params, k) for k in names),
            vmap_method="broadcast_all",
        )
        new = CData(*out[:8])
        readings = FTReading(*out[8:])
        return new, jax.vmap(sense)(readings)

    def set_eq_active(self, data: CData, eq: int, active: jax.Array) -> CData:
        """``data`` with equality constraint ``eq`` switched on where ``active`` (a bool of
        the world), else off: its ``eq_active`` entry of the integration state row (float64
        1.0 or 0.0, as uint32 words), which the next step's ``mj_setState`` applies."""
        i = 2 * (self._eq_active_adr + eq)
        on = jnp.asarray(self._on_words)
        words = jnp.where(active, on, jnp.zeros_like(on))
        return data.replace(state=data.state.at[i : i + 2].set(words))

    def to_mjdata(self, data: CData, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """Write one world's state into a MuJoCo ``MjData`` (rendering), forward done."""
        row = np.ascontiguousarray(np.asarray(data.state)).view(np.float64)
        mujoco.mj_setState(m, d, row, STATE_SPEC)
        mujoco.mj_forward(m, d)
