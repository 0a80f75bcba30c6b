"""``peghole demo``: the parser and the demo's names on disk. What the demo does is
:mod:`peghole_mjx.demo`, imported when the command runs (:mod:`peghole_mjx.core.lazy`: ``peghole
--help`` does not import the learner and the experiment, 2.8 s on the 2-core CPU, 2026-12-02).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg

#: the command's description (``peghole demo --help``)
DESCRIPTION = """``peghole demo``: the whole pipeline once, with a short report.

Steps (each also a command of its own):

1. ``peghole models build`` for rect-2 and dual-2 (MJCF scenes with the iiwa);
2. ``peghole experiment compliance --geometry rect --quick`` (L_C at tip / centre / top), in
   two cells of rect-2: the project's default stiffness (K_theta 300 N m/rad, where the
   quasi-static oracle predicts the thesis's R1 reversed) and the sweep's cell nearest R1
   (K_theta 30 N m/rad); the report puts the simulated reductions beside the oracle's for the
   same worlds and the thesis's, and names each cell's regime;
3. ``peghole train --env RectExtract --profile cpu`` on the ``mujoco`` engine (MuJoCo C) with
   training's defaults (RL + compliance strategy, the outcome reward, residual actions) and the
   profile's learner, the time-limit protocol's (256 worlds, a time-out a terminal failure, the
   time left observed; decided 2026-12-06 by that protocol's rule), the profile's whole 256k
   env steps, then the FINAL policy evaluated; ``--profile full`` on a GPU trains the same task
   at the GPU sizes;
4. ``peghole evaluate rect`` (the committed pretrained policy vs the scripted baseline);
5. ``report.md`` linking the figures.

Its wall clock on a 2-core CPU is in the one record of the suite and demo times,
benchmarks/results/perf/suite_time_cpu-2core.json (docs/guide/development.md, "How long the
suite takes"); the committed run's outputs are in benchmarks/results/evals/demo_cpu-2core.

Rerun in place: ``demo.json`` in the output folder records each stage as started and, once
complete, with the SHA-256 of every file it wrote. A rerun with the same ``--out`` reuses
every complete stage whose files still verify and whose settings (profile, engine, episodes)
are the same, and redoes the others (an interrupted stage is removed and run again); the
report is always rewritten. ``--force`` deletes the demo's earlier outputs and starts afresh.
A folder holding demo outputs that ``demo.json`` does not record (an older demo, other files)
is refused in one line unless ``--force``. The output folder is checked (writable, room for
the outputs) before any work.
"""

#: the record of the demo's stages in ``--out``
DEMO_STATE = "demo.json"
#: stage -> what it writes inside ``--out`` (None: nothing, its result lives in ``demo.json``)
STAGE_OUTPUTS: dict[str, str | None] = {
    "models": "models",
    "experiment": "compliance",
    "training": "train",
    "training_eval": None,
    "evaluation": "evaluation.json",
}
#: every name the demo writes in ``--out`` (what ``--force`` deletes)
DEMO_OUTPUTS = (*(v for v in STAGE_OUTPUTS.values() if v), "report.md", DEMO_STATE)
#: first line of the demo's report (how ``--force`` tells an older demo's folder)
REPORT_TITLE = "# peghole_mjx demo report"


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``peghole demo`` (run by :func:`peghole_mjx.demo.cmd_demo`)."""
    p = sub.add_parser(
        "demo",
        help="build models, run a quick experiment, train briefly, evaluate, write a report",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", type=Path, default=Path("peghole_demo"), help="output directory")
    p.add_argument(
        "--episodes",
        type=arg("episodes"),
        default=None,
        help="evaluation episodes (CPU 32, GPU 1024)",
    )
    p.add_argument(
        "--profile",
        choices=("auto", "quick", "cpu", "full"),
        default="auto",
        help="training profile: auto = full on a GPU (engine mjx), cpu on a CPU (engine "
        "mujoco); quick: a smoke run",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="start afresh: delete the demo's earlier outputs in --out ("
        + ", ".join(DEMO_OUTPUTS)
        + ") instead of reusing its complete stages",
    )
    p.set_defaults(func=command("peghole_mjx.demo:cmd_demo"))
