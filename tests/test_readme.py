"""The README and docs: generated result tables up to date, the quick start's two commands and
the CI script that runs them, every CLI command documented, every relative link resolving."""

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_docs_tables_match_committed_results():
    res = subprocess.run(
        [sys.executable, "-m", "benchmarks.tables", "--check"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def _ci_commands() -> list[str]:
    """The commands of .ci/run (comments, blank lines and shell setup left out)."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    skip = ("#", "set ", "cd ", "export ", "echo ")
    return [line.strip() for line in lines if line.strip() and not line.strip().startswith(skip)]


def test_ci_runs_the_readme_test_command_verbatim():
    readme = (ROOT / "README.md").read_text()
    block = readme.split("```bash", 1)[1].split("```", 1)[0].strip().splitlines()
    assert len(block) == 2, "the quick start has exactly two commands"
    test_cmd = next(line for line in block if "pytest" in line)
    commands = _ci_commands()
    assert test_cmd in commands
    # nothing is installed before it: the README's command alone sets up a fresh machine
    before = commands[: commands.index(test_cmd)]
    assert not [c for c in before if "pip" in c and "install" in c], before


def test_ci_runs_the_optional_playground_suite_after_the_readme_command_as_the_readme_says():
    readme = (ROOT / "README.md").read_text()
    commands = _ci_commands()
    readme_cmd = next(c for c in commands if "python3 -m pytest -q -n 2" in c)
    after = commands[commands.index(readme_cmd) + 1 :]
    install = '--no-deps "playground>=0.2.0" "lxml>=5"'
    assert any(install in c for c in after), after
    assert "python3 -m pytest -q tests/test_playground.py" in after
    assert f"pip install {install}" in readme and "tests/test_playground.py" in readme


def test_quick_start_main_job_is_the_demo():
    readme = (ROOT / "README.md").read_text()
    block = readme.split("```bash", 1)[1].split("```", 1)[0].strip().splitlines()
    main_cmd = next(line for line in block if "pytest" not in line)
    assert main_cmd.endswith("peghole demo")


def test_every_cli_command_is_documented_in_the_readme():
    from peghole_mjx.cli.main import build_parser

    readme = (ROOT / "README.md").read_text()
    sub = next(a for a in build_parser()._actions if a.dest == "group")
    for name in sub.choices:
        assert f"`peghole {name}" in readme, name


def test_relative_links_of_the_readme_and_docs_resolve():
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
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
    from peghole_mjx.cli.main import build_parser

    def walk(parser):
        yield parser
        for action in parser._actions:
            for sub in getattr(action, "choices", None) or {}:
                if isinstance(action.choices, dict):
                    yield from walk(action.choices[sub])

    shown = [p.prog for p in walk(build_parser()) if "%%" in p.format_help()]
    assert not shown, shown
