"""Suite, CI and demo times in one place (issue 52): the committed record
``benchmarks/results/perf/suite_time_cpu-2core.json`` (:mod:`benchmarks.perf.suite_time`)
carries every measured figure with its provenance; the block in docs/guide/development.md is
generated from it; every other page states such a time only as the record's texts write it.
"""

from __future__ import annotations

import json
import re
import sys

import pytest

from benchmarks import tables
from benchmarks.common import ROOT
from benchmarks.perf import suite_time
from benchmarks.provenance_rule import REQUIRED, field_problem, problems

REC = suite_time.load()

#: a duration as the docs write one
DURATION = r"(?:about |~)?\d+(?:[.,]\d+)?(?:-\d+)? (?:min(?: \d+ s)?|s\b|h\b|hours?|minutes)"
#: what a suite, CI or demo time is said of
SUBJECT = r"(?:\bsuite\b|\bdemo\b|\bCI\b|pytest -q -n 2|\.ci/run)"
_NEAR = r"(?:[^.;]|\.(?!\s))"  # within one sentence
NEAR_TIME = re.compile(
    rf"{SUBJECT}{_NEAR}{{0,80}}?({DURATION})|({DURATION}){_NEAR}{{0,40}}?{SUBJECT}"
)
#: a wall clock written in minutes and seconds (the demo's form)
MIN_SEC = re.compile(r"\b\d+ min \d{2} s\b")
#: durations near those words that are not the suite's, CI's or the demo's time, each with why
NOT_A_TOTAL = {
    ("docs/guide/development.md", "161 s"): "one test's share of the suite",
}
GENERATED = re.compile(r"<!-- table:suite_time -->.*?<!-- /table:suite_time -->", re.S)


def pages():
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def allowed() -> set[str]:
    """Every string a page may state: the record's texts and each measurement's wall clock."""
    out = set(suite_time.texts(REC).values())
    for m in REC["measurements"]:
        out |= {suite_time.minutes(m["wall_s"]), suite_time.seconds(m["wall_s"])}
    return out


def test_the_record_carries_its_provenance_and_each_measurement_its_own():
    assert problems(suite_time.RESULT) == []
    assert REC["measurements"], "no measurement"
    for m in REC["measurements"]:
        assert m["kind"] in suite_time.KINDS
        assert m["wall_s"] > 0 and m["source"] and m["label"]
        bad = [p for k in REQUIRED if (p := field_problem(m, k))]
        assert not bad, f"{m['label']} ({m['date']}): {bad}"


def test_the_recorded_figures_are_the_record_unchanged():
    n = len(suite_time.RECORDED)
    assert REC["measurements"][:n] == json.loads(json.dumps(suite_time.RECORDED))


def test_the_texts_are_computed_from_the_measurements():
    fake = {
        "measurements": [
            {"kind": "suite", "wall_s": 1572, "date": "2026-12-03"},
            {"kind": "suite", "wall_s": 2160, "date": "2026-12-04"},
            {"kind": "suite_loaded", "wall_s": 9000, "date": "2026-12-05"},
            {"kind": "ci", "wall_s": 1309, "date": "2026-12-03"},
            {"kind": "ci", "wall_s": 2201, "date": "2026-12-05"},
            {"kind": "demo", "wall_s": 548, "date": "2026-12-02T21:51Z"},
        ]
    }
    t = suite_time.texts(fake)
    assert t["suite"] == "26-36 min"  # the loaded run is left out of the range
    assert t["suite_date"] == "2026-12-03 to 2026-12-04"
    assert (t["ci_latest"], t["ci_latest_date"], t["ci_earlier"]) == (
        "2,201 s",
        "2026-12-05",
        "1,309 s",
    )
    assert (t["demo"], t["demo_date"]) == ("9 min 08 s", "2026-12-02")


def test_the_development_page_block_is_generated_from_the_record():
    md = ROOT / "docs" / "guide" / "development.md"
    text = md.read_text()
    assert GENERATED.search(text), "development.md lost its suite_time block"
    rendered = tables.render(
        text, "docs/guide/development.md", {"suite_time": suite_time.suite_time_table}
    )
    assert rendered == text, "stale: run python -m benchmarks.tables"


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_a_page_states_a_suite_ci_or_demo_time_only_as_recorded(page):
    rel = page.relative_to(ROOT).as_posix()
    text = re.sub(r"\s*\n\s*", " ", GENERATED.sub("", page.read_text()))
    ok = allowed()
    found = [m.group(1) or m.group(2) for m in NEAR_TIME.finditer(text)]
    found += MIN_SEC.findall(text)
    stray = sorted({d for d in found if d not in ok and (rel, d) not in NOT_A_TOTAL})
    assert not stray, (
        f"{rel} states {stray} as a suite, CI or demo time; state one of "
        f"{sorted(suite_time.texts(REC).values())} (benchmarks/perf/suite_time.py) or link to "
        "docs/guide/development.md#how-long-the-suite-takes"
    )


def test_the_scan_finds_a_stale_time():
    text = "The demo runs for about 10 min and the suite for 20 min; CI took 1,100 s."
    found = {m.group(1) or m.group(2) for m in NEAR_TIME.finditer(text)}
    assert found == {"about 10 min", "20 min", "1,100 s"}
    assert not found & allowed()


def test_measure_adds_a_timed_run_and_keeps_the_recorded_ones(tmp_path):
    out = tmp_path / "times.json"
    cmd = [sys.executable, "-c", "pass"]
    assert suite_time.main(["--out", str(out), "measure", "--label", "probe", "--", *cmd]) == 0
    rec = json.loads(out.read_text())
    assert rec["measurements"][: len(suite_time.RECORDED)] == json.loads(
        json.dumps(suite_time.RECORDED)
    )
    new = rec["measurements"][-1]
    assert (new["label"], new["command"], new["outcome"]) == (
        "probe",
        " ".join(cmd),
        "exit status 0",
    )
    assert problems(out) == [] and not [k for k in REQUIRED if field_problem(new, k)]
    # a rewrite keeps the measured run
    assert suite_time.main(["--out", str(out), "record"]) == 0
    assert json.loads(out.read_text())["measurements"][-1] == new
