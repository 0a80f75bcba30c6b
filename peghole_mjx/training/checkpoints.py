"""Checkpoint folders of a training run: which exist, which are intact, which to resume from.

``checkpoints/step_N/`` (N zero-padded to 10 digits) holds ``policy.json`` and
``params.npz``; the :data:`KEEP_STATES` newest also hold ``state.npz`` and ``state.json`` (the
whole learner, for ``--resume``). ``manifest.json``, written last, lists every file with its
size and SHA-256. A checkpoint is written in ``step_N.tmp/`` (every file fsynced, then the
folder) and renamed to ``step_N/``, so a folder named ``step_N`` is complete; other names
(``step_N.tmp``, ``step_N.old``, ``step_N.corrupt``) are never checkpoints.

On resume the newest checkpoint whose state verifies is used; a corrupt newer one (truncated,
garbled, a checksum that does not match) is renamed ``step_N.corrupt`` with a warning and the
previous one is used.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from peghole_mjx import fileio
from peghole_mjx.errors import CorruptFileError

MANIFEST = "manifest.json"
STATE_FILES = ("state.npz", "state.json")
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


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def seal(folder: Path) -> None:
    """Write ``manifest.json``: size and SHA-256 of every file in ``folder``."""
    files = {
        p.name: {"bytes": p.stat().st_size, "sha256": sha256(p)}
        for p in sorted(folder.iterdir())
        if p.is_file() and p.name != MANIFEST and not p.name.startswith(".")
    }
    fileio.write_text(folder / MANIFEST, json.dumps({"files": files}, indent=2) + "\n")


def verify(path: Path, need: tuple[str, ...] = POLICY_FILES) -> None:
    """Raise :class:`CorruptFileError` unless the files ``need`` of checkpoint ``path`` are
    present and match its manifest. A checkpoint without a manifest (written by an older
    peghole_mjx) passes when the files exist; loading them checks them further."""
    missing = [f for f in need if not (path / f).is_file()]
    if missing:
        raise CorruptFileError(f"{path}: missing {', '.join(missing)}")
    mpath = path / MANIFEST
    if not mpath.exists():
        return
    try:
        listed = json.loads(mpath.read_text())["files"]
        for name in need:
            entry = listed[name]
            actual = path / name
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
    seal(tmp)
    fileio.replace_dir(tmp, final)
    prune_states(Path(ckpt_dir))
    return final


#: what a damaged checkpoint raises while it is verified or loaded
CORRUPTION = (CorruptFileError, zipfile.BadZipFile, EOFError, json.JSONDecodeError)


def newest_valid(ckpt_dir: Path, load: Callable[[Path], Any]) -> tuple[Path, Any] | None:
    """``(path, load(path))`` of the newest checkpoint with a state that verifies and loads,
    or None. Each newer one that fails (:data:`CORRUPTION`, or a ValueError of ``np.load``)
    is set aside (:func:`set_aside`) with a warning; other errors (e.g. a checkpoint that does
    not fit the run's config) are raised."""
    from peghole_mjx.errors import UserInputError

    full = [p for p in checkpoint_dirs(ckpt_dir) if has_state(p)]
    for path in reversed(full):
        try:
            verify(path, (*POLICY_FILES, *STATE_FILES))
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
