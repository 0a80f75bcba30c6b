"""The peg extraction task in MJX: shared by RectExtract and DualExtract (thesis Ch 4).

API (MuJoCo Playground / Brax style): ``reset(rng) -> State``, ``step(state, action) -> State``,
``State(data, obs, reward, done, metrics, info)``, all pure and jit/vmap-able.

The progress of a step is ``dz = h_t - h_{t-1}`` (mm, h = tip depth below the mouth),
negative when the peg comes out, so the thesis's reward term ``-w_d dz`` (eq 4.4) rewards
pulling out.

Control. An action moves the commanded tip pose and feed-forward force; the impedance law
(:mod:`peghole_mjx.control`) runs at every physics substep and tracks the commanded pose with
its compliance centre ``L_C`` above the tip. See :class:`PegHoleEnv` for the tables.

Shifts toward a real robot (the ``randomization`` group's F/T, latency, tool-frame and payload
entries; all off by default, and then left out of the computation, so the published policies'
envs compute exactly what they did before the entries existed):

* the F/T sensor as the policy observes it: white noise per control step and a bias (an offset
  at the start that drifts as a random walk, ``info["ft_bias"]``), and with a payload draw the
  tare error (the nominal peg weight removed from a heavier or lighter peg's). Only the
  observation sees them: the metrics, the reward and the jam rule keep the true contact wrench,
  so a shifted cell measures the same physical forces as the nominal one;
* latencies: the policy observes the observation of ``obs_latency_steps`` steps ago
  (``info["obs_buffer"]``), the robot applies the action of ``action_latency_steps`` steps ago
  (``info["action_buffer"]``) and holds its command until the first one arrives;
* a tool-frame calibration error: the law (both twins) and the commands use the believed tool
  frame (``info["tool_offset"]``, ``info["tool_mat"]``), which starts at the believed tip (a
  robot entering impedance mode holds the pose it measures); depth, success and metrics use
  the true tip;
* the payload: the peg's mass and inertia per world times ``info["payload_scale"]`` (both
  engines), while the F/T tare and the law's gravity compensation keep the nominal mass.

A stuck joint (the ``stuck`` group, off by default and then absent from the scene and the
state): the peg starts welded in its hole and the weld releases once the axial F/T force
reaches the episode's breakaway force (:mod:`peghole_mjx.envs.stuck`); ``info`` and ``metrics``
then hold ``released``, ``release_time_s`` and ``breakaway_N``.

The pieces of a step that hold a number of the config are pure functions of the config
(:func:`decode_action`, :func:`impedance_params`, :func:`observation`, :func:`termination`,
:func:`~peghole_mjx.envs.reward.reward_terms`, and
:func:`~peghole_mjx.envs.randomization.randomization_fn` at reset).
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from ml_collections import config_dict

from peghole_mjx.control import ImpedanceParams, make_params
from peghole_mjx.control.kinematics import rot_z
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs import iiwa_constants as names
from peghole_mjx.envs import stuck
from peghole_mjx.envs.base import PegHoleBase, State
from peghole_mjx.envs.metrics import STUCK_METRICS, zero_metrics
from peghole_mjx.envs.randomization import (
    breakaway_draw,
    ft_drift_sd,
    ft_noise_sd,
    ft_sensor_shifted,
    payload_on,
    randomization_fn,
    tool_error_on,
)
from peghole_mjx.envs.reward import outcome_terms, reward_terms
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
from peghole_mjx.geometry.specs import MM
from peghole_mjx.sim.engines import world_where

#: the scripted baseline's constant pulling speed (thesis: 150 mm in about 7.6 s); with
#: ``action.residual`` the policy's pull is a residual on it
SCRIPTED_SPEED_M_S = 0.02


def clean_action(action: jax.Array) -> jax.Array:
    """The action clipped to [-1, 1], NaN entries set to 0 (the step also flags the world)."""
    return jnp.clip(jnp.where(jnp.isnan(action), 0.0, action), -1.0, 1.0)


def hold_command(decoded, info, valid):
    """The decoded command (:func:`decode_action`'s tuple) where ``valid``, else the command in
    effect (``info``): a robot with action latency holds its command until the first action
    arrives."""
    held = (info["cmd_tip"], info["wrench_ff"], info["k_xy"], info["k_rot"], info["L_C"])
    return tuple(jnp.where(valid, new, old) for new, old in zip(decoded, held, strict=True))


def latency_buffers(c: config_dict.ConfigDict, obs, action_size: int) -> dict[str, jax.Array]:
    """A reset's latency buffers (``randomization`` group; none without latency), oldest
    first: the observations of the last ``obs_latency_steps`` steps (all the first one) and
    the ``action_latency_steps`` actions sent but not yet applied (none sent: zeros, held)."""
    r, out = c.randomization, {}
    if r.obs_latency_steps:
        out["obs_buffer"] = jnp.tile(obs, (r.obs_latency_steps, 1))
    if r.action_latency_steps:
        out["action_buffer"] = jnp.zeros((r.action_latency_steps, action_size))
    return out


def compliance_actions(
    c: config_dict.ConfigDict, peg_length_m: float
) -> dict[str, tuple[int, float, float]]:
    """Each compliance-strategy action present: name (``k_xy``, ``k_rot``, ``L_C``) ->
    (action index, value at -1, value at +1), in N/m, N m/rad and m."""
    s = c.stiffness
    ranges = {}
    if c.compliance_strategy:
        ranges["k_xy"] = (s.k_xy_min_N_m, s.k_xy_max_N_m)
        if c.compliance_rotation:
            ranges["k_rot"] = (s.k_rot_min_Nm_rad, s.k_rot_max_Nm_rad)
        if c.learn_compliance_centre:
            ranges["L_C"] = (0.0, peg_length_m)
    return {name: (6 + i, *r) for i, (name, r) in enumerate(ranges.items())}


def fixed_compliance(c: config_dict.ConfigDict) -> dict[str, float]:
    """k_xy (N/m), K_theta (N m/rad) and L_C (m) of the fixed-compliance method (CS off)."""
    s = c.stiffness
    return {"k_xy": s.k_xy_N_m, "k_rot": s.k_rot_Nm_rad, "L_C": s.compliance_centre_mm * MM}


def scripted_action(
    c: config_dict.ConfigDict, compliance_actions, speed_m_s: float = SCRIPTED_SPEED_M_S
) -> np.ndarray:
    """The action (eq 4.3 layout, before any residual) of the scripted baseline: a straight
    pull at ``speed_m_s``, no lateral offset, no feed-forward, the compliance-strategy gains
    held at :func:`fixed_compliance`'s values."""
    a = np.zeros(6 + len(compliance_actions), np.float32)
    a[2] = speed_m_s / c.action.max_speed_m_s
    fixed = fixed_compliance(c)
    for name, (i, lo, hi) in compliance_actions.items():
        a[i] = 2 * (fixed[name] - lo) / (hi - lo) - 1
    return np.clip(a, -1.0, 1.0)


#: the action entries a residual policy leaves at the scripted pull's zero: the increments of
#: the lateral offset (0-1) and of the feed-forward force (3-5), integrators that sum any bias
#: of a policy's mean into a jam (docs/research/residual.md)
RESIDUAL_HELD = (0, 1, 3, 4, 5)


def residual_affine(
    c: config_dict.ConfigDict, compliance_actions
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(offset, gain)`` of a residual env (``action.residual``; None otherwise): the step
    applies ``clip(offset + gain * action, -1, 1)``. The pull (entry 2) is the scripted 20 mm/s
    plus ``action.residual_scale`` times its action; the learned gains (6 on) are the action
    itself, as without a residual; the integrators (:data:`RESIDUAL_HELD`) are held at 0."""
    if not c.action.residual:
        return None
    offset = np.zeros(6 + len(compliance_actions), np.float32)
    gain = np.ones_like(offset)
    offset[2] = scripted_action(c, compliance_actions)[2]
    gain[2] = c.action.residual_scale
    gain[list(RESIDUAL_HELD)] = 0.0
    return offset, gain


def residual_action(action, c: config_dict.ConfigDict, compliance_actions) -> jax.Array:
    """The action the step applies: ``action`` itself (NaN -> 0, clipped), or on a residual env
    :func:`residual_affine`'s ``clip(offset + gain * action, -1, 1)``: a residual policy on the
    scripted pull (Johannink et al. 2019, "Residual Reinforcement Learning for Robot
    Control") that learns the pulling speed and the compliance gains."""
    a = clean_action(action)
    affine = residual_affine(c, compliance_actions)
    if affine is None:
        return a
    offset, gain = (jnp.asarray(v) for v in affine)
    return jnp.clip(offset + gain * a, -1.0, 1.0)


def decode_action(action, info, c: config_dict.ConfigDict, compliance_actions):
    """Commanded tip pose, feed-forward force, k_xy, K_theta and L_C after this action.

    ``compliance_actions``: :attr:`PegHoleEnv.compliance_actions` (index and range of each
    learned gain). The feed-forward force is held within ``limits.max_force_N``, its lateral
    components also within ``action.max_ff_xy_N``. With ``action.residual`` the pull is a
    residual on the scripted 20 mm/s and the integrators are held (:func:`residual_action`).
    """
    a = residual_action(action, c, compliance_actions)
    H = info["hole_mat"]
    dxy = a[:2] * c.action.max_step_offset_mm * MM
    dz = a[2] * c.action.max_speed_m_s * c.ctrl_dt
    cmd_tip = info["cmd_tip"] + H @ jnp.array([dxy[0], dxy[1], dz])
    fx, fy, fz = c.limits.max_force_N
    ff_xy = c.action.max_ff_xy_N
    cap = jnp.asarray((min(fx, ff_xy), min(fy, ff_xy), fz), jnp.float32)
    wrench_ff = jnp.clip(info["wrench_ff"] + a[3:6] * c.action.max_force_step_N, -cap, cap)
    gains = {k: info[k] for k in ("k_xy", "k_rot", "L_C")}
    for name, (i, lo, hi) in compliance_actions.items():  # [-1, 1] -> [lo, hi]
        gains[name] = lo + 0.5 * (a[i] + 1.0) * (hi - lo)
    return cmd_tip, wrench_ff, gains["k_xy"], gains["k_rot"], gains["L_C"]


def impedance_params(
    c: config_dict.ConfigDict, k_xy, k_rot, L_C, wrench_ff_local, q_null
) -> ImpedanceParams:
    """The impedance law's parameters of a control step (``stiffness`` group of the config).

    ``wrench_ff_local``: the feed-forward force in the compliance (commanded) frame.
    """
    s = c.stiffness
    return make_params(
        L_C,
        q_null,
        stiffness=jnp.stack([k_xy, k_xy, s.k_z_N_m, k_rot, k_rot, k_rot]).astype(jnp.float32),
        damping_ratio=s.damping_ratio,
        wrench_ff=jnp.concatenate([wrench_ff_local, jnp.zeros(3)]),
        null_gains=(s.null_stiffness_Nm_rad, s.null_damping_Nms_rad),
    )


def observation(
    pos,
    rot,
    info,
    c: config_dict.ConfigDict,
    flange_z0_m: float,
    peg_length_m: float,
    cmd_offset_m=None,
) -> jax.Array:
    """The observation (table of :class:`PegHoleEnv`) from the flange pose (hole frame:
    position ``pos`` in m, tilt ``rot`` as a rotation vector in rad) and ``info``;
    ``cmd_offset_m``: the commanded tip minus the tip (hole frame, m), read with
    ``obs.commands``."""
    o = c.obs
    f, t = info["wrench"][:3], info["wrench"][3:]
    parts = [
        pos[:2] / MM,
        ((pos[2] - flange_z0_m) / peg_length_m)[None],
        f / o.force_scale_N,
        jnp.rad2deg(rot),
    ]
    if o.torques:
        parts.append(t / o.torque_scale_Nm)
    if o.stiffness:
        parts.append(
            jnp.stack(
                [
                    info["k_xy"] / o.k_xy_scale_N_m,
                    info["k_rot"] / o.k_rot_scale_Nm_rad,
                    info["L_C"] / peg_length_m,
                ]
            )
        )
    if o.prev_action:
        parts.append(info["prev_action"])
    if o.commands:  # the two integrators the actions drive, otherwise hidden from the policy
        parts.append(info["wrench_ff"] / o.force_scale_N)
        parts.append(cmd_offset_m / MM)
    if o.time_left:  # the share of the episode's time limit still left: 1 at the start, 0 at it
        parts.append((1.0 - info["step"].astype(jnp.float32) / c.episode_length)[None])
    obs = jnp.concatenate(parts)
    return jnp.where(jnp.isfinite(obs), obs, 0.0)


def termination(fxy_N, depth_mm, jam_time_prev_s, step, nan, overflow, c: config_dict.ConfigDict):
    """``(jam_time, jammed, success, failure, done)`` of a step: success ``success_margin_mm``
    above the mouth; failure on jamming (|f_xy| > ``jam_force_N`` for ``jam_time_s``), NaN,
    contact overflow or the ``episode_length`` limit."""
    jam_time = jnp.where(fxy_N > c.jam_force_N, jam_time_prev_s + c.ctrl_dt, 0.0)
    jammed = (jam_time >= c.jam_time_s).astype(jnp.float32)
    success = (depth_mm < -c.success_margin_mm).astype(jnp.float32) * (1.0 - nan)
    timeout = (step >= c.episode_length).astype(jnp.float32)
    failure = jnp.maximum(jnp.maximum(jammed, nan), jnp.maximum(timeout, overflow))
    failure = failure * (1.0 - success)
    done = jnp.maximum(success, failure)
    return jam_time, jammed, success, failure, done


class PegHoleEnv(PegHoleBase):
    """Pull a peg out of its hole with the iiwa's impedance layer (thesis Ch 4).

    Observation (eq 4.2, hole frame, scaled to order one; scales from ``config.obs``):

    | index | quantity | unit / scale |
    |---|---|---|
    | 0-1 | flange x, y offset from the hole axis | mm |
    | 2 | flange height above its start, / peg length | 0 inserted, 1 out |
    | 3-5 | F/T sensor force Fx, Fy, Fz (peg weight removed) | / 20 N |
    | 6-8 | flange tilt theta, phi, psi (rotation vector vs. straight down) | deg |
    | + | optional: torques (/3 N m), k_xy (/1000 N/m), K_theta (/300 N m/rad), L_C (/L), | |
    |   | previous action; commands: the accumulated feed-forward force (/20 N, hole | |
    |   | frame) and the commanded tip minus the tip (mm, hole frame); time_left: the share | |
    |   | of ``episode_length`` still left (1 at the start, 0 at the time limit) | |

    Action (eq 4.3), each in [-1, 1]:

    | index | quantity | mapping |
    |---|---|---|
    | 0-1 | dx, dy: commanded tip offset | x 0.1 mm per step |
    | 2 | dz: commanded pull (+ = out) | x 0.1 m/s x ctrl_dt |
    | 3-5 | dFx, dFy, dFz: feed-forward change | x 2 N per step, total within 20/20/60 N [1] |
    | 6 | k_xy (compliance_strategy) | [50, 1000] N/m |
    | 7 | K_theta (compliance_strategy and compliance_rotation) | [10, 300] N m/rad |
    | last | L_C (learn_compliance_centre) | [0, L] |

    [1] ``limits.max_force_N``, the lateral total also within ``action.max_ff_xy_N``.

    Reward: ``reward_config.kind`` (:mod:`peghole_mjx.envs.reward`), named terms logged as
    ``metrics["reward/<term>"]``. ``thesis``, eq (4.4) with the Table 4.1 weights:

    | term | value |
    |---|---|
    | progress | ``-w_d dz`` with dz = change of tip depth in mm (pulling out is positive) |
    | force | ``-w_f ||f_xy|| / 20 N`` |
    | stiffness | ``-w_stf ||k_xy|| / (1000 N/m)`` (k_xy in N/mm) |
    | rot_stiffness | ``-w_stf_rot K_theta / (300 N m/rad)``: not in eq 4.4, 0 by default |
    | extraction_force | ``-w_fz |f_z| / 1 N``: not in eq 4.4, 0 by default |
    | end | ``+1`` on success, ``-1`` on failure (jamming, NaN, time limit) |

    ``outcome`` (training's default): ``time`` ``-time_cost`` per step; ``force``
    ``-time_cost w_contact min(|f| / 20 N, 1)``; ``progress`` the potential-based shaping
    ``gamma Phi(s') - Phi(s)``; ``end`` ``-time_cost (1 + w_contact) / (1 - gamma)`` on a
    terminal failure (jamming, NaN, overflow). A time-out alone sets ``info["truncation"]``,
    unless ``reward_config.time_limit`` is ``failure``: then it is a terminal failure too, and
    the time limit is part of the task (the observation must then carry ``obs.time_left``).

    Episode starts are drawn by :attr:`randomization_fn`
    (:func:`peghole_mjx.envs.randomization.randomization_fn`; a task variant may replace it).
    """

    #: ``(rng, config.randomization, k_xy_fixed_N_m) -> EpisodeDraw``: the episode start's draw
    randomization_fn = staticmethod(randomization_fn)

    # ------------------------------------------------------------------ properties
    @property
    def compliance_actions(self) -> dict[str, tuple[int, float, float]]:
        """Each compliance-strategy action present (see :func:`compliance_actions`)."""
        return compliance_actions(self._config, self.peg_length_m)

    @property
    def fixed_compliance(self) -> dict[str, float]:
        """k_xy, K_theta and L_C of the fixed-compliance method (CS off; the baseline)."""
        return fixed_compliance(self._config)

    @property
    def action_size(self) -> int:
        return 6 + len(self.compliance_actions)

    @functools.cached_property
    def observation_size(self) -> int:
        """The length of :func:`observation`'s output for this config (traced on zeros, not
        through ``reset``: a reset trace costs seconds)."""
        z = jnp.zeros
        info = {"wrench": z(6), "k_xy": z(()), "k_rot": z(()), "L_C": z(())}
        info |= {"prev_action": z(self.action_size), "wrench_ff": z(3), "step": z((), jnp.int32)}
        out = jax.eval_shape(lambda: observation(z(3), z(3), info, self._config, 0.0, 1.0, z(3)))
        return int(out.shape[-1])

    # ------------------------------------------------------------------ reset
    def _solve_start(self, hole_pos, hole_mat):
        """Joint angles with the peg inserted in a moved hole: Newton steps from the keyframe,
        in the engine's kinematics (:meth:`~peghole_mjx.sim.engines.MjxEngine.solve_ik`)."""
        return self.engine.solve_ik(
            self._init_q[self._qadr],
            pos_target=hole_pos + hole_mat @ jnp.array([0.0, 0.0, -(self._depth0_mm * MM)]),
            mat_target=hole_mat @ jnp.asarray(TOOL_DOWN_MAT),
            point_local=self._tip_local,
            iterations=names.START_IK_ITERATIONS,
        )

    def reset(self, rng: jax.Array) -> State:
        """A fully re-randomised episode start (never a cached first state)."""
        return self.reset_finish(self.reset_start(rng))

    def reset_start(self, rng: jax.Array) -> dict[str, Any]:
        """The first half of :meth:`reset`: the episode's draw, the moved hole and the arm's
        joint angles with the peg inserted there (the engine's IK: MJX's kinematics on the MJX
        engines, MuJoCo C on ``mujoco``, where no MJX graph is compiled).

        Kept apart so that a caller can compile it as its own graph: on the MJX engines this
        half, MJX's IK, is most of the reset's compile time."""
        fixed = self.fixed_compliance
        draw = self.randomization_fn(rng, self._config.randomization, fixed["k_xy"])
        if stuck.enabled(self._config):
            draw = draw._replace(breakaway_N=breakaway_draw(rng, self._config.stuck))
        yaw = draw.hole_yaw
        hole_pos = jnp.asarray(self._hole_pos0) + draw.hole_offset
        hole_mat = rot_z(yaw)
        q = self._solve_start(hole_pos, hole_mat)
        hole_quat = jnp.array([jnp.cos(yaw / 2), 0.0, 0.0, jnp.sin(yaw / 2)])
        return {
            "draw": draw,
            "q": q,
            "hole_pos": hole_pos,
            "hole_mat": hole_mat,
            "hole_quat": hole_quat,
        }

    def reset_finish(self, start: dict[str, Any]) -> State:
        """The second half of :meth:`reset`: the engine's first state at ``start``'s joint
        angles, the commanded pose errors, the episode's info and first observation."""
        fixed = self.fixed_compliance
        rc = self._config.randomization
        draw, hole_pos, hole_mat = start["draw"], start["hole_pos"], start["hole_mat"]
        mass_scale = draw.payload_scale if payload_on(rc) else None
        data = self.engine.init_data(start["q"], hole_pos, start["hole_quat"], mass_scale)
        r = self.engine.readout(data)
        shifts = {}
        if tool_error_on(rc):
            shifts |= {"tool_offset": draw.tool_offset, "tool_mat": draw.tool_mat}
        if payload_on(rc):
            shifts["payload_scale"] = draw.payload_scale
        # commanded pose errors (hole frame): lateral offset in a disc, tilt about x and y; the
        # command starts at the tip the controller believes (the true one without a tool error)
        cmd_tip = self._tool_tip_world(r, shifts) + hole_mat @ draw.lateral_error
        cmd_mat = hole_mat @ draw.tilt_mat @ jnp.asarray(TOOL_DOWN_MAT)
        info = {
            "rng": draw.rng,
            "cmd_tip": cmd_tip,
            "cmd_mat": cmd_mat,
            "hole_pos": hole_pos,
            "hole_mat": hole_mat,
            "wrench_ff": jnp.zeros(3),
            "k_xy": jnp.asarray(draw.k_xy, jnp.float32),
            "k_rot": jnp.asarray(fixed["k_rot"], jnp.float32),
            "L_C": jnp.asarray(fixed["L_C"], jnp.float32),
            "friction_scale": draw.friction_scale,
            "depth_mm": self._depth_mm(r, hole_pos, hole_mat),
            "jam_time": jnp.zeros(()),
            "prev_action": jnp.zeros(self.action_size),
            "step": jnp.zeros((), jnp.int32),
            "success": jnp.zeros(()),
            "failure": jnp.zeros(()),
            "sum_fz": jnp.zeros(()),
            "sum_fxy": jnp.zeros(()),
            "peak_fz": jnp.zeros(()),
            "nan": jnp.zeros(()),
            # 1 when the episode ended by its time limit alone under the outcome reward (a
            # truncation the learner bootstraps, Brax's convention); 0 under the thesis's
            "truncation": jnp.zeros(()),
            # the F/T sensor is zeroed at the start (no contact there; the arm is not yet
            # under control, so the raw reading would hold its free-fall transient)
            "wrench": jnp.zeros(6),
            **shifts,
        }
        metrics = zero_metrics(stuck=self._weld is not None)
        if self._weld is not None:  # the weld holds at the start (the engines' eq_active0)
            info |= {"breakaway_N": draw.breakaway_N, "released": jnp.zeros(())}
            info["release_time_s"] = jnp.zeros(())
            metrics["breakaway_N"] = draw.breakaway_N
        key = None
        if ft_sensor_shifted(rc):
            info["rng"], key = jax.random.split(draw.rng)
            info["ft_bias"] = draw.ft_bias
        obs = self._obs(r, info, self._sensed_wrench(info["wrench"], info, key))
        info |= latency_buffers(self._config, obs, self.action_size)
        return State(data, obs, jnp.zeros(()), jnp.zeros(()), metrics, info)

    # ------------------------------------------------------------------ shifts
    def _tool_tip_world(self, r, info):
        """The tip the controller believes (world): the true tip without a tool-frame error."""
        if "tool_offset" not in info:
            return self._tip_world(r)
        return r.peg_pos + r.peg_mat @ (jnp.asarray(self._tip_local) + info["tool_offset"])

    def _sensed_wrench(self, wrench, info, key):
        """The F/T wrench the policy observes (hole frame): the true ``wrench`` plus, with the
        shifts on, the tare error of a payload draw, the bias and white noise (``key``)."""
        rc = self._config.randomization
        if "payload_scale" in info:  # the nominal weight removed from the true one
            error = (1.0 - info["payload_scale"]) * self._peg_mass * jnp.asarray(self._gravity)
            wrench = wrench + jnp.concatenate([info["hole_mat"].T @ error, jnp.zeros(3)])
        if key is not None:
            wrench = wrench + info["ft_bias"] + ft_noise_sd(rc) * jax.random.normal(key, (6,))
        return wrench

    def _delayed_obs(self, obs, info):
        """The observation the policy sees with ``obs_latency_steps`` of latency (``info``'s
        buffer updated in place); ``obs`` itself without."""
        if "obs_buffer" not in info:
            return obs
        buf = info["obs_buffer"]
        info["obs_buffer"] = jnp.concatenate([buf[1:], obs[None]])
        return buf[0]

    # ------------------------------------------------------------------ step
    def _decode_action(self, action, info):
        return decode_action(action, info, self._config, self.compliance_actions)

    def _obs(self, r, info, wrench=None) -> jax.Array:
        """The observation (no latency); ``wrench``: the sensed one if it differs from
        ``info["wrench"]`` (:meth:`_sensed_wrench`)."""
        pos, rot = self._flange_pose(r, info)
        cmd_offset = None
        if self._config.obs.commands:
            cmd_offset = info["hole_mat"].T @ (info["cmd_tip"] - self._tool_tip_world(r, info))
        if wrench is not None and wrench is not info["wrench"]:
            info = {**info, "wrench": wrench}
        return observation(
            pos, rot, info, self._config, self._flange_z0, self.peg_length_m, cmd_offset
        )

    def _physics(self, data, info, cmd_tip_prev, cmd_tip, wrench_ff, k_xy, k_rot, L_C):
        """Run the substeps with the impedance law tracking a linearly moving target:
        ``(data, wrench, peak_fz)``, the F/T wrench averaged over the substeps and, with a stuck
        joint, the largest |F_z| of a substep (N; None without one)."""
        c = self._config
        cmd_mat = info["cmd_mat"]
        axis = cmd_mat[:, 2]  # peg axis (towards the tip) of the commanded pose
        vel = (cmd_tip - cmd_tip_prev) / c.ctrl_dt
        # force feed-forward: hole frame -> compliance (commanded) frame
        ff = cmd_mat.T @ (info["hole_mat"] @ wrench_ff)
        params = impedance_params(c, k_xy, k_rot, L_C, ff, self._init_q[self._qadr])
        if "tool_offset" in info:  # the law holds the tool frame it believes
            params = params._replace(tool_offset=info["tool_offset"], tool_mat=info["tool_mat"])
        mass_scale, peg_mass = None, None
        if "payload_scale" in info:  # the law compensates the nominal weight only
            mass_scale = info["payload_scale"]
            peg_mass = self._peg_mass * mass_scale
            load = (mass_scale - 1.0) * self._peg_mass * jnp.asarray(self._gravity)
            params = params._replace(load_error=load.astype(params.L_C.dtype))
        # the compliance centre's commanded position at the end of each substep: the tip
        # target moving linearly from the last command to this one
        frac = jnp.arange(1, self._n_substeps + 1, dtype=jnp.float32) / self._n_substeps
        tips = cmd_tip_prev + frac[:, None] * (cmd_tip - cmd_tip_prev)
        targets = tips - L_C * axis

        def sense(reading):  # the true contact wrench (the true peg weight removed)
            f, t = self.contact_wrench(reading, info["hole_mat"], peg_mass)
            return jnp.concatenate([f, t])

        extra = {} if mass_scale is None else {"mass_scale": mass_scale}
        data, wrenches = self.engine.substeps(
            data, targets, cmd_mat, vel, params, info["friction_scale"], sense, **extra
        )
        # the F/T reading averaged over the control period (a sensor's anti-aliasing filter):
        # single-substep contact impulses do not reach the observation or the force metrics
        wrench = jnp.mean(jnp.where(jnp.isfinite(wrenches), wrenches, 0.0), axis=0)
        peak_fz = None
        if self._weld is not None:  # the largest |F_z| of a substep
            peak_fz = jnp.max(jnp.abs(jnp.where(jnp.isfinite(wrenches[:, 2]), wrenches[:, 2], 0.0)))
        return data, wrench, peak_fz

    def _reward(self, info, depth, f, k_xy, k_rot, success, failure, terminal_failure):
        """``(terms, truncation)`` of a step under ``reward_config.kind`` (envs/reward.py):
        the thesis's eq (4.4), where a time-out is a terminal failure (truncation 0), or the
        outcome reward, where a time-out alone is a truncation and not an outcome.
        ``terminal_failure``: jamming, NaN or contact overflow, and the time limit when
        ``reward_config.time_limit`` is ``failure``."""
        c = self._config
        rc = c.reward_config
        if rc.kind == "thesis":
            fxy, fz = jnp.linalg.norm(f[:2]), jnp.abs(f[2])
            dz = depth - info["depth_mm"]
            terms = reward_terms(dz, fxy, k_xy, success, failure, rc, k_rot, fz)
            return terms, jnp.zeros(())
        margin = c.success_margin_mm
        terms = outcome_terms(
            info["depth_mm"] + margin,
            depth + margin,
            self._depth0_mm + margin,
            jnp.linalg.norm(f),
            success,
            terminal_failure,
            rc,
        )
        return terms, failure * (1.0 - terminal_failure)

    def step(self, state: State, action: jax.Array) -> State:
        if jnp.shape(action) != (self.action_size,):  # at trace time (per world): costs nothing
            raise UserInputError(
                f"action of shape {jnp.shape(action)}: {type(self).__name__} takes "
                f"{self.action_size} actions per world"
            )
        c = self._config
        rc = c.randomization
        info = dict(state.info)
        if "action_buffer" in info:  # the action sent latency steps ago is applied now
            buf = info["action_buffer"]
            info["action_buffer"] = jnp.concatenate([buf[1:], clean_action(action)[None]])
            decoded = self._decode_action(buf[0], info)
            valid = info["step"] >= buf.shape[0]  # before: none has arrived, the command held
            cmd_tip, wrench_ff, k_xy, k_rot, L_C = hold_command(decoded, info, valid)
        else:
            cmd_tip, wrench_ff, k_xy, k_rot, L_C = self._decode_action(action, info)
        data, wrench, peak_fz = self._physics(
            state.data, info, info["cmd_tip"], cmd_tip, wrench_ff, k_xy, k_rot, L_C
        )
        finite = self.engine.readout(data).finite
        # a NaN action (NaN policy parameters) is applied as 0 and ends the episode like a NaN
        # world (counted in nan_worlds)
        finite = finite & jnp.all(jnp.isfinite(action))
        # a NaN world keeps its last finite state and ends its episode; the batch goes on
        data = world_where(finite, data, state.data)
        nan = 1.0 - finite.astype(jnp.float32)
        if self._weld is not None:  # the weld releases at the end of the step that breaks it
            released = stuck.released(
                jnp.where(finite, peak_fz, 0.0), info["breakaway_N"], info["released"]
            )
            data = self.engine.set_eq_active(data, self._weld, released == 0)
            now = released > info["released"]
            t_now = (info["step"] + 1).astype(jnp.float32) * c.ctrl_dt
            info.update(release_time_s=jnp.where(now, t_now, info["release_time_s"]))
            info["released"] = released
        r = self.engine.readout(data)
        overflow = r.overflow  # warp only: contacts were dropped, end the episode

        wrench = jnp.where(finite, wrench, 0.0)
        f = wrench[:3]
        fxy = jnp.linalg.norm(f[:2])
        fz = jnp.abs(f[2])
        depth = self._depth_mm(r, info["hole_pos"], info["hole_mat"])
        step = info["step"] + 1
        jam_time, jammed, success, failure, done = termination(
            fxy, depth, info["jam_time"], step, nan, overflow, c
        )

        terminal_failure = jnp.maximum(jnp.maximum(jammed, nan), overflow) * (1.0 - success)
        if c.reward_config.time_limit == "failure":  # the time-out is an outcome too
            terminal_failure = failure
        terms, truncation = self._reward(
            info, depth, f, k_xy, k_rot, success, failure, terminal_failure
        )
        if c.reward_config.kind == "thesis":  # a NaN step's depth change is not progress
            terms["progress"] = jnp.where(finite, terms["progress"], 0.0)
        reward = sum(terms.values())

        sum_fz = info["sum_fz"] + fz
        sum_fxy = info["sum_fxy"] + fxy
        peak_fz = jnp.maximum(info["peak_fz"], fz)
        info.update(
            cmd_tip=cmd_tip,
            wrench_ff=wrench_ff,
            k_xy=jnp.asarray(k_xy, jnp.float32),
            k_rot=jnp.asarray(k_rot, jnp.float32),
            L_C=jnp.asarray(L_C, jnp.float32),
            depth_mm=depth,
            jam_time=jam_time,
            prev_action=clean_action(action),
            step=step,
            success=success,
            failure=failure,
            sum_fz=sum_fz,
            sum_fxy=sum_fxy,
            peak_fz=peak_fz,
            nan=nan,
            truncation=truncation,
            wrench=wrench,
        )
        metrics = {f"reward/{k}": v for k, v in terms.items()}
        n = step.astype(jnp.float32)
        metrics.update(
            success=success,
            failure=failure,
            jammed=jammed * (1.0 - success),
            nan=nan,
            overflow=overflow,
            extraction_time_s=jnp.where(success > 0, n * c.ctrl_dt, 0.0),
            mean_fz_N=sum_fz / n,
            peak_fz_N=peak_fz,
            mean_fxy_N=sum_fxy / n,
            fz_N=fz,
            fxy_N=fxy,
            depth_mm=depth,
            k_xy_N_m=jnp.asarray(k_xy, jnp.float32),
            k_rot_Nm_rad=jnp.asarray(k_rot, jnp.float32),
        )
        if self._weld is not None:
            metrics.update({k: info[k] for k in STUCK_METRICS})
        key = None
        if ft_sensor_shifted(rc):  # the bias drifts; the noise is drawn anew each step
            rng, k_drift, key = jax.random.split(info["rng"], 3)
            walk = ft_drift_sd(rc) * jnp.sqrt(c.ctrl_dt) * jax.random.normal(k_drift, (6,))
            info.update(rng=rng, ft_bias=info["ft_bias"] + walk)
        obs = self._obs(r, info, self._sensed_wrench(wrench, info, key))
        obs = self._delayed_obs(obs, info)
        return State(data, obs, reward, done, metrics, info)
