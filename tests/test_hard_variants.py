"""RectExtractHard and DualExtractHard: registered, defined by their levers only, and hard for the
scripted Ch 2-3 method (docs/index.md, "Hard variants")."""

import numpy as np
import pytest

from peghole_mjx import envs
from peghole_mjx.envs import dual_extract, rect_extract
from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.geometry.specs import get_preset


def _flat(cfg) -> dict:
    out = {}

    def walk(d, prefix):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                out[prefix + k] = v

    walk(cfg.to_dict(), "")
    return out


def _diff(a, b) -> dict:
    fa, fb = _flat(a), _flat(b)
    return {k: (fa[k], fb[k]) for k in fa if fa[k] != fb[k]}


def test_hard_variants_are_registered_and_differ_only_in_their_levers():
    assert {"RectExtractHard", "DualExtractHard"} <= set(envs.ALL_ENVS)
    rect = _diff(envs.get_default_config("RectExtract"), envs.get_default_config("RectExtractHard"))
    assert rect == {
        "preset": ("rect-2", "rect-3"),
        "randomization.angular_error_deg": (0.5, rect_extract.HARD_ANGULAR_ERROR_DEG),
    }
    dual = _diff(envs.get_default_config("DualExtract"), envs.get_default_config("DualExtractHard"))
    levers = {"preset", "randomization.friction_scale", "randomization.angular_error_deg"}
    assert set(dual) == levers
    assert dual["preset"] == ("dual-2", "dual-3")
    # the friction range is the rect chapter's PLA mu 0.266 x (0.8, 1.2) (erratum E5)
    mu = get_preset("dual-3").friction * np.asarray(dual["randomization.friction_scale"][1])
    np.testing.assert_allclose(mu, 0.266 * np.array([0.8, 1.2]), rtol=1e-12)
    assert dual["randomization.angular_error_deg"][1] == dual_extract.HARD_ANGULAR_ERROR_DEG
    env = envs.load("DualExtractHard")  # builds (the env's own config checks accept the levers)
    assert env.spec.peg_radii_mm == (6.05, 6.05) and env.config.preset == "dual-3"


@pytest.mark.slow
def test_scripted_method_wedges_in_part_of_the_dual_hard_episodes():
    """16 episodes of seed 0: the scripted method extracts some and fails on others, each
    failure a peg held at the controller's 60 N axial force limit (wedged) until the time
    limit; the env's lateral jamming rule does not fire (the fixed 300 N/m lateral spring
    cannot load the sensor with 18 N). On the ``mujoco`` engine (the engines' scripted results
    agree on this env: benchmarks/results/evals/cross_engine*.json; an MJX rollout graph
    compiles for two minutes)."""
    env = envs.load("DualExtractHard", config_overrides={"engine": "mujoco"})
    e = rollout(env, scripted_policy(env), 16, seed=0, progress=False).per_episode
    ok, failed = e["success"] > 0, e["failure"] > 0
    assert ok.any() and failed.any() and (ok ^ failed).all()
    assert not (e["nan"] > 0).any() and not (e["jammed"] > 0).any()
    assert (e["peak_fz_N"][failed] > 55.0).all()  # at the 60 N limit of the axial force


def test_a_hard_variant_policy_fits_its_env_and_not_the_base_one():
    """The hard variants share their base env's class: the registry name tells them apart."""
    from pathlib import Path

    from peghole_mjx.core.errors import UserInputError
    from peghole_mjx.policies import PolicyBundle

    hard, base = envs.load("RectExtractHard"), envs.load("RectExtract")
    assert (hard.env_name, base.env_name) == ("RectExtractHard", "RectExtract")
    sizes = {"observation_size": hard.observation_size, "action_size": hard.action_size}
    bundle = PolicyBundle(Path("p"), {"env": "RectExtractHard", "network": sizes}, None)
    bundle.check_env(hard)
    with pytest.raises(UserInputError, match="for RectExtractHard, not for RectExtract$"):
        bundle.check_env(base)
