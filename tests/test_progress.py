"""Progress on stderr (peghole_mjx/core/progress.py): a labelled phase ticks while its work runs,
says nothing when disabled, and ends its line also when the work raises."""

from __future__ import annotations

import time

import pytest

from peghole_mjx.core import progress as prog


def test_phase_shows_its_label_and_ticks_while_the_work_runs(capsys, monkeypatch):
    monkeypatch.setattr(prog, "TICK_LOG_S", 0.05)  # stderr is captured: no terminal
    with prog.phase("building the env"):
        time.sleep(0.3)
    err = capsys.readouterr().err
    draws = [s for s in err.replace("\r", "\n").splitlines() if s.strip()]
    assert all(d.startswith("building the env: 00:0") for d in draws), draws
    assert len(draws) >= 3  # the first draw, redraws while it ran, the final line
    assert err.endswith("\n")  # the line is left with the phase's time


def test_compiling_says_what_and_that_a_second_run_is_cached(capsys):
    with prog.compiling("the env step"):
        pass
    err = capsys.readouterr().err
    assert "compiling the env step (first run only; cached after): 00:00" in err


def test_phase_disabled_writes_nothing_and_an_error_still_ends_the_line(capsys):
    with prog.phase("quiet", enabled=False):
        pass
    assert capsys.readouterr().err == ""
    with pytest.raises(RuntimeError), prog.phase("failing"):
        raise RuntimeError("boom")
    err = capsys.readouterr().err
    assert "failing: 00:00" in err and err.endswith("\n")


def test_bar_counts_on_stderr_and_is_silent_when_disabled(capsys):
    bar = prog.bar(3, "rendering x.gif", unit="step")
    bar.update(3)
    bar.close()
    captured = capsys.readouterr()
    assert "rendering x.gif: 100%" in captured.err and captured.out == ""
    bar = prog.bar(3, "quiet", enabled=False)
    bar.update(3)
    bar.close()
    assert capsys.readouterr().err == ""
