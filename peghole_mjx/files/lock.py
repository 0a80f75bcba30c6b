"""One writer per training run: ``DIR/run.lock`` holds the PID and host of the process writing.

Taken by ``peghole train`` (new run and ``--resume``) before anything of the run is read or
written, released when it ends. The process identity it records (PID, host, start time:
:func:`_proc_start`, :func:`_alive`) also names the holders of the sweep's slice claims
(:mod:`peghole_mjx.experiments.sweep`), which is why this module sits at the package's base
rather than in :mod:`peghole_mjx.training` (2026-12-02: the experiments import nothing of
training). The lock file is created complete and atomically (written under
a temporary name, then hard-linked to ``run.lock``, which fails if it exists), so a second
process either takes it or reads who holds it. A lock whose process is gone (killed with
kill -9, a crash, a reboot) is stale: on the same host it is detected (no such PID, or the PID
now belongs to a process started later) and taken over with a warning. A lock held from
another host cannot be checked from here: the message says which host, and to delete the
file if that run is known to be over.

:class:`OutputLock` (decided 2026-12-04) is the same lock for any output a command writes (a
folder written whole, a result file): ``PARENT/.NAME.lock`` beside it, taken before the work
and held until the output is in place, so that a second writer of the same output is refused
in one line naming the holder (PID, host, command) instead of both reporting success.
:func:`writing_files` (decided 2026-12-05) is that lock with the ownership rule of files
written one by one (:func:`peghole_mjx.files.fileio.check_file_replaceable`): every such writer
goes through it.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.files import fileio

LOCK_NAME = "run.lock"
#: the lock of a folder written into (:class:`OutputLock` with ``inside``)
OUTPUT_LOCK = ".peghole_output.lock"


def _proc_start(pid: int) -> str | None:
    """The start time of process ``pid`` (Linux ``/proc``), to tell a reused PID; else None."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[-1].split()[19]  # field 22, starttime


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    return True


class RunLockedError(UserInputError):
    """Another live process holds the run's lock."""


class RunLock:
    """The lock of the run in ``out`` (a context manager; :meth:`acquire` / :meth:`release`)."""

    def __init__(self, out: str | Path, command: str = "peghole train"):
        self.out = Path(out)
        self.folder = self.out  # where the lock file lives
        self.path = self.out / LOCK_NAME
        self.command = command
        self.held = False

    def _record(self) -> dict:
        return {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "start": _proc_start(os.getpid()),
            "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "command": self.command,
        }

    def _in_use(self, rec: dict) -> str:
        cmd = f"{rec['command']}, " if isinstance(rec.get("command"), str) else ""
        return (
            f"{self.out} is in use by another peghole process ({cmd}pid {rec['pid']} on "
            f"{rec.get('host', '?')}, since {rec.get('since', '?')}): wait for it to "
            f"end, or delete {self.path} if that run is known to be over"
        )

    def holder(self) -> dict | None:
        """The lock's record, ``{}`` if unreadable (garbled), None if there is no lock."""
        try:
            rec = json.loads(self.path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}
        return rec if isinstance(rec, dict) else {}

    def _is_stale(self, rec: dict) -> bool:
        if not rec or not isinstance(rec.get("pid"), int):
            return True  # garbled: no writer ever leaves it so (it is created complete)
        if rec.get("host") != socket.gethostname():
            return False  # cannot check another host's processes
        if not _alive(rec["pid"]):
            return True
        start = _proc_start(rec["pid"])
        return rec.get("start") is not None and start is not None and start != rec["start"]

    def acquire(self) -> RunLock:
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserInputError(
                f"cannot create the folder {self.folder} of the lock of {self.out} "
                f"({exc.strerror or exc})"
            ) from None
        tmp = self.folder / f".{self.path.name}.{os.getpid()}"
        try:
            self._write_record(tmp)
            for _ in range(3):
                try:
                    os.link(tmp, self.path)  # atomic: fails if the lock exists
                    self.held = True
                    return self
                except FileExistsError:
                    pass
                rec = self.holder()
                if rec is None:
                    continue  # released meanwhile: try again
                if rec.get("pid") == os.getpid() and rec.get("host") == socket.gethostname():
                    raise RunLockedError(f"{self.out} is already locked by this process")
                if not self._is_stale(rec):
                    raise RunLockedError(self._in_use(rec))
                print(
                    f"warning: removing the stale lock of {self.out} (pid {rec.get('pid', '?')} "
                    "is gone)",
                    file=sys.stderr,
                )
                with contextlib.suppress(FileNotFoundError):
                    self.path.unlink()
            raise RunLockedError(f"could not take the lock {self.path}: it keeps changing")
        finally:
            with contextlib.suppress(OSError):
                tmp.unlink()

    def _write_record(self, tmp: Path) -> None:
        """Write the lock record to ``tmp`` and flush it to disk; a failure (a full disk, a
        read-only folder) is one line naming the lock file (``tmp`` is removed by the
        caller)."""
        try:
            with open(tmp, "w") as f:
                f.write(json.dumps(self._record()) + "\n")
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise UserInputError(
                f"cannot write the lock file {self.path} of {self.out} ({exc.strerror or exc})"
            ) from None

    def release(self) -> None:
        if not self.held:
            return
        rec = self.holder()
        if rec and rec.get("pid") == os.getpid():
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        self.held = False

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


class OutputLock(RunLock):
    """One writer per output: the lock of the folder or file ``target``, a file
    ``.NAME.lock`` beside it (``target``'s links resolved, so two names of one output share
    it); ``inside``: a folder written into rather than replaced keeps it inside,
    ``.peghole_output.lock``. ``what`` names the option in the refusal (``--out``),
    ``command`` the holder."""

    def __init__(self, target: str | Path, command: str, what: str = "--out", inside: bool = False):
        super().__init__(target, command)
        self.what = what
        real = Path(os.path.realpath(os.path.abspath(target)))
        self.folder = real if inside else real.parent
        self.path = real / OUTPUT_LOCK if inside else real.parent / f".{real.name}.lock"

    def _in_use(self, rec: dict) -> str:
        cmd = rec["command"] if isinstance(rec.get("command"), str) else "a peghole command"
        return (
            f"{self.what} {self.out} is being written by another process ({cmd}, pid "
            f"{rec['pid']} on {rec.get('host', '?')}, since {rec.get('since', '?')}): nothing "
            f"was written; wait for it to end, or delete {self.path} if it is known to be over"
        )


@contextlib.contextmanager
def writing_files(
    files: dict[Path, dict],
    command: str,
    force: bool = False,
    what: str = "--out",
    lock: str | Path | None = None,
    has_force: bool = True,
) -> Iterator[None]:
    """Write ``files`` (path -> the parameters it is made with) as their one writer, under the
    program's ownership rule (decided 2026-12-05): the output's lock (:class:`OutputLock` of
    ``lock``, default the only file) is taken, then every existing file is checked
    (:func:`peghole_mjx.files.fileio.check_file_replaceable`: the program's, unchanged, of the same
    parameters unless ``force``), all before the body's work. Each file the body wrote, also
    when it then failed, gets its record (:func:`peghole_mjx.files.fileio.write_file_record`).
    ``has_force``: the command has a ``--force`` (named in the advice)."""
    if lock is None:
        if len(files) != 1:
            raise ValueError("writing_files: name the lock of several files")
        lock = next(iter(files))
    real = {}
    for path in files:
        fileio.check_no_link_loop(path, what)
        real[path] = fileio.real_path(path, what) if os.path.islink(path) else Path(path)
        fileio.check_name_length(real[path], what)
    fileio.check_no_link_loop(lock, what)
    above = Path(os.path.abspath(lock)).parent
    while not above.exists() and above != above.parent:
        above = above.parent
    if not above.is_dir():  # the lock's folder cannot be made: say why in the --out's words
        raise UserInputError(f"{what} {lock}: {above} is an existing file, not a folder")
    with OutputLock(lock, command, what):
        before = {}
        for path, params in files.items():
            fileio.check_file_replaceable(real[path], params, force, what, has_force)
            before[path] = _stamp(real[path])
        try:
            yield
        except BaseException:
            with contextlib.suppress(OSError):  # the first error is the one reported
                _record(files, real, before, command)
            raise
        _record(files, real, before, command)


def _record(files: dict, real: dict, before: dict, command: str) -> None:
    for path, params in files.items():
        if real[path].is_file() and _stamp(real[path]) != before[path]:
            fileio.write_file_record(real[path], command, params)


def _stamp(path: Path) -> tuple | None:
    """What tells that a file was (re)written: inode, size, modification time."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


def command_parameters(args, drop: tuple[str, ...] = ()) -> dict:
    """A command's parsed arguments as the parameters of what it writes: all but the output
    itself, ``--force``, the presentation flags and the dispatcher's own entries."""
    skip = {"out", "force", "json", "func", "argv", *drop}
    return {k: v for k, v in sorted(vars(args).items()) if k not in skip and not callable(v)}
