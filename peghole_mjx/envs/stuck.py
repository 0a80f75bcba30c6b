"""Stuck joints: a peg held in its hole by corrosion or glue, modelled as a breakaway weld.

The model (the env config's ``stuck`` group; docs/guide/stuck.md). With ``stuck.enabled`` the
scene holds one equality constraint of type weld, :data:`WELD_NAME`, between the peg body and
the hole body (a mocap body), anchored at the hole mouth and holding the peg at its inserted
pose relative to the hole (:func:`pose_weld`: the pose of the ``inserted`` keyframe; every
episode starts at that pose in the moved hole, by the reset's IK). It is active at every
episode start and releases for the rest of the episode once the axial force the F/T sensor
reads, |F_z| (hole frame, the peg's weight removed: the reading of the ``fz_N`` metric, which
quasi-statically carries the weld's load), reaches the episode's breakaway force
(:func:`~peghole_mjx.envs.randomization.breakaway_draw`) at any physics substep of a control
step (:func:`released`). The release lands at the end of that control step: the weld is
switched off between control steps (20 ms at 50 Hz), so it holds for the rest of the step in
which the force first reaches the breakaway force.

The weld's softness is MuJoCo's solref ``(stuck.timeconst_s, 1)`` (critically damped) with
MuJoCo's default solimp; its contacts with the walls are the scene's as without it.

Engines: the weld's switch is MuJoCo's ``eq_active`` on both, written by the engine's
``set_eq_active``: MJX reads ``mjx.Data.eq_active`` in its constraint rows; MuJoCo C carries it
in the integration state row (``mjSTATE_EQ_ACTIVE``) that the engine passes between steps.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from ml_collections import config_dict

from peghole_mjx.envs import iiwa_constants as names

#: the weld's name in the scene
WELD_NAME = "stuck_weld"


def enabled(c: config_dict.ConfigDict) -> bool:
    """Whether the env config ``c`` has a stuck joint (read when the env is built and traced)."""
    return bool(c.stuck.enabled)


def weld_solref(stuck: config_dict.ConfigDict) -> tuple[float, float]:
    """The weld's solref: the ``stuck`` group's time constant (s), damping ratio 1."""
    return (float(stuck.timeconst_s), 1.0)


def add_weld(spec: mujoco.MjSpec, stuck: config_dict.ConfigDict) -> None:
    """Add the (active) weld between the peg and the hole bodies to the scene ``spec``; its
    pose is set on the compiled model by :func:`pose_weld`."""
    spec.add_equality(
        name=WELD_NAME,
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=names.PEG_BODY,
        name2=names.HOLE_BODY,
        solref=weld_solref(stuck),
        active=True,
    )


def pose_weld(m: mujoco.MjModel) -> None:
    """Set the weld of the compiled model ``m`` to hold the peg at its pose in the hole of the
    ``inserted`` keyframe, anchored at the hole mouth (MuJoCo's weld data: anchor in the hole
    body's frame, then the anchor's pose in the peg body's frame, then the torque scale)."""
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(names.START_KEYFRAME).id)
    mujoco.mj_forward(m, d)
    peg, hole = m.body(names.PEG_BODY).id, m.body(names.HOLE_BODY).id
    mouth = d.site_xpos[m.site(names.HOLE_MOUTH_SITE).id]
    R_peg, R_hole = d.xmat[peg].reshape(3, 3), d.xmat[hole].reshape(3, 3)
    q_rel = np.zeros(4)
    q_peg_inv = np.zeros(4)
    mujoco.mju_negQuat(q_peg_inv, d.xquat[peg])
    mujoco.mju_mulQuat(q_rel, q_peg_inv, d.xquat[hole])
    i = m.equality(WELD_NAME).id
    m.eq_data[i, 0:3] = R_hole.T @ (mouth - d.xpos[hole])
    m.eq_data[i, 3:6] = R_peg.T @ (mouth - d.xpos[peg])
    m.eq_data[i, 6:10] = q_rel
    m.eq_data[i, 10] = 1.0


def released(peak_fz_N: jax.Array, breakaway_N: jax.Array, released_before: jax.Array):
    """1.0 once the weld has released: it had, or this control step's largest |F_z| over its
    substeps (N) reached the breakaway force (N)."""
    return jnp.maximum(released_before, (peak_fz_N >= breakaway_N).astype(jnp.float32))
