"""Checkpoint folders of a training run as a reader of policies sees them: names, manifest, the
newest intact policy.

``checkpoints/step_N/`` (N zero-padded to 10 digits) holds a policy (``policy.json`` and
``params.npz``; a multi-seed run one per seed in ``seed_K/``) and, for the newest ones, the
learner's state (:mod:`peghole_mjx.training.checkpoints`, which writes them). ``manifest.json``,
written last, lists every file below the folder with its size and SHA-256 (:func:`seal`,
:func:`verify`). Other names (``step_N.tmp``, ``step_N.old``, ``step_N.corrupt``) are never
checkpoints.

This part sits below both :mod:`peghole_mjx.policies` (``peghole evaluate RUN`` takes the newest
intact checkpoint of a run without a final policy) and :mod:`peghole_mjx.training`, so that
neither package imports the other in both directions (2026-12-02; before, ``policies`` imported
``training.checkpoints`` while ``training`` imports ``policies``).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from peghole_mjx.core.errors import CorruptFileError
from peghole_mjx.files import fileio

MANIFEST = "manifest.json"
POLICY_FILES = ("policy.json", "params.npz")
_NAME = re.compile(r"^step_(\d+)$")

#: the manifest's file hash
sha256 = fileio.sha256_file


def checkpoint_name(step: int) -> str:
    """The folder name of the checkpoint at ``step`` env steps."""
    return f"step_{step:010d}"


def checkpoint_dirs(ckpt_dir: str | Path) -> list[Path]:
    """Complete checkpoint folders, oldest first (by step; temporary folders excluded)."""
    ckpt_dir = Path(ckpt_dir)
    if not ckpt_dir.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in ckpt_dir.iterdir() if (m := _NAME.match(p.name))]
    return [p for _, p in sorted(found) if p.is_dir()]


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
