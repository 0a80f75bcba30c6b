"""Progress on stderr for every phase of a command that takes more than a few seconds.

Counted work (rollout chunks, evaluation batches, GIF frames) gets a tqdm bar (:func:`bar`).
A phase that cannot be counted, above all an XLA compile (minutes on a 2-core CPU the first
time, seconds from the persistent compilation cache after it: ``peghole_mjx/__init__.py``),
gets :func:`phase`: a labelled line whose elapsed time ticks while the work runs, so that no
phase is silent and no bar extrapolates a compile into an ETA of an hour. Callers pass
``enabled=False`` under ``--json`` (nothing is written then).

Decided 2026-12-02: `peghole evaluate` and the demo printed nothing for minutes while they
compiled, and the experiment's and training's bars counted the compile as their first chunk.
Relies on tqdm 4.70 (a dependency): ``tqdm.refresh`` takes the bar's own lock, so the ticking
thread of :func:`phase` is safe beside the main thread's work, and XLA releases the GIL while
it compiles, so the line keeps ticking.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tqdm import tqdm

#: what a compile label adds: the persistent compilation cache makes a second run fast
COMPILE_NOTE = "first run only; cached after"
#: seconds between two redraws of a :func:`phase` line: on a terminal the elapsed time ticks
#: every second; in a log (no terminal) every 5 s, so that a log shows no silent gap over 10 s
#: without filling it with redraws
TICK_TTY_S = 1.0
TICK_LOG_S = 5.0


def _is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stderr
        return False


def bar(total: int | None, desc: str, unit: str = "it", enabled: bool = True, **kw) -> tqdm:
    """A tqdm bar on stderr labelled ``desc`` (``enabled`` False: nothing is written)."""
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=not enabled,
        dynamic_ncols=True,
        **kw,
    )


@contextmanager
def phase(label: str, enabled: bool = True) -> Iterator[None]:
    """Show ``label: <elapsed>`` on stderr, redrawn while the block runs, and leave the line
    with the phase's total time when it ends (also when it raises)."""
    if not enabled:
        yield
        return
    tick = TICK_TTY_S if _is_tty() else TICK_LOG_S
    line = tqdm(
        total=None,
        desc=label,
        bar_format="{desc}: {elapsed}",
        file=sys.stderr,
        mininterval=tick,
    )
    stop = threading.Event()

    def redraw() -> None:
        while not stop.wait(tick):
            line.refresh()

    thread = threading.Thread(target=redraw, name="peghole-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        line.close()


def compiling(what: str, enabled: bool = True):
    """:func:`phase` for an XLA compile: ``compiling <what> (first run only; cached after)``."""
    return phase(f"compiling {what} ({COMPILE_NOTE})", enabled)


#: ``time.perf_counter()`` when the running ``peghole`` command began (:func:`command_clock`)
_command_start: float | None = None


@contextmanager
def command_clock(started: float) -> Iterator[None]:
    """While a command runs, :func:`command_start` is ``started`` (``time.perf_counter()``
    when it began); set by :func:`peghole_mjx.cli.main.main`."""
    global _command_start
    previous, _command_start = _command_start, started
    try:
        yield
    finally:
        _command_start = previous


def command_start() -> float | None:
    """``time.perf_counter()`` when the running command began, None outside a command."""
    return _command_start


def process_age_s() -> float | None:
    """Seconds since this process started, its imports included (Linux's ``/proc``, to 10
    ms), None where that cannot be read."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return max(uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return None
