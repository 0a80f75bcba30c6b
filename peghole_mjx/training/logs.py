"""The CSV logs of a training run, one reader and one writer: ``metrics.csv`` (a single run,
one row per evaluation) and ``history.csv`` (a multi-seed run, one row per seed and chunk).

A run appends its rows as it goes (:meth:`CsvLog.append`: written and fsynced before the
checkpoint of the same step) and, when it resumes, rewrites the log with the rows up to its
checkpoint (:meth:`CsvLog.rewrite`, atomically). A row that a kill cut short is the last line
without its newline, or ending in NUL bytes after a power cut: :meth:`CsvLog.read` drops it
(its work is after the newest checkpoint and is redone). Every read is schema-checked
(:func:`read_rows`).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.files import fileio


@dataclass(frozen=True)
class CsvLog:
    """The log ``path`` with the columns ``columns``; ``keys``: the columns every row must
    have (``step``, and ``seed`` in a multi-seed history)."""

    path: Path
    columns: tuple[str, ...]
    keys: tuple[str, ...] = ("step",)

    def read(self, upto: int | None = None) -> list[dict[str, str]]:
        """The rows (strings), schema-checked, without a torn last row; ``upto``: only the rows
        of env steps up to it. No file: no rows."""
        if not self.path.exists():
            return []
        rows = read_rows(self.path, self.keys, torn_tail=True)
        return [r for r in rows if upto is None or int(r["step"]) <= upto]

    def rewrite(self, rows: Iterable[dict[str, Any]]) -> None:
        """Replace the log with ``rows`` (the header alone for none), atomically."""
        with fileio.atomic_open(self.path, "w") as f:
            w = csv.DictWriter(f, fieldnames=self.columns)
            w.writeheader()
            for r in rows:
                w.writerow(self._cells(r))

    def append(self, rows: Iterable[dict[str, Any]], tb=None) -> None:
        """Append ``rows`` (the header first when the log is new), flushed to disk; ``tb``: a
        TensorBoard writer that gets their finite numbers too (each row's ``step``)."""
        rows = list(rows)
        new = not self.path.exists()
        with self.path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.columns)
            if new:
                w.writeheader()
            for r in rows:
                w.writerow(self._cells(r))
            f.flush()
            os.fsync(f.fileno())
        if tb is not None:
            for row in rows:
                for k, v in row.items():
                    if k not in self.keys and isinstance(v, int | float) and math.isfinite(v):
                        tb.add_scalar(k, v, row["step"])
            tb.flush()

    def _cells(self, row: dict[str, Any]) -> dict[str, Any]:
        return {k: _fmt(row.get(k, "")) for k in self.columns}


def _fmt(v: Any) -> Any:
    """A float as its 6 significant digits, anything else as it is."""
    return f"{v:.6g}" if isinstance(v, float) else v


def read_metrics(run: Path, torn_tail: bool = False) -> list[dict[str, str]]:
    """The rows of a training run's ``metrics.csv`` (one per evaluation), as strings,
    schema-checked (:func:`read_rows`)."""
    path = Path(run) / "metrics.csv"
    if not path.exists():
        raise UserInputError(f"{run}: no metrics.csv (not a training run directory)")
    return read_rows(path, ("step",), torn_tail=torn_tail)


def read_rows(
    path: Path, required: tuple[str, ...], torn_tail: bool = False
) -> list[dict[str, str]]:
    """The rows of a CSV log a run appends to (``metrics.csv``, ``history.csv``), checked:
    UTF-8 text without NUL bytes, a header holding the ``required`` columns (no empty or
    repeated names), every row with the header's number of fields and a whole-number ``step``
    >= 0. A problem is a :class:`CorruptFileError` naming the file and the line.

    ``torn_tail``: the last line as a kill or a power cut can leave it (no final newline, or
    ending in NUL bytes) is dropped instead (``--resume``: that row is after the newest
    checkpoint, whose work is redone)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UserInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends in one
    if torn_tail:
        if lines and b"\0" in lines[-1] and not tail.strip(b"\0"):
            lines.pop()  # a row whose end a power cut replaced with NUL bytes
    elif tail:
        lines.append(tail)  # checked as any other line
    for i, line in enumerate(lines, 1):
        if b"\0" in line:
            raise CorruptFileError(
                f"{path} line {i}: NUL bytes (a damaged file, e.g. the tail a crash leaves)"
            )
    try:
        text = [line.decode().rstrip("\r") for line in lines]
    except UnicodeDecodeError as exc:
        raise CorruptFileError(f"{path}: not UTF-8 text ({exc.reason})") from None
    if not text or not text[0]:
        raise CorruptFileError(f"{path} line 1: no header")
    try:
        parsed = [(i, f) for i, f in enumerate(csv.reader(text), 1) if f]  # blank lines skipped
    except csv.Error as exc:
        raise CorruptFileError(f"{path}: not CSV ({exc})") from None
    header, body = parsed[0][1], parsed[1:]
    if any(not h for h in header) or len(set(header)) != len(header):
        raise CorruptFileError(f"{path} line 1: empty or repeated column names {header!r:.80}")
    missing = [c for c in required if c not in header]
    if missing:
        raise CorruptFileError(f"{path} line 1: the header lacks the columns {missing}")
    rows = []
    for i, fields in body:
        if len(fields) != len(header):
            raise CorruptFileError(
                f"{path} line {i}: {len(fields)} fields, the header has {len(header)}"
            )
        row = dict(zip(header, fields, strict=True))
        step = row.get("step")
        if step is not None and not (step.isascii() and step.isdigit()):
            raise CorruptFileError(f"{path} line {i}: step must be a whole number, got {step!r}")
        rows.append(row)
    return rows
