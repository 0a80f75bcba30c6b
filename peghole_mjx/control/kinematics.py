"""Rotation helpers, MJX Jacobians and the Newton IK used by the impedance law and the envs.

One place for the rotation conventions (rotation vector = axis x angle, rad) and for the one
use of MJX's private ``mujoco.mjx._src.support`` module (point Jacobian, full inertia
matrix; imported through :mod:`peghole_mjx.core._mjx`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx.core._mjx import mjx, support


def rotvec_from_mat(R: jax.Array) -> jax.Array:
    """Rotation vector (axis * angle, rad) of a rotation matrix; smooth at zero angle."""
    s = 0.5 * jnp.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    sin = jnp.linalg.norm(s)
    cos = 0.5 * (jnp.trace(R) - 1.0)
    angle = jnp.arctan2(sin, cos)
    scale = jnp.where(sin > 1e-9, angle / jnp.maximum(sin, 1e-9), 1.0)
    return s * scale


def rot_from_rotvec(v: jax.Array) -> jax.Array:
    """Rotation matrix of a rotation vector (Rodrigues' formula, small-angle safe)."""
    th = jnp.linalg.norm(v)
    k = v / jnp.maximum(th, 1e-12)
    K = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return jnp.eye(3) + jnp.sin(th) * K + (1 - jnp.cos(th)) * K @ K


def rot_y(a: jax.Array) -> jax.Array:
    """Rotation by ``a`` rad about the y axis."""
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: jax.Array) -> jax.Array:
    """Rotation by ``a`` rad about the z axis."""
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def point_jacobian(
    m: mjx.Model, d: mjx.Data, point: jax.Array, body_id: int
) -> tuple[jax.Array, jax.Array]:
    """(nv, 3) translational and rotational Jacobians of a world point on a body (MJX)."""
    return support.jac(m, d, point, body_id)


def full_inertia(m: mjx.Model, d: mjx.Data) -> jax.Array:
    """The (nv, nv) joint-space inertia matrix M(q) (MJX)."""
    return support.full_m(m, d)


def point_on_body(d: mjx.Data, body_id: int, local: jax.Array) -> jax.Array:
    """World position of a point given in a body's frame."""
    return d.xpos[body_id] + d.xmat[body_id] @ jnp.asarray(local)


def newton_ik(
    m: mjx.Model,
    d0: mjx.Data,
    q0: jax.Array,
    qadr,
    dadr,
    body_id: int,
    point_local,
    pos_target: jax.Array,
    mat_target: jax.Array,
    iterations: int,
) -> jax.Array:
    """Joint angles (at ``qadr``) that put a body point at ``pos_target`` with the body
    rotation ``mat_target``: ``iterations`` least-squares Newton steps from ``q0``.

    ``d0``: data holding everything else (e.g. mocap poses); only ``qpos[qadr]`` changes.
    The MJX engines' reset IK; the ``mujoco`` engine runs the same Newton steps in MuJoCo C
    (:meth:`peghole_mjx.sim.engine_mujoco.MujocoEngine.solve_ik`).

    A jitted function of its own (:func:`_newton_ik`, the indices and the body point as
    static arguments): JAX keeps its trace, so the second and later graphs that hold it (an
    env's reset, its auto-reset inside a training step, an evaluation's reset) reuse it
    instead of tracing MJX's kinematics again (about 2 s each on a 2-core CPU, measured
    2026-12-03). Inside another jitted function it is inlined: the same start states as
    the IK written inline, bit for bit (tests/test_env_config.py).
    """
    return _newton_ik(
        m,
        d0,
        q0,
        pos_target,
        mat_target,
        qadr=tuple(int(i) for i in qadr),
        dadr=tuple(int(i) for i in dadr),
        body_id=int(body_id),
        point_local=tuple(float(x) for x in point_local),
        iterations=int(iterations),
    )


@functools.partial(
    jax.jit, static_argnames=("qadr", "dadr", "body_id", "point_local", "iterations")
)
def _newton_ik(m, d0, q0, pos_target, mat_target, *, qadr, dadr, body_id, point_local, iterations):
    """:func:`newton_ik` with hashable static arguments."""
    qadr, dadr = np.asarray(qadr), np.asarray(dadr)

    def newton(q, _):
        d = d0.replace(qpos=d0.qpos.at[qadr].set(q))
        d = mjx.kinematics(m, d)
        d = mjx.com_pos(m, d)
        R = d.xmat[body_id]
        p = d.xpos[body_id] + R @ jnp.asarray(point_local)
        jacp, jacr = point_jacobian(m, d, p, body_id)
        J = jnp.concatenate([jacp.T, jacr.T])[:, dadr]
        err = jnp.concatenate([pos_target - p, rotvec_from_mat(mat_target @ R.T)])
        dq = jnp.linalg.lstsq(J, err)[0]
        return q + dq, None

    q, _ = jax.lax.scan(newton, q0, None, length=iterations)
    return q
