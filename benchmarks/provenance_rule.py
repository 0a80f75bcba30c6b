"""The provenance rule: what every result file linked from the docs must record.

A result file is a ``.json`` or ``.csv`` under ``benchmarks/results/`` or a policy's
``peghole_mjx/policies/NAME/evaluation.json``. Its record must hold the six
:data:`REQUIRED` fields, each present and not empty (decision 2026-12-04, issue 52):

* a JSON result file holds them as top-level keys; a JSON list of results (``peghole evaluate
  A B --out F``: one result per policy) holds them in each entry;
* a CSV result file has them in the JSON record of the same run beside it, the file of the same
  stem (``throughput_engines_cpu-2core.csv`` -> ``throughput_engines_cpu-2core.json``);
* a field that cannot be recovered is the string ``"unknown: REASON"`` (the reason not empty);
* ``config`` may be a dict, or a string ``"see KEY, KEY, ...[; remark]"`` naming the top-level
  keys of the same record that hold the run's settings (each must exist).

``python -m pytest tests/test_provenance_links.py`` walks every link of README.md and
docs/**/*.md and applies :func:`problems` to each result file linked.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from benchmarks.common import ROOT

#: the fields every result file's record holds
REQUIRED = ("device", "versions", "date", "command", "config", "commit")

_LINK = re.compile(r"\]\(([^)\s]+)\)")
_POLICY_EVAL = re.compile(r"peghole_mjx/policies/[^/]+/evaluation\.json")


def is_result(rel_path: str) -> bool:
    """Whether the repository-relative ``rel_path`` is a result file under the rule."""
    if rel_path.startswith("benchmarks/results/"):
        return rel_path.endswith((".json", ".csv"))
    return bool(_POLICY_EVAL.fullmatch(rel_path))


def record_path(path: Path) -> Path:
    """Where ``path``'s provenance is: the file itself (JSON) or its same-stem JSON (CSV)."""
    return path.with_suffix(".json") if path.suffix == ".csv" else path


def linked_results(root: Path = ROOT) -> dict[str, list[str]]:
    """Every result file linked from README.md and docs/**/*.md of ``root``: repository-
    relative path -> the Markdown files that link it."""
    files = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    out: dict[str, list[str]] = {}
    for md in files:
        if not md.exists():
            continue
        for target in _LINK.findall(md.read_text()):
            if re.match(r"[a-z]+:|#", target):
                continue
            path = (md.parent / target.split("#")[0]).resolve()
            if not path.is_relative_to(root.resolve()):
                continue
            rel_path = path.relative_to(root.resolve()).as_posix()
            if is_result(rel_path):
                out.setdefault(rel_path, [])
                if md.relative_to(root).as_posix() not in out[rel_path]:
                    out[rel_path].append(md.relative_to(root).as_posix())
    return dict(sorted(out.items()))


def field_problem(record: dict, key: str) -> str | None:
    """What is wrong with ``record[key]`` under the rule (None when it is fine)."""
    if key not in record:
        return f"no {key!r}"
    value = record[key]
    if value is None or value == "" or value == {} or value == []:
        return f"{key!r} is empty"
    if isinstance(value, str):
        low = value.strip().lower()
        if low.startswith("unknown"):
            reason = low[len("unknown") :].lstrip()
            if not reason.startswith(":") or not reason[1:].strip():
                return f"{key!r} is unknown without a reason ('unknown: REASON')"
        elif key == "config" and low.startswith("see "):
            named = [k.strip() for k in value.strip()[4:].split(";")[0].split(",")]
            absent = [k for k in named if k not in record]
            if absent:
                return f"'config' names keys the record lacks: {absent}"
    return None


def problems(path: Path) -> list[str]:
    """Each breach of the rule by the result file ``path``, one line each."""
    rec_path = record_path(path)
    if not path.exists():
        return [f"{path.name}: missing"]
    if not rec_path.exists():
        return [f"{path.name}: no record {rec_path.name} beside it"]
    try:
        record = json.loads(rec_path.read_text())
    except json.JSONDecodeError as exc:
        return [f"{rec_path.name}: not JSON ({exc})"]
    if isinstance(record, list) and record and all(isinstance(r, dict) for r in record):
        return [
            f"{rec_path.name}[{i}]: {p}"
            for i, r in enumerate(record)
            for k in REQUIRED
            if (p := field_problem(r, k))
        ]
    if not isinstance(record, dict):
        return [f"{rec_path.name}: not a JSON object or a list of them"]
    return [f"{rec_path.name}: {p}" for k in REQUIRED if (p := field_problem(record, k))]
