"""Product pages, configs and docstrings read as a product, not a log (issue 52): no word of how
the work was organised, no dated change history in the training profiles' descriptions or in
the package's docstrings and comments. Dated entries belong to the research record
(docs/research/*.md).
"""

from __future__ import annotations

import ast
import io
import json
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: where the acceptance greps, and the text files it reads there
SCANNED = ("README.md", "docs", "train", "peghole_mjx", "benchmarks")
TEXT_SUFFIXES = {".md", ".py", ".json", ".txt", ".csv", ".toml", ".sh", ".yml", ".yaml"}
#: words of a log, not of a product or a research record
LOG_WORDS = re.compile(
    r"this session|\bsessions?\b|last cuts|cuts of that day|the day's cuts|development process",
    re.I,
)
DATE = r"\d{4}-\d{2}-\d{2}"
#: a dated change history: what something was until or since a date
HISTORY = re.compile(rf"\b(until|since)\s+(the\s+)?{DATE}|\b(formerly|previously)\b", re.I)


def text_files() -> list[Path]:
    out = []
    for name in SCANNED:
        path = ROOT / name
        files = [path] if path.is_file() else sorted(path.rglob("*"))
        out += [p for p in files if p.is_file() and p.suffix in TEXT_SUFFIXES]
    return out


def test_no_log_words_in_product_files_or_the_record():
    hits = []
    for path in text_files():
        for i, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if LOG_WORDS.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:100]}")
    assert not hits, "\n".join(hits)


def _strings(obj, where=""):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _strings(v, f"{where}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _strings(v, f"{where}[{i}]")
    elif isinstance(obj, str):
        yield where, obj


CONFIGS = sorted((ROOT / "train" / "configs").glob("*.json"))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_a_training_profile_states_its_settings_without_dates(path):
    cfg = json.loads(path.read_text())
    dated = [f"{k}: {s[:80]}" for k, s in _strings(cfg) if re.search(DATE, s) or HISTORY.search(s)]
    assert not dated, f"{path.name}: dates belong in docs/research/train_profiles.md: {dated}"
    assert "docs/research/" in cfg["description"], f"{path.name}: no link to the research page"


def comments_and_docstrings(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring of the Python file ``path``."""
    src = path.read_text()
    out = [
        (tok.start[0], tok.string)
        for tok in tokenize.generate_tokens(io.StringIO(src).readline)
        if tok.type == tokenize.COMMENT
    ]
    for node in ast.walk(ast.parse(src)):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            value = body[0].value
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                out.append((value.lineno, value.value))
    return out


SOURCES = sorted((ROOT / "peghole_mjx").rglob("*.py")) + sorted((ROOT / "train").glob("*.py"))


def test_no_dated_change_history_in_docstrings_or_comments():
    hits = []
    for path in SOURCES:
        for line, text in comments_and_docstrings(path):
            for m in HISTORY.finditer(text):
                hits.append(f"{path.relative_to(ROOT)}:{line}: ...{m.group(0)}...")
    assert not hits, "state the current setting and link its dated record:\n" + "\n".join(hits)


def test_the_checks_see_a_history_and_log_words():
    assert HISTORY.search("the outcome reward since 2026-12-04")
    assert HISTORY.search("a field until 2026-12-02")
    assert not HISTORY.search("a folder written before 2026-12-04 has no manifest")
    assert LOG_WORDS.search("after the cuts of that day")
    tree = comments_and_docstrings(Path(__file__))
    assert any("read as a product" in text for _, text in tree)
