"""Trained policies: save, load and run them; the committed pretrained policies live here.

A policy directory holds two files:

* ``policy.json``: the env name and its config overrides (so the env is rebuilt exactly as
  trained: every entry of the training config's ``env_overrides`` with its trained value, plus
  pins of physics defaults changed since, ``env_overrides_note``), the network (hidden sizes,
  observation and action sizes, normalisation), the training hyperparameters and where the
  policy came from. A policy is published and evaluated in its training env: a folder whose
  ``env_overrides`` contradict its ``train_config``, or that carries a ``deployment`` record
  (env settings changed when it was published, a mechanism removed on 2026-11-29), is
  refused in one line; other envs are an evaluation option (``peghole evaluate --cross``)
  that writes only to its own output;
* ``params.npz``: the observation normaliser and the policy network's parameters (Brax SAC
  layout), one array per leaf named by its tree path (``0/mean``, ``1/params/hidden_0/kernel``;
  :mod:`peghole_mjx.core.treenames`).

``policy.json`` carries ``format_version`` (:data:`FORMAT_VERSION`, docs/guide/training.md, "Policy
format"): 2 names the arrays by tree path and loads them by name; 1 (before 2026-11-29) stored
them by position (``leaf_0000``...) and is upgraded when loaded (:func:`upgrade_policy`
rewrites a folder as 2: ``python train/upgrade_policy.py DIR``); any other version is refused
in one line.

Pretrained policies (``PRETRAINED``) are addressed by name (``rect``, ``dual``,
``rect_hard``, ``dual_hard``) or by path.
"""

from __future__ import annotations

import functools
import json
import re
import shutil
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from brax.training.acme import running_statistics, specs
from brax.training.agents.sac import networks as sac_networks

from peghole_mjx import envs
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.treenames import differences, named_leaves
from peghole_mjx.core.validation import MAX_HIDDEN_LAYERS, RANGES, loads
from peghole_mjx.files import fileio
from peghole_mjx.files.checkpoint_folders import MANIFEST, checkpoint_name, newest_policy_checkpoint
from peghole_mjx.sim.engines import ENGINE_KEYS, engine_overrides, task_overrides

POLICY_DIR = Path(__file__).resolve().parent
#: committed pretrained policies: name -> directory inside the package
PRETRAINED = {
    "rect": POLICY_DIR / "rect_extract",
    "dual": POLICY_DIR / "dual_extract",
    "rect_hard": POLICY_DIR / "rect_extract_hard",  # RectExtractHard (docs/guide/training.md)
    "dual_hard": POLICY_DIR / "dual_extract_hard",  # DualExtractHard (docs/guide/training.md)
}
#: the format ``save_policy`` writes
FORMAT_VERSION = 2
#: formats ``load_policy`` reads (1: positional arrays, upgraded on load)
READABLE_VERSIONS = (1, 2)


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

    def trained_engine(self) -> dict[str, Any]:
        """The engine entries of the env the policy was trained on (provenance, not the task:
        :func:`make_env` runs on ``auto`` unless given them): ``engine`` of a policy from
        2026-12-05 on, else its ``env_overrides`` entries, else ``mjx`` (the env default then)."""
        if "engine" in self.meta:
            return engine_overrides(self.meta["engine"])
        over = self.env_overrides
        return {k: over[k] for k in ENGINE_KEYS if k in over} or {"engine": "mjx"}

    def make_env(self, extra_overrides: dict | None = None):
        """The env the policy was trained on; ``extra_overrides`` change it (a cross
        evaluation: :func:`peghole_mjx.training.evaluate.evaluate` with ``cross=True``)."""
        over = {**self.env_overrides, **(extra_overrides or {})}
        env = envs.load(self.env_name, config_overrides=over or None)
        self.check_env(env)
        return env

    def check_env(self, env) -> None:
        """Refuse an env whose name or observation/action sizes differ from the policy's."""
        net = self.meta["network"]
        name = env.env_name  # the registry name (RectExtractHard is a RectExtract class)
        if name != self.env_name:
            raise UserInputError(f"{self.path}: a policy for {self.env_name}, not for {name}")
        have = (env.observation_size, env.action_size)
        want = (int(net["observation_size"]), int(net["action_size"]))
        if have != want:
            raise UserInputError(
                f"{self.path}: the policy takes observations of size {want[0]} and gives "
                f"actions of size {want[1]}; this {name} has {have[0]} and {have[1]}"
            )

    def policy_fn(self):
        """``policy(params, obs, rng) -> action`` (deterministic: the mode of the policy)."""
        return make_policy_fn(self.meta["network"], deterministic=True)


def make_networks(network: dict[str, Any]):
    """Brax SAC networks from a network description (see ``policy.json``)."""
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
    make_policy = sac_networks.make_inference_fn(make_networks(json.loads(network_json)))

    def policy(params, obs, rng):
        action, _ = make_policy(params, deterministic=deterministic)(obs, rng)
        return action

    return policy


def init_params(network: dict[str, Any], seed: int = 0):
    """Fresh (normaliser, policy) parameters."""
    return _init_normaliser(network), make_networks(network).policy_network.init(
        jax.random.PRNGKey(seed)
    )


def params_template(network: dict[str, Any]):
    """The template that ``params.npz`` fills: :func:`init_params`'s tree, shapes and dtypes,
    with the network's weights as zeros (traced, not run: loading a policy compiles nothing
    before its rollout)."""
    init = make_networks(network).policy_network.init
    shapes = jax.eval_shape(init, jax.random.PRNGKey(0))
    return _init_normaliser(network), jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), shapes)


def _init_normaliser(network: dict[str, Any]):
    return running_statistics.init_state(
        specs.Array((int(network["observation_size"]),), jnp.dtype("float32"))
    )


#: the files :func:`save_policy` writes
POLICY_FOLDER_FILES = ("policy.json", "params.npz")


def save_policy(path: str | Path, params, meta: dict[str, Any], atomic: bool = True) -> Path:
    """Write ``policy.json`` and ``params.npz`` into ``path``.

    ``atomic``: both files are written into a uniquely named temporary folder beside
    ``path`` that then replaces it (both files or neither; an existing ``path`` holding files
    the program did not write is refused, :func:`peghole_mjx.files.fileio.replace_dir`); otherwise
    into ``path`` itself (already a temporary folder).
    """
    path = Path(path)
    if atomic:
        path.absolute().parent.mkdir(parents=True, exist_ok=True)
        target = fileio.temp_dir_beside(path)
    else:
        target = path
        target.mkdir(parents=True, exist_ok=True)
    try:
        arrays = named_leaves(params)
        fileio.write_bytes_with(target / "params.npz", lambda f: np.savez(f, **arrays))
        meta = {
            "format_version": FORMAT_VERSION,
            **{k: v for k, v in meta.items() if k != "format_version"},
        }
        text = json.dumps(meta, indent=2, default=_json_default) + "\n"
        fileio.write_text(target / "policy.json", text)
    except BaseException:
        if atomic:
            shutil.rmtree(target, ignore_errors=True)
        raise
    if atomic:
        # params.npz's SHA-256 recorded (2026-12-04): check_recorded_params
        fileio.replace_dir(target, path, known=POLICY_FOLDER_FILES, hashed=("params.npz",))
    return path


def _final_policy_record(path: Path) -> tuple[Path, str, Path] | None:
    """``(checkpoint params.npz, its recorded SHA-256, the manifest)`` of the checkpoint of
    a training run at the step of its final policy ``path`` (``RUN/final_policy`` or
    ``RUN/seed_K/final_policy``), or None when the run has none."""
    if path.name != "final_policy":
        return None
    run, sub = path.parent, "params.npz"
    if re.fullmatch(r"seed_\d+", run.name) and not (run / "checkpoints").is_dir():
        run, sub = run.parent, f"{run.name}/params.npz"
    try:
        step = json.loads((path / "policy.json").read_text())["env_steps"]
        manifest = run / "checkpoints" / checkpoint_name(int(step)) / MANIFEST
        sha = json.loads(manifest.read_text())["files"][sub]["sha256"]
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        return None
    return (manifest.parent / sub, sha, manifest) if isinstance(sha, str) else None


def _same_arrays(a: Path, b: Path) -> bool:
    """The two ``params.npz`` hold the same arrays (two writes of the same arrays differ in
    their zip timestamps)."""
    try:
        with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
            return set(za.files) == set(zb.files) and all(
                np.array_equal(za[k], zb[k]) for k in za.files
            )
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return False


def check_recorded_params(path: str | Path) -> None:
    """Refuse (:class:`CorruptFileError`, one line naming the file) a policy folder whose
    ``params.npz`` is not the file recorded when it was written (decided 2026-12-04): its
    SHA-256 against the folder's :data:`~peghole_mjx.files.fileio.OWNER_MANIFEST` (written by
    :func:`save_policy`), else, for a training run's ``final_policy``, against the manifest
    of the run's checkpoint at the same step (there the arrays are compared when the bytes
    differ). A folder with neither record is not checked."""
    path = Path(path)
    params = path / "params.npz"
    if not params.is_file():
        return  # loading names it
    actual = fileio.sha256_file(params)
    recorded = fileio.recorded_sha256(path, "params.npz")
    where = f"{path / fileio.OWNER_MANIFEST}"
    if recorded is None:
        found = _final_policy_record(path)
        if found is None:
            return
        ckpt_params, recorded, manifest = found
        if actual == recorded or (ckpt_params.is_file() and _same_arrays(params, ckpt_params)):
            return
        where = f"{manifest} (the run's checkpoint at the same step)"
    if actual != recorded:
        raise CorruptFileError(
            f"{params} was changed after it was written: its SHA-256 is {actual[:16]}..., "
            f"{where} records {recorded[:16]}...; restore it, or export/retrain the policy"
        )


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
    # a run directory: its final policy, else its newest intact checkpoint (step_N.tmp and
    # other unfinished folders are not checkpoints)
    if (path / "final_policy" / "policy.json").exists():
        return path / "final_policy"

    ckpt = newest_policy_checkpoint(path / "checkpoints")
    if ckpt is not None:
        return ckpt
    raise UserInputError(
        f"no policy at {path}: expected a directory with policy.json, a training run directory "
        f"(with final_policy/ or checkpoints/), or one of {sorted(PRETRAINED)}"
    )


def check_meta(meta: Any, where: str) -> dict[str, Any]:
    """Schema of ``policy.json``, checked before anything is allocated: format version, a
    known env (the same one its training config names), and a network whose sizes are within
    :data:`peghole_mjx.core.validation.RANGES`. Returns ``meta``; raises
    :class:`CorruptFileError`."""

    def need(cond: bool, what: str) -> None:
        if not cond:
            raise CorruptFileError(f"{where}: {what}")

    need(isinstance(meta, dict), "not a JSON object")
    versions = " and ".join(map(str, READABLE_VERSIONS))
    version = meta.get("format_version")
    need(
        type(version) is int,  # not true (== 1 in Python), 2.0 or "2"
        f"format_version must be an integer ({' or '.join(map(str, READABLE_VERSIONS))}), "
        f"got {_short(version)}",
    )
    need(
        version in READABLE_VERSIONS,
        f"format_version {version!r} is unknown: this peghole_mjx reads {versions}",
    )
    env = meta.get("env")
    need(
        isinstance(env, str) and env in envs.ENV_NAMES,
        f"env {env!r} is not one of {list(envs.ENV_NAMES)}",
    )
    train_config = meta.get("train_config")
    need(
        train_config is None or isinstance(train_config, dict),
        f"train_config must be an object, got {_short(train_config)}",
    )
    trained_on = (train_config or {}).get("env", env)
    need(
        trained_on == env,
        f"env {env!r}, but the policy was trained on {trained_on!r} (relabelled policy)",
    )
    need(isinstance(meta.get("env_overrides", {}), dict), "env_overrides is not an object")
    trained_over = (train_config or {}).get("env_overrides")
    need(
        trained_over is None or isinstance(trained_over, dict),
        f"train_config.env_overrides must be an object, got {_short(trained_over)}",
    )
    check_as_trained(meta, where)
    net = meta.get("network")
    need(isinstance(net, dict), "no network description ('network')")
    for key in ("observation_size", "action_size"):
        msg = RANGES[key].problem(net.get(key))
        need(msg is None, f"network.{key} {msg}")
    sizes = net.get("hidden_layer_sizes")
    need(
        isinstance(sizes, list)
        and 1 <= len(sizes) <= MAX_HIDDEN_LAYERS
        and all(RANGES["hidden_layer_size"].problem(w) is None for w in sizes),
        f"network.hidden_layer_sizes must be 1 to {MAX_HIDDEN_LAYERS} widths in "
        f"[1, {RANGES['hidden_layer_size'].hi:g}], got {sizes!r}",
    )
    need(
        isinstance(net.get("normalize_observations"), bool),
        "network.normalize_observations must be true or false",
    )
    return meta


def _short(value: Any, limit: int = 60) -> str:
    """``value`` as JSON, cut to ``limit`` characters (for a one-line message)."""
    text = json.dumps(value, default=repr)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_as_trained(meta: dict[str, Any], where: str) -> None:
    """Refuse (:class:`UserInputError`, one line) a policy that would run in an env other than
    its training env: a ``deployment`` record, or an ``env_overrides`` entry that differs from
    the training config's (``train_config.env_overrides``)."""
    if "deployment" in meta:
        raise UserInputError(
            f"{where}: carries a 'deployment' record (env settings changed after training); "
            "a published policy runs as trained: republish it (train/publish_policy.py), or "
            "evaluate another env with peghole evaluate --cross --set env.KEY=VALUE"
        )
    # the engine entries are provenance, not the task (ENGINE_KEYS): a policy from before
    # 2026-12-05 carries them in env_overrides, a newer one only in train_config
    trained = task_overrides((meta.get("train_config") or {}).get("env_overrides") or {})
    have = task_overrides(meta.get("env_overrides", {}))
    differ = sorted(k for k, v in trained.items() if k not in have or have[k] != v)
    if differ:
        raise UserInputError(
            f"{where}: env_overrides differ from the training config in "
            + ", ".join(f"{k} ({have.get(k, 'unset')!r}, trained {trained[k]!r})" for k in differ)
            + "; a published policy runs as trained"
        )


def load_policy(name: str | Path) -> PolicyBundle:
    """Load a policy by pretrained name or path (see :func:`resolve_policy_path`).

    ``policy.json`` is schema-checked (:func:`check_meta`) before the network is built;
    ``params.npz`` must hold exactly the network's arrays, as finite floats.
    """
    path = resolve_policy_path(name)
    meta, arrays = _read(path)
    treedef = jax.tree.structure(params_template(meta["network"]))
    params = jax.tree.unflatten(treedef, [jnp.asarray(x) for x in arrays.values()])
    return PolicyBundle(path=path, meta=meta, params=params)


def _read(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """``policy.json`` (strict JSON, nesting limited, schema-checked) and the arrays of
    ``params.npz`` by tree path, in the network's tree order (format 1 upgraded), each checked
    against the network in ``policy.json``: name, shape, dtype, finite numbers, and a
    normaliser consistent with ``normalize_observations``. All before anything is compiled."""
    try:
        meta = loads((path / "policy.json").read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise CorruptFileError(f"{path}/policy.json is not valid JSON ({exc})") from None
    check_meta(meta, f"{path}/policy.json")
    want = named_leaves(params_template(meta["network"]))
    try:
        with np.load(path / "params.npz", allow_pickle=False) as z:
            arrays = {n: z[n] for n in z.files}
    except (zipfile.BadZipFile, EOFError, ValueError, OSError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise CorruptFileError(f"{path}/params.npz is unreadable ({exc})") from None
    if meta["format_version"] == 1:
        arrays = _upgrade_arrays(arrays, want, path)
    check_arrays(arrays, want, meta["network"], f"{path}/params.npz")
    return meta, {k: arrays[k] for k in want}


def check_arrays(
    arrays: dict[str, np.ndarray], want: dict[str, np.ndarray], network: dict, where: str
) -> None:
    """Refuse (:class:`CorruptFileError`, one line naming the array) parameters that are not
    exactly the arrays of ``want`` (the network's template): a missing or unexpected name,
    another shape (one line naming the array, its shape and the expected one) or dtype (int8
    weights), NaN or infinity, or a normaliser that contradicts ``normalize_observations``."""
    names = differences({k: None for k in arrays}, {k: None for k in want})
    if names:
        raise CorruptFileError(
            f"{where} does not match the network in policy.json ({'; '.join(names)})"
        )
    net = (
        f"observation_size {network['observation_size']}, action_size "
        f"{network['action_size']}, hidden_layer_sizes {network['hidden_layer_sizes']}"
    )
    for k, w in want.items():
        x = arrays[k]
        if np.shape(x) != np.shape(w):
            raise CorruptFileError(
                f"{where}: array {k} has shape {tuple(np.shape(x))}, the network in "
                f"policy.json ({net}) expects {tuple(np.shape(w))} (parameters of another "
                "policy?)"
            )
        if not _dtype_fits(x.dtype, w.dtype):
            raise CorruptFileError(f"{where}: array {k} has dtype {x.dtype}, expected {w.dtype}")
        if np.issubdtype(x.dtype, np.floating) and not np.all(np.isfinite(x)):
            raise CorruptFileError(f"{where}: array {k} holds NaN or infinity")
    _check_normaliser(arrays, bool(network["normalize_observations"]), where)


def _dtype_fits(have: np.dtype, want: np.dtype) -> bool:
    """A saved dtype that holds the template's values: a 32- or 64-bit float for a float
    (the scalar ``std_eps`` is saved as either), an integer for an integer (the count)."""
    if np.issubdtype(want, np.floating):
        return have in (np.dtype(np.float32), np.dtype(np.float64))
    if np.issubdtype(want, np.integer):
        return np.issubdtype(have, np.integer)
    return have == want


def _check_normaliser(arrays: dict[str, np.ndarray], normalize: bool, where: str) -> None:
    """The observation normaliser (``0/...``) agrees with ``normalize_observations``: training
    updates it only when normalising, so ``false`` comes with the initial state (count 0, mean
    0, std 1), and ``true`` with positive standard deviations (an initial state too when no
    observation was seen yet, which normalises nothing)."""
    mean, std = arrays.get("0/mean"), arrays.get("0/std")
    hi, lo = arrays.get("0/count/hi"), arrays.get("0/count/lo")
    if mean is None or std is None or hi is None or lo is None:
        return  # a layout without brax's running statistics: nothing to compare
    count = (int(hi) << 32) | int(lo)
    initial = not np.any(mean) and np.all(std == 1) and not np.any(arrays.get("0/summed_variance"))
    if not normalize and (count or not initial):
        raise CorruptFileError(
            f"{where}: network.normalize_observations is false, but the normaliser holds the "
            f"statistics of {count} observations (policy.json's flag changed after training?)"
        )
    if normalize and not np.all(std > 0):
        raise CorruptFileError(f"{where}: the normaliser's 0/std holds values <= 0")
    if normalize and count == 0 and not initial:
        raise CorruptFileError(
            f"{where}: the normaliser holds statistics but a count of 0 observations"
        )


def _upgrade_arrays(arrays: dict[str, Any], want: dict[str, Any], path: Path) -> dict[str, Any]:
    """Format 1's positional arrays (``leaf_0000``...) named by the tree paths of the network
    in ``policy.json`` (``want``, in tree order), after checking their count and shapes."""
    names = [f"leaf_{i:04d}" for i in range(len(arrays))]
    if sorted(arrays) != names:
        raise CorruptFileError(f"{path}/params.npz holds unexpected arrays")
    if len(names) != len(want):
        raise CorruptFileError(
            f"{path}/params.npz does not match the network in policy.json "
            f"({len(names)} arrays vs {len(want)} expected)"
        )
    # shapes and dtypes are checked by name afterwards (check_arrays)
    return {k: arrays[n] for k, n in zip(want, names, strict=True)}


def upgrade_policy(path: str | Path) -> bool:
    """Rewrite the policy folder ``path`` in the current format (:data:`FORMAT_VERSION`),
    arrays unchanged bit for bit, the rest of ``policy.json`` as it was; other files in the
    folder are kept. The folder is rewritten as a copy that then replaces it (all or
    nothing). Returns False when it already was current."""
    path = Path(path)
    meta, arrays = _read(path)
    if meta["format_version"] == FORMAT_VERSION:
        return False
    tmp = fileio.temp_dir_beside(path)
    try:
        shutil.copytree(path, tmp, dirs_exist_ok=True, symlinks=True)
        fileio.write_bytes_with(tmp / "params.npz", lambda f: np.savez(f, **arrays))
        meta = {**meta, "format_version": FORMAT_VERSION}
        text = json.dumps(meta, indent=2, default=_json_default) + "\n"
        fileio.write_text(tmp / "policy.json", text)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    # every file of the folder is carried over (the user's too); only ours are listed as ours
    owned = (fileio.owned_files(path) or set()) | set(POLICY_FOLDER_FILES)
    fileio.replace_dir(tmp, path, owned=owned)
    return True


__all__ = [
    "PRETRAINED",
    "PolicyBundle",
    "check_arrays",
    "check_as_trained",
    "check_meta",
    "check_recorded_params",
    "init_params",
    "load_policy",
    "make_networks",
    "make_policy_fn",
    "resolve_policy_path",
    "save_policy",
    "upgrade_policy",
]
