"""The experiments' file output: every file written atomically
(:mod:`peghole_mjx.files.fileio`), and a failed write (a full disk, a read-only folder) reported
naming the file.

A reader, or a sweep resumed after a kill, sees the old file or the complete new one; a failed
write leaves no temporary file behind and the old file as it was.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from peghole_mjx.core.validation import dumps
from peghole_mjx.files import fileio


@contextlib.contextmanager
def naming(path: str | Path) -> Iterator[None]:
    """Re-raise an OSError without a file name (``os.fsync`` on a full disk) naming ``path``."""
    try:
        yield
    except OSError as exc:
        if exc.filename:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None


def write_text(path: str | Path, text: str) -> Path:
    """Atomically replace ``path`` with ``text``."""
    with naming(path):
        return fileio.write_text(path, text)


def write_json(path: str | Path, obj: Any, indent: int = 1) -> Path:
    """Atomically write ``obj`` as strict JSON (NaN and infinity as ``null``)."""
    return write_text(path, dumps(obj, indent=indent) + "\n")


def write_png(fig, path: str | Path, dpi: int) -> Path:
    """Atomically save a matplotlib figure as PNG."""
    with naming(path):
        return fileio.write_bytes_with(path, lambda f: fig.savefig(f, format="png", dpi=dpi))


def write_npz(path: str | Path, arrays: dict) -> Path:
    """Atomically save ``arrays`` with ``np.savez`` (file and folder flushed to disk)."""
    with naming(path):
        return fileio.write_bytes_with(path, lambda f: np.savez(f, **arrays))


def check_out(folder: str | Path, need_bytes: int, what: str = "--out") -> Path:
    """Before any simulation: ``folder`` is (made) a writable folder whose disk has room for
    ``need_bytes`` (an estimate of what the command writes); else UserInputError."""
    folder = fileio.check_out_dir(folder, what)
    fileio.check_room(folder, need_bytes, what)
    return folder
