"""Checkpoint folders of a training run: which exist, which are intact, which to resume from.

``checkpoints/step_N/`` (N zero-padded to 10 digits) holds ``policy.json`` and
``params.npz``; the :data:`KEEP_STATES` newest also hold ``state/`` and ``state.json`` (the
whole learner, for ``--resume``). ``state/`` is an orbax checkpoint (``StandardCheckpointer``)
of the carry as nested dicts named by the carry's tree paths (``ts/q_params/...``,
``env_state/data/qpos``), so it is restored by name, not by leaf order (:func:`save_state`,
:func:`restore_state`). ``manifest.json``, written last, lists every file (those inside
``state/`` too) with its size and SHA-256. A checkpoint is written in ``step_N.tmp/`` (every
file fsynced, then the folders) and renamed to ``step_N/``, so a folder named ``step_N`` is
complete; other names (``step_N.tmp``, ``step_N.old``, ``step_N.corrupt``) are never
checkpoints.

On resume the newest checkpoint whose state verifies is used; a corrupt newer one (truncated,
garbled, a checksum that does not match, no manifest) is renamed ``step_N.corrupt`` with a
warning and the previous one is used. Checkpoints written before the orbax format (a
positional ``state.npz``) are not resumable: :func:`newest_valid` refuses them in one line
(their policies still load).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from peghole_mjx import fileio
from peghole_mjx.errors import CorruptFileError, UserInputError
from peghole_mjx.treenames import differences, named_leaves, path_name

MANIFEST = "manifest.json"
#: ``state`` is a folder (orbax); the manifest lists the files inside it
STATE_FILES = ("state", "state.json")
#: what checkpoints written before the orbax format hold instead of ``state/``
LEGACY_STATE = "state.npz"
POLICY_FILES = ("policy.json", "params.npz")
#: checkpoints that keep their full state (the newest and the one before, for a fallback)
KEEP_STATES = 2
_NAME = re.compile(r"^step_(\d+)$")


def checkpoint_name(step: int) -> str:
    return f"step_{step:010d}"


def checkpoint_dirs(ckpt_dir: str | Path) -> list[Path]:
    """Complete checkpoint folders, oldest first (by step; temporary folders excluded)."""
    ckpt_dir = Path(ckpt_dir)
    if not ckpt_dir.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in ckpt_dir.iterdir() if (m := _NAME.match(p.name))]
    return [p for _, p in sorted(found) if p.is_dir()]


def has_state(path: Path) -> bool:
    return all((path / f).exists() for f in STATE_FILES)


# ---------------------------------------------------------------------- state by name
def _nest(flat: dict[str, Any]) -> dict[str, Any]:
    nested: dict[str, Any] = {}
    for name, x in flat.items():
        *parents, last = name.split("/")
        node = nested
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = x
    return nested


def _checkpointer():
    import orbax.checkpoint as ocp

    return ocp.StandardCheckpointer()


def save_state(folder: Path, tree: Any) -> dict[str, Any]:
    """Save ``tree`` as the orbax checkpoint ``folder/state`` (nested dicts named by tree path).

    orbax cannot store zero-size arrays: their names and shapes are returned (for
    ``state.json``, key ``empty_leaves``) and checked on restore."""
    flat = named_leaves(tree)
    full = {k: v for k, v in flat.items() if v.size}
    empty = {k: [list(v.shape), str(v.dtype)] for k, v in flat.items() if not v.size}
    ckptr = _checkpointer()
    try:
        ckptr.save(Path(folder).absolute() / STATE_FILES[0], _nest(full))
        ckptr.wait_until_finished()
    finally:
        ckptr.close()
    return {"empty_leaves": empty}


def restore_state(folder: Path, template: Any, empty_leaves: dict[str, Any]) -> Any:
    """The tree saved by :func:`save_state` in ``folder``, in the structure of ``template``.

    Leaves are matched by tree path: a saved state whose paths, shapes or dtypes differ from
    ``template``'s raises :class:`UserInputError` naming the first differences; leaves are
    numpy arrays of ``template``'s dtypes."""
    import jax

    want = named_leaves(template)
    ckptr = _checkpointer()
    try:
        path = Path(folder).absolute() / STATE_FILES[0]
        meta = ckptr.metadata(path).item_metadata.tree
        have = {
            path_name(p): (tuple(m.shape), np.dtype(m.dtype))
            for p, m in jax.tree_util.tree_flatten_with_path(meta)[0]
        }
        have.update({k: (tuple(s), np.dtype(d)) for k, (s, d) in empty_leaves.items()})
        _check_same_structure(folder, have, {k: (v.shape, v.dtype) for k, v in want.items()})
        full = {k: np.zeros(v.shape, v.dtype) for k, v in want.items() if v.size}
        restored = ckptr.restore(path, _nest(full))
    finally:
        ckptr.close()
    flat = named_leaves(restored)
    leaves = [flat[k] if v.size else v for k, v in want.items()]
    return jax.tree.unflatten(jax.tree.structure(template), leaves)


def _check_same_structure(folder: Path, have: dict, want: dict) -> None:
    problems = differences(have, want)
    if problems:
        raise UserInputError(
            f"{folder}: saved state does not match this run's config ({'; '.join(problems)}): "
            "the config or the peghole_mjx version changed since the checkpoint; its policy "
            "(policy.json, params.npz) still loads with peghole evaluate"
        )


sha256 = fileio.sha256_file  # the manifest's file hash


def seal(folder: Path) -> None:
    """Write ``manifest.json``: size and SHA-256 of every file in ``folder`` and below."""
    files = {
        p.relative_to(folder).as_posix(): {"bytes": p.stat().st_size, "sha256": sha256(p)}
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != MANIFEST and not p.name.startswith(".")
    }
    fileio.write_text(folder / MANIFEST, json.dumps({"files": files}, indent=2) + "\n")


def verify(path: Path, need: tuple[str, ...] = POLICY_FILES) -> None:
    """Raise :class:`CorruptFileError` unless the files ``need`` of checkpoint ``path`` (a
    folder in ``need``: every file the manifest lists in it) are present and match its
    manifest. A checkpoint without a manifest (written by an older peghole_mjx) passes for
    its policy files when they exist (loading them checks them further); its state never
    does (a state is always written with a manifest)."""
    missing = [f for f in need if not (path / f).exists()]
    if missing:
        raise CorruptFileError(f"{path}: missing {', '.join(missing)}")
    mpath = path / MANIFEST
    if not mpath.exists():
        if any((path / f).is_dir() for f in need):
            raise CorruptFileError(f"{path}: no {MANIFEST}")
        return
    try:
        listed = json.loads(mpath.read_text())["files"]
        for name in need:
            entries = [k for k in listed if k == name or k.startswith(name + "/")]
            if not entries:
                raise CorruptFileError(f"{path}: {name} is not in its manifest")
            for key in entries:
                entry, actual = listed[key], path / key
                if not actual.is_file():
                    raise CorruptFileError(f"{actual}: missing")
                if actual.stat().st_size != entry["bytes"] or sha256(actual) != entry["sha256"]:
                    raise CorruptFileError(f"{actual}: checksum does not match its manifest")
    except CorruptFileError:
        raise
    except (ValueError, KeyError, TypeError) as exc:
        raise CorruptFileError(f"{mpath}: unreadable manifest ({exc})") from None


def set_aside(path: Path, reason: str) -> Path:
    """Rename a corrupt checkpoint to ``step_N.corrupt`` (kept for inspection), warning."""
    dest = path.with_name(path.name + ".corrupt")
    n = 1
    while dest.exists():
        n += 1
        dest = path.with_name(f"{path.name}.corrupt{n}")
    path.rename(dest)
    print(
        f"warning: checkpoint {path.name} is corrupt ({reason}): moved to {dest.name}; "
        "falling back to the checkpoint before it",
        file=sys.stderr,
    )
    return dest


def prune_states(ckpt_dir: Path, keep: int = KEEP_STATES) -> None:
    """Delete the state files of all but the ``keep`` newest checkpoints that have them
    (every checkpoint keeps its policy)."""
    full = [p for p in checkpoint_dirs(ckpt_dir) if has_state(p)]
    for old in full[:-keep] if keep else full:
        for f in STATE_FILES:
            if (old / f).is_dir():
                shutil.rmtree(old / f)
            else:
                (old / f).unlink(missing_ok=True)


def write(ckpt_dir: Path, step: int, write_files: Callable[[Path], None]) -> Path:
    """Write checkpoint ``step``: ``write_files(folder)`` fills ``step_N.tmp/``, which is then
    sealed (manifest), fsynced and renamed to ``step_N/``; then :func:`prune_states`. A kill or
    a failed write at any point leaves the earlier checkpoints as they were."""
    from peghole_mjx import fileio

    final = Path(ckpt_dir) / checkpoint_name(step)
    tmp = final.with_name(final.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    write_files(tmp)
    _fsync_tree(tmp)
    seal(tmp)
    fileio.replace_dir(tmp, final)
    prune_states(Path(ckpt_dir))
    return final


def _fsync_tree(folder: Path) -> None:
    """fsync every file and folder below ``folder`` (orbax writes subfolders)."""
    for p in sorted(folder.rglob("*"), key=lambda q: -len(q.parts)):
        if p.is_file():
            with open(p, "rb") as fh:
                os.fsync(fh.fileno())
        elif p.is_dir():
            fileio.fsync_dir(p)


#: what a damaged checkpoint raises while it is verified or loaded
CORRUPTION = (CorruptFileError, zipfile.BadZipFile, EOFError, json.JSONDecodeError)


def newest_valid(
    ckpt_dir: Path,
    load: Callable[[Path], Any],
    need: tuple[str, ...] = (*POLICY_FILES, *STATE_FILES),
) -> tuple[Path, Any] | None:
    """``(path, load(path))`` of the newest checkpoint with a state that verifies and loads,
    or None. ``need``: the files (or folders) the run's checkpoints hold, verified against the
    manifest (a single run: its policy files and the state; a multi-seed run: ``seed_K/``
    and the state). Each newer one that fails (:data:`CORRUPTION`, or a ValueError of
    ``np.load``) is set aside (:func:`set_aside`) with a warning; other errors (e.g. a
    checkpoint that does not fit the run's config) are raised."""
    dirs = checkpoint_dirs(ckpt_dir)
    full = [p for p in dirs if has_state(p)]
    legacy = [p for p in dirs if (p / LEGACY_STATE).exists()]
    if legacy and not full:
        raise UserInputError(
            f"{legacy[-1]}: a checkpoint of an older peghole_mjx (positional {LEGACY_STATE}), "
            "not resumable by this version; its policy still loads with peghole evaluate"
        )
    for path in reversed(full):
        try:
            verify(path, need)
            loaded = load(path)
        except (*CORRUPTION, ValueError, KeyError) as exc:
            if isinstance(exc, UserInputError) and not isinstance(exc, CorruptFileError):
                raise  # intact, but not this run's
            set_aside(path, " ".join(str(exc).split()) or type(exc).__name__)
            continue
        return path, loaded
    return None


def newest_policy_checkpoint(ckpt_dir: Path) -> Path | None:
    """The newest checkpoint whose policy files verify (skipping corrupt ones)."""
    for path in reversed(checkpoint_dirs(ckpt_dir)):
        try:
            verify(path, POLICY_FILES)
        except CorruptFileError as exc:
            print(f"warning: skipping checkpoint {path.name}: {exc}", file=sys.stderr)
            continue
        return path
    return None
