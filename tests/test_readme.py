"""The README's result tables are generated from committed result files and up to date."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_readme_tables_match_committed_results():
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "readme_tables.py"), "--check"],
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
