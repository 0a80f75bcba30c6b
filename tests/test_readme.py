"""The README and docs: generated result tables up to date, the quick start's two commands,
every CLI command documented, every relative link resolving."""

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_readme_tables_match_committed_results():
    res = subprocess.run(
        [sys.executable, "-m", "benchmarks.readme_tables", "--check"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_ci_runs_the_readme_test_command_verbatim():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    block = readme.split("```bash", 1)[1].split("```", 1)[0].strip().splitlines()
    assert len(block) == 2, "the quick start has exactly two commands"
    test_cmd = next(line for line in block if "pytest" in line)
    assert test_cmd in ci.splitlines()


def test_quick_start_main_job_is_the_demo():
    readme = (ROOT / "README.md").read_text()
    block = readme.split("```bash", 1)[1].split("```", 1)[0].strip().splitlines()
    main_cmd = next(line for line in block if "pytest" not in line)
    assert main_cmd.endswith("peghole demo")


def test_every_cli_command_is_documented_in_the_readme():
    from peghole_mjx.cli import build_parser

    readme = (ROOT / "README.md").read_text()
    sub = next(a for a in build_parser()._actions if a.dest == "group")
    for name in sub.choices:
        assert f"`peghole {name}" in readme, name


def test_relative_links_of_the_readme_and_docs_resolve():
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    missing = []
    for md in files:
        for target in re.findall(r"\]\(([^)\s]+)\)", md.read_text()):
            if re.match(r"[a-z]+:|#", target):
                continue
            if not (md.parent / target.split("#")[0]).exists():
                missing.append(f"{md.relative_to(ROOT)}: {target}")
    assert not missing, missing


def test_help_texts_show_no_doubled_percent_sign():
    """argparse %-formats ``help=`` strings, not ``description=``: a "%%" there shows as is."""
    from peghole_mjx.cli import build_parser

    def walk(parser):
        yield parser
        for action in parser._actions:
            for sub in getattr(action, "choices", None) or {}:
                if isinstance(action.choices, dict):
                    yield from walk(action.choices[sub])

    shown = [p.prog for p in walk(build_parser()) if "%%" in p.format_help()]
    assert not shown, shown
