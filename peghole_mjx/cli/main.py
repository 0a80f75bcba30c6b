"""The ``peghole`` command line: one sub-command group per subpackage.

Each group module exposes ``add_parser(subparsers)``, which adds its parser and sets
``func`` (called with the parsed namespace, returns an exit status).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import threading
import time
import traceback

import peghole_mjx.core._mjx  # noqa: F401  (first: keeps mjx's import chatter off stdout)
from peghole_mjx import __version__
from peghole_mjx.core import progress as prog
from peghole_mjx.core import runtime
from peghole_mjx.core.errors import REPORTED_ERRORS
from peghole_mjx.files import lock

#: command group -> module that defines it
GROUPS: dict[str, str] = {
    "models": "peghole_mjx.geometry.cli",
    "analyze": "peghole_mjx.analysis.cli",
    "experiment": "peghole_mjx.experiments.cli",
    "envs": "peghole_mjx.envs.cli",
    "task": "peghole_mjx.envs.task_cli",  # a task folder (any peg-hole) for MeshExtract
    "train": "peghole_mjx.training.cli",  # also adds `evaluate` and `compare`
    "demo": "peghole_mjx.cli.demo",
    "export": "peghole_mjx.cli.export",  # policy -> ONNX for a robot (peghole_mjx.deploy)
}


#: commands whose ``--out`` file the dispatcher writes through :func:`lock.writing_files` (one
#: writer, the program's own file, a file of other parameters refused; decided 2026-12-05):
#: their modules write it with :mod:`peghole_mjx.files.fileio`, and have no ``--force``
FILE_OUTPUTS = {"evaluate": "peghole evaluate", "compare": "peghole compare"}


def _output_guard(args: argparse.Namespace):
    """:func:`lock.writing_files` of the ``--out`` file of a command in :data:`FILE_OUTPUTS`
    (else nothing)."""
    command = FILE_OUTPUTS.get(getattr(args, "group", None))
    out = getattr(args, "out", None)
    if command is None or out is None:
        return contextlib.nullcontext()
    params = lock.command_parameters(args, drop=("group",))
    return lock.writing_files({out: params}, command, force=False, has_force=False)


#: where a traceback (a bug, not a user error) should be reported
REPORT_BUG = "this is a bug in peghole_mjx: please report it with the traceback above"


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``peghole ...: error: ...`` and exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _one_line(exc: BaseException) -> str:
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    if isinstance(exc, OSError) and exc.filename and exc.strerror:
        msg = f"{exc.filename}: {exc.strerror}"
    text = " ".join(str(msg).split())  # one line, whatever the message held
    return text or type(exc).__name__


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="peghole",
        description="Simulation, analysis and learning for robotic peg-hole disassembly.",
    )
    parser.add_argument("--version", action="version", version=f"peghole_mjx {__version__}")
    sub = parser.add_subparsers(dest="group", metavar="COMMAND")
    for module in GROUPS.values():
        try:
            importlib.import_module(module).add_parser(sub)
        except ModuleNotFoundError as exc:  # a group not installed in this build
            if not exc.name or not module.startswith(exc.name):
                raise
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch scheduler, ``docker stop``), raised in the main thread like
    Ctrl-C, so that the same clean-up runs: ``with`` blocks exit (a run's lock is released,
    temporary files are removed) and ``peghole`` ends with one line and exit status 143."""


#: exit statuses of an interrupted command: 128 + the signal's number, as a shell reports it
EXIT_INTERRUPTED = 128 + signal.SIGINT  # 130, Ctrl-C
EXIT_TERMINATED = 128 + signal.SIGTERM  # 143, SIGTERM


def _on_sigterm(signum, frame):
    # a second SIGTERM while the first unwinds is ignored: it would cut the clean-up short
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated()


def _handle_sigterm():
    """Install :func:`_on_sigterm` (main thread only; not where SIGTERM is ignored); returns
    the previous handler to restore, or None when nothing was installed."""
    if threading.current_thread() is not threading.main_thread():
        return None
    previous = signal.getsignal(signal.SIGTERM)
    if previous is signal.SIG_IGN:
        return None
    signal.signal(signal.SIGTERM, _on_sigterm)
    return previous


def console() -> int:
    """The ``peghole`` program: :func:`main` with the command's clock
    (:func:`peghole_mjx.core.progress.command_start`) set to the process's start, its imports
    included (``peghole task make``'s 30 s CoACD verdict counts from there)."""
    age = prog.process_age_s()
    return main(started=None if age is None else time.perf_counter() - age)


def main(argv: list[str] | None = None, started: float | None = None) -> int:
    """The ``peghole`` entry point: process-wide settings first
    (:func:`peghole_mjx.core.runtime.configure`; importing JAX and MJX above starts no backend, so
    the XLA flags still apply), then the command. ``started``: ``time.perf_counter()`` when
    the command began (default: now)."""
    started = time.perf_counter() if started is None else started
    runtime.configure()

    previous = _handle_sigterm()
    try:
        with prog.command_clock(started):
            return _run(argv)
    except Terminated:
        print("peghole: terminated (SIGTERM)", file=sys.stderr, flush=True)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print("peghole: interrupted", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = [str(a) for a in (sys.argv[1:] if argv is None else argv)]  # result records
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        with _output_guard(args):
            return int(args.func(args) or 0)
    except REPORTED_ERRORS as exc:
        print(f"peghole: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except Exception:
        traceback.print_exc()
        print(f"peghole: internal error: {REPORT_BUG}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(console())
