"""Reproduce commands in the docs are the commands the results recorded (issue 52): every
command of docs/research/*.md and docs/guide/*.md given beside a committed result that ran the
same program is that result file's recorded ``command`` (:mod:`benchmarks.command_rule`).
Nothing is run: the check reads the result files' records.
"""

from __future__ import annotations

import json

import pytest

from benchmarks import command_rule
from benchmarks.command_rule import Pair, blocks, normal, problem

PAIRS = command_rule.pairs()


def test_the_docs_give_commands_beside_results_that_recorded_theirs():
    checked = [p for p in PAIRS if any(p.exact)]
    pages = {p.page for p in checked}
    assert len(checked) >= 15, checked
    assert {"docs/research/time_to_success.md", "docs/research/generalisation.md"} <= pages


@pytest.mark.parametrize("pair", PAIRS, ids=lambda p: f"{p.page}:{p.command[:60]}")
def test_a_docs_command_is_the_one_its_result_recorded(pair):
    assert problem(pair) is None, problem(pair)


def test_normal_form_maps_old_module_paths_drops_the_note_and_reads_numbers():
    assert normal("python -m benchmarks.time_to_success --budget-s 600.0 --note a b") == normal(
        "python -m benchmarks.baselines.time_to_success --budget-s 600"
    )
    assert normal("python -m benchmarks.perf.cost --speed") != normal(
        "python -m benchmarks.perf.cost"
    )


def test_a_fenced_block_joins_continued_lines_and_takes_its_neighbouring_prose():
    text = (
        "Run it:\n\n```bash\npeghole train --env RectExtract \\\n    --out runs/x\n```\n\n"
        "Result: [r](r.json).\n"
    )
    fenced = [b for b in blocks(text) if b[1]]
    assert fenced == [
        ("Run it: Result: [r](r.json).", ["peghole train --env RectExtract --out runs/x"])
    ]


def test_a_wrong_command_is_reported_and_a_program_only_record_is_not_held_to_flags():
    wrong = Pair(
        "p.md",
        "peghole evaluate rect --episodes 32",
        ("r.json",),
        ("peghole evaluate rect --episodes 16",),
        (True,),
    )
    assert "not the command" in problem(wrong)
    named = Pair(
        "p.md",
        "peghole evaluate rect --episodes 32",
        ("r.json",),
        ("peghole evaluate rect",),
        (False,),
    )
    assert problem(named) is None
    either = Pair(
        "p.md",
        "peghole evaluate rect --episodes 16",
        ("a.json", "b.json"),
        ("peghole evaluate rect --episodes 32", "peghole evaluate rect --episodes 16"),
        (True, True),
    )
    assert problem(either) is None


def test_the_rule_reads_a_page_and_its_results(tmp_path):
    root = tmp_path
    (root / "docs" / "research").mkdir(parents=True)
    (root / "docs" / "guide").mkdir(parents=True)
    res = root / "benchmarks" / "results" / "evals"
    res.mkdir(parents=True)
    (res / "x.json").write_text(
        json.dumps({"command": "python -m benchmarks.evals.stuck --episodes 8"})
    )
    (root / "docs" / "research" / "x.md").write_text(
        "Command: `python -m benchmarks.evals.stuck --episodes 9`; result "
        "[x](../../benchmarks/results/evals/x.json).\n"
    )
    found = command_rule.pairs(root)
    assert [(p.page, p.results) for p in found] == [
        ("docs/research/x.md", ("benchmarks/results/evals/x.json",))
    ]
    assert "not the command" in problem(found[0])
