"""RectExtract and DualExtract: API, determinism, randomised resets, failure paths, rewards."""

import functools
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import loads as strict_json  # no bare NaN
from peghole_mjx.envs.contacts import ContactReplay
from peghole_mjx.envs.reward import REWARD_WEIGHTS, reward_terms
from peghole_mjx.envs.rollout import random_policy, rollout, scripted_policy
from peghole_mjx.geometry.check import numeric
from peghole_mjx.geometry.mjcf import CONTACT_CAPS
from peghole_mjx.sim.engines import ENGINES

N_WORLDS = 8


class Compiled:
    """One env with its jitted, vmapped reset and step (compiled once per module)."""

    def __init__(self, name: str, engine: str = "mjx"):
        self.env = envs.load(name, config_overrides={"engine": engine})  # pinned: MJX numbers
        self.reset = jax.jit(jax.vmap(self.env.reset))
        self.step = jax.jit(jax.vmap(self.env.step))

    def keys(self, seed: int, n: int = N_WORLDS):
        return jax.random.split(jax.random.PRNGKey(seed), n)


@functools.cache
def get_compiled(name: str, engine: str = "mjx") -> Compiled:
    """One jitted env per name and engine for the whole session (an MJX step compiles for
    minutes)."""
    return Compiled(name, engine)


@pytest.fixture(scope="module", params=envs.ALL_ENVS)
def compiled_c(request) -> Compiled:
    """Every env on the ``mujoco`` engine."""
    return get_compiled(request.param, "mujoco")


#: the envs that also run on MJX here: the hard variants differ from their base envs in
#: config values only (preset, ranges), and each MJX env costs a compile of about two minutes
#: on a 2-core CPU (four of them were 7 min of the suite, 2026-12-03)
MJX_ENVS = ("RectExtract", "DualExtract")


#: the task's tests run on every physics engine (sim/engines.py): one task definition
@pytest.fixture(
    scope="module",
    params=[(e, g) for g in ENGINES for e in (MJX_ENVS if g == "mjx" else envs.ALL_ENVS)],
    ids=lambda p: f"{p[0]}-{p[1]}",
)
def compiled_any(request) -> Compiled:
    return get_compiled(*request.param)


@pytest.fixture(scope="module")
def rect() -> Compiled:
    return get_compiled("RectExtract")


@pytest.fixture(scope="module", params=ENGINES)
def rect_any(request) -> Compiled:
    return get_compiled("RectExtract", request.param)


def test_registry():
    assert set(envs.ALL_ENVS) == {
        "RectExtract",
        "DualExtract",
        "RectExtractHard",  # tests/test_hard_variants.py
        "DualExtractHard",
    }
    cfg = envs.get_default_config("DualExtract")
    assert cfg.preset == "dual-2" and cfg.reward_config.w_stf == REWARD_WEIGHTS["w_stf"]
    with pytest.raises(UserInputError, match="unknown env"):
        envs.load("PegInsert")
    with pytest.raises(UserInputError, match="impl"):
        envs.load("RectExtract", config_overrides={"impl": "cuda"})
    env = envs.load(
        "RectExtract",
        config_overrides={"compliance_strategy": True, "learn_compliance_centre": True},
    )
    index = {name: v[0] for name, v in env.compliance_actions.items()}
    assert env.action_size == 9 and index == {"k_xy": 6, "k_rot": 7, "L_C": 8}
    env = envs.load(
        "RectExtract", config_overrides={"compliance_strategy": True, "compliance_rotation": False}
    )
    index = {name: v[0] for name, v in env.compliance_actions.items()}
    assert env.action_size == 7 and index == {"k_xy": 6}


def test_compliance_strategy_action_maps_onto_its_ranges_and_baseline_holds_the_fixed_gains():
    env = envs.load(
        "RectExtract",
        config_overrides={"compliance_strategy": True, "learn_compliance_centre": True},
    )
    s, L = env.config.stiffness, env.spec.length_mm * 1e-3
    info = {
        "hole_mat": jnp.eye(3),
        "cmd_tip": jnp.zeros(3),
        "wrench_ff": jnp.zeros(3),
        "k_xy": jnp.float32(0.0),
        "k_rot": jnp.float32(0.0),
        "L_C": jnp.float32(0.0),
    }

    def decode(a):
        _, _, k_xy, k_rot, L_C = env._decode_action(jnp.asarray(a, jnp.float32), info)
        return float(k_xy), float(k_rot), float(L_C)

    lo, hi = -np.ones(9), np.ones(9)
    np.testing.assert_allclose(decode(lo), (s.k_xy_min_N_m, s.k_rot_min_Nm_rad, 0.0), rtol=1e-6)
    np.testing.assert_allclose(decode(hi), (s.k_xy_max_N_m, s.k_rot_max_Nm_rad, L), rtol=1e-6)
    np.testing.assert_allclose(decode(3 * hi), decode(hi))  # actions are clipped to [-1, 1]
    # the scripted baseline (the Ch 2-3 method) commands exactly the fixed gains and L_C
    a = np.asarray(scripted_policy(env)(None, None))
    np.testing.assert_allclose(
        decode(a), (s.k_xy_N_m, s.k_rot_Nm_rad, s.compliance_centre_mm * 1e-3), atol=1e-4
    )


def test_feed_forward_accumulates_within_its_bounds():
    """Feed-forward: +-max_force_step_N per step, lateral total within max_ff_xy_N, z 60 N."""
    info = {"hole_mat": jnp.eye(3), "cmd_tip": jnp.zeros(3), "wrench_ff": jnp.zeros(3)}
    info |= {k: jnp.float32(0.0) for k in ("k_xy", "k_rot", "L_C")}
    a = jnp.asarray([0, 0, 0, 1, -1, 1], jnp.float32)

    def total(env, steps):
        ff = jnp.zeros(3)
        for _ in range(steps):
            _, ff, *_ = env._decode_action(a, {**info, "wrench_ff": ff})
        return np.asarray(ff)

    default = envs.load("RectExtract")
    step = default.config.action.max_force_step_N
    np.testing.assert_allclose(total(default, 1), (step, -step, step))
    np.testing.assert_allclose(total(default, 40), (20.0, -20.0, 60.0))  # E11's force limits
    capped = envs.load("RectExtract", config_overrides={"action.max_ff_xy_N": 3.0})
    np.testing.assert_allclose(total(capped, 40), (3.0, -3.0, 60.0))  # z keeps its 60 N


@pytest.mark.slow
def test_random_actions_200_steps_no_nan_and_determinism(compiled_any):
    compiled = compiled_any
    env = compiled.env
    s0 = compiled.reset(compiled.keys(0))
    assert s0.obs.shape == (N_WORLDS, env.observation_size) and env.observation_size == 9
    actions = jax.random.uniform(
        jax.random.PRNGKey(1), (200, N_WORLDS, env.action_size), minval=-1, maxval=1
    )

    def run(s):
        obs = []
        for a in actions:
            s = compiled.step(s, a)
            obs.append(s.obs)
        return s, jnp.stack(obs)

    s1, traj1 = run(s0)
    if compiled.env.engine.name == "mjx":  # MJX allocates the scene's contact cap, if it has one
        cap = numeric(env.mj_model, "max_contact_points")
        assert cap == 0 or s1.data._impl.contact.dist.shape[-1] == cap
    assert np.isfinite(np.asarray(traj1)).all()
    assert np.asarray(s1.metrics["nan"]).sum() == 0
    assert np.isfinite(np.asarray(s1.data.qpos)).all()
    # same seed: same trajectory (first 50 steps, to keep the dual test short)
    s2 = compiled.reset(compiled.keys(0))
    for i, a in enumerate(actions[:50]):
        s2 = compiled.step(s2, a)
        np.testing.assert_array_equal(np.asarray(s2.obs), np.asarray(traj1[i]))


@pytest.mark.slow
def test_rollouts_stay_below_the_contact_cap(compiled_c):
    """Every capped scene: the active contacts (distance <= 0) after every physics step of
    scripted and random rollouts stay below the scene's ``max_contact_points`` (a rollout that
    reaches it may have lost contacts; the caps are sized in
    benchmarks/results/perf/contact_caps.json). Counted in MuJoCo C by replaying each env step
    (:class:`~peghole_mjx.envs.contacts.ContactReplay`, checked bit for bit against the env),
    as the caps were measured; that MJX allocates the cap is checked in the MJX runs above."""
    compiled = compiled_c
    env = compiled.env
    cap = numeric(env.mj_model, "max_contact_points")
    entry = CONTACT_CAPS.get((env.spec.kind, env.representation))
    assert cap == (entry.cap if entry else 0)
    if not cap:
        pytest.skip(f"{env.representation}: no contact cap (every allocated contact can be active)")
    assert cap > entry.measured_max
    scripted = jnp.broadcast_to(scripted_policy(env)(None, None), (N_WORLDS, env.action_size))
    rand = jax.random.uniform(
        jax.random.PRNGKey(7), (60, N_WORLDS, env.action_size), minval=-1, maxval=1
    )
    worst = 0
    with ContactReplay(env) as replay:
        for actions in ([scripted] * 40, rand):
            s = compiled.reset(compiled.keys(5))
            for a in actions:
                prev, s = s, compiled.step(s, a)
                worst = max(worst, replay.max_active(prev, s))
    assert worst > 0, "the rollouts never touched the hole"
    assert worst < cap, f"{env.representation}: {worst} active contacts reach the cap {cap}"


def test_every_reset_is_randomised(rect):
    a = rect.reset(rect.keys(0))
    b = rect.reset(rect.keys(1))
    for key in ("hole_pos", "cmd_tip", "cmd_mat", "friction_scale"):
        assert not np.allclose(np.asarray(a.info[key]), np.asarray(b.info[key])), key
    # worlds of one batch differ from each other too
    assert len(np.unique(np.asarray(a.info["friction_scale"]))) == N_WORLDS
    assert not np.allclose(np.asarray(a.data.qpos[0]), np.asarray(a.data.qpos[1]))
    # each start is a valid inserted pose: tip at depth0 below the (moved) mouth, no contact
    depth = np.asarray(a.info["depth_mm"])
    np.testing.assert_allclose(depth, depth[0], atol=0.05)
    assert (np.asarray(a.data._impl.contact.dist) > 0).all()  # no contact at the start


def test_max_lateral_push_ends_in_jamming_not_a_crash(rect_any):
    rect = rect_any
    s = rect.reset(rect.keys(2))
    push = jnp.tile(jnp.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]), (N_WORLDS, 1))
    done_at = np.full(N_WORLDS, -1)
    m = {k: np.zeros(N_WORLDS) for k in ("jammed", "failure", "success", "reward/end", "nan")}
    for i in range(150):
        s = rect.step(s, push)
        newly = (np.asarray(s.done) > 0) & (done_at < 0)
        done_at[newly] = i
        for k in m:  # metrics at the step that ended each episode
            m[k] = np.where(newly, np.asarray(s.metrics[k]), m[k])
        if (done_at >= 0).all():
            break
    assert (done_at >= 0).all(), "the push must end every episode"
    assert (m["jammed"] == 1).all() and (m["failure"] == 1).all() and (m["success"] == 0).all()
    assert (m["reward/end"] == -1).all() and (m["nan"] == 0).all()


def test_nan_action_is_applied_as_zero_and_counted_as_a_nan_world(rect_any):
    rect = rect_any
    """NaN policy parameters give NaN actions: the world ends like a NaN world, and nothing
    (gains, reward, observation) turns NaN."""
    s = rect.reset(rect.keys(4))
    a = np.zeros((N_WORLDS, rect.env.action_size), np.float32)
    a[: N_WORLDS // 2] = np.nan
    s = rect.step(s, jnp.asarray(a))
    nan = np.asarray(s.metrics["nan"])
    assert (nan[: N_WORLDS // 2] == 1).all() and (nan[N_WORLDS // 2 :] == 0).all()
    assert (np.asarray(s.done)[: N_WORLDS // 2] == 1).all()
    for x in (s.reward, s.obs, s.info["k_xy"], s.info["k_rot"], s.info["prev_action"]):
        assert np.isfinite(np.asarray(x)).all()


def test_reward_terms_signs_and_scales():
    rc = envs.get_default_config("RectExtract").reward_config
    t = reward_terms(-0.4, 10.0, 300.0, 0.0, 0.0, rc)  # pulling out 0.4 mm with 10 N sideways
    assert float(t["progress"]) == pytest.approx(0.4)  # pulling out is rewarded
    assert float(t["force"]) == pytest.approx(-10.0 / 20.0)
    assert float(t["stiffness"]) == pytest.approx(-0.1 * np.sqrt(2) * 0.3)
    assert float(t["end"]) == 0.0
    assert float(reward_terms(0.4, 0.0, 0.0, 0.0, 0.0, rc)["progress"]) == pytest.approx(-0.4)
    assert float(reward_terms(0.0, 0.0, 0.0, 1.0, 0.0, rc)["end"]) == 1.0
    assert float(reward_terms(0.0, 0.0, 0.0, 0.0, 1.0, rc)["end"]) == -1.0
    stiffer = reward_terms(0.0, 0.0, 1000.0, 0.0, 0.0, rc)["stiffness"]
    assert float(stiffer) < float(t["stiffness"]) < 0
    # the K_theta term is not in eq (4.4): zero at the default weight, linear when set
    assert float(reward_terms(0.0, 0.0, 0.0, 0.0, 0.0, rc, 300.0)["rot_stiffness"]) == 0.0
    rc_rot = envs.get_default_config("DualExtract").reward_config
    rc_rot.w_stf_rot = 0.5
    stiff_rot = reward_terms(0.0, 0.0, 0.0, 0.0, 0.0, rc_rot, 300.0)["rot_stiffness"]
    soft_rot = reward_terms(0.0, 0.0, 0.0, 0.0, 0.0, rc_rot, 30.0)["rot_stiffness"]
    assert float(stiff_rot) == pytest.approx(-0.5) and float(soft_rot) == pytest.approx(-0.05)
    # so is the extraction-force term: -w_fz |f_z| / 1 N, either sign of f_z
    assert float(reward_terms(0.0, 0.0, 0.0, 0.0, 0.0, rc, 0.0, 3.0)["extraction_force"]) == 0.0
    rc_rot.w_fz = 2.0
    for fz in (0.25, -0.25):
        t_fz = reward_terms(0.0, 0.0, 0.0, 0.0, 0.0, rc_rot, 0.0, fz)["extraction_force"]
        assert float(t_fz) == pytest.approx(-0.5)


def test_step_logs_named_reward_terms_that_sum_to_the_reward(rect_any):
    rect = rect_any
    s = rect.reset(rect.keys(3))
    s = rect.step(s, jnp.tile(jnp.array([0, 0, 0.5, 0, 0, 0.0]), (N_WORLDS, 1)))
    parts = [
        np.asarray(s.metrics[f"reward/{k}"])
        for k in ("progress", "force", "stiffness", "rot_stiffness", "extraction_force", "end")
    ]
    # equal up to float32 rounding of the summands: a few ulps of the largest term (a
    # relative tolerance on the sum fails where the terms nearly cancel, in any summation order)
    scale = np.sum(np.abs(parts), axis=0)
    np.testing.assert_array_less(np.abs(sum(parts) - np.asarray(s.reward)), 1e-6 * scale + 1e-12)
    assert (np.asarray(s.metrics["reward/progress"]) > 0).all()  # pulled up 2 mm commanded


@pytest.mark.slow
def test_scripted_baseline_solves_dual():
    """The 64-episode runs of both envs are in benchmarks/results/perf/env_rollouts.json.

    Steps the session's compiled dual env on the ``mujoco`` engine (no rollout graph to
    compile; on MJX these episodes took 50 s of the suite, 2026-12-03) and records each
    world's first ``done``.
    """
    dual = get_compiled("DualExtract", "mujoco")
    env = dual.env
    action = jnp.broadcast_to(scripted_policy(env)(None, None), (N_WORLDS, env.action_size))
    s = dual.reset(dual.keys(3))
    done = np.zeros(N_WORLDS, bool)
    success, nan, t = np.zeros(N_WORLDS), np.zeros(N_WORLDS), np.zeros(N_WORLDS)
    for _ in range(env.config.episode_length):
        s = dual.step(s, action)
        new = (np.asarray(s.done) > 0) & ~done
        success[new] = np.asarray(s.metrics["success"])[new]
        nan[new] = np.asarray(s.metrics["nan"])[new]
        t[new] = np.asarray(s.metrics["extraction_time_s"])[new]
        done |= new
        if done.all():
            break
    assert done.all()
    assert success.mean() >= 0.9 and nan.sum() == 0
    assert 0 < t[success > 0].mean() < 8.0


@pytest.mark.slow
def test_random_policy_rarely_extracts_the_rect_peg():
    env = get_compiled("RectExtract", "mujoco").env
    rnd = rollout(env, random_policy(env), 8, seed=0, progress=False).summary()
    assert rnd.success_rate <= 0.25  # random dz averages zero: no net pull


@pytest.mark.slow
@pytest.mark.parametrize("name", envs.ALL_ENVS)
def test_cli_rollout_runs_on_every_registered_env(name):
    """`peghole envs rollout --env E --policy scripted --episodes 4` for every registered env
    (the hard variants' presets once failed a name check), on the MuJoCo C engine."""
    res = subprocess.run(
        [sys.executable, "-m", "peghole_mjx.cli.main", "envs", "rollout", "--env", name,
         "--policy", "scripted", "--episodes", "4", "--engine", "mujoco", "--json"],
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    out = strict_json(res.stdout)
    assert out["episodes"] == 4 and out["engine"] == "mujoco" and out["nan_worlds"] == 0


def test_cli_rollout_scripted_rect_8_episodes():
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "peghole_mjx.cli.main",
            "envs",
            "rollout",
            "--env",
            "RectExtract",
            "--policy",
            "scripted",
            "--episodes",
            "8",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert res.returncode == 0, res.stderr
    out = strict_json(res.stdout)
    for key in (
        "success_rate",
        "mean_time_s",
        "mean_fz_N",
        "peak_fz_N",
        "mean_fxy_N",
        "episodes",
        "nan_worlds",
    ):
        assert key in out
    assert out["episodes"] == 8 and out["nan_worlds"] == 0
    assert out["success_rate"] >= 0.9
    assert out["physics_steps_per_s"] > 0 and out["compile_s"] > 0


def test_cli_rollout_bad_input():
    for args, msg in (
        (["--env", "RectExtract", "--policy", "nope.ckpt"], "no policy at nope.ckpt"),
        (["--env", "RectExtract", "--episodes", "0"], "--episodes"),
        (["--env", "RectExtract", "--preset", "dual-1"], "does not fit"),
        (["--env", "RectExtract", "--set", "action.nope=1"], "action has no 'nope'"),
    ):
        res = subprocess.run(
            [sys.executable, "-m", "peghole_mjx.cli.main", "envs", "rollout", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert res.returncode == 2 and msg in res.stderr, res.stderr
        assert "Traceback" not in res.stderr


def test_contact_overflow_reads_warps_buffer_bits_only():
    """MJX-JAX data never overflows; Warp's sticky bitmask counts only dropped contacts/rows."""
    from types import SimpleNamespace

    from peghole_mjx.core._mjx import mjx
    from peghole_mjx.envs.base import contact_overflow

    env = envs.load("RectExtract")
    assert float(contact_overflow(mjx.make_data(env.mjx_model, impl="jax"))) == 0.0

    def warp_like(bits):
        return SimpleNamespace(_impl=SimpleNamespace(overflow=jnp.array([bits], jnp.int32)))

    assert float(contact_overflow(warp_like(0))) == 0.0
    assert float(contact_overflow(warp_like(1 << 3))) == 1.0  # NARROWPHASE: contacts dropped
    assert float(contact_overflow(warp_like(1 << 0))) == 1.0  # NEFC: constraint rows dropped
    assert float(contact_overflow(warp_like(1 << 9))) == 0.0  # solver iteration limit only


def _cuda_warp() -> bool:
    from peghole_mjx.core._mjx import WARP_AVAILABLE

    return WARP_AVAILABLE and any(d.platform == "gpu" for d in jax.devices())


@pytest.mark.gpu
@pytest.mark.skipif(not _cuda_warp(), reason="needs a CUDA GPU and warp-lang (impl='warp')")
def test_warp_contact_buffer_overflow_ends_the_episode_and_is_counted():
    """A deliberately tiny contact buffer must be reported, not silently drop contacts."""
    env = envs.load("RectExtract", config_overrides={"impl": "warp", "naconmax": 1})
    res = rollout(env, scripted_policy(env), 4, seed=0, progress=False)
    s = res.summary()
    assert s.overflow_worlds > 0
    assert s.success_rate < 1.0


@pytest.mark.gpu
@pytest.mark.skipif(not _cuda_warp(), reason="needs a CUDA GPU and warp-lang (impl='warp')")
@pytest.mark.parametrize(
    "name,rep", [("RectExtract", "box"), ("DualExtract", "capsule"), ("DualExtract", "cylinder")]
)
def test_warp_scenes_step_without_overflow(name, rep):
    """MuJoCo Warp runs every scene (the dual cylinder one too) with the default buffers."""
    env = envs.load(name, config_overrides={"impl": "warp", "representation": rep})
    res = rollout(env, scripted_policy(env), 4, seed=0, progress=False)
    s = res.summary()
    assert s.overflow_worlds == 0 and s.nan_worlds == 0


def test_cylinder_needs_warp_one_line_error():
    """MJX-JAX has no cylinder-box collision: the cylinder scene on engine mjx with impl jax
    is refused in one line (MuJoCo C and MuJoCo Warp collide it)."""
    over = {"representation": "cylinder", "engine": "mjx"}
    with pytest.raises(UserInputError, match="cannot run with impl='jax'"):
        envs.load("DualExtract", config_overrides=over)
    c_engine = envs.load("DualExtract", config_overrides={**over, "engine": "mujoco"})
    assert c_engine.representation == "cylinder"
    with pytest.raises(UserInputError, match="unknown collision representation"):
        envs.load("DualExtract", config_overrides={"representation": "sphere"})
    with pytest.raises(UserInputError, match="below the measured maximum"):
        envs.load("DualExtract", config_overrides={"contact_cap": 4})


def test_unknown_config_override_key_is_refused_by_name():
    """A typo in a flat override (``--set env.KEY=...``) is an error, not a silently new key."""
    for key, msg in (
        ("action.max_ff_xy", "action has no 'max_ff_xy'"),
        ("episode_lenght", "the env config has no 'episode_lenght'"),
        ("episode_length.steps", "episode_length has no 'steps'"),
    ):
        with pytest.raises(UserInputError, match=msg):
            envs.load("DualExtract", config_overrides={key: 1})
