"""Command functions imported when the command runs, not when the parser is built.

``peghole --help`` builds every group's parser (:mod:`peghole_mjx.cli.main`), so a group's parser
module imports only what its arguments need; what a command does lives in another module
with its imports at the top, named here as ``module:function`` and imported on the first
call. Decided 2026-12-02 while every import of the package moved to the top of its module:
the training commands' modules import Brax, orbax, matplotlib and SciPy's statistics, about
3 s more on the 2-core CPU than the parser needs (``python -X importtime``).
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable


def command(target: str) -> Callable[[argparse.Namespace], int]:
    """``func(args)`` that imports ``target`` (``"package.module:function"``) on its first
    call and runs it."""
    module, _, name = target.partition(":")
    if not module or not name:
        raise ValueError(f"command target must be 'module:function', got {target!r}")

    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(module), name)(args)

    run.__name__ = name
    run.__qualname__ = name
    run.__doc__ = f"{target}, imported when the command runs"
    return run
