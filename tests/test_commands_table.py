"""README's command table is the ``peghole`` parser's own (benchmarks/commands.py): regenerated
in memory, it equals the table between README.md's ``<!-- table:commands -->`` markers, so a
command added, renamed or re-described in the code cannot leave the README behind.

Cheap: the parser's group modules load their commands lazily (peghole_mjx/core/lazy.py); no JAX
graph is built or compiled (the import of the package, JAX included, is the cost).
"""

import re
from pathlib import Path

from benchmarks import commands

ROOT = Path(__file__).resolve().parents[1]


def committed_table() -> str:
    readme = (ROOT / "README.md").read_text()
    found = re.search(r"<!-- table:commands -->\n(.*?)\n<!-- /table:commands -->", readme, re.S)
    assert found, "README.md has no <!-- table:commands --> ... <!-- /table:commands --> block"
    return found.group(1)


def test_readme_command_table_is_the_parsers():
    assert committed_table() == commands.commands_table(), (
        "README.md's command table is stale: run python -m benchmarks.tables"
    )


def test_every_command_has_a_row_with_its_help_line():
    table = committed_table()
    rows = list(commands.commands(commands.build_parser()))
    assert len(table.splitlines()) == len(rows) + 2  # header and rule
    usages = [u for u, _ in rows]
    for usage in ("peghole task builtin", "peghole task show", "peghole train"):
        assert any(u == usage or u.startswith(usage + " ") for u in usages), usage
        assert f"| `{usage}" in table, usage
    assert all(help_line for _, help_line in rows), "a command without a help line"


def test_usage_keeps_required_arguments_and_positionals():
    import argparse

    p = argparse.ArgumentParser()
    p.add_argument("--out", required=True)
    p.add_argument("--mode", choices=["a", "b"], required=True)
    p.add_argument("--quiet", action="store_true")
    p.add_argument("runs", nargs="+")
    p.add_argument("extra", nargs="?", metavar="X")
    assert commands.usage(["x"], p) == "peghole x --out OUT --mode {a,b} runs [runs ...] [X]"
