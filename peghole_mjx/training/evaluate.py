"""Evaluate a policy against the scripted fixed-compliance baseline on the same episodes.

Both run through :func:`peghole_mjx.envs.rollout.rollout` with the same seed, so they meet
the same randomised starts (hole pose, lateral and angular errors, friction). The force
reduction is ``100 (F_baseline - F_policy) / F_baseline`` on the mean extraction force
(mean |F_z| per episode, averaged over episodes), the quantity of the thesis's R3.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import zipfile
import zlib
from pathlib import Path
from typing import Any

import jax
import numpy as np

from peghole_mjx.core import progress as prog
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.validation import load_json_object
from peghole_mjx.envs import get_default_config
from peghole_mjx.envs.config import apply_overrides
from peghole_mjx.envs.metrics import EPISODE_RECORD, STUCK_METRICS, stuck_summary
from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S, rollout, scripted_policy
from peghole_mjx.files import fileio
from peghole_mjx.policies import PolicyBundle, load_policy
from peghole_mjx.sim.engines import ENGINE_KEYS, engine_label

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
    if not cfg.get("stuck", {}).get("enabled"):  # no stuck joint: keys as before the group
        cfg.pop("stuck", None)
    for dotted in ignored:
        *path, leaf = dotted.split(".")
        node = cfg
        for k in path:
            node = node.get(k, {})
        node.pop(leaf, None)
    return json.dumps(cfg, sort_keys=True)


def _read_key(key_file: Path) -> dict[str, Any]:
    """A slice folder's ``key.json`` (strict JSON, an object), else one line naming it."""
    return load_json_object(
        key_file,
        lambda why: CorruptFileError(
            f"{key_file} is damaged ({why}): delete its folder to run its slices again"
        ),
    )


def _keyed_dir(root: Path, key: dict[str, Any]) -> Path:
    """``root`` with its ``key.json``; raises if the folder holds another evaluation's slices."""
    key_file = root / "key.json"
    if key_file.exists():
        old = _read_key(key_file)
        diff = sorted(k for k in key.keys() | old.keys() if old.get(k) != key.get(k))
        if diff:
            raise UserInputError(
                f"{root} holds the slices of another evaluation (differs in {', '.join(diff)}); "
                "choose another --parts folder or delete it"
            )
    else:
        root.mkdir(parents=True, exist_ok=True)
        fileio.write_text(key_file, json.dumps(key, indent=2) + "\n")
    return root


#: a slice file of :func:`peghole_mjx.envs.rollout.rollout`: first episode and episode count
SLICE_NAME = re.compile(r"episodes_(\d{7})_(\d{7})\.npz")
#: suffix of a slice set aside as unusable (kept for inspection; its episodes are run again)
SET_ASIDE = ".damaged"


def slice_problem(path: Path) -> str | None:
    """None if the slice file ``path`` holds exactly the episode records of its episodes (one
    finite-size float array per :data:`EPISODE_RECORD` key, and with a stuck joint per
    :data:`STUCK_METRICS` key, of the length its name says), else what is wrong with it (random
    bytes, pickled data, truncation, other arrays)."""
    m = SLICE_NAME.fullmatch(path.name)
    n = int(m.group(2)) if m else None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, ValueError, OSError, zlib.error) as exc:
        if isinstance(exc, FileNotFoundError | PermissionError):
            raise
        return f"unreadable: {' '.join(str(exc).split()) or type(exc).__name__}"
    extra = set(arrays) - set(EPISODE_RECORD)  # a stuck joint's keys: all or none
    if not set(EPISODE_RECORD) <= set(arrays) or extra not in (set(), set(STUCK_METRICS)):
        return "not the episode records of this version"
    for k, x in arrays.items():
        if not np.issubdtype(x.dtype, np.floating) or x.shape != (n,):
            return f"array {k} has shape {x.shape} and dtype {x.dtype}, expected ({n},) floats"
    return None


def check_slices(folder: Path | None) -> list[Path]:
    """Set aside every unusable slice of ``folder`` (renamed ``NAME.npz.damaged``, with a
    one-line warning naming it), so that the rollout runs its episodes again instead of
    failing on it; returns the set-aside paths. Done before any simulation."""
    if folder is None or not folder.is_dir():
        return []
    moved = []
    for path in sorted(folder.iterdir()):
        if not SLICE_NAME.fullmatch(path.name) or not path.is_file():
            continue
        why = slice_problem(path)
        if why is None:
            continue
        aside = path.with_name(path.name + SET_ASIDE)
        os.replace(path, aside)
        print(
            f"peghole: warning: {path} is damaged ({why}); set aside as {aside.name}, its "
            "episodes are run again",
            file=sys.stderr,
            flush=True,
        )
        moved.append(aside)
    return moved


def output_bytes(n_policies: int, episodes: int, batch: int | None, parts: bool, out: bool) -> int:
    """A generous estimate of what ``peghole evaluate`` writes: the ``--out`` JSON and, with
    ``--parts``, each policy's and baseline's slices (one float64 per record key per episode,
    plus the npz headers of each slice) and key files."""
    total = (8192 * n_policies + 4096) if out else 0
    if parts:
        slices = -(-episodes // max(1, min(batch or episodes, episodes)))
        per_folder = len(EPISODE_RECORD) * (8 * episodes + 512 * slices) + 4096
        total += (n_policies + 1) * per_folder
    return 2 * total  # margin: the temporary copy beside each file while it is written


def check_parts_keys(parts_dir: str | Path, env_names: list[str], seed: int, batch: int) -> None:
    """Before the first evaluation: the baseline slices of ``parts_dir`` (shared by every
    policy of a command) are of these episodes. A second env, seed or batch is refused here,
    not after the first policy's evaluation (:func:`_parts_dirs` checks the full key)."""
    envs = sorted(set(env_names))
    if len(envs) > 1:
        raise UserInputError(
            f"--parts {parts_dir}: one folder holds the baseline of one env, and these policies "
            f"are for {' and '.join(envs)}: evaluate them with separate --parts folders"
        )
    key_file = Path(parts_dir) / "baseline" / "key.json"
    if not key_file.exists():
        return
    old = _read_key(key_file)
    want = {"env": envs[0], "seed": seed, "batch": batch, "speed_m_s": SCRIPTED_SPEED_M_S}
    diff = sorted(k for k in want if old.get(k) != want[k])
    if diff:
        raise UserInputError(
            f"{key_file.parent} holds the slices of another evaluation (differs in "
            f"{', '.join(diff)}); choose another --parts folder or delete it"
        )


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
    the env's defaults). The engine entries (:data:`ENGINE_KEYS`) are provenance, not the task:
    a policy on another engine is not a difference (2026-12-05)."""
    trained = requested_config(bundle, None)
    a, b = _flat(json.loads(trained.to_json())), _flat(json.loads(config.to_json()))
    keys = sorted((a.keys() | b.keys()) - set(ENGINE_KEYS))
    return {k: [a.get(k), b.get(k)] for k in keys if a.get(k) != b.get(k)}


def requested_config(bundle: PolicyBundle, env_overrides: dict | None = None):
    """The env config of ``bundle``'s training env with ``env_overrides`` (not built; None:
    the training env's config)."""
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
    baselines: dict[str, tuple[dict[str, Any], dict]] | None = None,
    cross: bool = False,
    keep_episodes: bool = False,
) -> dict[str, Any]:
    """``{"policy", "baseline", "force_reduction_pct", "episodes", ...}`` (see module doc).

    ``progress``: each phase on stderr (:mod:`peghole_mjx.core.progress`): building the env, each
    rollout's compile (first run only; cached after) and its bar of env steps.
    ``policy_only``: skip the baseline (``baseline`` and ``force_reduction_pct`` are None).
    ``baselines``: baseline results by episodes key (filled here), so several policies
    evaluated on the same episodes and env run the baseline once.
    ``env``: an already built env of the policy's config (reuses its compiled rollouts).
    ``env_overrides`` (or ``env``) other than the policy's training env config are refused
    (:func:`check_requested_env`) unless ``cross``: a cross evaluation (another preset,
    geometry or setting); its result records the differences (``differs_from_training``).
    ``batch``: worlds run at once (default: all ``episodes``). ``parts_dir``: finished slices
    of ``batch`` episodes are saved there, and a rerun with the same policy, env, seed and
    batch loads them (a long evaluation survives an interruption or is extended to more
    episodes; see :func:`rollout`); another policy evaluated in the same folder reuses the
    baseline's slices (:func:`_parts_dirs`). ``keep_episodes``: the result also holds the
    per-episode records (``per_episode``: ``{"policy": {key: array}, "baseline": ...}``, keys
    of :data:`~peghole_mjx.envs.metrics.EPISODE_RECORD`), for comparisons paired by episode.
    """
    bundle = policy if isinstance(policy, PolicyBundle) else load_policy(policy)
    if env is not None:
        if env_overrides:
            raise ValueError("give env or env_overrides, not both")
        bundle.check_env(env)
        diff = check_requested_env(bundle, env.config, cross)
    else:  # checked before the env is built
        config = requested_config(bundle, env_overrides)
        diff = check_requested_env(bundle, config, cross)
        with prog.phase(f"building the {bundle.env_name} env ({engine_label(config)})", progress):
            env = bundle.make_env(env_overrides)
    parts = _parts_dirs(parts_dir, bundle, env, seed, batch or episodes)
    for folder in parts:  # before any simulation: an unusable slice is set aside, run again
        check_slices(folder)
    kw = dict(seed=seed, progress=progress, batch=batch)
    res_p = rollout(
        env,
        bundle.policy_fn(),
        episodes,
        params=bundle.params,
        parts_dir=parts[0],
        label="policy rollout",
        **kw,
    )
    pol, base, base_episodes = res_p.summary().as_dict(), None, None
    if not policy_only:
        key = json.dumps(
            [_config_key(env, BASELINE_IGNORED_CONFIG), seed, episodes, batch or episodes]
        )
        baselines = {} if baselines is None else baselines
        if key not in baselines:
            res_b = rollout(
                env,
                scripted_policy(env),
                episodes,
                parts_dir=parts[1],
                label="scripted baseline rollout",
                **kw,
            )
            baselines[key] = (res_b.summary().as_dict(), res_b.per_episode)
        base, base_episodes = baselines[key]
    extra = {}
    if env.config.stuck.enabled:  # a stuck joint: how often each method broke the weld
        base_stuck = None if base_episodes is None else stuck_summary(base_episodes)
        extra["stuck"] = {"policy": stuck_summary(res_p.per_episode), "baseline": base_stuck}
    if keep_episodes:
        extra["per_episode"] = {"policy": res_p.per_episode, "baseline": base_episodes}
    return {
        "policy": pol,
        "baseline": base,
        "force_reduction_pct": None if base is None else force_reduction_pct(pol, base),
        "episodes": episodes,
        "batch": batch or episodes,  # episodes per slice: numbers differ ~2 % between batches
        "seed": seed,
        "env": bundle.env_name,
        "preset": env.config.preset,
        "engine": engine_label(env.config),  # the physics engine (docs/research/performance.md)
        "geometry": env.config.geometry or None,  # spec changes from the preset's, if any
        **({"task": env.config.task} if "task" in env.config else {}),  # MeshExtract's folder
        "compliance_strategy": bool(env.config.compliance_strategy),
        # {key: [trained, evaluated]}: empty for an evaluation as trained
        "differs_from_training": diff,
        "policy_path": str(bundle.path),
        "thesis": THESIS_RL,
        **extra,
    }
