"""Per-episode domain randomisation of the extraction task: one pure, vmappable draw.

The counterpart of MuJoCo Playground's ``randomization_fn``: everything random about an
episode start comes from :func:`randomization_fn` (a pure function of a key and the config's
``randomization`` group), so it can be ``jax.vmap``-ed over keys, replaced by a task variant
(:attr:`PegHoleEnv.randomization_fn <peghole_mjx.envs.extraction.PegHoleEnv>`), or called on
its own to inspect the distribution. Unlike Playground's, it draws per-world quantities that
the env applies to its state (the hole is a mocap body, the friction scales the contact pairs
at each step), so one compiled model serves every world.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from ml_collections import config_dict

from peghole_mjx.control.kinematics import rot_from_rotvec
from peghole_mjx.geometry.specs import MM


class EpisodeDraw(NamedTuple):
    """The random quantities of one episode start (SI; hole frame where a frame is needed)."""

    hole_offset: jax.Array  # (3,) hole position offset from its nominal position, world, m
    hole_yaw: jax.Array  # () hole rotation about its (vertical) axis, rad
    lateral_error: jax.Array  # (3,) commanded tip offset from the hole axis, hole frame, m
    tilt_mat: jax.Array  # (3, 3) commanded tilt about the hole's x and y axes
    friction_scale: jax.Array  # () factor on the preset's friction coefficients
    k_xy: jax.Array  # () lateral stiffness of the episode, N/m
    rng: jax.Array  # the key the episode continues with


def randomization_fn(
    rng: jax.Array, r: config_dict.ConfigDict, k_xy_fixed_N_m: float
) -> EpisodeDraw:
    """One episode's draw from the ``randomization`` config group ``r``.

    Hole position uniform in a square of half-side ``hole_xy_mm``, yaw uniform in
    ``+-hole_yaw_deg``; commanded lateral error uniform in a disc of radius
    ``lateral_error_mm``, tilt about x and y each uniform in ``+-angular_error_deg``;
    friction scale uniform in ``friction_scale``; k_xy uniform in ``stiffness_N_m`` when its
    upper bound is > 0, else ``k_xy_fixed_N_m``.
    """
    keys = jax.random.split(rng, 8)
    hole_xy = jax.random.uniform(keys[0], (2,), minval=-1.0, maxval=1.0) * r.hole_xy_mm * MM
    yaw = jax.random.uniform(keys[1], (), minval=-1.0, maxval=1.0) * jnp.deg2rad(r.hole_yaw_deg)
    rad = r.lateral_error_mm * MM * jnp.sqrt(jax.random.uniform(keys[2]))
    ang = jax.random.uniform(keys[3], (), maxval=2 * jnp.pi)
    lat = jnp.array([rad * jnp.cos(ang), rad * jnp.sin(ang), 0.0])
    tilt = jax.random.uniform(keys[4], (2,), minval=-1.0, maxval=1.0) * jnp.deg2rad(
        r.angular_error_deg
    )
    fric = jax.random.uniform(keys[5], (), minval=r.friction_scale[0], maxval=r.friction_scale[1])
    lo, hi = r.stiffness_N_m
    k_xy_draw = jax.random.uniform(keys[6], (), minval=lo, maxval=hi)
    return EpisodeDraw(
        hole_offset=jnp.concatenate([hole_xy, jnp.zeros(1)]),
        hole_yaw=yaw,
        lateral_error=lat,
        tilt_mat=rot_from_rotvec(jnp.array([tilt[0], tilt[1], 0.0])),
        friction_scale=fric,
        k_xy=jnp.where(hi > 0, k_xy_draw, k_xy_fixed_N_m),
        rng=keys[7],
    )
