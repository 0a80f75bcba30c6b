"""The committed pretrained policies: they load, fit their envs, and their evaluation holds."""

import json
import math

import pytest

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.policies import PRETRAINED, load_policy, resolve_policy_path

ROLLOUT_KEYS = {"success_rate", "mean_time_s", "mean_fz_N", "peak_fz_N", "mean_fxy_N", "episodes"}


@pytest.mark.parametrize("name", sorted(PRETRAINED))
def test_pretrained_policy_loads_and_fits_its_env(name):
    bundle = load_policy(name)
    env = bundle.make_env()
    assert bundle.meta["network"]["observation_size"] == env.observation_size
    assert bundle.meta["network"]["action_size"] == env.action_size
    assert "selection" in bundle.meta  # which checkpoint was published, and why


@pytest.mark.parametrize("name", sorted(PRETRAINED))
def test_committed_evaluation_has_the_issue_keys(name):
    ev = json.loads((PRETRAINED[name] / "evaluation.json").read_text())
    assert {"policy", "baseline", "force_reduction_pct", "episodes"} <= set(ev)
    for side in ("policy", "baseline"):
        assert ROLLOUT_KEYS <= set(ev[side])
        assert ev[side]["episodes"] == ev["episodes"]
    b, p = ev["baseline"]["mean_fz_N"], ev["policy"]["mean_fz_N"]
    assert ev["force_reduction_pct"] == pytest.approx(100 * (b - p) / b)


@pytest.mark.slow
def test_rect_policy_reproduces_its_committed_success_rate():
    """A fresh evaluation (other episodes) agrees with the committed one within sampling error:
    16 episodes of another seed on the engine of the committed evaluation (MuJoCo C, the CPU
    default, compiles in seconds) against its ``evaluation.json``."""
    from peghole_mjx.envs.rollout import rollout
    from peghole_mjx.sim.engines import engine_overrides

    committed = json.loads((PRETRAINED["rect"] / "evaluation.json").read_text())
    assert committed["engine"] == "mujoco"
    bundle = load_policy("rect")
    env = bundle.make_env(engine_overrides("mujoco"))
    assert env.engine.name == "mujoco"
    n = 16
    res = rollout(env, bundle.policy_fn(), n, seed=123, progress=False, params=bundle.params)
    res = res.summary()
    p0 = committed["policy"]["success_rate"]
    # 3 sigma of the difference of two binomial proportions, plus one episode of slack
    sigma = math.sqrt(max(p0 * (1 - p0), 0.02) * (1 / n + 1 / committed["episodes"]))
    assert abs(res.success_rate - p0) <= 3 * sigma + 1 / n
    assert res.nan_worlds == 0


def test_unknown_policy_name_is_a_clear_error(tmp_path):
    with pytest.raises(UserInputError, match="no policy at"):
        resolve_policy_path(tmp_path / "nothing_here")


@pytest.mark.parametrize("name", sorted(PRETRAINED))
def test_pretrained_policy_runs_in_its_training_env(name):
    """A published policy's env is its training env: every training env override with its
    trained value (pins of later physics defaults may be added; the engine entries are
    provenance, not the task: ``ENGINE_KEYS``), and no deployment record."""
    from peghole_mjx.sim.engines import ENGINE_KEYS

    meta = json.loads((PRETRAINED[name] / "policy.json").read_text())
    assert "deployment" not in meta
    trained = {
        k: v for k, v in meta["train_config"]["env_overrides"].items() if k not in ENGINE_KEYS
    }
    assert {k: meta["env_overrides"].get(k) for k in trained} == trained


def _copy_policy(tmp_path, name="rect"):
    import shutil

    dest = tmp_path / name
    shutil.copytree(PRETRAINED[name], dest)
    return dest, json.loads((dest / "policy.json").read_text())


def test_policy_with_a_deployment_record_is_refused_in_one_line(tmp_path):
    dest, meta = _copy_policy(tmp_path)
    meta["deployment"] = {"env_overrides": {"action.max_ff_xy_N": 0.5}}
    (dest / "policy.json").write_text(json.dumps(meta))
    with pytest.raises(UserInputError, match="'deployment' record") as err:
        load_policy(dest)
    assert "\n" not in str(err.value)


def test_policy_whose_env_differs_from_its_training_config_is_refused(tmp_path):
    dest, meta = _copy_policy(tmp_path)
    meta["env_overrides"]["action.max_speed_m_s"] = 0.05  # trained with 0.025
    (dest / "policy.json").write_text(json.dumps(meta))
    with pytest.raises(UserInputError, match=r"action.max_speed_m_s \(0.05, trained 0.025\)"):
        load_policy(dest)


def test_evaluation_refuses_an_env_other_than_the_training_env(capsys):
    """Evaluation of a policy in an env config other than its training one is refused in one
    line naming the keys (before any env is built), unless asked for (--cross)."""
    from peghole_mjx.cli.main import main
    from peghole_mjx.training.evaluate import evaluate

    with pytest.raises(UserInputError, match=r"preset \(trained 'rect-2', requested 'rect-1'\)"):
        evaluate("rect", 2, env_overrides={"preset": "rect-1"}, progress=False)
    argv = ["evaluate", "rect", "--episodes", "2", "--preset", "rect-3"]
    assert main([*argv, "--set", "env.action.max_ff_xy_N=0.5"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "rect-3" in err and "action.max_ff_xy_N" in err
    assert "--cross" in err
    # the training value itself is no difference
    with pytest.raises(UserInputError, match="preset"):
        evaluate("rect", 2, env_overrides={"preset": "rect-1", "action.max_speed_m_s": 0.025})
    # another env name
    assert main(["evaluate", "rect", "--env", "DualExtract"]) == 2
    assert "not for DualExtract" in capsys.readouterr().err
    # a cross evaluation is not written into a policy folder
    out = PRETRAINED["rect"] / "cross.json"
    assert main([*argv, "--cross", "--out", str(out)]) == 2
    assert "not written into a policy folder" in capsys.readouterr().err
    assert not out.exists()
