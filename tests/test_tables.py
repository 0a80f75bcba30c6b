"""The docs-table registry (benchmarks/tables.py): every registered table regenerated between
its markers wherever they are, and ``--check`` failing on a stale table, a table with no
marker, a marker with no generator and a marker that appears twice."""

import json
import math
import shutil
from pathlib import Path

import pytest

from benchmarks import common, tables
from benchmarks.evals import brief, learning
from peghole_mjx.training.config import load_train_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def registry():
    return tables.load_tables()


@pytest.fixture(scope="module")
def generated(registry):
    """Each registered table's text as the docs hold it (before the relinking)."""
    return {name: tables.current_names(fn()) for name, fn in registry.items()}


def block(name: str, body: str) -> str:
    return f"<!-- table:{name} -->\n{body}\n<!-- /table:{name} -->\n"


@pytest.fixture
def docs(tmp_path, registry, generated):
    """A docs tree holding every registered table once, up to date: half of them in README.md,
    the rest in docs/guide/tables.md (two folders down: its links are relinked)."""
    names = sorted(registry)
    readme, nested = names[::2], names[1::2]
    (tmp_path / "README.md").write_text(
        "# Test\n\n" + "\n".join(block(n, generated[n]) for n in readme)
    )
    guide = tmp_path / "docs" / "guide"
    guide.mkdir(parents=True)
    body = "\n".join(block(n, tables.relink(generated[n], "docs/guide/tables.md")) for n in nested)
    (guide / "tables.md").write_text("# Tables\n\n" + body)
    return tmp_path


def check(root: Path, capsys) -> tuple[int, str]:
    rc = tables.main(["--check", "--root", str(root)])
    return rc, capsys.readouterr().err


# the committed tree passing --check: test_readme.py (test_docs_tables_match_committed_results)


def test_an_up_to_date_tree_passes_and_a_stale_table_is_named_then_rewritten(docs, capsys):
    assert check(docs, capsys) == (0, "")
    guide = docs / "docs" / "guide" / "tables.md"
    text = guide.read_text()
    start = text.index("<!-- table:") + len("<!-- table:")
    name = text[start : text.index(" -->", start)]
    body_at = text.index("-->\n", start) + len("-->\n")
    guide.write_text(text[:body_at] + "| an edited row |\n" + text[body_at:])
    rc, err = check(docs, capsys)
    assert rc == 1 and f"table {name}: out of date in docs/guide/tables.md" in err
    assert "| an edited row |" in guide.read_text()  # --check writes nothing
    assert tables.main(["--root", str(docs)]) == 0  # the rewrite restores it
    assert guide.read_text() == text
    assert check(docs, capsys) == (0, "")


def test_a_registered_table_without_a_marker_fails_the_check(docs, capsys, registry):
    readme = docs / "README.md"
    text = readme.read_text()
    name = sorted(registry)[0]  # the first of README.md's tables
    start, end = text.index(f"<!-- table:{name} -->"), text.index(f"<!-- /table:{name} -->")
    readme.write_text(text[:start] + text[end + len(f"<!-- /table:{name} -->") :])
    rc, err = check(docs, capsys)
    assert rc == 1
    assert f"table {name}: registered" in err and "no <!-- table:" in err


def test_a_duplicate_marker_and_a_marker_without_a_generator_fail_the_check(
    docs, capsys, generated
):
    extra = docs / "docs" / "research" / "page.md"
    extra.parent.mkdir()
    extra.write_text(block("throughput", generated["throughput"]) + block("no_such_table", "x"))
    rc, err = check(docs, capsys)
    assert rc == 1
    assert "table throughput: marker appears 2 times (" in err and "docs/research/page.md" in err
    assert "table no_such_table: marker in docs/research/page.md, but no generator" in err


def test_an_unclosed_marker_fails_the_check(docs, capsys):
    readme = docs / "README.md"
    text = readme.read_text()
    readme.write_text(text.replace("<!-- /table:", "<!-- /tabel:", 1))
    rc, err = check(docs, capsys)
    assert rc == 1 and "marker not closed" in err


def test_a_copy_of_a_real_docs_file_is_regenerated_in_place(tmp_path, capsys):
    """A temporary copy of README.md (never the real one): its tables are rewritten from the
    registry, and the copy then passes the check of its own markers."""
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    tables.main(["--root", str(tmp_path)])  # other tables may have no marker in this tree
    capsys.readouterr()
    text = (tmp_path / "README.md").read_text()
    found = tables.scan(tmp_path)
    assert found.where, "README.md holds table markers"
    registry = tables.load_tables()
    names = {n: registry[n] for n in found.where if n in registry}
    assert tables.render(text, "README.md", names) == text


def test_links_are_relinked_and_old_names_resolved():
    table = "[`a`](benchmarks/results/perf/roofline.json) [web](https://x.org/a) [up](#anchor)"
    assert tables.relink(table, "README.md") == table
    got = tables.relink(table, "docs/guide/page.md")
    assert "](../../benchmarks/results/perf/roofline.json)" in got
    assert "](https://x.org/a)" in got and "](#anchor)" in got
    old = (
        "`python -m benchmarks.seed_stack --env X` (benchmarks/seed_stack.py), "
        "benchmarks/results/roofline.json, benchmarks/results/dual_cpu-2core/paired256.json, "
        "benchmarks/results/no_such_file.json, python -m benchmarks.perf.throughput"
    )
    assert tables.current_names(old) == (
        "`python -m benchmarks.baselines.seed_stack --env X` "
        "(benchmarks/baselines/seed_stack.py), benchmarks/results/perf/roofline.json, "
        "benchmarks/results/evals/dual_cpu-2core/paired256.json, "
        "benchmarks/results/no_such_file.json, python -m benchmarks.perf.throughput"
    )


def test_a_name_registered_by_two_functions_is_refused(registry):
    def throughput() -> str:
        return "another generator"

    with pytest.raises(ValueError, match="registered twice"):
        common.table("throughput")(throughput)
    assert common.TABLES["throughput"] is registry["throughput"]


def test_results_brief_rows_read_committed_files(generated):
    """At most 15 rows of six cells; every row's verdict is one of the four (or says it is no
    thesis claim) and links its research page; every row's result files exist; the thesis's
    numbers in the code's table are those the committed evaluation records (rect_extract)."""
    lines = generated["results_brief"].splitlines()
    assert lines[0] == "| claim | thesis | ours | interval | verdict | result file |"
    rows = lines[2:]
    assert 0 < len(rows) <= brief.MAX_ROWS
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        assert len(cells) == 6, row
        assert "pending" not in cells[2], row
        if cells[4] != brief.NO_CLAIM:
            text, page = cells[4].removeprefix("[").removesuffix(")").split("](")
            assert (ROOT / page).exists(), page
            for part in text.split("; "):
                assert part.split(": ", 1)[-1].split(" (")[0] in brief.VERDICTS, row
        for target in (t.split(")")[0] for t in cells[5].split("](")[1:]):
            assert (ROOT / target).exists(), target
    ev = json.loads((ROOT / "peghole_mjx/policies/rect_extract/evaluation.json").read_text())
    th = ev["thesis"]
    assert brief.THESIS["R3"][1] == f"{th['force_reduction_pct']} % lower"
    assert brief.THESIS["R4"][1] == f"{th['success_rate'] * 100:g} %, {th['mean_time_s']} s"
    assert brief.THESIS["R5"][1] == (
        f"<= {th['peak_fz_N_policy']:g} N vs > {th['peak_fz_N_baseline']:g} N"
    )


def test_settings_diff_names_every_setting_that_differs():
    a = {"lr": 3e-4, "env_overrides": {"engine": "mjx", "x": 1}, "seed": 0}
    b = {"lr": 1e-4, "env_overrides": {"engine": "mujoco"}, "seed": 0, "new": True}
    diffs = common.settings_diff(a, b)
    assert diffs == [
        ("lr", 3e-4, 1e-4),
        ("env_overrides.engine", "mjx", "mujoco"),
        ("env_overrides.x", 1, None),
        ("new", None, True),
    ]
    assert common.fmt_settings_diff(diffs) == (
        "lr 0.0003 vs 0.0001; env_overrides.engine mjx vs mujoco; env_overrides.x 1 vs unset; "
        "new unset vs True"
    )
    assert common.settings_diff(a, b, ignore=("env_overrides.", "new")) == [("lr", 3e-4, 1e-4)]
    assert common.fmt_settings_diff(common.settings_diff(a, a)) == "nothing"


def test_clock_to_95_counts_a_seed_that_never_reached_it_as_late():
    """A median over the seeds that reached 95 % alone would flatter a stack."""
    late = [{"clock_to_95_s": v} for v in (1.0, 2.0, None, None, None)]
    med, q1, q3 = learning.censored_median_iqr(late, "clock_to_95_s")
    assert math.isinf(med) and q1 == 2.0 and math.isinf(q3)
    mixed = [{"clock_to_95_s": v} for v in (5.0, 1.0, None, 3.0, 2.0)]
    assert learning.censored_median_iqr(mixed, "clock_to_95_s") == (3.0, 2.0, 5.0)


def _stack_entry(task, engine, reward, residual, budget, updates, clocks, untrained=0):
    return {
        "task": task,
        "seeds": list(range(len(clocks))),
        "per_seed": [{"clock_to_95_s": c} for c in clocks],
        "reached_95": sum(c is not None for c in clocks),
        "at_95_untrained": untrained,
        "config": {"num_timesteps": budget, "env_overrides": {"action.residual": residual}},
        "engine": engine,
        "reward_kind": reward,
        "updates_per_env_step": updates,
        "final_success_iqm": 0.9,
        "final_success_ci95": [0.8, 1.0],
        "share_at_95": 0.4,
    }


def test_the_readme_learning_rows_come_from_the_stacks_files_and_name_what_differs(
    tmp_path, monkeypatch
):
    files = {s: tmp_path / f"learning_{s}.json" for s in ("ours", "seed", "sb3")}
    monkeypatch.setattr(brief, "STACK_FILES", files)
    ours_file = tmp_path / "taskq" / "learning.json"
    monkeypatch.setattr(brief, "published_protocol_file", lambda: ours_file)
    rows = brief._time_rows()
    assert all("| pending |" in r for r in rows)  # no stack file: nothing compared
    ours_file.parent.mkdir()
    ours = _stack_entry("RectExtract", "mujoco", "outcome", True, 32_000, 1.0, [1.0] * 5, 5)
    seed = _stack_entry("RectExtract", "pybullet", "thesis", None, 32_000, 0.02,
                        [10.0, 20.0, 30.0, None, 40.0])  # fmt: skip
    ours_file.write_text(json.dumps({"tasks": [ours]}))
    files["ours"].write_text(json.dumps({"tasks": [ours | {"seeds": [9] * 5}]}))  # not read
    files["seed"].write_text(json.dumps({"tasks": [seed]}))
    time_row, hard_row = brief._time_rows()
    assert "ours 1 s (5 of 5 at 95 % untrained)" in time_row
    assert "seed stack 30 s (4 of 5 reached)" in time_row
    assert "ours / seed stack 0.033" in time_row
    assert "seed stack: pybullet, thesis, plain, 32k steps, 0.02 updates/step" in time_row
    assert "ours: mujoco, outcome, residual, 32k steps, 1 updates/step" in time_row
    assert "IQR ours [1, 1] s; seed stack [20, 40] s" in time_row
    assert "not run: SB3 SAC" in time_row
    assert "learning_ours.json" not in time_row  # ours is read from the published protocol's
    assert "| pending |" in hard_row  # neither file has RectExtractHard
    # a --finished-only report of ours: its finished task is an entry, its unfinished one named
    partial = ours_file.with_name("learning_partial.json")
    ours_file.unlink()
    pending = [{"task": "RectExtractHard", "seed": 404}]
    hard = _stack_entry("RectExtractHard", "mujoco", "outcome", True, 32_000, 1.0, [None] * 5)
    hard["config"] |= {"lr_schedule": "constant"}
    partial.write_text(json.dumps({"tasks": [ours, hard | {"seeds": [400]}], "pending": pending}))
    assert "| pending |" in brief._time_rows()[1]  # no other stack: nothing compared
    files["sb3"].write_text(json.dumps({"tasks": [hard]}))
    assert "| pending |" in brief._time_rows()[1]  # ours unfinished: nothing compared
    partial.write_text(json.dumps({"tasks": [ours, hard], "pending": []}))
    hard_row = brief._time_rows()[1]
    assert "IQM ours 0.90 (2 of 5 >= 0.95), SB3 SAC 0.90 (2 of 5 >= 0.95)" in hard_row
    assert "not run: seed stack" in hard_row
    # every entry on the same engine, reward and actions: said once
    assert "all: mujoco, outcome, residual; ours: 32k steps, 1 updates/step; " in hard_row
    # our learner's settings that differ from the task's cpu profile are named (here the
    # record's lr_schedule against the profile's default)
    assert "; ours vs RectExtractHard's cpu profile: " in hard_row
    assert "lr_schedule constant vs linear" in hard_row
    assert "learning_partial.json" in hard_row
    partial.write_text(json.dumps({"tasks": [ours, hard], "pending": pending}))
    assert "| pending |" in brief._time_rows()[1]
    # a time-out made a terminal failure is a setting that differs between the stacks: named
    hard["config"]["env_overrides"]["reward_config.time_limit"] = "failure"
    partial.write_text(json.dumps({"tasks": [ours, hard], "pending": []}))
    hard_row = brief._time_rows()[1]
    assert "ours: mujoco, outcome, residual, time-out a failure, 32k steps" in hard_row
    assert "SB3 SAC: mujoco, outcome, residual, 32k steps" in hard_row
    # our learner exactly the task's cpu profile: said so, no empty comparison
    hard["config"] = load_train_config("RectExtractHard", "cpu").as_dict()
    partial.write_text(json.dumps({"tasks": [ours, hard], "pending": []}))
    hard_row = brief._time_rows()[1]
    assert "; ours: RectExtractHard's cpu profile" in hard_row
    assert "cpu profile: " not in hard_row


def test_the_readme_reads_ours_from_the_protocol_the_published_policies_name(tmp_path, monkeypatch):
    # the committed policies: one protocol, whose report sits beside it
    path = brief.published_protocol_file()
    assert path.name == "learning.json" and (path.parent / "protocol.md").is_file()
    # policies published under two protocols (or none) are refused, naming each policy's
    policies = {}
    for name, protocol in (("rect", "a/protocol.md"), ("dual", "b/protocol.md")):
        (tmp_path / name).mkdir()
        meta = {"selection": {"protocol": protocol}}
        (tmp_path / name / "policy.json").write_text(json.dumps(meta))
        policies[name] = tmp_path / name
    monkeypatch.setattr(brief, "PRETRAINED", policies)
    with pytest.raises(ValueError, match="'rect': 'a/protocol.md', 'dual': 'b/protocol.md'"):
        brief.published_protocol_file()
    (tmp_path / "dual" / "policy.json").write_text(json.dumps({"selection": {}}))
    with pytest.raises(ValueError, match="'dual': None"):
        brief.published_protocol_file()
    (tmp_path / "dual" / "policy.json").write_text(
        json.dumps({"selection": {"protocol": "a/protocol.md"}})
    )
    assert brief.published_protocol_file() == common.ROOT / "a" / "learning.json"


def test_a_study_of_two_collapsed_learners_is_not_a_readme_row():
    path = common.EVALS_RESULTS / "rl_vs_rlcs_dual_hard_seeds_cpu-2core.json"
    assert brief.collapsed(json.loads(path.read_text()))
    assert path not in brief.latest_per_env()
    assert brief.latest_per_env()  # the other envs' studies are rows
