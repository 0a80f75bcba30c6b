"""Checkpoints of a training run: the one writer (:func:`save`) and reader (:func:`load`) of a
run's saved state, which to resume from, and which to keep.

``checkpoints/step_N/`` (names, manifest and policy look-up:
:mod:`peghole_mjx.files.checkpoint_folders`) holds the run's policy files and, in the
:data:`KEEP_STATES` newest, ``state/`` and
``state.json`` (the whole learner, for ``--resume``). ``state/`` is an orbax checkpoint
(``StandardCheckpointer``) of the carry as nested dicts named by the carry's tree paths
(``ts/q_params/...``, ``env_state/data/qpos``), so it is restored by name, not by leaf order
(:func:`save_state`, :func:`restore_state`); ``state.json`` holds the env-step count and the
driver's schedule (``wall_s``, ``n_eval``, ... : :class:`peghole_mjx.training.run.Run`). A
checkpoint is written in ``step_N.tmp/`` (every file fsynced, then the folders), sealed with its
manifest and renamed to ``step_N/``, so a folder named ``step_N`` is complete.

On resume the newest checkpoint whose state verifies is used; a corrupt newer one (truncated,
garbled, a checksum that does not match, no manifest) is renamed ``step_N.corrupt`` with a
warning and the previous one is used. Checkpoints written before the orbax format (a
positional ``state.npz``) are not resumable: :func:`newest_valid` refuses them in one line
(their policies still load).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np
import orbax.checkpoint as ocp

from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.treenames import differences, named_leaves, path_name
from peghole_mjx.core.validation import dumps
from peghole_mjx.files import fileio
from peghole_mjx.files.checkpoint_folders import (
    MANIFEST,
    POLICY_FILES,
    checkpoint_dirs,
    checkpoint_name,
    seal,
    verify,
)

#: ``state`` is a folder (orbax); the manifest lists the files inside it
__all__ = [  # the folder names and checks of peghole_mjx.files.checkpoint_folders belong to the API
    "CORRUPTION",
    "KEEP_STATES",
    "MANIFEST",
    "POLICY_FILES",
    "STATE_FILES",
    "checkpoint_dirs",
    "checkpoint_name",
    "has_state",
    "load",
    "newest_valid",
    "prune_states",
    "restore_state",
    "save",
    "save_state",
    "set_aside",
    "verify",
    "write",
]

STATE_FILES = ("state", "state.json")
#: what checkpoints written before the orbax format hold instead of ``state/``
LEGACY_STATE = "state.npz"
#: checkpoints that keep their full state (the newest and the one before, for a fallback)
KEEP_STATES = 2


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


def _checkpointer() -> ocp.StandardCheckpointer:
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


# ---------------------------------------------------------------------- one checkpoint
def save(
    ckpt_dir: Path,
    step: int,
    state: Any,
    schedule: dict[str, Any],
    write_policies: Callable[[Path], None],
) -> Path:
    """Write the checkpoint of ``step`` env steps (:func:`write`): the run's policies
    (``write_policies(folder)``: one policy, or one per seed), the learner's ``state`` (a tree
    of host arrays, :func:`save_state`) and ``state.json`` (``step``, the driver's
    ``schedule`` and the names of the state's zero-size leaves). Every training driver writes
    its checkpoints here (:mod:`peghole_mjx.training.run`)."""

    def write_files(folder: Path) -> None:
        write_policies(folder)
        saved = save_state(folder, state)
        text = dumps({"step": step, **schedule, **saved}, indent=2) + "\n"
        fileio.write_text(folder / STATE_FILES[1], text)

    return write(ckpt_dir, step, write_files)


def load(path: Path, template: Any, schedule_keys: tuple[str, ...] = ()) -> tuple[Any, dict]:
    """``(state, schedule)`` of checkpoint ``path`` (written by :func:`save`): the state in the
    structure and dtypes of ``template``, as host arrays (:func:`restore_state`), and
    ``state.json`` without its bookkeeping (``step`` and the driver's schedule). A
    ``state.json`` without a whole-number ``step`` or without one of ``schedule_keys`` is a
    :class:`CorruptFileError`."""
    sched = json.loads((path / STATE_FILES[1]).read_text())
    if not isinstance(sched, dict) or not isinstance(sched.get("step"), int):
        raise CorruptFileError(f"{path}/state.json holds no step")
    if not set(schedule_keys) <= set(sched):
        raise CorruptFileError(f"{path}/state.json lacks the evaluation schedule")
    empty = sched.pop("empty_leaves", {})
    return restore_state(path, template, empty), sched
