"""The docs: the site builds under ``mkdocs build --strict``, README.md and every page stay within
their size limits, and the code blocks of README.md, docs/index.md and docs/guide/ run.

Code blocks are found, and their marks read, by pytest-codeblocks' own parser (0.18.0,
``pytest_codeblocks.extract_from_file``: a fenced block whose info string is ``python``, ``bash``
or ``sh``, and the ``<!--pytest.mark.skip(reason="...")-->`` line before it). Each block runs in
its own process, in a fresh temporary folder that links the repository's top-level folders, so
that a reader's commands (``python -m benchmarks...``, ``bash benchmarks/...``) work from it and
nothing is written into the checkout. A skipped block must give its reason in the mark and say
in the text before it that it is not run by the tests.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from pytest_codeblocks import extract_from_file

ROOT = Path(__file__).resolve().parents[1]
#: size limits, bytes (README within 12 KB, every docs page within 25 KB)
README_MAX_BYTES = 12_000
PAGE_MAX_BYTES = 25_000
#: the files whose code blocks run (the research record cites commands, it does not teach them)
RUN_FILES = [
    ROOT / "README.md",
    ROOT / "docs" / "index.md",
    *sorted((ROOT / "docs" / "guide").rglob("*.md")),
]
#: what the blocks may reach through the temporary folder (read only by the executed blocks)
LINKED = ("README.md", "pyproject.toml", "benchmarks", "docs", "mjcf", "train")
RUNNERS = {"python": [sys.executable], "bash": ["bash", "-euo", "pipefail"], "sh": ["sh", "-e"]}
SKIP_NOTE = "not run by the tests"
BLOCK_TIMEOUT_S = 600


def _blocks():
    for md in RUN_FILES:
        for block in extract_from_file(md):
            if block.syntax not in RUNNERS:
                continue
            marks = [eval(m, {"pytest": pytest, "sys": sys}) for m in block.marks]
            name = f"{md.relative_to(ROOT).as_posix()}:{block.lineno}"
            yield pytest.param(md, block, id=name, marks=marks)


BLOCKS = list(_blocks())


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    env["NO_MKDOCS_2_WARNING"] = "1"
    return env


@pytest.mark.parametrize(("md", "block"), BLOCKS)
def test_code_block_runs(md, block, tmp_path):
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name)
    if block.syntax == "python":
        script = tmp_path / f"block_{block.lineno}.py"
        script.write_text(block.code)
        cmd = [*RUNNERS["python"], str(script)]
    else:
        cmd = [*RUNNERS[block.syntax], "-c", block.code]
    try:
        res = subprocess.run(
            cmd,
            cwd=tmp_path,
            env=_env(),
            capture_output=True,
            text=True,
            timeout=BLOCK_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{md.name}:{block.lineno}: still running after {BLOCK_TIMEOUT_S} s")
    out = (res.stdout + res.stderr)[-4000:]
    assert res.returncode == 0, f"{md.name}:{block.lineno} exited {res.returncode}:\n{out}"
    if block.expected_output is not None:
        assert res.stdout == block.expected_output, out


def test_skipped_blocks_give_their_reason():
    """Every skipped block has a reason in its mark and says so in the text before it."""
    bad = []
    skipped = 0
    for param in BLOCKS:
        md, block = param.values
        skips = [m for m in param.marks if m.name == "skip"]
        if not skips:
            continue
        skipped += 1
        where = f"{md.relative_to(ROOT)}:{block.lineno}"
        if not all(str(m.kwargs.get("reason", "")).strip() for m in skips):
            bad.append(f"{where}: skip mark without a reason")
        before = md.read_text().splitlines()[max(0, block.lineno - 9) : block.lineno - 1]
        if SKIP_NOTE not in " ".join(" ".join(before).split()):
            bad.append(f"{where}: the text before it does not say it is {SKIP_NOTE!r}")
    assert not bad, bad
    assert skipped < len(BLOCKS) / 2, "most blocks are skipped: keep the skipped ones few"


def test_readme_and_docs_pages_stay_within_their_size():
    sizes = {ROOT / "README.md": README_MAX_BYTES}
    sizes.update({p: PAGE_MAX_BYTES for p in (ROOT / "docs").rglob("*.md")})
    over = [
        f"{p.relative_to(ROOT)}: {p.stat().st_size} > {limit} bytes"
        for p, limit in sizes.items()
        if p.stat().st_size > limit
    ]
    assert not over, over


def test_site_builds_strict(tmp_path):
    """``mkdocs build --strict``: every page in the nav, every link between pages and every
    anchor resolves (mkdocs.yml's validation settings), nothing else warns."""
    site = tmp_path / "site"
    res = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    warnings = [line for line in res.stderr.splitlines() if re.match(r"(WARNING|ERROR)", line)]
    assert res.returncode == 0, "\n".join(warnings) or res.stderr[-3000:]
    assert (site / "index.html").is_file()
    assert (site / "guide" / "getting_started" / "index.html").is_file()
    assert (site / "research" / "index.html").is_file()
