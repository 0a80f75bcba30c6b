"""Durable file output: every file is written to a temporary name, flushed to disk and renamed.

A reader (or a run resumed after kill -9 or a power cut) sees either the old file or the
complete new one, never a half-written one; a failed write (a full disk, a read-only folder)
leaves the old file as it was. ``check_out_*`` tell a bad output path before the work starts.

**Ownership** (decided 2026-12-04): the program deletes or replaces only what it can prove it
wrote. Every folder written whole (:func:`replace_dir`: ``peghole export``, ``peghole task
make``, a saved policy, a checkpoint) holds :data:`OWNER_MANIFEST`, the list of the files the
program wrote there. Temporary and set-aside folders get unique names beside the target
(:func:`temp_dir_beside`, ``tempfile.mkdtemp``), never a fixed ``NAME.tmp`` or ``NAME.old``,
so a folder of the user's with such a name is never touched. A folder that holds a file the
program cannot prove it wrote (not in its manifest; in a folder written before the manifest
existed, a name the writer does not write) is not replaced: the command is refused in one
line naming those files (:func:`foreign_files`), and nothing is deleted.

**Files written one by one** (decided 2026-12-05: ``evaluate --out``, ``compare --out``,
``models check --out``, ``models build``, ``analyze figure``, ``analyze jamming --out``): each
gets a record beside it, ``.NAME.peghole.json`` (:func:`write_file_record`: the command, its
parameters and the file's SHA-256). An existing file is replaced only when its record proves
it the program's, unchanged since (:func:`check_file_replaceable`); a file of other
parameters only with ``--force``; a file without a matching record never.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO

from peghole_mjx.core.errors import UserInputError


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


#: the most bytes a temporary name beside an output adds to its name: ``.NAME.tmp-XXXXXXXX``
#: and ``.NAME.old-XXXXXXXX`` (:func:`temp_dir_beside`) add 14, ``.NAME.PID.tmp``
#: (:func:`atomic_open`, a PID of up to 7 digits) 13, a lock ``.NAME.lock`` 6
TEMP_NAME_EXTRA = 14


def check_no_link_loop(path: str | Path, what: str = "--out") -> None:
    """Refuse (one line) a ``path`` that is, or lies under, a symbolic link loop (a
    RuntimeError or ELOOP traceback otherwise)."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise UserInputError(
                f"{_named(what, path)} is a symbolic link loop: nothing can be written there; "
                "give another path"
            ) from None


def real_path(path: str | Path, what: str = "--out") -> Path:
    """``path`` with every symbolic link resolved (a link is written through, never replaced
    by a file); a link loop is refused in one line."""
    check_no_link_loop(path, what)
    try:
        return Path(os.path.realpath(path))
    except (OSError, RuntimeError):
        raise UserInputError(f"{_named(what, path)} is a symbolic link loop") from None


def _named(what: str, path: str | Path) -> str:
    return f"{what} {path}" if what else str(path)


def check_name_length(path: str | Path, what: str = "--out") -> None:
    """Refuse (one line) an output name that fits the file system but not with the temporary
    names written beside it (:data:`TEMP_NAME_EXTRA` bytes more): such a name would fail only
    after the work, at its first temporary write."""
    name = Path(os.path.abspath(path)).name
    n = len(os.fsencode(name))
    parent = Path(os.path.abspath(path)).parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    try:
        limit = os.pathconf(parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    if n + TEMP_NAME_EXTRA > limit:
        raise UserInputError(
            f"{what} {path}: the name is {n} bytes; the temporary names written beside it "
            f"(.NAME.tmp-XXXXXXXX) add {TEMP_NAME_EXTRA}, more than the {limit} this file "
            f"system allows: choose a name of at most {limit - TEMP_NAME_EXTRA} bytes"
        )


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", sync_dir: bool = True) -> Iterator[IO]:
    """Open a temporary file beside ``path``; on success flush, fsync and rename it onto
    ``path``; on any error remove it and leave ``path`` untouched. A ``path`` that is a
    symbolic link is written through (its target replaced, the link kept)."""
    path = Path(path)
    if os.path.islink(path):
        path = real_path(path, "")
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
    files = {real_path(p, "") if os.path.islink(p) else p: t for p, t in files.items()}
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


#: the file, in every folder the program writes whole, that lists the files it wrote there
OWNER_MANIFEST = ".peghole_manifest.json"


def temp_dir_beside(target: str | Path, tag: str = "tmp") -> Path:
    """A new, empty folder with a unique name beside ``target`` (``.NAME.tag-XXXXXXXX``), made
    by ``tempfile.mkdtemp``: it never is, nor replaces, a folder of the user's."""
    target = Path(target).absolute()
    path = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.{tag}-"))
    mask = os.umask(0o022)  # mkdtemp makes it 0700: give it a plain mkdir's mode
    os.umask(mask)
    os.chmod(path, 0o777 & ~mask)
    return path


def _files_under(folder: Path) -> list[str]:
    """Every file (or link, or other non-folder) under ``folder``, as POSIX relative paths."""
    out = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        # a link to a folder is listed as an entry, never followed
        out += [(rel / d).as_posix() for d in dirs if (Path(root) / d).is_symlink()]
        out += [(rel / f).as_posix() for f in files]
    return sorted(out)


def owned_files(folder: str | Path) -> set[str] | None:
    """The files ``folder``'s :data:`OWNER_MANIFEST` says the program wrote, or None when it
    has none (or an unreadable one: then nothing in it is proven ours)."""
    path = Path(folder) / OWNER_MANIFEST
    try:
        files = json.loads(path.read_text())["files"]
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        return None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return set(files)


def write_owner_manifest(
    folder: str | Path,
    files: Iterable[str] | None = None,
    hashed: Iterable[str] = (),
    parameters: dict | None = None,
) -> None:
    """Record in ``folder`` the files the program wrote there (default: every file now in
    it), the SHA-256 of those named in ``hashed`` (:func:`recorded_sha256`) and the
    ``parameters`` they were made with (:func:`recorded_parameters`)."""
    folder = Path(folder)
    names = sorted(set(_files_under(folder) if files is None else files) - {OWNER_MANIFEST})
    doc: dict = {"written_by": "peghole_mjx", "files": names}
    hashes = {n: sha256_file(folder / n) for n in sorted(hashed) if (folder / n).is_file()}
    if hashes:
        doc["sha256"] = hashes
    if parameters is not None:
        doc["parameters"] = plain_json(parameters)
    write_text(folder / OWNER_MANIFEST, json.dumps(doc, indent=1) + "\n")


def plain_json(obj):
    """``obj`` as plain JSON values (paths and other objects as their text, tuples as lists),
    so that parameters compare equal after a round trip through a file."""
    return json.loads(json.dumps(obj, default=str, sort_keys=True))


def recorded_parameters(folder: str | Path) -> dict | None:
    """The parameters :data:`OWNER_MANIFEST` of ``folder`` records (None: none recorded)."""
    try:
        doc = json.loads((Path(folder) / OWNER_MANIFEST).read_text())
    except (OSError, ValueError, RecursionError):
        return None
    params = doc.get("parameters") if isinstance(doc, dict) else None
    return params if isinstance(params, dict) else None


def differences(a, b, prefix: str = "", whole: str = "parameters") -> list[str]:
    """The keys (dotted) whose values differ between two JSON trees (``whole``: the name
    given when the trees themselves differ and are not both dicts)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b), key=str):
            out += differences(a.get(k), b.get(k), f"{prefix}{k}.", whole)
        return out
    return [] if a == b else [prefix.rstrip(".") or whole]


def check_same_parameters(
    folder: str | Path, parameters: dict, force: bool, what: str = "--out", has_force: bool = True
) -> None:
    """A folder of results written whole (a task folder) is replaced by a run of other
    ``parameters`` only with ``force`` (decided 2026-12-05): refused in one line naming the
    differing keys, or saying none were recorded (a folder written before then)."""
    folder = Path(folder)
    if force or not folder.is_dir() or not any(folder.iterdir()):
        return
    recorded = recorded_parameters(folder)
    mine = plain_json(parameters)
    if recorded == mine:
        return
    diff = describe_files(differences(mine, recorded), 4)
    why = (
        "its parameters were not recorded (written before 2026-12-05)"
        if recorded is None
        else f"made with other parameters (differing: {diff})"
    )
    advice = "pass --force to replace it, or " if has_force else ""
    raise UserInputError(
        f"{what} {folder} holds results {why}: nothing was written; {advice}choose another folder"
    )


#: the record beside a file the program wrote one by one: ``.NAME`` + this
RECORD_SUFFIX = ".peghole.json"


def record_path(path: str | Path) -> Path:
    """The record of the file ``path`` (:func:`write_file_record`): ``.NAME.peghole.json``."""
    path = Path(path)
    return path.with_name(f".{path.name}{RECORD_SUFFIX}")


def write_file_record(path: str | Path, command: str, parameters: dict) -> None:
    """Record beside ``path`` (just written by ``command``) that the program wrote it: the
    command, its ``parameters`` and the file's SHA-256."""
    path = Path(path)
    doc = {
        "written_by": "peghole_mjx",
        "file": path.name,
        "command": command,
        "parameters": plain_json(parameters),
        "sha256": sha256_file(path),
    }
    write_text(record_path(path), json.dumps(doc, indent=1) + "\n")


def file_record(path: str | Path) -> dict | None:
    """The record of ``path`` when it proves the file the program's (its SHA-256 matches the
    file's bytes); else None."""
    path = Path(path)
    try:
        doc = json.loads(record_path(path).read_text())
        if not isinstance(doc, dict) or doc.get("written_by") != "peghole_mjx":
            return None
        return doc if doc.get("sha256") == sha256_file(path) else None
    except (OSError, ValueError, RecursionError):
        return None


def check_file_replaceable(
    path: str | Path,
    parameters: dict,
    force: bool = False,
    what: str = "--out",
    has_force: bool = True,
) -> None:
    """Refuse (one line) to replace the existing file ``path`` unless the program wrote it
    (its record, :func:`file_record`, or the manifest of its folder) and it is unchanged
    since; one written with other ``parameters`` only with ``force``. Nothing is touched."""
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        return
    if path.is_dir():
        raise UserInputError(f"{what} {path} is a folder, not a file")
    rec = file_record(path)
    recorded = rec.get("parameters") if rec else None
    if rec is None:
        parent = path.parent
        listed = path.name in (owned_files(parent) or ())
        sha = recorded_sha256(parent, path.name)
        if not listed or (sha is not None and sha != sha256_file(path)):
            raise UserInputError(
                f"{what} {path} is a file peghole_mjx did not write, or one changed since it "
                f"was written (no matching record {record_path(path).name}): nothing was "
                "written; give another path, or move it away"
            )
    mine = plain_json(parameters)
    if recorded == mine or force:
        return
    why = (
        "its parameters were not recorded"
        if recorded is None
        else f"differing: {describe_files(differences(mine, recorded), 4)}"
    )
    advice = "pass --force to replace it, or " if has_force else ""
    raise UserInputError(
        f"{what} {path} holds results of other parameters ({why}): nothing was written; "
        f"{advice}give another path"
    )


def recorded_sha256(folder: str | Path, name: str) -> str | None:
    """The SHA-256 :data:`OWNER_MANIFEST` of ``folder`` records for its file ``name``, or
    None (no manifest, or one written without hashes: before 2026-12-04)."""
    try:
        rec = json.loads((Path(folder) / OWNER_MANIFEST).read_text()).get("sha256", {})
        sha = rec.get(name) if isinstance(rec, dict) else None
    except (OSError, ValueError, AttributeError, RecursionError):
        return None
    return sha if isinstance(sha, str) else None


def foreign_files(folder: str | Path, known: Iterable[str] = ()) -> list[str]:
    """The files under ``folder`` the program cannot prove it wrote: those not in its
    :data:`OWNER_MANIFEST`; when it has none (a folder written before 2026-12-04), those
    whose first path component is not in ``known`` (the names its writer writes). What an
    atomic write of one of ours left behind when killed (``.NAME.PID.tmp``) counts as ours."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    owned = owned_files(folder)
    known = set(known)

    def ours(rel: str) -> bool:
        if owned is not None:
            return rel in owned or rel == OWNER_MANIFEST
        return rel.split("/", 1)[0] in known | {OWNER_MANIFEST}

    def recorded(rel: str) -> bool:  # a file written one by one, with its record
        rec = re.fullmatch(r"((?:.*/)?)\.([^/]+)" + re.escape(RECORD_SUFFIX), rel)
        name = rec[1] + rec[2] if rec else rel
        return file_record(folder / name) is not None

    out = []
    for rel in _files_under(folder):
        left = re.fullmatch(r"((?:.*/)?)\.([^/]+)\.\d+\.tmp", rel)  # an atomic write's leftover
        if ours(rel) or (left and ours(left[1] + left[2])) or recorded(rel):
            continue
        out.append(rel)
    return out


def describe_files(names: list[str], limit: int = 5) -> str:
    """``a, b, c and 4 more`` for a one-line message."""
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def check_replaceable(folder: str | Path, known: Iterable[str] = (), what: str = "--out") -> None:
    """Refuse (one line, UserInputError) to replace ``folder`` when it holds files the
    program did not write (:func:`foreign_files`); nothing is deleted."""
    foreign = foreign_files(folder, known)
    if foreign:
        raise UserInputError(
            f"{what} {folder} holds files peghole_mjx did not write ({describe_files(foreign)}): "
            "nothing was replaced; move them away or choose another folder"
        )


def replace_dir(
    tmp: Path,
    final: Path,
    known: Iterable[str] | None = None,
    owned: Iterable[str] | None = None,
    hashed: Iterable[str] = (),
    parameters: dict | None = None,
) -> None:
    """Move a completely written folder ``tmp`` (made by :func:`temp_dir_beside`) onto
    ``final``, replacing an old one only when every file in it is the program's.

    ``tmp`` gets an :data:`OWNER_MANIFEST` of ``owned`` (default: every file in it; with
    the SHA-256 of the files named in ``hashed`` and the run's ``parameters``). An
    existing ``final`` with a file the program cannot prove it wrote (:func:`foreign_files`;
    ``known`` default: the names in ``tmp``) is refused in one line: ``tmp`` is removed and
    ``final`` left as it was. Otherwise ``final`` is renamed to a unique name beside it,
    ``tmp`` renamed onto ``final``, and the old folder removed."""
    tmp, final = Path(tmp), Path(final)
    names = {p.name for p in tmp.iterdir()}
    write_owner_manifest(tmp, owned, hashed, parameters)
    for f in tmp.iterdir():
        if f.is_file() and not f.is_symlink():
            with open(f, "rb") as fh:
                os.fsync(fh.fileno())
    fsync_dir(tmp)
    old = None
    if final.exists() or final.is_symlink():
        if not final.is_dir() or final.is_symlink():
            shutil.rmtree(tmp, ignore_errors=True)
            raise UserInputError(f"{final} is not a folder: nothing was replaced")
        try:
            check_replaceable(final, names if known is None else known, what="")
        except UserInputError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            raise UserInputError(str(exc).strip()) from None
        old = temp_dir_beside(final, "old")
        os.replace(final, old)  # onto the new empty folder: a rename, atomic
    os.replace(tmp, final)
    fsync_dir(final.parent)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def check_out_dir(path: str | Path, what: str = "--out", beside: bool = True) -> Path:
    """``path`` is, or can be made, a writable folder (created here); else UserInputError.
    ``beside``: temporary names are written beside it (its name is checked against them,
    :func:`check_name_length`)."""
    path = Path(path)
    check_no_link_loop(path, what)
    if beside and path.name:
        check_name_length(path, what)
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
    check_no_link_loop(path, what)
    if path.is_dir():
        raise UserInputError(f"{what} {path} is a folder, not a file")
    check_name_length(path, what)
    if path.exists() and not os.access(path, os.W_OK):
        raise UserInputError(f"{what} {path}: the file is not writable")
    folder = path.parent if str(path.parent) else Path(".")
    check_out_dir(folder, what=f"{what} {path}: folder", beside=False)
    return path
