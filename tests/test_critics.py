"""The critics beside Brax's (training/critics.py): shapes, structure, that they learn a known
function, and that a run's ``critic`` reaches the trainer (and is refused when unknown)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from peghole_mjx import envs
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.training.config import load_train_config
from peghole_mjx.training.critics import CRITICS, SIMBA_EXPANSION, make_q_network
from peghole_mjx.training.sac import SACTrainer

OBS, ACT, WIDTH = 9, 8, 32


def _params(critic: str, hidden=(WIDTH, WIDTH)):
    net = make_q_network(critic, OBS, ACT, hidden_layer_sizes=hidden)
    return net, net.init(jax.random.PRNGKey(0))


@pytest.mark.parametrize("critic", CRITICS)
def test_twin_critics_of_every_kind(critic):
    net, params = _params(critic)
    q = net.apply(None, params, jnp.ones((5, OBS)), jnp.ones((5, ACT)))
    assert q.shape == (5, 2) and bool(jnp.all(jnp.isfinite(q)))
    assert float(jnp.abs(q[:, 0] - q[:, 1]).max()) > 0, "the twin critics start different"
    paths = [jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(params)]
    assert any("LayerNorm" in p for p in paths) == (critic != "mlp"), paths


def test_simba_structure():
    """SimBa: per critic an embedding, one residual block per hidden width (inner 4 d), a final
    LayerNorm and the output."""
    _, params = _params("simba", hidden=(WIDTH, WIDTH, WIDTH))
    p = params["params"]
    assert sorted(k for k in p if k.startswith("LayerNorm")) == ["LayerNorm_0", "LayerNorm_1"]
    assert len([k for k in p if k.startswith("Dense")]) == 2 * 2  # embedding and output each
    blocks = sorted(k for k in p if k.startswith("SimbaBlock"))
    assert len(blocks) == 2 * 3  # two critics, three blocks each
    inner = p[blocks[0]]["Dense_0"]["kernel"]
    assert inner.shape == (WIDTH, SIMBA_EXPANSION * WIDTH)


@pytest.mark.parametrize("critic", CRITICS)
def test_critic_learns_a_known_function(critic):
    """300 Adam steps on Q(s, a) = sum(s) - 2 sum(a) bring the error down 20x: the gradient
    reaches every critic's layers."""
    net, params = _params(critic)
    rng = np.random.default_rng(0)
    obs = jnp.asarray(rng.normal(size=(256, OBS)), jnp.float32)
    act = jnp.asarray(rng.uniform(-1, 1, size=(256, ACT)), jnp.float32)
    target = (obs.sum(-1) - 2 * act.sum(-1))[:, None]

    def loss(p):
        return jnp.mean((net.apply(None, p, obs, act) - target) ** 2)

    opt = optax.adam(1e-3)
    state = opt.init(params)

    @jax.jit
    def step(p, s):
        g = jax.grad(loss)(p)
        u, s = opt.update(g, s)
        return optax.apply_updates(p, u), s

    first = float(loss(params))
    for _ in range(300):
        params, state = step(params, state)
    assert float(loss(params)) < first / 20


def test_run_critic_reaches_the_trainer():
    env = envs.load("RectExtract", config_overrides={"engine": "mujoco"})
    cfg = load_train_config("RectExtract", "quick", {"critic": "simba", "env.engine": "mujoco"})
    assert cfg.critic == "simba"
    trainer = SACTrainer(env, cfg, single_device=True)
    params = trainer.nets.q_network.init(jax.random.PRNGKey(0))
    assert any(k.startswith("SimbaBlock") for k in params["params"])
    default = load_train_config("RectExtract", "quick", {"env.engine": "mujoco"})
    assert default.critic == "mlp"


def test_unknown_critic_is_refused():
    with pytest.raises(UserInputError, match="critic must be one of"):
        load_train_config("RectExtract", "quick", {"critic": "transformer"})
    with pytest.raises(UserInputError, match="critic must be one of"):
        make_q_network("transformer", OBS, ACT)


def _batch(trainer: SACTrainer, n: int, seed: int):
    """A replay batch of ``n`` random transitions of the trainer's sizes (none truncated)."""
    from brax.training.types import Transition

    rng = np.random.default_rng(seed)
    obs, act = trainer.obs_size, trainer.act_size
    return Transition(
        observation=jnp.asarray(rng.normal(size=(n, obs)), jnp.float32),
        action=jnp.asarray(rng.uniform(-1, 1, size=(n, act)), jnp.float32),
        reward=jnp.asarray(rng.normal(size=n), jnp.float32),
        discount=jnp.ones(n),
        next_observation=jnp.asarray(rng.normal(size=(n, obs)), jnp.float32),
        extras={"state_extras": {"truncation": jnp.zeros(n)}, "policy_extras": {}},
    )


def _one_update(cfg_overrides: dict, log_alpha: float):
    """The critics' parameters after one SGD step of a fresh learner (seed 0, fixed batch) whose
    temperature is ``exp(log_alpha)``."""

    from peghole_mjx.training.sac import AXIS

    env = envs.load("RectExtract", config_overrides={"engine": "mujoco"})
    cfg = load_train_config("RectExtract", "quick", {"env.engine": "mujoco", **cfg_overrides})
    trainer = SACTrainer(env, cfg, single_device=True)
    ts = trainer.learner_state(jax.random.PRNGKey(0))
    ts = ts.replace(log_alpha=jnp.asarray(log_alpha, jnp.float32))
    trans = _batch(trainer, 16, seed=1)
    step = jax.vmap(
        lambda t, tr: trainer._sgd_step((t, jax.random.PRNGKey(2)), tr)[0][0], axis_name=AXIS
    )
    out = step(*(jax.tree.map(lambda x: jnp.asarray(x)[None], t) for t in (ts, trans)))
    return out.q_params


@pytest.mark.parametrize("backup", [True, False])
def test_entropy_backup_decides_whether_alpha_reaches_the_critics(backup):
    """With ``entropy_backup`` false the critics' update does not depend on the temperature
    (their target is the task reward alone); with Brax's target (true) it does."""
    low, high = (_one_update({"entropy_backup": backup}, la) for la in (-5.0, 2.0))
    diff = max(
        float(jnp.abs(a - b).max())
        for a, b in zip(jax.tree.leaves(low), jax.tree.leaves(high), strict=True)
    )
    assert (diff > 1e-6) == backup, diff


def test_linear_lr_schedule_falls_to_zero_at_the_last_update():
    from peghole_mjx.training.config import learning_rate

    cfg = load_train_config("RectExtract", "quick", {"lr_schedule": "linear"})
    updates = cfg.num_timesteps // cfg.num_envs * cfg.grad_updates_per_step
    lr = learning_rate(cfg)
    assert float(lr(0)) == pytest.approx(cfg.learning_rate)
    assert float(lr(updates // 2)) == pytest.approx(cfg.learning_rate / 2, rel=1e-3)
    assert float(lr(updates)) == 0.0 and float(lr(2 * updates)) == 0.0
    const = load_train_config("RectExtract", "quick")
    assert learning_rate(const) == const.learning_rate


def test_outcome_return_bounds_hold_the_rewards_extremes():
    """The bounds of envs/reward.py's return_bounds against the reward's own extremes: a full
    pull with no cost reaches w_progress at most; the worst stay then failure is above lo."""
    from peghole_mjx.envs.reward import failure_cost, return_bounds

    rc = envs.load("RectExtract", config_overrides={"reward_config.kind": "outcome"})
    rc = rc.config.reward_config
    lo, hi = return_bounds(rc)
    assert hi == rc.w_progress
    c_max = rc.time_cost * (1 + rc.w_contact)
    worst = -c_max / (1 - rc.discount) - failure_cost(rc) - rc.w_progress
    assert lo <= worst < hi
    with pytest.raises(ValueError, match="outcome"):
        thesis = envs.load("RectExtract", config_overrides={"reward_config.kind": "thesis"})
        return_bounds(thesis.config.reward_config)


def test_clipped_target_critic_loss_is_braxs_inside_the_bounds_and_clips_outside():
    """Within wide bounds the clipped loss equals Brax's, value for value; with a ceiling
    below every target the critics regress on the ceiling."""
    from brax.training.agents.sac import losses as sac_losses

    from peghole_mjx.training.losses import make_clipped_critic_loss

    env = envs.load("RectExtract", config_overrides={"engine": "mujoco"})
    cfg = load_train_config("RectExtract", "quick", {"env.engine": "mujoco"})
    trainer = SACTrainer(env, cfg, single_device=True)
    ts = trainer.learner_state(jax.random.PRNGKey(0))
    trans = _batch(trainer, 32, seed=3)
    act = trainer.act_size
    args = (ts.q_params, ts.policy_params, ts.normalizer, ts.target_q_params, 0.1, trans)
    key = jax.random.PRNGKey(4)
    _, brax_loss, _ = sac_losses.make_losses(trainer.nets, 1.0, cfg.discounting, act)
    wide = make_clipped_critic_loss(trainer.nets, 1.0, cfg.discounting, (-1e6, 1e6))
    assert float(wide(*args, key)) == pytest.approx(float(brax_loss(*args, key)), rel=1e-6)
    ceiling = -50.0  # below every target here (rewards ~N(0, 1), a fresh critic near 0)
    low = make_clipped_critic_loss(trainer.nets, 1.0, cfg.discounting, (-1e6, ceiling))
    q = trainer.nets.q_network.apply(ts.normalizer, ts.q_params, trans.observation, trans.action)
    assert float(low(*args, key)) == pytest.approx(float(0.5 * jnp.mean((q - ceiling) ** 2)))
    with pytest.raises(ValueError, match="increasing"):
        make_clipped_critic_loss(trainer.nets, 1.0, cfg.discounting, (1.0, -1.0))


def test_q_target_clip_is_refused_under_the_thesis_reward():
    env = envs.load(
        "RectExtract", config_overrides={"engine": "mujoco", "reward_config.kind": "thesis"}
    )
    cfg = load_train_config(
        "RectExtract",
        "quick",
        {"env.engine": "mujoco", "env.reward_config.kind": "thesis", "q_target_clip": True},
    )
    with pytest.raises(UserInputError, match="q_target_clip needs the outcome reward"):
        SACTrainer(env, cfg, single_device=True)
