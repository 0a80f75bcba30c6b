"""The reproduce-command rule: a command the docs give beside a committed result is the command
that result file recorded.

In docs/research/*.md and docs/guide/*.md a *block* is a paragraph, a list item, a table row,
or a fenced code block together with the paragraphs just before and after it. A command in a
block is an inline or fenced ``python -m benchmarks...``, ``python benchmarks/...`` or
``peghole ...`` line. A result in a block is a link to a JSON result file
(:func:`benchmarks.provenance_rule.is_result`) or a result file's bare name in backticks.
A command in a block beside results that ran the same program (its first three words) must be
the ``command`` one of them recorded, compared under :func:`benchmarks.tables.current_names`
(module paths from before the scripts moved into kinds) and :func:`normal` (a trailing
``--note`` dropped, numbers by value). A result whose command is ``"unknown: ... written by
`CMD` ..."`` names only its program: a command beside it is checked to that program only.

``python -m pytest tests/test_reproduce_commands.py`` applies :func:`problems` to every pair.
"""

from __future__ import annotations

import json
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from benchmarks.common import RESULTS, ROOT
from benchmarks.provenance_rule import is_result
from benchmarks.tables import current_names

_CODE = re.compile(r"`([^`]+)`")
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_CMD = re.compile(r"^(python3? (-m )?benchmarks[./]|peghole [a-z])")
_WRITTEN_BY = re.compile(r"written by `([^`]+)`")


@dataclass(frozen=True)
class Pair:
    """A command of the docs and the result files beside it that recorded the same program."""

    page: str
    command: str
    results: tuple[str, ...]
    recorded: tuple[str, ...]  # each result's recorded command, in order
    exact: tuple[bool, ...]  # False: the record names only the program (``written by``)


def doc_pages(root: Path = ROOT) -> list[Path]:
    return sorted((root / "docs" / "research").glob("*.md")) + sorted(
        (root / "docs" / "guide").glob("*.md")
    )


def blocks(text: str) -> list[tuple[str, list[str]]]:
    """``text`` cut into blocks: (the block's prose, the commands of its fenced code)."""
    paras: list[tuple[str, list[str]]] = []  # (text, fenced lines); fenced lines mark a fence
    cur: list[str] = []
    fence: list[str] | None = None

    def flush():
        if cur:
            paras.append((" ".join(cur), []))
            cur.clear()

    for line in text.splitlines():
        if fence is not None:
            if line.startswith("```"):
                joined = re.sub(r"\\\n\s*", "", "\n".join(fence))  # continued lines
                paras.append(("", [c.strip() for c in joined.splitlines() if c.strip()]))
                fence = None
            else:
                fence.append(line)
            continue
        if line.startswith("```"):
            flush()
            fence = []
        elif line.startswith("|") or line.startswith("#"):
            flush()
            paras.append((line, []))
        elif not line.strip():
            flush()
        elif re.match(r"\s*([-*]|\d+\.) ", line):
            flush()
            cur.append(line)
        else:
            cur.append(line)
    flush()
    out = []
    for i, (prose, fenced) in enumerate(paras):
        if prose or not fenced:
            out.append((prose, []))
            continue
        before = paras[i - 1][0] if i > 0 else ""
        after = paras[i + 1][0] if i + 1 < len(paras) else ""
        out.append((before + " " + after, fenced))
    return out


def _program(cmd: str) -> str:
    return " ".join(current_names(cmd).split()[:3])


def _recorded(path: Path) -> tuple[str, bool] | None:
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    cmd = rec.get("command") if isinstance(rec, dict) else None
    if not isinstance(cmd, str) or not cmd.strip():
        return None
    if cmd.strip().lower().startswith("unknown"):
        m = _WRITTEN_BY.search(cmd)
        return (m.group(1), False) if m and _CMD.match(m.group(1)) else None
    return cmd, True


def _results(md: Path, prose: str, root: Path) -> list[str]:
    out = []
    for target in _LINK.findall(prose):
        if re.match(r"[a-z]+:|#", target):
            continue
        path = (md.parent / target.split("#")[0]).resolve()
        if path.is_relative_to(root.resolve()) and path.suffix == ".json" and path.exists():
            rel = path.relative_to(root.resolve()).as_posix()
            if is_result(rel):
                out.append(rel)
    for name in _CODE.findall(prose):
        if name.endswith(".json") and "/" not in name:
            hits = list(RESULTS.rglob(name))
            if len(hits) == 1:
                out.append(hits[0].relative_to(ROOT).as_posix())
    return list(dict.fromkeys(out))


def pairs(root: Path = ROOT) -> list[Pair]:
    """Every docs command with the result files of its block that recorded its program."""
    out = []
    for md in doc_pages(root):
        page = md.relative_to(root).as_posix()
        for prose, fenced in blocks(md.read_text()):
            inline = [c for c in _CODE.findall(prose) if _CMD.match(c)] if not fenced else []
            cmds = [c for c in [*inline, *fenced] if _CMD.match(c)]
            if not cmds:
                continue
            recs = [(res, r) for res in _results(md, prose, root) if (r := _recorded(root / res))]
            for cmd in dict.fromkeys(cmds):
                same = [(res, r) for res, r in recs if _program(cmd) == _program(r[0])]
                if same:
                    out.append(
                        Pair(
                            page,
                            cmd,
                            tuple(res for res, _ in same),
                            tuple(r[0] for _, r in same),
                            tuple(r[1] for _, r in same),
                        )
                    )
    return out


def normal(cmd: str) -> list[str]:
    """``cmd``'s words under the current module names, a trailing ``--note`` and its text
    dropped (a remark stored in the result, not a setting), numbers as floats."""
    text = current_names(cmd)
    text = re.split(r"\s--note\b", text)[0]
    try:
        words = shlex.split(text)
    except ValueError:
        words = text.split()
    out = []
    for w in words:
        try:
            out.append(repr(float(w)))
        except ValueError:
            out.append(w)
    return out


def problem(pair: Pair) -> str | None:
    """What is wrong with ``pair`` under the rule: None when the command is the recorded
    command of one of its results (or, where no result recorded its command, when it runs
    the program they name)."""
    exact = [rec for rec, ex in zip(pair.recorded, pair.exact, strict=True) if ex]
    if not exact or any(normal(pair.command) == normal(rec) for rec in exact):
        return None
    recorded = "; ".join(
        f"{res}: `{current_names(rec)}`"
        for res, rec in zip(pair.results, pair.recorded, strict=True)
    )
    return f"{pair.page}: `{pair.command}` is not the command its results recorded ({recorded})"


def problems(root: Path = ROOT) -> list[str]:
    return [p for pair in pairs(root) if (p := problem(pair))]
