"""Trained policies: save, load and run them; the committed pretrained policies live here.

A policy directory holds two files:

* ``policy.json``: the env name and its config overrides (so the env is rebuilt exactly as
  trained, or as deployed), the network (hidden sizes, observation and action sizes,
  normalisation), the training hyperparameters and where the policy came from; optionally
  ``deployment``: env overrides set when the policy was published that differ from its
  training env (e.g. a tighter force bound), with the trained values
  (``train/publish_policy.py --deploy-set``);
* ``params.npz``: the observation normaliser and the policy network's parameters (Brax SAC
  layout, leaves in tree order).

Pretrained policies (``PRETRAINED``) are addressed by name (``rect``, ``dual``) or by path.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from peghole_mjx.errors import UserInputError

POLICY_DIR = Path(__file__).resolve().parent
#: committed pretrained policies: name -> directory inside the package
PRETRAINED = {"rect": POLICY_DIR / "rect_extract", "dual": POLICY_DIR / "dual_extract"}
FORMAT_VERSION = 1


@dataclass
class PolicyBundle:
    """A loaded policy: its metadata and parameters, and how to build its env and network."""

    path: Path
    meta: dict[str, Any]
    params: Any = field(repr=False)  # (normaliser state, policy params)

    @property
    def env_name(self) -> str:
        return self.meta["env"]

    @property
    def env_overrides(self) -> dict[str, Any]:
        return dict(self.meta.get("env_overrides", {}))

    def make_env(self, extra_overrides: dict | None = None):
        """The env the policy was trained on (plus ``extra_overrides``)."""
        from peghole_mjx.envs import load

        over = {**self.env_overrides, **(extra_overrides or {})}
        return load(self.env_name, config_overrides=over or None)

    def policy_fn(self):
        """``policy(params, obs, rng) -> action`` (deterministic: the mode of the policy)."""
        return make_policy_fn(self.meta["network"], deterministic=True)


def make_networks(network: dict[str, Any]):
    """Brax SAC networks from a network description (see ``policy.json``)."""
    from brax.training.acme import running_statistics
    from brax.training.agents.sac import networks as sac_networks

    normalize = running_statistics.normalize if network["normalize_observations"] else None
    kwargs = {"hidden_layer_sizes": tuple(network["hidden_layer_sizes"])}
    if normalize is not None:
        kwargs["preprocess_observations_fn"] = normalize
    return sac_networks.make_sac_networks(
        observation_size=int(network["observation_size"]),
        action_size=int(network["action_size"]),
        **kwargs,
    )


def make_policy_fn(network: dict[str, Any], deterministic: bool = True):
    """``policy(params, obs, rng) -> action`` for a network description.

    The same description gives the same function object, so jitted rollouts of it compile once.
    """
    return _policy_fn(json.dumps(network, sort_keys=True, default=_json_default), deterministic)


@functools.lru_cache(maxsize=32)
def _policy_fn(network_json: str, deterministic: bool):
    from brax.training.agents.sac import networks as sac_networks

    make_policy = sac_networks.make_inference_fn(make_networks(json.loads(network_json)))

    def policy(params, obs, rng):
        action, _ = make_policy(params, deterministic=deterministic)(obs, rng)
        return action

    return policy


def init_params(network: dict[str, Any], seed: int = 0):
    """Fresh (normaliser, policy) parameters: the template that ``params.npz`` fills."""
    from brax.training.acme import running_statistics, specs

    nets = make_networks(network)
    norm = running_statistics.init_state(
        specs.Array((int(network["observation_size"]),), jnp.dtype("float32"))
    )
    return norm, nets.policy_network.init(jax.random.PRNGKey(seed))


def save_policy(path: str | Path, params, meta: dict[str, Any]) -> Path:
    """Write ``policy.json`` and ``params.npz`` into ``path`` (created)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    leaves = jax.tree.leaves(jax.device_get(params))
    np.savez(path / "params.npz", **{f"leaf_{i:04d}": np.asarray(x) for i, x in enumerate(leaves)})
    meta = {"format_version": FORMAT_VERSION, **meta}
    (path / "policy.json").write_text(json.dumps(meta, indent=2, default=_json_default) + "\n")
    return path


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, tuple):
        return list(x)
    raise TypeError(f"not JSON serialisable: {type(x)}")


def resolve_policy_path(name: str | Path) -> Path:
    """A pretrained name, a policy directory, or a training run / checkpoint directory."""
    if str(name) in PRETRAINED:
        path = PRETRAINED[str(name)]
        if not (path / "policy.json").exists():
            raise UserInputError(f"the pretrained policy {name!r} is not in this installation")
        return path
    path = Path(name)
    if (path / "policy.json").exists():
        return path
    # a run directory: its final policy, else its latest checkpoint
    if (path / "final_policy" / "policy.json").exists():
        return path / "final_policy"
    ckpts = sorted((path / "checkpoints").glob("step_*")) if (path / "checkpoints").is_dir() else []
    ckpts = [c for c in ckpts if (c / "policy.json").exists()]
    if ckpts:
        return ckpts[-1]
    raise UserInputError(
        f"no policy at {path}: expected a directory with policy.json, a training run directory "
        f"(with final_policy/ or checkpoints/), or one of {sorted(PRETRAINED)}"
    )


def load_policy(name: str | Path) -> PolicyBundle:
    """Load a policy by pretrained name or path (see :func:`resolve_policy_path`)."""
    path = resolve_policy_path(name)
    meta = json.loads((path / "policy.json").read_text())
    if meta.get("format_version") != FORMAT_VERSION:
        raise UserInputError(
            f"{path}/policy.json has format_version {meta.get('format_version')}, "
            f"this peghole_mjx reads {FORMAT_VERSION}"
        )
    template = init_params(meta["network"])
    treedef = jax.tree.structure(template)
    tleaves = jax.tree.leaves(template)
    with np.load(path / "params.npz") as z:
        leaves = [z[f"leaf_{i:04d}"] for i in range(len(z.files))]
    if len(leaves) != len(tleaves) or any(
        a.shape != np.shape(b) for a, b in zip(leaves, tleaves, strict=True)
    ):
        raise UserInputError(
            f"{path}/params.npz does not match the network in policy.json "
            f"({len(leaves)} arrays vs {len(tleaves)} expected)"
        )
    params = jax.tree.unflatten(treedef, [jnp.asarray(x) for x in leaves])
    return PolicyBundle(path=path, meta=meta, params=params)


__all__ = [
    "PRETRAINED",
    "PolicyBundle",
    "init_params",
    "load_policy",
    "make_networks",
    "make_policy_fn",
    "resolve_policy_path",
    "save_policy",
]
