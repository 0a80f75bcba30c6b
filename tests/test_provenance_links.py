"""Provenance is a rule (issue 52, decided 2026-12-04): every result file that README.md or a
docs page links records its device, versions, date, command, config and commit.

The rule and its formats are in :mod:`benchmarks.provenance_rule` (JSON: top-level keys; CSV:
the same-stem JSON record beside it; an unrecoverable field is ``"unknown: REASON"``).
"""

from __future__ import annotations

import json

import pytest

from benchmarks.common import ROOT
from benchmarks.provenance_backfill import append_keys
from benchmarks.provenance_rule import REQUIRED, field_problem, linked_results, problems

LINKED = linked_results(ROOT)


def test_the_docs_link_result_files():
    assert any(p.startswith("benchmarks/results/") for p in LINKED)
    assert "peghole_mjx/policies/rect_extract/evaluation.json" in LINKED


@pytest.mark.parametrize("rel_path", sorted(LINKED))
def test_every_linked_result_file_records_its_provenance(rel_path):
    bad = problems(ROOT / rel_path)
    assert not bad, f"{rel_path} (linked from {', '.join(LINKED[rel_path])}): {bad}"


def test_the_rule_refuses_a_missing_key_an_empty_value_and_an_unknown_without_reason():
    full = {k: "x" for k in REQUIRED}
    assert all(field_problem(full, k) is None for k in REQUIRED)
    assert field_problem({}, "device") == "no 'device'"
    assert "empty" in field_problem({"versions": {}}, "versions")
    assert "without a reason" in field_problem({"commit": "unknown"}, "commit")
    assert "without a reason" in field_problem({"commit": "unknown:  "}, "commit")
    assert field_problem({"commit": "unknown: not recorded by the run"}, "commit") is None


def test_a_config_pointer_must_name_keys_the_record_has():
    rec = {"settings": {"a": 1}, "seed": 0}
    assert field_problem({**rec, "config": "see settings, seed; a remark"}, "config") is None
    assert "lacks" in field_problem({**rec, "config": "see settings, env"}, "config")


def test_a_csv_is_checked_through_its_same_stem_record(tmp_path):
    csv = tmp_path / "rows.csv"
    csv.write_text("a,b\n1,2\n")
    assert problems(csv) == ["rows.csv: no record rows.json beside it"]
    (tmp_path / "rows.json").write_text(json.dumps({k: "x" for k in REQUIRED[:-1]}))
    assert problems(csv) == ["rows.json: no 'commit'"]


def test_a_list_of_results_is_checked_entry_by_entry(tmp_path):
    path = tmp_path / "two.json"
    full = {k: "x" for k in REQUIRED}
    path.write_text(json.dumps([full, full]))
    assert problems(path) == []
    path.write_text(json.dumps([full, {k: "x" for k in REQUIRED[:-1]}]))
    assert problems(path) == ["two.json[1]: no 'commit'"]
    for bad in ([], [1, 2], "text"):
        path.write_text(json.dumps(bad))
        assert problems(path) == ["two.json: not a JSON object or a list of them"]


def test_backfill_appends_keys_without_touching_what_is_there():
    text = '{\n  "x": 1.0000000000000002,\n  "y": [1e-05, NaN]\n}\n'
    out = append_keys(text, {"commit": "unknown: not recorded"})
    assert out.startswith('{\n  "x": 1.0000000000000002,\n  "y": [1e-05, NaN],\n')
    assert json.loads(out)["commit"] == "unknown: not recorded"
    assert append_keys('{"a": 1}', {"b": 2}) == '{"a": 1, "b": 2}\n'
