"""Add the provenance fields a result file lacks, recovered from its own records (2026-12-04).

``python -m benchmarks.provenance_backfill`` (``--check``: write nothing, list what would be
added). For every result file linked from the docs (:func:`benchmarks.provenance_rule.
linked_results`) it adds only the :data:`~benchmarks.provenance_rule.REQUIRED` keys that are
missing; it never changes or removes a key that is there, so no number changes. Where a field
comes from:

* ``commit``: git history of the file (``git log --follow``): the commit that added it and its
  date, an upper bound on the source the run used; written ``unknown: ...`` with that commit,
  because no run before 2026-12-04 recorded its own commit;
* ``date``: the date of that commit when the file recorded none (said so in the value);
* ``device``: the 2-core CPU where the file's own siblings or the research record say every run
  of that date was made on it; else ``unknown: ...``;
* ``versions``: ``unknown: ...`` where the file recorded none (they cannot be recovered);
* ``command``: the commands recorded in the file's ``runs`` (the throughput records); else
  ``unknown: ...`` naming the module or CLI command that writes such files;
* ``config``: ``see KEY, ...`` naming the file's own keys that hold its settings; else
  ``unknown: ...``.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from benchmarks.common import ROOT
from benchmarks.provenance_rule import linked_results, record_path

#: top-level keys that hold a run's settings, in the order they are named
CONFIG_KEYS = (
    "config",
    "settings",
    "env_config",
    "env_overrides",
    "overrides",
    "reference_overrides",
    "profile",
    "sac",
    "env",
    "preset",
    "geometry",
    "representation",
    "engine",
    "trained_engine",
    "policy",
    "policy_name",
    "method",
    "compliance_strategy",
    "differs_from_training",
    "mu",
    "theta0_deg",
    "cell",
    "case",
    "variants",
    "bounds",
    "jam_rule",
    "randomization",
    "fixed_compliance",
    "episode_length_s",
    "episodes",
    "episodes_per_cell",
    "batch",
    "seed",
    "worlds",
    "steps",
    "repeats",
    "hold_s",
    "budget_s",
    "success_threshold",
    "breakaway_N",
    "weld_timeconst_s",
    "clearance_mm",
    "force_cap_N",
    "torque_cap_Nm",
    "chosen_on_episodes",
    "episodes_csv",
    "evaluated_on",
)
#: keys that only look like settings in some files (the policy's rollout summary, ...)
_NOT_SETTINGS = {"policy": dict}

#: the writer of each family of result files (by a part of the file's path)
WRITERS = (
    ("policies/", "`peghole evaluate NAME --episodes N --json` (train/publish_policy.py)"),
    ("evaluation512", "`peghole evaluate rect_hard --episodes 512 --batch 64 --json` on seed 1"),
    ("paired", "`python -m benchmarks.evals.paired_reduction analyse` on `episodes_csv`"),
    ("compliance_sweep", "`peghole experiment sweep` (its settings in `settings`)"),
    ("cone_fix_check", "`peghole experiment sweep` (its settings in `settings`)"),
    ("contact_check", "`peghole experiment contact-check`"),
    ("models_check", "`peghole models check --json`"),
    ("cross_engine", "`python -m benchmarks.evals.cross_engine`"),
    ("hard_variants", "`python -m benchmarks.evals.hard_variants`"),
    ("rl_vs_rlcs", "`python -m benchmarks.evals.rl_vs_rlcs` from the two runs named in it"),
    ("trace_", "`python -m benchmarks.studies.policy_trace`"),
    ("task_builtins", "`python -m benchmarks.evals.task_builtins`"),
    ("contact_caps", "`python -m benchmarks.perf.contact_caps`"),
    ("cost_", "`python -m benchmarks.perf.cost`"),
    ("env_rollouts", "`python -m benchmarks.perf.env_rollouts`"),
    ("roofline", "`python -m benchmarks.perf.roofline`"),
    ("capsule_fidelity", "`python -m benchmarks.studies.capsule_fidelity`"),
    ("contact_diagnosis", "`python -m benchmarks.studies.contact_diagnosis`"),
    ("engine_contacts", "`python -m benchmarks.studies.engine_contacts`"),
    ("force_sources", "`python -m benchmarks.studies.force_sources`"),
    ("friction_frontier", "`python -m benchmarks.studies.friction_frontier`"),
    ("low_stiffness_check", "`python -m benchmarks.studies.low_stiffness_check`"),
    ("pull_speed", "`python -m benchmarks.studies.pull_speed`"),
    ("r2_map", "`python -m benchmarks.studies.r2_map`"),
)
#: what a file's ``config`` pointer adds about settings kept elsewhere or not kept at all
NOTES = {
    "policies/": "the training settings are in policy.json beside it",
    "evaluation512": "the policy's training settings are in peghole_mjx/policies/rect_extract_hard",
    "rl_vs_rlcs": "not recorded: the arms' env overrides and engine (see the research page)",
}
CPU = "cpu (2 cores, x86_64)"
#: result files whose device the research record states (docs/research/index.md, 2026-12-02:
#: "Everything was measured on a 2-core x86_64 CPU; no GPU has run any of it yet")
DEVICE_FROM_RECORD = (
    f"{CPU} (recovered: the file recorded none; every run before 2026-12-04 was made on the "
    "2-core CPU, docs/research/index.md)"
)


def added_in(path: Path) -> tuple[str, str]:
    """``(commit, YYYY-MM-DD)`` of the last commit that wrote ``path``'s content (renames
    followed, a pure move skipped)."""
    out = subprocess.run(
        [
            *("git", "-C", str(ROOT), "log", "--follow", "--format=%H %ad", "--date=short"),
            "--diff-filter=AM",
            *("--", str(path.relative_to(ROOT))),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    if len(out) < 2:
        return "", ""
    return out[0], out[1]


def writer(rel_path: str) -> str:
    for part, what in WRITERS:
        if part in rel_path:
            return what
    return "its writer"


def recovered(rel_path: str, record: dict) -> dict[str, object]:
    """The REQUIRED fields ``record`` (the result file ``rel_path``'s record) lacks."""
    path = ROOT / rel_path
    sha, day = added_in(path)
    added = f"last written in commit {sha[:12]} on {day}" if sha else "not yet committed"
    out: dict[str, object] = {}
    if "commit" not in record:
        out["commit"] = f"unknown: the run did not record its source commit; the file was {added}"
    if "date" not in record:
        out["date"] = (
            f"{day} (the date of the last commit that wrote the file; the run recorded no date)"
            if day
            else "unknown: the run recorded no date and the file is not committed"
        )
    if "device" not in record:
        out["device"] = DEVICE_FROM_RECORD
    if "versions" not in record:
        out["versions"] = (
            "unknown: the evaluation did not record them (the training's are in policy.json, "
            "provenance)"
            if rel_path.startswith("peghole_mjx/policies/")
            else "unknown: the run did not record the library versions"
        )
    if "command" not in record:
        runs = record.get("runs")
        cmds = (
            [r["command"] for r in runs if isinstance(r, dict) and r.get("command")]
            if (isinstance(runs, list))
            else []
        )
        out["command"] = (
            " ; ".join(dict.fromkeys(cmds))
            if cmds
            else f"unknown: the run did not record its command line; written by {writer(rel_path)}"
        )
    if "config" not in record:
        keys = [
            k
            for k in CONFIG_KEYS
            if k in record and not isinstance(record[k], _NOT_SETTINGS.get(k, ()))
        ]
        if "rl_vs_rlcs" in rel_path:
            keys += [k for k in ("rl_cs", "rl") if k in record]
        note = NOTES.get(next((p for p in NOTES if p in rel_path), ""), "")
        if keys:
            out["config"] = "see " + ", ".join(keys) + (f"; {note}" if note else "")
        else:
            out["config"] = "unknown: the run recorded no settings beyond those in its rows"
    return out


def append_keys(text: str, add: dict[str, object]) -> str:
    """The JSON object ``text`` with the keys of ``add`` appended before its closing brace:
    nothing already there is re-serialised, so no number or key changes."""
    body = text.rstrip()
    if not body.endswith("}"):
        raise ValueError("not a JSON object")
    m = re.search(r'\n([ \t]+)"', body)
    indent = m.group(1) if m else None
    head = body[:-1].rstrip()
    sep = "" if head.endswith("{") else ","
    if indent is None:
        items = ", ".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in add.items())
        out = f"{head}{sep} {items}}}"
    else:
        items = (",\n").join(f"{indent}{json.dumps(k)}: {json.dumps(v)}" for k, v in add.items())
        out = f"{head}{sep}\n{items}\n}}"
    json.loads(out)  # still one valid object
    return out + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="write nothing; list what is missing")
    args = ap.parse_args(argv)
    todo = 0
    seen = set()
    for rel_path in linked_results(ROOT):
        rec_path = record_path(ROOT / rel_path)
        if rec_path in seen or not rec_path.exists():
            continue  # a CSV without its record: written by hand (see the module's docs)
        seen.add(rec_path)
        record = json.loads(rec_path.read_text())
        if not isinstance(record, dict):
            continue
        add = recovered(rel_path, record)
        if not add:
            continue
        todo += 1
        print(f"{rec_path.relative_to(ROOT)}: + {', '.join(add)}")
        if not args.check:
            rec_path.write_text(append_keys(rec_path.read_text(), add))
            json.loads(rec_path.read_text())
    return 1 if args.check and todo else 0


if __name__ == "__main__":
    sys.exit(main())
