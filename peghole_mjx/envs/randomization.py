"""Per-episode domain randomisation of the extraction task: one pure, vmappable draw.

The counterpart of MuJoCo Playground's ``randomization_fn``: everything random about an
episode start comes from :func:`randomization_fn` (a pure function of a key and the config's
``randomization`` group), so it can be ``jax.vmap``-ed over keys, replaced by a task variant
(:attr:`PegHoleEnv.randomization_fn <peghole_mjx.envs.extraction.PegHoleEnv>`), or called on
its own to inspect the distribution. Unlike Playground's, it draws per-world quantities that
the env applies to its state (the hole is a mocap body, the friction scales the contact pairs
at each step, the payload scales the peg's mass per world), so one compiled model serves
every world.

The shifts toward a real robot (F/T noise and bias, latencies, tool-frame calibration error,
payload mass; docs/research/transfer.md) are off by default. A draw that is off is not made:
its field holds the neutral value (no bias, no tool error, scale 1) and the env leaves it out
of its computation (:func:`ft_sensor_shifted`, :func:`tool_error_on`, :func:`payload_on`, read
from the config when the step is traced), so an env without shifts computes exactly what it
did before they existed. The shifts' keys are folded from the episode key, so the draws that
existed before (hole, errors, friction, k_xy) are the same with or without them.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from ml_collections import config_dict

from peghole_mjx.control.kinematics import rot_from_rotvec
from peghole_mjx.geometry.specs import MM

#: the F/T entries of the ``randomization`` group (noise, initial bias, drift)
FT_ENTRIES = (
    "ft_noise_force_N",
    "ft_noise_torque_Nm",
    "ft_bias_force_N",
    "ft_bias_torque_Nm",
    "ft_drift_force_N_sqrt_s",
    "ft_drift_torque_Nm_sqrt_s",
)
#: the tool-frame calibration error entries of the ``randomization`` group, (lo, hi) each
TOOL_ENTRIES = ("tool_axial_mm", "tool_lateral_mm", "tool_tilt_deg")
#: what :func:`fold_in` mixes into the episode key for each shift's draw
_FOLD_FT, _FOLD_TOOL, _FOLD_PAYLOAD = 1, 2, 3
#: ... and for a stuck joint's breakaway force (``stuck`` group)
_FOLD_STUCK = 4


def ft_sensor_shifted(r: config_dict.ConfigDict) -> bool:
    """Whether the observed F/T reading has noise or a bias (any F/T entry above 0)."""
    return any(float(r[k]) > 0 for k in FT_ENTRIES)


def tool_error_on(r: config_dict.ConfigDict) -> bool:
    """Whether the controller's believed tool frame may differ from the true one."""
    return any(tuple(r[k]) != (0.0, 0.0) for k in TOOL_ENTRIES)


def payload_on(r: config_dict.ConfigDict) -> bool:
    """Whether the peg's mass may differ from the preset's (the robot's load data)."""
    return tuple(r.payload_mass_scale) != (1.0, 1.0)


def _per_component(force: float, torque: float) -> jax.Array:
    """(6,) of a force figure on the three forces and a torque figure on the three torques."""
    return jnp.array([force] * 3 + [torque] * 3, jnp.float32)


def ft_noise_sd(r: config_dict.ConfigDict) -> jax.Array:
    """(6,) SD of the white noise of each observed F/T component per control step (N, N m)."""
    return _per_component(r.ft_noise_force_N, r.ft_noise_torque_Nm)


def ft_drift_sd(r: config_dict.ConfigDict) -> jax.Array:
    """(6,) SD per sqrt(s) of the random walk of each F/T component's bias."""
    return _per_component(r.ft_drift_force_N_sqrt_s, r.ft_drift_torque_Nm_sqrt_s)


class EpisodeDraw(NamedTuple):
    """The random quantities of one episode start (SI; hole frame where a frame is needed)."""

    hole_offset: jax.Array  # (3,) hole position offset from its nominal position, world, m
    hole_yaw: jax.Array  # () hole rotation about its (vertical) axis, rad
    lateral_error: jax.Array  # (3,) commanded tip offset from the hole axis, hole frame, m
    tilt_mat: jax.Array  # (3, 3) commanded tilt about the hole's x and y axes
    friction_scale: jax.Array  # () factor on the preset's friction coefficients
    k_xy: jax.Array  # () lateral stiffness of the episode, N/m
    rng: jax.Array  # the key the episode continues with
    # the shifts (neutral when off): the F/T bias at the start (6,), N and N m; the believed
    # tool point minus the true one (3,), peg body frame, m, and the believed tool axes in the
    # true ones (3, 3); the peg's mass factor ()
    ft_bias: jax.Array = None
    tool_offset: jax.Array = None
    tool_mat: jax.Array = None
    payload_scale: jax.Array = None
    # a stuck joint's breakaway force, N (:func:`breakaway_draw`; None without one)
    breakaway_N: jax.Array = None


def randomization_fn(
    rng: jax.Array, r: config_dict.ConfigDict, k_xy_fixed_N_m: float
) -> EpisodeDraw:
    """One episode's draw from the ``randomization`` config group ``r``.

    Hole position uniform in a square of half-side ``hole_xy_mm``, yaw uniform in
    ``+-hole_yaw_deg``; commanded lateral error uniform in a disc of radius
    ``lateral_error_mm``, tilt about x and y each uniform in ``+-angular_error_deg``;
    friction scale uniform in ``friction_scale``; k_xy uniform in ``stiffness_N_m`` when its
    upper bound is > 0, else ``k_xy_fixed_N_m``.

    The shifts, each drawn only when on: the F/T bias at the start, Gaussian with SD
    ``ft_bias_force_N`` / ``ft_bias_torque_Nm`` per component; the tool-frame error, an offset
    along the peg axis uniform in ``tool_axial_mm`` (+ = the believed tip above the true one,
    towards the flange), one across it uniform in ``tool_lateral_mm`` in a uniform direction,
    and a tilt of the believed axis uniform in ``tool_tilt_deg`` about a uniform direction
    across it; the payload's mass factor uniform in ``payload_mass_scale``.
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
        **shift_draws(rng, r),
    )


def shift_draws(rng: jax.Array, r: config_dict.ConfigDict) -> dict[str, jax.Array]:
    """The shifts' fields of :class:`EpisodeDraw` (see :func:`randomization_fn`), each from its
    own key folded from the episode key ``rng``; neutral values for a shift that is off."""
    out = {
        "ft_bias": jnp.zeros(6, jnp.float32),
        "tool_offset": jnp.zeros(3, jnp.float32),
        "tool_mat": jnp.eye(3, dtype=jnp.float32),
        "payload_scale": jnp.ones((), jnp.float32),
    }
    if ft_sensor_shifted(r):
        sd = _per_component(r.ft_bias_force_N, r.ft_bias_torque_Nm)
        out["ft_bias"] = sd * jax.random.normal(jax.random.fold_in(rng, _FOLD_FT), (6,))
    if tool_error_on(r):
        k = jax.random.split(jax.random.fold_in(rng, _FOLD_TOOL), 5)

        def uniform(key, lo_hi):
            return jax.random.uniform(key, (), minval=lo_hi[0], maxval=lo_hi[1])

        axial = uniform(k[0], r.tool_axial_mm) * MM
        lateral = uniform(k[1], r.tool_lateral_mm) * MM
        a = jax.random.uniform(k[2], (), maxval=2 * jnp.pi)
        tilt = jnp.deg2rad(uniform(k[3], r.tool_tilt_deg))
        b = jax.random.uniform(k[4], (), maxval=2 * jnp.pi)
        # peg body frame: z points from the mount to the tip, so "towards the flange" is -z
        out["tool_offset"] = jnp.stack([lateral * jnp.cos(a), lateral * jnp.sin(a), -axial])
        out["tool_mat"] = rot_from_rotvec(tilt * jnp.stack([jnp.cos(b), jnp.sin(b), 0.0]))
    if payload_on(r):
        lo, hi = r.payload_mass_scale
        key = jax.random.fold_in(rng, _FOLD_PAYLOAD)
        out["payload_scale"] = jax.random.uniform(key, (), minval=lo, maxval=hi)
    return out


def breakaway_draw(rng: jax.Array, stuck: config_dict.ConfigDict) -> jax.Array:
    """A stuck joint's breakaway force (N) for the episode of key ``rng``: uniform in the
    ``stuck`` group's ``breakaway_N`` range, from its own key folded from the episode key (the
    other draws stay the same with the weld on or off)."""
    lo, hi = stuck.breakaway_N
    key = jax.random.fold_in(rng, _FOLD_STUCK)
    return jax.random.uniform(key, (), minval=lo, maxval=hi)
