"""Import :mod:`mujoco.mjx` quietly.

mujoco-mjx prints ``Failed to import warp: ...`` to STDOUT when warp-lang is not installed
(the normal case on a CPU machine), which would corrupt ``--json`` output. Importing it once
through here, early, keeps stdout clean; any other import output still goes to stderr.
"""

from __future__ import annotations

import contextlib
import io
import sys

_buf = io.StringIO()
with contextlib.redirect_stdout(_buf):
    from mujoco import mjx

WARP_AVAILABLE = "Failed to import warp" not in _buf.getvalue()
for _line in _buf.getvalue().splitlines():
    if "import warp" not in _line and "import mujoco_warp" not in _line:
        print(_line, file=sys.stderr)

__all__ = ["WARP_AVAILABLE", "mjx"]
