"""CoACD in a process of its own: ``python -m peghole_mjx.geometry.coacd_child FOLDER``.

:func:`peghole_mjx.geometry.decompose.run_coacd` writes ``FOLDER/mesh.npz`` (``vertices``,
``faces``) and ``FOLDER/options.json`` (CoACD's keyword arguments and ``log_level``); this
process runs CoACD on them and writes ``FOLDER/pieces.npz`` (``v0``, ``f0``, ``v1``, ...) or
``FOLDER/error.txt`` (one line). CoACD's ``info`` log goes to this process's standard output,
which the parent points at a file it follows.

A fresh interpreter that imports only NumPy and CoACD: decided 2026-12-05
(docs/research/models.md, bounded CoACD). A ``multiprocessing`` child re-imports the parent's
main module, and the ``peghole`` command's imports JAX and MJX: 10 s of a 30 s verdict before
CoACD began on the 2-core machine; this child starts in under a second.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import numpy as np


def main(folder: str) -> int:
    """Run CoACD on ``folder``'s mesh (module docstring); 0 once a result file is written."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's: it ends this process
    out = Path(folder)
    try:
        import coacd

        options = json.loads((out / "options.json").read_text())
        coacd.set_log_level(options.pop("log_level"))
        with np.load(out / "mesh.npz") as mesh:
            parts = coacd.run_coacd(coacd.Mesh(mesh["vertices"], mesh["faces"]), **options)
        arrays = {}
        for i, (v, f) in enumerate(parts):
            arrays[f"v{i}"], arrays[f"f{i}"] = np.asarray(v), np.asarray(f)
        tmp = out / "pieces.tmp.npz"
        np.savez(tmp, **arrays)
        os.replace(tmp, out / "pieces.npz")
    except BaseException as exc:  # everything is reported to the parent, in one line
        (out / "error.txt").write_text(" ".join(f"{type(exc).__name__}: {exc}".split()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
