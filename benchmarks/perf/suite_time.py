"""How long the test suite and ``peghole demo`` take: the one record of both, and the docs
text generated from it.

The record is ``benchmarks/results/perf/suite_time_cpu-2core.json``. Each measurement in it
carries its own device, versions, date, command, config and commit, and says where the figure
was recorded; the file's top-level fields are those of the command that last wrote it
(:func:`peghole_mjx.files.provenance.run_provenance`). The docs state these times only as
:func:`texts` writes them: the block under "How long the suite takes" in
``docs/guide/development.md`` is generated (``python -m benchmarks.tables``), and every other
page that states a suite, CI or demo time states one of :func:`texts`' strings
(``tests/test_suite_time.py``) or links to that block.

* ``python -m benchmarks.perf.suite_time record`` writes the file from :data:`RECORDED` (the
  figures measured before this record existed, each with its source) and keeps any
  measurement added since;
* ``python -m benchmarks.perf.suite_time measure [--label L] [--loaded] [-- CMD ...]`` runs
  CMD (default the README's test command, :data:`SUITE_COMMAND`), times it and adds the
  measurement (``--loaded``: other work shared the CPU, so it is shown but left out of the
  free-CPU range).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.common import PERF_RESULTS, rel, table
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import run_provenance

#: the committed record
RESULT = PERF_RESULTS / "suite_time_cpu-2core.json"
#: the README's test command, which CI runs verbatim
SUITE_COMMAND = ["python3", "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile"]
#: the measurement kinds: a local suite run on a free CPU, one on a loaded CPU, a CI landing
#: (all of ``.ci/run``), a demo run
KINDS = ("suite", "suite_loaded", "ci", "demo")

_SUITE_CONFIG = {
    "workers": 2,
    "dist": "loadfile",
    "compile_cache": "cold",
    "tree": "a git archive copy of the commit, as CI's clone",
}
#: the stack of the 2026-12-05 local runs, warp-lang installed
_VERSIONS_WARP = {
    "mujoco": "4.0.1",
    "mujoco-mjx": "3.17.0",
    "jax": "0.10.2",
    "brax": "0.14.2",
    "warp-lang": "1.18.0",
}
#: the stack of the 2026-12-06 demo runs (their run.json)
_VERSIONS_DEMO = {
    "python": "3.11.7",
    "peghole_mjx": "0.1.0",
    "mujoco": "4.0.1",
    "mujoco-mjx": "3.17.0",
    "jax": "0.10.2",
    "jaxlib": "0.10.2",
    "brax": "0.14.2",
    "numpy": "2.4.6",
    "coacd": "1.0.14",
    "trimesh": "5.2.0",
}
_CI_UNKNOWN = {
    "device": "unknown: CI's machine is not recorded by the landing report",
    "versions": "unknown: CI installs what pyproject.toml allows; its versions are not recorded",
    "commit": "unknown: the landing report gives CI's time, not the commit of the tree",
}
_CI_COMMAND = ".ci/run (pip install -e .[dev], the suite, ruff check, ruff format --check, "
_CI_COMMAND += "tests/test_playground.py)"


def _warm_local_suite(
    wall_s: int, label: str, durations: int, commit: str, outcome: str, source: str
) -> dict:
    """A local run of the README's suite on 2026-12-05 with warp-lang installed (its Warp tests
    ran in it) and the compile cache kept from earlier runs: not CI-like, so outside the
    cold-cache range."""
    return {
        "kind": "suite_loaded",
        "label": label,
        "wall_s": wall_s,
        "device": "cpu (2 cores, x86_64)",
        "versions": _VERSIONS_WARP,
        "date": "2026-12-05",
        "command": " ".join(SUITE_COMMAND) + f" -p no:cacheprovider --durations={durations}",
        "config": {
            **_SUITE_CONFIG,
            "warp_lang_installed": True,
            "compile_cache": "warm: the suite's cache folder kept from earlier runs",
            "tree": "the working tree at the commit",
        },
        "commit": commit,
        "outcome": outcome,
        "source": source,
    }


#: the figures measured before this record existed, with where each was recorded
RECORDED: list[dict] = [
    {
        "kind": "suite",
        "label": "free 2-core CPU",
        "wall_s": 1572,
        "device": "cpu (2 cores, x86_64)",
        "versions": {
            "mujoco": "4.0.0",
            "mujoco-mjx": "3.17.0",
            "jax": "0.10.2",
            "brax": "0.14.2",
            "pytest-xdist": "3.8.0",
        },
        "date": "2026-12-03",
        "command": " ".join(SUITE_COMMAND),
        "config": _SUITE_CONFIG,
        "commit": "c468cdd4170f7db521fcbcc7e6c2c872aebb60c0",
        "outcome": "961 passed, 15 skipped, 0 failed; largest process 2.5 GB",
        "source": "commit 76ee425 (its message; it changes only README.md and "
        "docs/guide/development.md, so the tree measured is its parent c468cdd)",
    },
    {
        "kind": "suite",
        "label": "free 2-core CPU, a slower machine (AMD EPYC)",
        "wall_s": 2160,
        "device": "cpu (2 cores, x86_64)",
        "versions": {"mujoco": "4.0.1", "mujoco-mjx": "3.17.0", "jax": "0.10.2", "brax": "0.14.2"},
        "date": "2026-12-03",
        "command": " ".join(SUITE_COMMAND),
        "config": _SUITE_CONFIG,
        "commit": "089b5c8236800d5353e4926198c01ef5ee7b3bfa",
        "outcome": "not recorded",
        "source": "commit 280ca0f (its message: 36 min 00 s before the changes of b281567)",
    },
    {
        "kind": "suite",
        "label": "free 2-core CPU, the same slower machine",
        "wall_s": 1858,
        "device": "cpu (2 cores, x86_64)",
        "versions": {"mujoco": "4.0.1", "mujoco-mjx": "3.17.0", "jax": "0.10.2", "brax": "0.14.2"},
        "date": "2026-12-03",
        "command": " ".join(SUITE_COMMAND),
        "config": _SUITE_CONFIG,
        "commit": "b281567b6f2f09c8f75a480b4d12ac4a51753766",
        "outcome": "962 passed, 15 skipped",
        "source": "commit 280ca0f (its message: 30 min 58 s after the changes of b281567)",
    },
    {
        "kind": "suite_loaded",
        "label": "loaded 2-core CPU (load 3-8 from a training run for the first minutes)",
        "wall_s": 3011,
        "device": "cpu (2 cores, x86_64)",
        "versions": _VERSIONS_WARP,
        "date": "2026-12-05",
        "command": " ".join(SUITE_COMMAND),
        "config": {**_SUITE_CONFIG, "warp_lang_installed": True},
        "commit": "unknown: the uncommitted tree that a908a0c then mended (its stale tests)",
        "outcome": "1154 passed, 13 failed, 3 errors, 15 skipped (tests made stale by the "
        "changes, fixed in a908a0c)",
        "source": "commit a908a0c (its message) and the change's closing record of 2026-12-05",
    },
    *[
        {
            "kind": "ci",
            "label": "all of `.ci/run`",
            "wall_s": wall,
            **_CI_UNKNOWN,
            "date": date,
            "command": _CI_COMMAND,
            "config": {"what": "all of .ci/run; how much of it was the suite is not recorded"},
            "outcome": "passed",
            "source": "the landing report (CI passed in N s); date: the day the landed "
            "change was closed",
        }
        for wall, date in (
            (1309, "2026-12-03"),
            (1343, "2026-12-03"),
            (1493, "2026-12-03"),
            (2201, "2026-12-05"),
            (3008, "2026-12-05"),
            (3237, "2026-12-05"),
            (2610, "2026-12-05"),
            (3425, "2026-12-05"),
            (705, "2026-12-06"),
            (628, "2026-12-06"),
            (650, "2026-12-06"),
            (679, "2026-12-06"),
        )
    ],
    _warm_local_suite(
        3707,
        "2-core CPU, warm compile cache, warp-lang installed (its Warp tests ran in "
        "the suite), the worktree: not a CI-like run, so outside the cold-cache range",
        120,
        "39c1b94",
        "1357 passed, 2 failed (a stale census of broad handlers, fixed in 132e925; "
        "a SIGINT test past its 30 s, not reproduced in five reruns), 15 skipped",
        "the run's log (pytest's summary line), 13:07-14:09 UTC; the worktree "
        "checkout, not a git archive copy",
    ),
    _warm_local_suite(
        2589,
        "free 2-core CPU, warm compile cache, warp-lang installed (its Warp tests ran "
        "in the suite), the worktree: not a CI-like run, so outside the cold-cache range",
        60,
        "734fac7",
        "1368 passed, 8 failed (tests that expected MJX as the env default or the "
        "engine among a policy's task differences; mended in the next commit), 15 skipped",
        "the run's log (pytest's summary line), 17:18-18:01 UTC; the worktree "
        "checkout, not a git archive copy",
    ),
    _warm_local_suite(
        2401,
        "2-core CPU, warm compile cache, warp-lang installed (its Warp tests ran in "
        "the suite), a profiling job beside it for its first minutes: not a CI-like run, so "
        "outside the cold-cache range",
        80,
        "c505680",
        "1377 passed, 1 failed (the cylinder scene's refusal, which the MuJoCo C "
        "engine no longer needs; mended in the next commit), 15 skipped",
        "the run's log (pytest's summary line), 19:16-19:56 UTC",
    ),
    _warm_local_suite(
        2836,
        "free 2-core CPU, warm compile cache, warp-lang installed (its Warp tests ran "
        "in the suite): not a CI-like run, so outside the cold-cache range",
        60,
        "9bdc311",
        "1378 passed, 2 failed (the throughput command's record could not hold a "
        "path, and a word of a log in a result file; mended in the next commit), 15 skipped",
        "the run's log (pytest's summary line), 20:37-21:25 UTC",
    ),
    {
        "kind": "demo",
        "label": "2-core CPU shared with two short jobs (140 % CPU to the demo)",
        "wall_s": 548,
        "device": "cpu (2 cores, x86_64)",
        "versions": {
            "python": "3.11.7",
            "peghole_mjx": "0.1.0",
            "mujoco": "4.0.0",
            "mujoco-mjx": "3.17.0",
            "jax": "0.10.2",
            "jaxlib": "0.10.2",
            "brax": "0.14.2",
            "numpy": "2.4.6",
        },
        "date": "2026-12-02T21:51Z",
        "command": "/usr/bin/time -v peghole demo --out /tmp/demo_run",
        "config": {
            "profile": "auto -> cpu",
            "engine": "mujoco",
            "stop": "first evaluation >= 0.95 (demo.DEMO_CPU_STOP_AT_SUCCESS)",
            "reward": "eq (4.4), training's default then",
            "compliance_cells": ["default", "r1_regime"],
        },
        "commit": "unknown: not recorded by the run; its files were committed in 6ef1e0d",
        "outcome": "peak memory 2.2 GB; eval success 1.00 at 70.4k env steps",
        "source": "benchmarks/results/evals/demo_cpu-2core/ until 2026-12-06 (its git history: "
        "README.md, run.json, summary.json)",
    },
    {
        "kind": "demo",
        "label": "free 2-core CPU (158 % CPU to the demo)",
        "wall_s": 410,
        "device": "cpu (2 cores, x86_64)",
        "versions": _VERSIONS_DEMO,
        "date": "2026-12-06T06:07Z",
        "command": "/usr/bin/time -v peghole demo --out /tmp/demo_run",
        "config": {
            "profile": "auto -> cpu",
            "engine": "mujoco",
            "stop": "none: the profile's whole 100k env steps, the final policy evaluated",
            "reward": "outcome, residual actions, RL + compliance strategy, critic burn-in "
            "5000 (training's defaults from 2026-12-06)",
            "compliance_cells": ["default", "r1_regime"],
        },
        "commit": "f88e7c4f953f3478fa89531cd159eb18005940a7",
        "outcome": "peak memory 1.5 GB; final policy 32 of 32 demo episodes, mean F_z 3.66 N "
        "against the baseline's 8.18 N",
        "source": "benchmarks/results/evals/demo_cpu-2core/ until 2026-12-06T20:41Z (its git "
        "history: README.md, run.json, summary.json)",
    },
    {
        "kind": "demo",
        "label": "free 2-core CPU (156 % CPU to the demo)",
        "wall_s": 440,
        "device": "cpu (2 cores, x86_64)",
        "versions": _VERSIONS_DEMO,
        "date": "2026-12-06T20:41Z",
        "command": "/usr/bin/time -v peghole demo --out /tmp/demo_run",
        "config": {
            "profile": "auto -> cpu",
            "engine": "mujoco",
            "stop": "none: the profile's whole 256k env steps, the final policy evaluated",
            "reward": "outcome, residual actions, RL + compliance strategy, a time-out a "
            "terminal failure with the time left observed, 256 worlds (the cpu profile from "
            "2026-12-06, the time-limit protocol's learner)",
            "compliance_cells": ["default", "r1_regime"],
        },
        "commit": "94ce5c3a498fc5cdb6bc3b993224005fdadc7dd6",
        "outcome": "peak memory 1.8 GB; final policy 32 of 32 demo episodes, mean F_z 0.60 N "
        "against the baseline's 8.18 N",
        "source": "benchmarks/results/evals/demo_cpu-2core/README.md (its run.json, "
        "summary.json: device, versions, date)",
    },
]


def load(path: Path = RESULT) -> dict:
    """The committed record."""
    return json.loads(Path(path).read_text())


def minutes(wall_s: float) -> str:
    """``548`` -> ``9 min 08 s``."""
    m, s = divmod(round(wall_s), 60)
    return f"{m} min {s:02d} s"


def seconds(wall_s: float) -> str:
    """``2201`` -> ``2,201 s``."""
    return f"{round(wall_s):,} s"


def _of(rec: dict, kind: str) -> list[dict]:
    return [m for m in rec["measurements"] if m["kind"] == kind]


def texts(rec: dict | None = None) -> dict[str, str]:
    """The strings the docs may state, each computed from the record:

    * ``suite``: the free-CPU range, ``26-36 min`` (whole minutes, floor and ceiling);
    * ``suite_date``: its dates; ``ci_latest``, ``ci_latest_date``: the newest CI landing;
    * ``ci_earlier``: the landings before it (``1,309, 1,343 and 1,493 s``);
    * ``demo``, ``demo_date``: the newest demo run, ``9 min 08 s``.
    """
    rec = load() if rec is None else rec
    suite = [m["wall_s"] for m in _of(rec, "suite")]
    suite_dates = sorted({m["date"][:10] for m in _of(rec, "suite")})
    ci = sorted(_of(rec, "ci"), key=lambda m: m["date"])
    demo = sorted(_of(rec, "demo"), key=lambda m: m["date"])[-1]
    earlier = [seconds(m["wall_s"]) for m in ci[:-1]]
    return {
        "suite": f"{math.floor(min(suite) / 60)}-{math.ceil(max(suite) / 60)} min",
        "suite_date": " to ".join(dict.fromkeys([suite_dates[0], suite_dates[-1]])),
        "ci_latest": seconds(ci[-1]["wall_s"]),
        "ci_latest_date": ci[-1]["date"][:10],
        "ci_earlier": " and ".join(filter(None, [", ".join(earlier[:-1]), *earlier[-1:]])),
        "demo": minutes(demo["wall_s"]),
        "demo_date": demo["date"][:10],
    }


@table("suite_time")
def suite_time_table() -> str:
    """The block under "How long the suite takes" (docs/guide/development.md)."""
    rec = load()
    t = texts(rec)
    lines = [
        f"**The suite takes {t['suite']} on a free 2-core CPU** (cold compile cache, "
        f"{t['suite_date']}) **and CI's latest landing took {t['ci_latest']}** for all of "
        f"`.ci/run` ({t['ci_latest_date']}; before it {t['ci_earlier']}). **`peghole demo` "
        f"took {t['demo']}** ({t['demo_date']}). Each measurement with its device, versions, "
        f"command, commit and source: [`{RESULT.name}`]({rel(RESULT)}).",
        "",
        "| what | wall clock | date | commit | outcome |",
        "|---|---|---|---|---|",
    ]
    for m in rec["measurements"]:
        wall = minutes(m["wall_s"]) if m["kind"] != "ci" else seconds(m["wall_s"])
        commit = m["commit"][:7] if not m["commit"].startswith("unknown") else "unknown"
        what = {
            "suite": "suite",
            "suite_loaded": "suite, loaded (not in the range)",
            "ci": "CI",
            "demo": "demo",
        }[m["kind"]]
        lines.append(
            f"| {what}: {m['label']} | {wall} | {m['date'][:10]} | {commit} | {m['outcome']} |"
        )
    return "\n".join(lines)


def record(measurements: list[dict], argv: list[str], out: Path = RESULT) -> dict:
    """Write ``out``: the ``measurements`` under the provenance of the command ``argv``."""
    rec = {
        "what": "wall-clock times of the test suite, of CI's landings and of peghole demo",
        **run_provenance(argv),
        "config": "see measurements; each measurement records its own device, versions, "
        "date, command, config and commit, and its source",
        "measurements": measurements,
    }
    fileio.write_text(out, json.dumps(rec, indent=1) + "\n")
    return rec


def measure(command: list[str], label: str, loaded: bool = False) -> dict:
    """Run ``command``, timing it: one measurement (its own :func:`run_provenance`)."""
    t0 = time.perf_counter()
    rc = subprocess.run(command, check=False).returncode
    wall = time.perf_counter() - t0
    prov = run_provenance(command)
    return {
        "kind": "suite_loaded" if loaded else "suite",
        "label": label,
        "wall_s": round(wall, 1),
        **{k: prov[k] for k in ("device", "versions", "date", "command")},
        "config": {"loaded": loaded},
        "commit": prov["commit"],
        "outcome": f"exit status {rc}",
        "source": "python -m benchmarks.perf.suite_time measure",
    }


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(prog="python -m benchmarks.perf.suite_time", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("record", help="write the record from the recorded figures (keeps new ones)")
    m = sub.add_parser("measure", help="time a command (default the suite) and add it")
    m.add_argument("--label", default="free 2-core CPU")
    m.add_argument("--loaded", action="store_true", help="other work shared the CPU")
    m.add_argument("command", nargs="*", help="after --: the command (default the suite)")
    p.add_argument("--out", type=Path, default=RESULT)
    args = p.parse_args(argv)
    full = ["python", "-m", "benchmarks.perf.suite_time", *argv]
    old = load(args.out)["measurements"] if args.out.exists() else []
    added = [x for x in old if x.get("source") == "python -m benchmarks.perf.suite_time measure"]
    if args.cmd == "measure":
        added.append(measure(args.command or SUITE_COMMAND, args.label, args.loaded))
    rec = record(RECORDED + added, full, args.out)
    print(f"{rel(args.out)}: {len(rec['measurements'])} measurements; {texts(rec)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
