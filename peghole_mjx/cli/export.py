"""``peghole export``: a trained policy as ONNX plus its action decoding, for a robot.

Writes ``policy.onnx``, ``action.json`` and a copy of ``policy.json`` into ``--out``
(:mod:`peghole_mjx.policies.export`); run it with :class:`peghole_mjx.deploy.DeployedPolicy`
(NumPy + ONNX Runtime, no JAX). docs/guide/deploy.md maps the command onto a KUKA iiwa.

Examples::

    peghole export rect --out exported/rect
    peghole export runs/my_run --out exported/mine --verify 8   # closed loop vs JAX evaluation
"""

from __future__ import annotations

import argparse
from pathlib import Path

from peghole_mjx.core.lazy import command
from peghole_mjx.core.validation import arg


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="export a policy to ONNX + action.json for a robot (peghole_mjx.deploy runs it)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "policy",
        metavar="POLICY",
        help="a pretrained name (rect, dual, rect_hard, dual_hard), a policy folder or a "
        "training run folder",
    )
    p.add_argument("--out", type=Path, required=True, help="the folder to write")
    p.add_argument(
        "--force", action="store_true", help="replace --out when it holds an earlier export"
    )
    p.add_argument(
        "--verify",
        type=arg("episodes"),
        default=0,
        metavar="N",
        help="also run N episodes (engine mujoco) driven through the export and compare them "
        "with the JAX evaluation of the same episodes: success identical, mean F_z within 1 %% "
        "(writes verification.json; a mismatch writes nothing, exit status 1)",
    )
    p.add_argument("--seed", type=arg("seed"), default=0, help="episodes of --verify")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=command("peghole_mjx.policies.export:cmd_export"))
