"""The shifts toward a real robot (env config ``randomization``: F/T noise and bias, latencies,
tool-frame calibration error, payload mass): off by default and then absent from the state;
each changes what it should and nothing else; the payload on both engines; bad values refused
in one line.

Most envs run on the ``mujoco`` engine (its graphs compile in seconds); one world pair per shift,
all from the same reset keys and actions, so a shifted env is compared step by step with the
nominal one."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import MAX_LATENCY_STEPS
from peghole_mjx.envs.config import apply_overrides
from peghole_mjx.envs.extraction import hold_command
from peghole_mjx.envs.randomization import randomization_fn
from peghole_mjx.sim.engines import MjxEngine

N = 2
STEPS = 6
R = "randomization."
#: the nominal env of the comparisons (obs.commands on: the tool-frame error reaches it)
BASE = {"engine": "mujoco", "mujoco_threads": 2, "obs.commands": True}
SHIFTS = {
    "nominal": {},
    "obs_latency": {R + "obs_latency_steps": 1},
    "ft": {
        R + "ft_noise_force_N": 0.5,
        R + "ft_noise_torque_Nm": 0.01,
        R + "ft_bias_force_N": 0.3,
        R + "ft_drift_force_N_sqrt_s": 0.2,
    },
    "action_latency": {R + "action_latency_steps": 1},
    "tool_axial": {R + "tool_axial_mm": (2.0, 2.0)},
    "payload": {R + "payload_mass_scale": (1.2, 1.2)},
}
#: the observation's F/T force entries (the default observation: flange x, y, height, force)
FORCE = slice(3, 6)


@functools.cache
def compiled(name: str, engine: str = "mujoco"):
    env = envs.load("RectExtract", config_overrides={**BASE, "engine": engine, **SHIFTS[name]})
    return env, jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))


def actions(env, seed: int = 1) -> jax.Array:
    """A pull with random lateral and feed-forward moves: (STEPS, N, action_size)."""
    a = jax.random.uniform(jax.random.PRNGKey(seed), (STEPS, N, env.action_size), minval=-1)
    return a.at[:, :, 2].set(0.8)


@functools.cache
def trajectory(name: str, engine: str = "mujoco", kind: str = "random", steps: int = STEPS):
    """The states after reset and after each of ``steps`` actions: :func:`actions`
    (``random``); a hold (zero) action first, then those but the last (``shifted``: the
    nominal view of one step of action latency); a straight pull at 20 mm/s (``pull``)."""
    env, reset, step = compiled(name, engine)
    s = reset(jax.random.split(jax.random.PRNGKey(3), N))
    acts = actions(env)
    if kind == "shifted":
        acts = jnp.concatenate([jnp.zeros_like(acts[:1]), acts[:-1]])
    elif kind == "pull":
        acts = jnp.zeros((steps, N, env.action_size)).at[:, :, 2].set(0.2)
    out = [s]
    for a in acts:
        s = step(s, a)
        out.append(s)
    return env, out


def _same(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_defaults_are_off_and_leave_no_trace_in_the_state():
    """Every shift entry defaults to off, and the nominal state holds none of the shifts'
    buffers (a published policy's env is the env it was trained in)."""
    for name in envs.ALL_ENVS:
        r = envs.get_default_config(name).randomization
        assert r.obs_latency_steps == r.action_latency_steps == 0
        assert tuple(r.payload_mass_scale) == (1.0, 1.0)
        for k in ("tool_axial_mm", "tool_lateral_mm", "tool_tilt_deg"):
            assert tuple(r[k]) == (0.0, 0.0)
        assert all(r[k] == 0.0 for k in r if k.startswith("ft_"))
    _, states = trajectory("nominal")
    shift_keys = {"ft_bias", "obs_buffer", "action_buffer", "tool_offset", "tool_mat"}
    assert not (shift_keys | {"payload_scale"}) & set(states[-1].info)


def test_the_draw_of_the_nominal_quantities_is_the_same_with_shifts_on():
    """The shifts draw from keys of their own: the hole, errors, friction and k_xy of an
    episode are the same with every shift on; off, the shifts' fields are neutral."""
    base = envs.get_default_config("RectExtract").randomization
    on = apply_overrides(
        envs.get_default_config("RectExtract"),
        {
            **SHIFTS["ft"],
            R + "tool_tilt_deg": (0.5, 0.5),
            R + "tool_lateral_mm": (-2.0, 2.0),
            R + "payload_mass_scale": (0.8, 1.2),
        },
    ).randomization
    keys = jax.random.split(jax.random.PRNGKey(0), 64)
    d0 = jax.vmap(lambda k: randomization_fn(k, base, 300.0))(keys)
    d1 = jax.vmap(lambda k: randomization_fn(k, on, 300.0))(keys)
    for f in ("hole_offset", "hole_yaw", "lateral_error", "tilt_mat", "friction_scale", "k_xy"):
        np.testing.assert_array_equal(getattr(d0, f), getattr(d1, f))
    np.testing.assert_array_equal(d0.ft_bias, 0.0)
    np.testing.assert_array_equal(d0.tool_mat, np.broadcast_to(np.eye(3), (64, 3, 3)))
    np.testing.assert_array_equal(d0.payload_scale, 1.0)
    # on: the tilt is 0.5 deg about an axis across the tool, the lateral offset within 2 mm
    # across the axis, the payload within its range
    angle = np.degrees(np.arccos(np.clip(np.asarray(d1.tool_mat)[:, 2, 2], -1, 1)))
    np.testing.assert_allclose(angle, 0.5, atol=1e-3)
    off = np.asarray(d1.tool_offset)
    assert np.all(np.linalg.norm(off[:, :2], axis=1) <= 2e-3 + 1e-9) and np.all(off[:, 2] == 0)
    assert np.all((d1.payload_scale >= 0.8) & (d1.payload_scale <= 1.2))
    assert np.asarray(d1.ft_bias)[:, :3].std() == pytest.approx(0.3, rel=0.25)


def test_observation_latency_shows_the_previous_observation_and_nothing_else():
    _, nom = trajectory("nominal")
    _, lat = trajectory("obs_latency")
    np.testing.assert_array_equal(lat[0].obs, nom[0].obs)  # the reset observation
    for t in range(1, STEPS + 1):
        np.testing.assert_array_equal(lat[t].obs, nom[t - 1].obs)
        _same(
            (lat[t].data, lat[t].metrics, lat[t].reward),
            (nom[t].data, nom[t].metrics, nom[t].reward),
        )


def test_ft_noise_and_bias_change_the_observed_force_only():
    """The physics, metrics and reward are the nominal env's; the observation differs in the
    F/T entries only, by the bias and noise (SD 0.5 N: within a few N). Equal to float32
    rounding, not bit for bit: the draws' extra operations change how XLA fuses the reset's
    graph, which moves the start's joint angles by an ulp."""
    _, nom = trajectory("nominal")
    _, ft = trajectory("ft")
    for t in range(STEPS + 1):
        a, b = ft[t], nom[t]
        np.testing.assert_allclose(a.data.qpos, b.data.qpos, rtol=0, atol=1e-6)
        for k in ("fz_N", "fxy_N", "depth_mm", "mean_fz_N"):
            np.testing.assert_allclose(a.metrics[k], b.metrics[k], rtol=1e-3, atol=1e-3)
        np.testing.assert_allclose(a.reward, b.reward, rtol=1e-3, atol=1e-3)
        o, n = np.asarray(a.obs), np.asarray(b.obs)
        keep = np.ones(o.shape[-1], bool)
        keep[FORCE] = False
        np.testing.assert_allclose(o[:, keep], n[:, keep], rtol=0, atol=1e-4)
        diff_N = (o[:, FORCE] - n[:, FORCE]) * 20.0  # obs.force_scale_N
        assert np.all(np.abs(diff_N) < 5.0) and np.any(np.abs(diff_N) > 1e-3)
    # the bias walks: it changed between the first and the last step
    b0, b1 = (np.asarray(ft[t].info["ft_bias"]) for t in (1, STEPS))
    assert not np.array_equal(b0, b1)


def test_action_latency_applies_the_previous_action():
    """With one step of action latency the robot holds its command for a step, then applies
    each action a step late: the physics of the nominal env driven by (hold, a0, a1, ...)."""
    _, lat = trajectory("action_latency")
    _, nom = trajectory("nominal", kind="shifted")
    for t in range(STEPS + 1):
        np.testing.assert_allclose(lat[t].data.qpos, nom[t].data.qpos, rtol=0, atol=1e-6)
        np.testing.assert_allclose(lat[t].info["cmd_tip"], nom[t].info["cmd_tip"], atol=1e-7)
    # the observation's previous action is the policy's own, not the one applied
    env = compiled("action_latency")[0]
    np.testing.assert_array_equal(lat[1].info["prev_action"], np.clip(actions(env)[0], -1, 1))


def test_a_held_command_keeps_every_integrator():
    info = {
        "cmd_tip": jnp.ones(3),
        "wrench_ff": jnp.full(3, 2.0),
        "k_xy": jnp.array(300.0),
        "k_rot": jnp.array(30.0),
        "L_C": jnp.array(0.01),
    }
    new = (jnp.zeros(3), jnp.zeros(3), jnp.array(50.0), jnp.array(10.0), jnp.array(0.0))
    held = hold_command(new, info, jnp.array(False))
    for h, k in zip(held, ("cmd_tip", "wrench_ff", "k_xy", "k_rot", "L_C"), strict=True):
        np.testing.assert_array_equal(h, info[k])
    for h, n in zip(hold_command(new, info, jnp.array(True)), new, strict=True):
        np.testing.assert_array_equal(h, n)


def test_a_tool_offset_along_the_axis_moves_the_believed_tip_and_not_the_observed_pose():
    """A +2 mm axial tool error: the controller believes the tip 2 mm up the peg, so its
    command starts there (the observed commanded offset is the nominal one) and the law holds
    that point; the peg then moves differently, and depth and success read the true tip."""
    _, nom = trajectory("nominal")
    _, tool = trajectory("tool_axial")
    np.testing.assert_allclose(tool[0].info["tool_offset"], [[0.0, 0.0, -2e-3]] * N, atol=1e-9)
    np.testing.assert_allclose(tool[0].obs, nom[0].obs, atol=1e-5)
    np.testing.assert_array_equal(tool[0].info["depth_mm"], nom[0].info["depth_mm"])
    axis = np.asarray(tool[0].data.peg_mat)[:, :, 2]  # the peg's axis, towards the tip
    shift = np.asarray(tool[0].info["cmd_tip"] - nom[0].info["cmd_tip"])
    np.testing.assert_allclose(shift, -2e-3 * axis, atol=1e-6)
    assert not np.allclose(tool[-1].data.qpos, nom[-1].data.qpos, atol=1e-7)


def test_payload_scales_the_peg_and_the_tare_stays_nominal():
    """x1.2 payload: the C engine's per-world peg mass and inertia (nothing else), the MJX
    engine's model the same; the observed force holds the tare error (the nominal weight
    removed from the heavier peg's) at the start, while the metrics' force is the contact's."""
    env, pay = trajectory("payload")
    p = env.engine._pool(N)
    m = env.mj_model
    b = env._peg_body
    np.testing.assert_allclose(p.body_mass[:, b], np.full(N, 1.2 * m.body_mass[b]))
    np.testing.assert_allclose(p.body_inertia[:, b], np.tile(1.2 * m.body_inertia[b], (N, 1)))
    others = np.arange(m.nbody) != b
    np.testing.assert_array_equal(
        p.body_mass[:, others], np.broadcast_to(m.body_mass[others], (N, others.sum()))
    )
    mjx_engine = MjxEngine(env.mjx_model, env._ctrl, env.engine.ids)
    mx = mjx_engine.scaled_mass(env.mjx_model, jnp.float32(1.2))
    np.testing.assert_allclose(mx.body_mass[b], 1.2 * m.body_mass[b], rtol=1e-6)
    # the reset's reading is zero: the policy sees the tare error alone, +0.2 x the peg's
    # weight along z (up); later the contact wrench (what the metrics read) plus that error
    tare = np.array([0.0, 0.0, 0.2 * env._peg_mass * 9.81])
    for s in (pay[0], pay[-1]):
        seen_N = np.asarray(s.obs)[:, FORCE] * 20.0  # obs.force_scale_N
        true_N = np.asarray(s.info["wrench"])[:, :3]
        np.testing.assert_allclose(seen_N - true_N, np.broadcast_to(tare, (N, 3)), atol=1e-4)
        np.testing.assert_allclose(np.abs(true_N[:, 2]), s.metrics["fz_N"], rtol=1e-6)
    _, nom = trajectory("nominal")
    np.testing.assert_array_equal(nom[0].obs[:, FORCE], 0.0)


@pytest.mark.slow
def test_payload_acts_alike_on_both_engines():
    """The heavier peg, whose extra weight the law does not compensate, sags at the start of
    the pull: by the same amount on MJX and on MuJoCo C, each measured against MuJoCo C's
    nominal run (one MJX compile, not two: over the first three steps the engines' nominal
    runs agree within 6 um, measured 2026-12-03, against a sag of 70-80 um; later the
    engines' known contact differences move even the nominal runs apart)."""
    _, nom = trajectory("nominal", "mujoco", "pull", 3)
    sag = {}
    for engine in ("mujoco", "mjx"):
        _, pay = trajectory("payload", engine, "pull", 3)
        sag[engine] = np.array(
            [pay[t].info["depth_mm"] - nom[t].info["depth_mm"] for t in range(4)]
        )
        assert np.all(sag[engine][3] > 0.05), sag  # deeper: 0.2 x the peg's weight pulls
    np.testing.assert_allclose(sag["mjx"][1:], sag["mujoco"][1:], rtol=0.1, atol=2e-3)


@pytest.mark.parametrize(
    "over, needle",
    [
        ({R + "ft_noise_force_N": -0.1}, "ft_noise_force_N must be >= 0"),
        ({R + "ft_drift_torque_Nm_sqrt_s": float("nan")}, "ft_drift_torque_Nm_sqrt_s"),
        ({R + "obs_latency_steps": MAX_LATENCY_STEPS + 1}, "obs_latency_steps must be an integer"),
        ({R + "action_latency_steps": 1.5}, "action_latency_steps must be an integer"),
        ({R + "tool_axial_mm": (2.0, -2.0)}, r"tool_axial_mm must be a range \(lo, hi\)"),
        ({R + "tool_tilt_deg": (0.0, 45.0)}, "tool_tilt_deg"),
        ({R + "payload_mass_scale": (0.0, 1.0)}, "payload_mass_scale"),
        ({R + "payload_mass_scale": 1.2}, "payload_mass_scale must be a list of 2 numbers"),
    ],
)
def test_bad_shift_values_are_refused_in_one_line(over, needle):
    with pytest.raises(UserInputError, match=needle) as err:
        apply_overrides(envs.get_default_config("RectExtract"), over)
    assert "\n" not in str(err.value)
