"""Evaluate a policy against the scripted fixed-compliance baseline on the same episodes.

Both run through :func:`peghole_mjx.envs.rollout.rollout` with the same seed, so they meet
the same randomised starts (hole pose, lateral and angular errors, friction). The force
reduction is ``100 (F_baseline - F_policy) / F_baseline`` on the mean extraction force
(mean |F_z| per episode, averaged over episodes), the quantity of the thesis's R3.
"""

from __future__ import annotations

from typing import Any

from peghole_mjx.envs.rollout import rollout, scripted_policy
from peghole_mjx.policies import PolicyBundle, load_policy

#: the thesis's headline RL numbers (Sec 4.3.2, 4.4; seed_parameters.md R3-R5)
THESIS_RL = {
    "force_reduction_pct": 29.6,  # R3: RL + CS vs the Ch 2-3 method
    "success_rate": 0.94,  # R4
    "mean_time_s": 7.6,  # R4
    "peak_fz_N_policy": 8.0,  # R5: RL peak F_z <= 8 N ...
    "peak_fz_N_baseline": 12.0,  # ... vs > 12 N for the Ch 2-3 method
}


def force_reduction_pct(policy: dict[str, Any], baseline: dict[str, Any]) -> float:
    """R3's measure: percent reduction of the mean extraction force vs the baseline."""
    b = baseline["mean_fz_N"]
    return 100.0 * (b - policy["mean_fz_N"]) / b if b > 0 else float("nan")


def evaluate(
    policy: str | PolicyBundle,
    episodes: int,
    seed: int = 0,
    progress: bool = True,
    env_overrides: dict | None = None,
    env=None,
) -> dict[str, Any]:
    """``{"policy", "baseline", "force_reduction_pct", "episodes", ...}`` (see module doc).

    ``env``: an already built env of the policy's config (reuses its compiled rollouts).
    """
    bundle = policy if isinstance(policy, PolicyBundle) else load_policy(policy)
    env = env if env is not None else bundle.make_env(env_overrides)
    res_p = rollout(
        env, bundle.policy_fn(), episodes, seed=seed, progress=progress, params=bundle.params
    )
    res_b = rollout(env, scripted_policy(env), episodes, seed=seed, progress=progress)
    pol, base = res_p.summary().as_dict(), res_b.summary().as_dict()
    return {
        "policy": pol,
        "baseline": base,
        "force_reduction_pct": force_reduction_pct(pol, base),
        "episodes": episodes,
        "seed": seed,
        "env": bundle.env_name,
        "preset": env.config.preset,
        "compliance_strategy": bool(env.config.compliance_strategy),
        "policy_path": str(bundle.path),
        "thesis": THESIS_RL,
    }
