"""Import :mod:`mujoco.mjx` quietly: every MJX import of the package goes through here.

mujoco-mjx prints ``Failed to import warp: ...`` to STDOUT when warp-lang is not installed
(the normal case on a CPU machine), which would corrupt ``--json`` output. Importing it once
through here, early, keeps stdout clean; any other import output still goes to stderr.

``support`` is MJX's private ``mujoco.mjx._src.support`` (point Jacobian, full inertia matrix),
used by :mod:`peghole_mjx.control.kinematics`; a MuJoCo upgrade that moves it breaks here
only; ``solver`` is MJX's private ``mujoco.mjx._src.solver``, which :mod:`peghole_mjx.sim.mjx_fixes`
patches; ``warp_types`` and ``tree_path_to_attr_str`` give MJX's own table of MuJoCo Warp's
fields shared by a batch's worlds (read by :func:`peghole_mjx.sim.engines.select_worlds`).
"""

from __future__ import annotations

import contextlib
import io
import sys

_buf = io.StringIO()
with contextlib.redirect_stdout(_buf):
    from mujoco import mjx
    from mujoco.mjx._src import solver, support
    from mujoco.mjx._src.types import tree_path_to_attr_str
    from mujoco.mjx.warp import types as warp_types

WARP_AVAILABLE = "Failed to import warp" not in _buf.getvalue()
for _line in _buf.getvalue().splitlines():
    if "import warp" not in _line and "import mujoco_warp" not in _line:
        print(_line, file=sys.stderr)


__all__ = [
    "WARP_AVAILABLE",
    "mjx",
    "solver",
    "support",
    "tree_path_to_attr_str",
    "warp_types",
]
