"""Durable file output: every file is written to a temporary name, flushed to disk and renamed.

A reader (or a run resumed after kill -9 or a power cut) sees either the old file or the
complete new one, never a half-written one; a failed write (a full disk, a read-only folder)
leaves the old file as it was. ``check_out_*`` tell a bad output path before the work starts.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

from peghole_mjx.errors import UserInputError


def fsync_dir(path: str | Path) -> None:
    """Flush a folder's entries (a rename inside it) to disk; a no-op where unsupported."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot fsync a folder
    finally:
        os.close(fd)


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _tmp_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", sync_dir: bool = True) -> Iterator[IO]:
    """Open a temporary file beside ``path``; on success flush, fsync and rename it onto
    ``path``; on any error remove it and leave ``path`` untouched."""
    path = Path(path)
    tmp = _tmp_name(path)
    try:
        with open(tmp, mode, **({} if "b" in mode else {"newline": ""})) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    if sync_dir:
        fsync_dir(path.parent)


def write_text(path: str | Path, text: str) -> Path:
    """Atomically replace ``path`` with ``text``."""
    with atomic_open(path, "w") as f:
        f.write(text)
    return Path(path)


def write_bytes_with(path: str | Path, writer: Callable[[IO[bytes]], None]) -> Path:
    """Atomically replace ``path`` with what ``writer(file)`` writes (e.g. ``np.savez``)."""
    with atomic_open(path, "wb") as f:
        writer(f)
    return Path(path)


def write_many(files: dict[Path, str]) -> None:
    """Write every file or none: all are written to temporary names first, then renamed."""
    tmps: list[tuple[Path, Path]] = []
    try:
        for path, text in files.items():
            tmp = _tmp_name(path)
            tmps.append((tmp, path))
            with open(tmp, "w") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
        for tmp, path in tmps:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in tmps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise
    for parent in {p.parent for p in files}:
        fsync_dir(parent)


def replace_dir(tmp: Path, final: Path) -> None:
    """Move a completely written folder ``tmp`` onto ``final`` (replacing an old one)."""
    for f in tmp.iterdir():
        if f.is_file():
            with open(f, "rb") as fh:
                os.fsync(fh.fileno())
    fsync_dir(tmp)
    old = None
    if final.exists():
        old = final.with_name(final.name + ".old")
        if old.exists():
            shutil.rmtree(old)
        os.replace(final, old)
    os.replace(tmp, final)
    fsync_dir(final.parent)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def check_out_dir(path: str | Path, what: str = "--out") -> Path:
    """``path`` is, or can be made, a writable folder (created here); else UserInputError."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserInputError(f"{what} {path} is an existing file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserInputError(f"{what} {path}: cannot create the folder ({exc.strerror})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UserInputError(f"{what} {path}: the folder is not writable")
    _probe_write(path, what)
    return path


def _probe_write(folder: Path, what: str) -> None:
    """Create and remove a small file in ``folder``: ``os.access`` says yes to root on a folder
    without write bits and cannot see every read-only or full file system; a real write can."""
    probe = folder / f".peghole_write_probe.{os.getpid()}"
    try:
        with open(probe, "wb") as f:
            f.write(b"0")
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise UserInputError(
            f"{what} {folder}: the folder is not writable ({exc.strerror or exc})"
        ) from None
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()


def free_bytes(path: str | Path) -> int:
    """Bytes free for an unprivileged writer on the file system holding ``path`` (or the
    nearest existing folder above it)."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    st = os.statvfs(p)
    return st.f_bavail * st.f_frsize


def check_room(path: str | Path, need_bytes: int, what: str = "--out") -> None:
    """Refuse (UserInputError, before any work) when the file system of ``path`` has less free
    space than ``need_bytes`` (an estimate of what the command will write)."""
    free = free_bytes(path)
    if free < need_bytes:
        raise UserInputError(
            f"{what} {path}: {_mib(free)} free, the command writes about {_mib(need_bytes)}"
        )


def _mib(n: float) -> str:
    return f"{n / 2**20:.1f} MiB" if n < 2**30 else f"{n / 2**30:.1f} GiB"


def check_out_file(path: str | Path, what: str = "--out") -> Path:
    """``path`` can be written as a file (its folder created here); else UserInputError."""
    path = Path(path)
    if path.is_dir():
        raise UserInputError(f"{what} {path} is a folder, not a file")
    if path.exists() and not os.access(path, os.W_OK):
        raise UserInputError(f"{what} {path}: the file is not writable")
    check_out_dir(path.parent if str(path.parent) else Path("."), what=f"{what} {path}: folder")
    return path
