"""The committed pretrained policies: they load, fit their envs, and their evaluation holds."""

import json
import math

import pytest

from peghole_mjx.errors import UserInputError
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
    """A fresh evaluation (other episodes) agrees with the committed one within sampling error."""
    from peghole_mjx.envs.rollout import rollout

    committed = json.loads((PRETRAINED["rect"] / "evaluation.json").read_text())
    bundle = load_policy("rect")
    n = 16
    res = rollout(
        bundle.make_env(), bundle.policy_fn(), n, seed=123, progress=False, params=bundle.params
    ).summary()
    p0 = committed["policy"]["success_rate"]
    # 3 sigma of the difference of two binomial proportions, plus one episode of slack
    sigma = math.sqrt(max(p0 * (1 - p0), 0.02) * (1 / n + 1 / committed["episodes"]))
    assert abs(res.success_rate - p0) <= 3 * sigma + 1 / n
    assert res.nan_worlds == 0


def test_unknown_policy_name_is_a_clear_error(tmp_path):
    with pytest.raises(UserInputError, match="no policy at"):
        resolve_policy_path(tmp_path / "nothing_here")
