"""Evaluate a policy against the scripted fixed-compliance baseline on the same episodes.

Both run through :func:`peghole_mjx.envs.rollout.rollout` with the same seed, so they meet
the same randomised starts (hole pose, lateral and angular errors, friction). The force
reduction is ``100 (F_baseline - F_policy) / F_baseline`` on the mean extraction force
(mean |F_z| per episode, averaged over episodes), the quantity of the thesis's R3.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import jax
import numpy as np

from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S, rollout, scripted_policy
from peghole_mjx.errors import UserInputError
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


#: env-config entries that cannot change a scripted-baseline episode: its lateral offset and
#: feed-forward actions are 0, so the commanded offset stays 0 and the feed-forward stays 0
#: whatever their step sizes and bounds; its action is constant, so what the observation
#: holds (``obs``) changes nothing it commands. Left out of the baseline's slice key, so
#: policies trained with different feed-forward or observation settings share one baseline
#: (same episodes). The compiled program still differs, and with it the float32 rounding: in
#: the dual scene turning ``obs.commands`` on moved each episode's mean F_z by up to 0.0058 N
#: of 0.1 N (2026-11-30), the 256-episode mean by 0.03 %.
BASELINE_IGNORED_CONFIG = (
    "action.max_step_offset_mm",
    "action.max_force_step_N",
    "action.max_ff_xy_N",
    "obs",
)


def _config_key(env, ignored=()) -> str:
    cfg = json.loads(env.config.to_json())
    if not cfg.get("geometry"):  # the preset's own geometry: keys as before the entry existed
        cfg.pop("geometry", None)
    for dotted in ignored:
        *path, leaf = dotted.split(".")
        node = cfg
        for k in path:
            node = node.get(k, {})
        node.pop(leaf, None)
    return json.dumps(cfg, sort_keys=True)


def _keyed_dir(root: Path, key: dict[str, Any]) -> Path:
    """``root`` with its ``key.json``; raises if the folder holds another evaluation's slices."""
    key_file = root / "key.json"
    if key_file.exists():
        old = json.loads(key_file.read_text())
        diff = sorted(k for k in key.keys() | old.keys() if old.get(k) != key.get(k))
        if diff:
            raise UserInputError(
                f"{root} holds the slices of another evaluation (differs in {', '.join(diff)}); "
                "choose another --parts folder or delete it"
            )
    else:
        root.mkdir(parents=True, exist_ok=True)
        from peghole_mjx import fileio

        fileio.write_text(key_file, json.dumps(key, indent=2) + "\n")
    return root


def params_sha256(params) -> str:
    """Digest of a policy's parameters (names its slice folder)."""
    return hashlib.sha256(
        b"".join(np.asarray(x).tobytes() for x in jax.tree.leaves(params))
    ).hexdigest()


def _parts_dirs(parts_dir, bundle, env, seed, batch):
    """(policy, baseline) slice folders under ``parts_dir``, each keyed by its ``key.json``.

    ``policy-<params sha256[:12]>-<env config sha256[:8]>/``: one per policy parameters and
    env (a checkpoint run in a changed env, e.g. a tighter force bound, gets its own
    folder); ``baseline/``: shared by every policy
    evaluated in this folder whose env differs at most in :data:`BASELINE_IGNORED_CONFIG`.
    Not the episode count: slice k holds episodes [k batch, (k + 1) batch) of any evaluation
    with this seed (JAX's partitionable threefry splits keys prefix-stably), so a 256-episode
    evaluation's slices are reused when it is extended to 1024.
    """
    if parts_dir is None:
        return None, None
    root = Path(parts_dir)
    episodes_key = {"env": bundle.env_name, "seed": seed, "batch": batch}
    sha = params_sha256(bundle.params)
    policy_key = {  # by parameters, not path: a published copy of a checkpoint reuses its slices
        "params_sha256": sha,
        **episodes_key,
        "env_config": _config_key(env),
    }
    baseline_key = {
        **episodes_key,
        "env_config": _config_key(env, BASELINE_IGNORED_CONFIG),
        "speed_m_s": SCRIPTED_SPEED_M_S,
    }
    baseline_dir = _keyed_dir(root / "baseline", baseline_key)
    cfg_sha = hashlib.sha256(policy_key["env_config"].encode()).hexdigest()
    policy_dir = root / f"policy-{sha[:12]}-{cfg_sha[:8]}"
    return _keyed_dir(policy_dir, policy_key), baseline_dir


def _flat(tree: dict, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = list(v) if isinstance(v, tuple) else v
    return out


def config_differences(bundle: PolicyBundle, config) -> dict[str, list]:
    """``{dotted key: [trained value, requested value]}`` for every entry of the env config
    ``config`` that differs from the policy's training env config (its ``env_overrides`` on
    the env's defaults)."""
    trained = requested_config(bundle, None)
    a, b = _flat(json.loads(trained.to_json())), _flat(json.loads(config.to_json()))
    return {k: [a.get(k), b.get(k)] for k in sorted(a.keys() | b.keys()) if a.get(k) != b.get(k)}


def requested_config(bundle: PolicyBundle, env_overrides: dict | None = None):
    """The env config of ``bundle``'s training env with ``env_overrides`` (not built; None:
    the training env's config)."""
    from peghole_mjx.envs import get_default_config
    from peghole_mjx.envs.config import apply_overrides

    over = {**bundle.env_overrides, **(env_overrides or {})}
    return apply_overrides(get_default_config(bundle.env_name), over)


def check_requested_env(bundle: PolicyBundle, config, cross: bool) -> dict[str, list]:
    """The differences of ``config`` from the policy's training env (:func:`config_differences`);
    refused in one line unless ``cross`` (an explicit cross evaluation)."""
    diff = config_differences(bundle, config)
    if diff and not cross:
        shown = ", ".join(f"{k} (trained {a!r}, requested {b!r})" for k, (a, b) in diff.items())
        raise UserInputError(
            f"{bundle.path}: the requested env differs from the policy's training env in "
            f"{shown}; a policy is evaluated as trained (pass --cross / cross=True to evaluate "
            "it in another env)"
        )
    return diff


def evaluate(
    policy: str | PolicyBundle,
    episodes: int,
    seed: int = 0,
    progress: bool = True,
    env_overrides: dict | None = None,
    env=None,
    batch: int | None = None,
    parts_dir: str | Path | None = None,
    policy_only: bool = False,
    baselines: dict[str, dict[str, Any]] | None = None,
    cross: bool = False,
) -> dict[str, Any]:
    """``{"policy", "baseline", "force_reduction_pct", "episodes", ...}`` (see module doc).

    ``policy_only``: skip the baseline (``baseline`` and ``force_reduction_pct`` are None).
    ``baselines``: baseline summaries by episodes key (filled here), so several policies
    evaluated on the same episodes and env run the baseline once.
    ``env``: an already built env of the policy's config (reuses its compiled rollouts).
    ``env_overrides`` (or ``env``) other than the policy's training env config are refused
    (:func:`check_requested_env`) unless ``cross``: a cross evaluation (another preset,
    geometry or setting); its result records the differences (``differs_from_training``).
    ``batch``: worlds run at once (default: all ``episodes``). ``parts_dir``: finished slices
    of ``batch`` episodes are saved there, and a rerun with the same policy, env, seed and
    batch loads them (a long evaluation survives an interruption or is extended to more
    episodes; see :func:`rollout`); another policy evaluated in the same folder reuses the
    baseline's slices (:func:`_parts_dirs`).
    """
    bundle = policy if isinstance(policy, PolicyBundle) else load_policy(policy)
    if env is not None:
        if env_overrides:
            raise ValueError("give env or env_overrides, not both")
        bundle.check_env(env)
        diff = check_requested_env(bundle, env.config, cross)
    else:  # checked before the env is built
        diff = check_requested_env(bundle, requested_config(bundle, env_overrides), cross)
        env = bundle.make_env(env_overrides)
    parts = _parts_dirs(parts_dir, bundle, env, seed, batch or episodes)
    kw = dict(seed=seed, progress=progress, batch=batch)
    res_p = rollout(
        env, bundle.policy_fn(), episodes, params=bundle.params, parts_dir=parts[0], **kw
    )
    pol, base = res_p.summary().as_dict(), None
    if not policy_only:
        key = json.dumps(
            [_config_key(env, BASELINE_IGNORED_CONFIG), seed, episodes, batch or episodes]
        )
        baselines = {} if baselines is None else baselines
        if key not in baselines:
            res_b = rollout(env, scripted_policy(env), episodes, parts_dir=parts[1], **kw)
            baselines[key] = res_b.summary().as_dict()
        base = baselines[key]
    return {
        "policy": pol,
        "baseline": base,
        "force_reduction_pct": None if base is None else force_reduction_pct(pol, base),
        "episodes": episodes,
        "batch": batch or episodes,  # episodes per slice: numbers differ ~2 % between batches
        "seed": seed,
        "env": bundle.env_name,
        "preset": env.config.preset,
        "engine": env.config.engine,  # the physics engine (docs/engines.md)
        "geometry": env.config.geometry or None,  # spec changes from the preset's, if any
        "compliance_strategy": bool(env.config.compliance_strategy),
        # {key: [trained, evaluated]}: empty for an evaluation as trained
        "differs_from_training": diff,
        "policy_path": str(bundle.path),
        "thesis": THESIS_RL,
    }
