"""One default engine, ``auto``, and the engine as provenance, not the task.

``auto`` is :func:`peghole_mjx.sim.engines.default_engine`: MuJoCo C without a GPU; on a CUDA GPU
MJX-Warp when warp-lang is installed, else MJX-JAX. The env config, the commands, the
experiments, the Gymnasium adapter and Playground default to it; a built env's config holds
the engine chosen. A policy's ``env_overrides`` carry no engine entry (its ``engine`` field
records the one trained on), and a policy on another engine is not a different task.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import pytest

from peghole_mjx import envs
from peghole_mjx.envs import playground
from peghole_mjx.experiments import cli as exp_cli
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.policies import PolicyBundle, check_as_trained
from peghole_mjx.sim import engines as sim_engines
from peghole_mjx.sim.engines import ENGINE_KEYS, engine_label, resolve_engine, task_overrides
from peghole_mjx.training.config import load_train_config
from peghole_mjx.training.evaluate import config_differences, requested_config
from peghole_mjx.training.run import policy_meta


@pytest.mark.parametrize(
    ("backend", "warp", "engine"),
    [
        ("cpu", True, "mujoco"),
        ("cpu", False, "mujoco"),
        ("gpu", True, "mjx-warp"),
        ("gpu", False, "mjx"),
        ("tpu", True, "mjx"),  # MuJoCo Warp is CUDA only
    ],
)
def test_default_engine_by_backend_and_warp(monkeypatch, backend, warp, engine):
    monkeypatch.setattr(jax, "default_backend", lambda: backend)
    monkeypatch.setattr(sim_engines, "WARP_AVAILABLE", warp)
    assert sim_engines.default_engine() == engine
    # the experiments have no warp path: auto on a GPU is their mjx
    assert cx.auto_engine() == ("mujoco" if backend == "cpu" else "mjx")
    assert cx.auto_engine(x64=True) == "mjx"  # MJX's float64 asked for


def test_resolve_engine_gpu_with_warp_sets_impl(monkeypatch):
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    monkeypatch.setattr(sim_engines, "WARP_AVAILABLE", True)
    config = resolve_engine(envs.get_default_config("RectExtract"))
    assert (config.engine, config.impl) == ("mjx", "warp")
    assert engine_label(config) == "mjx-warp"
    assert playground.playground_engine() == {"engine": "mjx", "impl": "warp"}


def test_env_config_defaults_to_auto_and_a_built_env_holds_the_engine():
    assert jax.default_backend() == "cpu"  # this suite's machines
    config = envs.get_default_config("RectExtract")
    assert config.engine == "auto"
    env = envs.load("RectExtract")
    assert env.config.engine == "mujoco"
    assert type(env.engine).__name__ == "MujocoEngine"
    assert engine_label(env.config) == "mujoco"
    assert config.engine == "auto"  # the caller's config is not changed
    # an engine named is kept
    assert envs.load("RectExtract", config_overrides={"engine": "mjx"}).config.engine == "mjx"


def test_gym_adapter_defaults_to_auto():
    gym = pytest.importorskip("peghole_mjx.gym")
    env = gym.PegHoleGymEnv("RectExtract")
    assert env.env.config.engine == "mujoco"


def test_playground_auto_is_mjx_without_a_gpu():
    assert playground.playground_engine() == {"engine": "mjx"}
    env = playground.load("RectExtract", {"episode_length": 5})
    assert env.config.engine == "mjx"
    assert env.config.episode_length == 5
    assert playground.load("RectExtract", {"engine": "mujoco"}).config.engine == "mujoco"


def _experiment_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    exp_cli.add_parser(parser.add_subparsers(dest="group"))
    return parser


@pytest.mark.parametrize(
    "argv",
    [
        ["experiment", "sweep", "--geometry", "rect", "--out", "x"],
        ["experiment", "contact-check"],
    ],
)
def test_experiment_commands_default_to_auto(argv):
    args = _experiment_parser().parse_args(argv)
    assert args.engine == "auto"
    assert cx.check_engine(args.engine) == "mujoco"  # no GPU here
    assert cx.check_engine(args.engine, x64=True) == "mjx"
    with pytest.raises(Exception, match="engine must be"):
        cx.check_engine("mjx-warp")


def test_contact_check_variant_config_defaults_to_auto():
    from peghole_mjx.experiments import contact_check as cc

    variant = next(iter(cc.VARIANTS.values()))
    assert cc.variant_config(variant).engine == "mujoco"
    assert cc.variant_config(variant, "mjx").engine == "mjx"


def _bundle(meta: dict) -> PolicyBundle:
    return PolicyBundle(path=Path("policy"), meta=meta, params=None)


def test_policy_meta_records_the_engine_outside_the_task():
    cfg = load_train_config(
        "RectExtract", overrides={"env.engine": "mjx", "env.episode_length": 100}
    )
    assert cfg.env_overrides["engine"] == "mjx"  # what the run stepped with
    meta = policy_meta(cfg, {"hidden": [8]}, 10, "mjx")
    assert meta["engine"] == "mjx"
    assert not set(meta["env_overrides"]) & set(ENGINE_KEYS)
    assert meta["env_overrides"]["episode_length"] == 100
    check_as_trained(meta, "policy")  # train_config's engine is provenance, not a difference


def test_a_policy_on_another_engine_is_the_same_task():
    old = {  # a policy file from before 2026-12-05: its engine in env_overrides
        "env": "RectExtract",
        "env_overrides": {"engine": "mjx", "impl": "jax", "episode_length": 100},
    }
    bundle = _bundle(old)
    on_mujoco = requested_config(bundle, {"engine": "mujoco", "mujoco_threads": 2})
    assert config_differences(bundle, on_mujoco) == {}
    # a task entry is still a difference
    longer = requested_config(bundle, {"engine": "mujoco", "episode_length": 200})
    assert config_differences(bundle, longer) == {"episode_length": [100, 200]}
    # an old policy whose env_overrides and train_config agree but for the engine still loads
    old_meta = {**old, "train_config": {"env_overrides": {"engine": "mujoco"}}}
    check_as_trained(old_meta, "policy")
    with pytest.raises(Exception, match="episode_length"):
        check_as_trained(
            {**old, "train_config": {"env_overrides": {"episode_length": 50}}}, "policy"
        )


def test_task_overrides_drops_flat_and_prefixed_engine_keys():
    over = {"engine": "mjx", "env.impl": "warp", "env.mujoco_threads": 2, "env.preset": "rect-3"}
    assert task_overrides(over) == {"env.preset": "rect-3"}


def test_trained_engine_of_new_old_and_oldest_policies():
    assert _bundle({"env": "RectExtract", "engine": "mjx-warp"}).trained_engine() == {
        "engine": "mjx",
        "impl": "warp",
    }
    old = {"env": "RectExtract", "env_overrides": {"engine": "mujoco", "episode_length": 9}}
    assert _bundle(old).trained_engine() == {"engine": "mujoco"}
    # before the engine was recorded the env default was MJX
    assert _bundle({"env": "RectExtract", "env_overrides": {}}).trained_engine() == {
        "engine": "mjx"
    }
