"""Every env config entry that reset or step reads changes what the env does when overridden.

The step's pieces that hold a config number are pure functions of the config (action
decoding, impedance parameters, observation, termination, reward, the reset's draw), so
most entries are checked there, without compiling an env: the default config and the config
with one entry overridden give different outputs. Entries used when the env is built (scene,
substeps, wrench caps) are checked on built envs. One trace of reset and step (no
compilation) checks that the env calls those functions with its own config, and a source
check that no step module reads the robot's global limits or gains instead of the config.
"""

from __future__ import annotations

import ast
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs import base, extraction
from peghole_mjx.envs.config import apply_overrides
from peghole_mjx.envs.randomization import (
    breakaway_draw,
    ft_drift_sd,
    ft_noise_sd,
    randomization_fn,
)
from peghole_mjx.envs.reward import outcome_terms, reward_terms
from peghole_mjx.envs.stuck import weld_solref
from peghole_mjx.sim import engines

ENV = "RectExtract"
PEG_LENGTH_M = 0.15
#: probe settings under which every entry of a probe's function matters (e.g. the learned
#: gains present, the non-thesis reward terms on)
PROBE_BASE = {
    "compliance_strategy": True,
    "learn_compliance_centre": True,
    "obs.torques": True,
    "obs.stiffness": True,
    "obs.prev_action": True,
    "obs.commands": True,
    "obs.time_left": True,
    "reward_config.w_stf_rot": 0.5,
    "reward_config.w_fz": 0.5,
}


def config(overrides: dict | None = None):
    return apply_overrides(envs.get_default_config(ENV), {**PROBE_BASE, **(overrides or {})})


def _flat(tree) -> np.ndarray:
    return np.concatenate([np.ravel(np.asarray(x, np.float64)) for x in jax.tree.leaves(tree)])


# ---------------------------------------------------------------------- probes (pure)
ACTION = jnp.array([0.5, -0.3, 0.7, 1.0, -1.0, 1.0, 0.2, -0.4, 0.6])


def probe_action(c):
    """Decoded action from two states: no feed-forward yet, and feed-forward near its caps."""
    out = []
    for ff in ((0.0, 0.0, 0.0), (19.5, -19.5, 59.5)):
        info = {
            "hole_mat": jnp.eye(3),
            "cmd_tip": jnp.zeros(3),
            "wrench_ff": jnp.asarray(ff),
            "k_xy": 111.0,
            "k_rot": 22.0,
            "L_C": 0.01,
        }
        ca = extraction.compliance_actions(c, PEG_LENGTH_M)
        out.append(_flat(extraction.decode_action(ACTION, info, c, ca)))
    return np.concatenate(out)


def probe_residual(c):
    """The decoded action of a residual env (``action.residual`` on)."""
    c = c.copy_and_resolve_references()
    c.action.residual = True
    return probe_action(c)


def probe_params(c):
    return _flat(extraction.impedance_params(c, 300.0, 30.0, 0.0, jnp.zeros(3), jnp.zeros(7)))


def probe_fixed(c):
    return _flat(extraction.fixed_compliance(c))


def probe_obs(c):
    info = {
        "wrench": jnp.array([3.0, -2.0, 5.0, 0.3, -0.2, 0.1]),
        "k_xy": 300.0,
        "k_rot": 30.0,
        "L_C": 0.01,
        "prev_action": ACTION,
        "wrench_ff": jnp.array([1.5, -2.0, 30.0]),
        "step": jnp.array(7, jnp.int32),
    }
    pos, rot = jnp.array([1e-3, -2e-3, 0.12]), jnp.array([0.01, -0.02, 0.003])
    cmd_offset = jnp.array([0.4e-3, -0.1e-3, 2e-3])
    return _flat(extraction.observation(pos, rot, info, c, 0.1, PEG_LENGTH_M, cmd_offset))


def probe_reward(c):
    t = reward_terms(-0.4, 10.0, 300.0, 1.0, 1.0, c.reward_config, 30.0, 3.0)
    return _flat(t)


def probe_outcome(c):
    """The outcome reward's terms of one terminal-failure step with contact and progress."""
    t = outcome_terms(20.0, 19.0, 30.0, 10.0, 0.0, 1.0, c.reward_config)
    return _flat(t)


def probe_termination(c):
    """Two worlds: one jamming and above the success margin, one at the time limit."""
    default_length = envs.get_default_config(ENV).episode_length
    out = extraction.termination(
        jnp.array([19.0, 0.0]),  # |f_xy|, N
        jnp.array([-5.5, 3.0]),  # depth, mm
        jnp.array([0.28, 0.0]),  # jamming time so far, s
        jnp.array([10, default_length]),
        0.0,
        0.0,
        c,
    )
    return _flat(out)


def probe_ft(c):
    """The F/T noise and drift SDs of each component (the step draws with them)."""
    return _flat((ft_noise_sd(c.randomization), ft_drift_sd(c.randomization)))


def probe_latency(c):
    """The latency buffers a reset starts with."""
    return _flat((jnp.zeros(0), extraction.latency_buffers(c, jnp.arange(3.0), 2)))


def probe_stuck(c):
    """A stuck joint's breakaway draws and its weld's solref."""
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    b = jax.vmap(lambda k: breakaway_draw(k, c.stuck))(keys)
    return _flat((b, jnp.asarray(weld_solref(c.stuck))))


def probe_reset_draw(c):
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    draw = jax.vmap(lambda k: randomization_fn(k, c.randomization, 300.0))(keys)
    return _flat(draw._replace(rng=jnp.zeros(())))


#: entry -> (overridden value, probe); each value differs from the probe setting
PURE = {
    "ctrl_dt": (0.04, [probe_action, probe_termination]),
    "episode_length": (10_000, [probe_termination, probe_obs]),
    "success_margin_mm": (6.0, [probe_termination]),
    "jam_force_N": (19.5, [probe_termination]),
    "jam_time_s": (0.35, [probe_termination]),
    "action.max_step_offset_mm": (0.2, [probe_action]),
    "action.max_speed_m_s": (0.05, [probe_action]),
    "action.max_force_step_N": (3.0, [probe_action]),
    "action.max_ff_xy_N": (10.0, [probe_action]),
    "action.residual": (True, [probe_action]),
    "action.residual_scale": (0.3, [probe_residual]),
    "limits.max_force_N": ((25.0, 25.0, 70.0), [probe_action]),
    "compliance_strategy": (False, [probe_action]),
    "compliance_rotation": (False, [probe_action]),
    "learn_compliance_centre": (False, [probe_action]),
    "stiffness.k_xy_min_N_m": (100.0, [probe_action]),
    "stiffness.k_xy_max_N_m": (900.0, [probe_action]),
    "stiffness.k_rot_min_Nm_rad": (20.0, [probe_action]),
    "stiffness.k_rot_max_Nm_rad": (200.0, [probe_action]),
    "stiffness.k_xy_N_m": (400.0, [probe_fixed]),
    "stiffness.k_rot_Nm_rad": (200.0, [probe_fixed]),
    "stiffness.compliance_centre_mm": (10.0, [probe_fixed]),
    "stiffness.k_z_N_m": (3000.0, [probe_params]),
    "stiffness.damping_ratio": (0.7, [probe_params]),
    "stiffness.null_stiffness_Nm_rad": (5.0, [probe_params]),
    "stiffness.null_damping_Nms_rad": (1.0, [probe_params]),
    "obs.torques": (False, [probe_obs]),
    "obs.stiffness": (False, [probe_obs]),
    "obs.prev_action": (False, [probe_obs]),
    "obs.commands": (False, [probe_obs]),
    "obs.time_left": (False, [probe_obs]),
    "obs.force_scale_N": (10.0, [probe_obs]),
    "obs.torque_scale_Nm": (1.0, [probe_obs]),
    "obs.k_xy_scale_N_m": (500.0, [probe_obs]),
    "obs.k_rot_scale_Nm_rad": (100.0, [probe_obs]),
    **{
        f"reward_config.{k}": (v, [probe_outcome])
        for k, v in {"discount": 0.9, "time_cost": 0.5, "w_contact": 0.5, "w_progress": 5.0}.items()
    },
    **{
        f"reward_config.{k}": (v, [probe_reward])
        for k, v in {
            "w_d": 2.0,
            "w_f": 2.0,
            "w_stf": 0.2,
            "r_success": 2.0,
            "r_failure": -2.0,
            "force_scale_N": 10.0,
            "stiffness_scale_N_m": 500.0,
            "w_stf_rot": 1.0,
            "rot_stiffness_scale_Nm_rad": 100.0,
            "w_fz": 1.0,
            "fz_scale_N": 2.0,
        }.items()
    },
    **{
        f"randomization.{k}": (v, [probe_reset_draw])
        for k, v in {
            "lateral_error_mm": 2.0,
            "angular_error_deg": 1.0,
            "hole_xy_mm": 3.0,
            "hole_yaw_deg": 2.0,
            "friction_scale": (0.9, 1.0),
            "stiffness_N_m": (100.0, 200.0),
            # the shifts drawn per episode (docs/research/transfer.md)
            "ft_bias_force_N": 0.1,
            "ft_bias_torque_Nm": 0.01,
            "tool_axial_mm": (1.0, 2.0),
            "tool_lateral_mm": (1.0, 2.0),
            "tool_tilt_deg": (0.1, 0.5),
            "payload_mass_scale": (0.9, 1.1),
        }.items()
    },
    **{
        f"randomization.{k}": (v, [probe_ft])
        for k, v in {
            "ft_noise_force_N": 0.1,
            "ft_noise_torque_Nm": 0.01,
            "ft_drift_force_N_sqrt_s": 0.1,
            "ft_drift_torque_Nm_sqrt_s": 0.01,
        }.items()
    },
    "stuck.breakaway_N": ((25.0, 35.0), [probe_stuck]),
    "stuck.timeconst_s": (0.01, [probe_stuck]),
    "randomization.obs_latency_steps": (1, [probe_latency]),
    "randomization.action_latency_steps": (2, [probe_latency]),
}


@pytest.mark.parametrize("key", sorted(PURE))
def test_override_changes_the_step_function_that_reads_it(key):
    value, probes = PURE[key]
    default, changed = config(), config({key: value})
    for probe in probes:
        a, b = probe(default), probe(changed)
        assert a.shape != b.shape or not np.allclose(a, b), f"{key} ignored by {probe.__name__}"


# ---------------------------------------------------------------------- built envs
def _scene(env) -> dict:
    m = env.mj_model
    return {
        "n_substeps": env.n_substeps,
        "timestep": m.opt.timestep,
        "ngeom": m.ngeom,
        "nbody": m.nbody,
        "pair_solref": np.asarray(m.pair_solref).round(9).tolist(),
        "pair_solreffriction": np.asarray(m.pair_solreffriction).round(9).tolist(),
        "pair_friction": np.asarray(m.pair_friction).round(9).tolist(),
        "max_contact_points": [m.numeric(i).data.tolist() for i in range(m.nnumeric)],
        "wrench_caps": env._ctrl.limits.max_wrench,
        "geom_size": float(np.abs(m.geom_size).sum()).__round__(9),
        "peg_length_m": env.peg_length_m,
        "neq": m.neq,
    }


#: entries used when the env is built: overridden value (built envs, no compilation)
SCENE = {
    "preset": "rect-3",
    "geometry": {"peg_w_mm": 59.8, "peg_v_mm": 39.8},
    "representation": "box",
    "contact_cap": 32,  # above the rect scene's measured maximum (20), below its 52
    "sim_dt": 0.004,
    "ctrl_dt": 0.04,
    "contact.timeconst_s": 0.02,
    "contact.friction_timeconst_s": 0.5,
    "limits.max_force_N": (25.0, 25.0, 70.0),
    "limits.max_torque_Nm": (2.0, 2.0, 1.0),
    "stuck.enabled": True,  # the breakaway weld (envs/stuck.py)
}


@pytest.fixture(scope="module")
def default_scene():
    return _scene(envs.load(ENV))


@pytest.mark.parametrize("key", sorted(SCENE))
def test_override_changes_the_built_env(key, default_scene):
    assert _scene(envs.load(ENV, config_overrides={key: SCENE[key]})) != default_scene


def test_peg_length_comes_from_the_preset():
    """The flange-height and L_C scale is the preset's peg length (no separate entry)."""
    rect = envs.load(ENV, config_overrides={"compliance_strategy": True})
    dual = envs.load("DualExtract", config_overrides={"compliance_strategy": True})
    assert (rect.peg_length_m, dual.peg_length_m) == pytest.approx((0.15, 0.05))
    assert "peg_length_mm" not in rect.config


def test_impl_and_warp_buffers_are_read(monkeypatch):
    """impl selects the backend; naconmax and njmax size MuJoCo Warp's buffers, whose
    make_data takes the compiled MjModel (mujoco-mjx 3.17.0 refuses an mjx.Model)."""
    if not base.WARP_AVAILABLE:
        with pytest.raises(UserInputError, match="warp"):
            envs.load(ENV, config_overrides={"impl": "warp"})
    seen = []
    monkeypatch.setattr(engines.mjx, "make_data", lambda m, **kw: seen.append((m, kw)))
    for over in ({}, {"naconmax": 32, "njmax": 128}):
        c = apply_overrides(envs.get_default_config(ENV), {"impl": "warp", **over})
        engine = engines.MjxEngine(None, None, None, c.impl, c.naconmax, c.njmax, mj_model="mj")
        engine.make_data(worlds=1)  # the reset IK's data (one world)
    assert seen == [
        ("mj", {"impl": "warp", "naconmax": 64, "njmax": 256}),
        ("mj", {"impl": "warp", "naconmax": 32, "njmax": 128}),
    ]


def test_engine_and_its_threads_are_read():
    """engine selects the physics engine; mujoco_threads sizes its mujoco.batch pool."""
    from peghole_mjx.sim.engine_mujoco import MujocoEngine, available_threads
    from peghole_mjx.sim.engines import MjxEngine

    assert isinstance(envs.load(ENV, config_overrides={"engine": "mjx"}).engine, MjxEngine)
    auto = MujocoEngine if jax.default_backend() == "cpu" else MjxEngine  # engine auto
    assert isinstance(envs.load(ENV).engine, auto)
    one = envs.load(ENV, config_overrides={"engine": "mujoco", "mujoco_threads": 1}).engine
    every = envs.load(ENV, config_overrides={"engine": "mujoco"}).engine
    assert isinstance(one, MujocoEngine) and one.threads == 1
    assert every.threads == available_threads()
    assert one._pool(2).batch.nthread == 1


# ---------------------------------------------------------------------- coverage and wiring
def _leaves(c, prefix=""):
    for k, v in c.items():
        if hasattr(v, "items"):
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield prefix + k


def test_every_config_entry_is_checked():
    # test_impl_and_warp_buffers_are_read, test_engine_and_its_threads_are_read
    # and reward_config.kind and .time_limit, which pick the function and the terminal steps:
    # tests/test_reward.py (the env's step)
    extra = {"impl", "naconmax", "njmax", "engine", "mujoco_threads", "reward_config.kind"}
    extra |= {"reward_config.time_limit"}
    for name in envs.ALL_ENVS:
        leaves = set(_leaves(envs.get_default_config(name)))
        assert leaves == set(PURE) | set(SCENE) | extra, name


def test_reset_and_step_call_the_config_functions_with_the_env_config(monkeypatch):
    """A trace (no compilation) of reset and step: each config-reading function is called
    with the env's own config, so an override reaches the step through them."""
    env = envs.load(ENV, config_overrides={"compliance_strategy": True})
    calls: dict[str, object] = {}

    def spy(name, fn, config_arg):
        def wrapped(*a, **k):
            calls[name] = config_arg(a)
            return fn(*a, **k)

        monkeypatch.setattr(extraction, name, wrapped)

    spy("decode_action", extraction.decode_action, lambda a: a[2])
    spy("impedance_params", extraction.impedance_params, lambda a: a[0])
    spy("observation", extraction.observation, lambda a: a[3])
    spy("termination", extraction.termination, lambda a: a[6])
    spy("reward_terms", extraction.reward_terms, lambda a: a[5])

    def draw(rng, r, k_xy):
        calls["draw"] = r
        return randomization_fn(rng, r, k_xy)

    monkeypatch.setattr(type(env), "randomization_fn", staticmethod(draw))
    state = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
    jax.eval_shape(env.step, state, jnp.zeros(env.action_size))
    assert calls.pop("draw") is env.config.randomization
    assert calls.pop("reward_terms") is env.config.reward_config
    assert set(calls) == {
        "decode_action",
        "impedance_params",
        "observation",
        "termination",
    }
    assert all(c is env.config for c in calls.values())


STEP_MODULES = ("base.py", "extraction.py", "randomization.py", "reward.py", "metrics.py")


@pytest.mark.parametrize("module", STEP_MODULES)
def test_step_modules_read_no_global_limits_or_gains(module):
    """The robot's LIMITS and GAINS are copied into the config (envs/config.py) and nowhere
    else read by the env: a module that reads them would ignore an override."""
    path = Path(extraction.__file__).with_name(module)
    tree = ast.parse(path.read_text())
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
    assert not names & {"LIMITS", "GAINS"}, module


def test_geometry_entry_changes_the_preset_spec_and_refuses_bad_changes():
    """config.geometry: a JSON object of spec fields changed from the preset's (held-out
    geometries); a dict given as an override is stored as canonical JSON; unknown fields and
    infeasible specs are refused in one line."""
    from peghole_mjx.core.errors import UserInputError
    from peghole_mjx.envs.config import env_spec
    from peghole_mjx.geometry.specs import get_preset

    default = envs.get_default_config("RectExtract")
    assert default.geometry == "" and env_spec(default) == get_preset("rect-2")
    cfg = apply_overrides(default, {"geometry": {"peg_w_mm": 59.8, "peg_v_mm": 39.8}})
    assert cfg.geometry == '{"peg_v_mm": 39.8, "peg_w_mm": 59.8}'
    spec = env_spec(cfg)
    assert (spec.peg_w_mm, spec.peg_v_mm, spec.hole_w_mm) == (59.8, 39.8, 60.1)
    dual = apply_overrides(
        envs.get_default_config("DualExtract"), {"geometry": {"peg_radii_mm": [5.9, 5.9]}}
    )
    assert env_spec(dual).peg_radii_mm == (5.9, 5.9)
    for bad, match in (
        ({"peg_width": 50.0}, "peg_width not fields of RectSpec"),
        ({"peg_w_mm": 61.0}, "w' < w violated"),
        ("[1]", "must be a JSON object"),
    ):
        with pytest.raises(UserInputError, match=match) as err:
            apply_overrides(default, {"geometry": bad})
        assert "\n" not in str(err.value)


def test_observed_commands_are_the_feed_forward_and_the_commanded_tip_offset():
    """``obs.commands``: at reset the feed-forward is 0 and the commanded tip sits at the
    drawn lateral error from the tip (hole frame), exactly what reset commands."""
    env = envs.load(ENV, config_overrides={"obs.commands": True, "engine": "mujoco"})
    key = jax.random.PRNGKey(3)
    obs = np.asarray(jax.jit(env.reset)(key).obs)
    assert env.observation_size == envs.load(ENV).observation_size + 6 == obs.shape[0]
    draw = randomization_fn(key, env.config.randomization, env.fixed_compliance["k_xy"])
    np.testing.assert_array_equal(obs[-6:-3], 0.0)
    np.testing.assert_allclose(obs[-3:], np.asarray(draw.lateral_error) * 1e3, atol=1e-4)
    assert np.linalg.norm(obs[-3:-1]) > 0.01  # a real lateral error, in mm


def test_the_start_ik_is_traced_once_and_equals_the_inline_ik_bit_for_bit(monkeypatch):
    """The reset's Newton IK is a jitted function of its own: a second env of the same scene
    reuses its trace (MJX's kinematics is not traced again), and the start joint angles are
    those of the same Newton steps written inline in the reset's graph, bit for bit."""
    from peghole_mjx.control import kinematics

    traced, mjx = [], kinematics.mjx

    def counted_kinematics(m, d):
        traced.append(1)
        return mjx.kinematics(m, d)

    counting = types.SimpleNamespace(kinematics=counted_kinematics, com_pos=mjx.com_pos)
    monkeypatch.setattr(kinematics, "mjx", counting)
    kinematics._newton_ik.clear_cache()
    keys = jax.random.split(jax.random.PRNGKey(3), 4)
    mjx_engine = {"engine": "mjx"}
    first, second, third = (envs.load("RectExtract", config_overrides=mjx_engine) for _ in "123")
    q = jax.jit(jax.vmap(first.reset_start))(keys)["q"]
    assert traced, "the IK's body was not traced"
    n_first = len(traced)
    jax.jit(jax.vmap(second.reset_start)).lower(keys)
    assert len(traced) == n_first  # the second env's reset reused the trace

    def inline(m, d0, q0, qadr, dadr, body_id, point_local, pos_target, mat_target, iterations):
        statics = {"qadr": tuple(qadr), "dadr": tuple(dadr), "body_id": body_id}
        statics |= {"point_local": tuple(point_local), "iterations": iterations}
        return kinematics._newton_ik.__wrapped__(m, d0, q0, pos_target, mat_target, **statics)

    monkeypatch.setattr(engines, "newton_ik", inline)
    q_inline = jax.jit(jax.vmap(third.reset_start))(keys)["q"]
    assert len(traced) > n_first  # traced again, inline in the reset's graph
    np.testing.assert_array_equal(np.asarray(q), np.asarray(q_inline))
    assert float(jnp.abs(q - q[:1]).max()) > 0  # the four starts differ (moved holes)


def test_the_mjx_step_is_traced_once_per_process(monkeypatch):
    """MJX-JAX's step is a jitted function of its own (``sim.engines._mjx_step``): the step
    graph of a second env of the same scene reuses its trace instead of tracing MJX again."""
    traced = []

    def counted_step(m, d):
        traced.append(1)
        return engines.mjx.step(m, d)

    monkeypatch.setattr(engines, "_mjx_step", jax.jit(counted_step))
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    for _ in range(2):
        env = envs.load("RectExtract", config_overrides={"engine": "mjx"})
        state = jax.eval_shape(jax.vmap(env.reset), keys)
        jax.jit(jax.vmap(env.step)).lower(state, jnp.zeros((2, env.action_size)))
    assert len(traced) == 1
