"""Fault injection and bad input for the experiments (``peghole experiment sweep | compliance |
contact-check``): every case ends in one clear line (exit 2) before any simulation, or is
handled, with nothing lost or half-written (docs/guide/reliability.md).

Cheap by design: no physics runs. ``Extraction`` (the compiled scene) is replaced by a stand-in
that fails the test if it is built where a refusal must come first, or by a fake whose slices
are synthetic world summaries; a full disk is ``os.fsync`` raising ENOSPC, a read-only disk
EROFS (CI runs as root, so chmod would not stop it).
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_faults import assert_one_line, peghole

from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import contact_check as cc
from peghole_mjx.experiments import sweep
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import _proc_start

TINY = [
    "experiment",
    "sweep",
    "--geometry",
    "rect",
    "--grid",
    "tiny",
    "--engine",
    "mjx",
]  # tiny_cfg


# ---------------------------------------------------------------------- helpers
class NoSimulation:
    """Stands in for ``Extraction``: building a scene fails the test (exit 1, not 2)."""

    def __init__(self, *a, **k):
        raise AssertionError("a simulation was started")


@pytest.fixture
def no_sim(monkeypatch):
    monkeypatch.setattr(cx, "Extraction", NoSimulation)
    monkeypatch.setattr(cc, "run_variant", NoSimulation)


def fake_summary(n: int, geometry: str, seed: int = 0, nan: bool = False) -> dict:
    """A slice's world summaries as ``sweep._world_summary`` returns them (synthetic)."""
    rng = np.random.default_rng(seed)
    edges = np.arange(0.0, sweep.PRESETS_LENGTH[geometry] + 1e-9, sweep.CURVE_BIN_MM[geometry])
    peak = rng.uniform(1.0, 2.0, n)
    return {
        "peak_fz": np.where(nan, np.nan, peak),
        "peak_fz_late": np.where(nan, np.nan, peak * 0.9),
        "peak_mag": np.where(nan, np.nan, peak * 1.1),
        "peak_mag_late": np.where(nan, np.nan, peak),
        "nan": np.full(n, nan),
        "penetration_mm": rng.uniform(0, 1e-3, n),
        "penetration_in_hole_mm": rng.uniform(0, 1e-3, n),
        "penetration_two_point_mm": rng.uniform(0, 1e-3, n),
        "two_point_samples": rng.integers(0, 20, n),
        "both_frac": rng.uniform(0.5, 1.0, n),
        "curve_fz": rng.uniform(0.0, 2.0, (n, len(edges) - 1)),
        "curve_edges_mm": edges,
    }


class FakeScene:
    """Stands in for ``Extraction`` in a sweep whose slices are synthetic."""

    def __init__(self, preset, cfg, mu=None):
        pass


class Slices(list):
    """The slices a fake sweep simulated, ``(s0, n)``; ``nan``: its worlds go NaN."""

    nan = False


@pytest.fixture
def fake_sweep(monkeypatch):
    """Sweeps run with synthetic slices; returns the list of slices simulated ``(s0, n)``."""
    ran = Slices()

    def simulate(ex, table, s0, batch, nw, geometry):
        n = min(batch, nw - s0)
        ran.append((s0, n))
        return fake_summary(n, geometry, seed=s0, nan=ran.nan)

    monkeypatch.setattr(cx, "Extraction", FakeScene)
    monkeypatch.setattr(sweep, "_simulate_slice", simulate)
    return ran


def tiny_cfg(batch_worlds: int = 96) -> sweep.SweepConfig:
    """The config ``peghole experiment sweep --geometry rect --grid tiny`` runs."""
    return sweep.SweepConfig(grid=sweep.GRIDS["rect"]["tiny"], batch_worlds=batch_worlds)


def fsync_fails(monkeypatch, code: int, only: str | None = None):
    """``os.fsync`` fails with ``code`` (for every file, or those whose path holds ``only``)."""
    real = os.fsync

    def fsync(fd):
        path = os.readlink(f"/proc/self/fd/{fd}")
        if only is None or only in path:
            raise OSError(code, os.strerror(code))
        return real(fd)

    monkeypatch.setattr(fileio.os, "fsync", fsync)


def files_in(folder: Path) -> dict[str, bytes]:
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def sleeper():
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])


# ---------------------------------------------------------------------- 1. slice claims
def test_a_claim_whose_pid_was_reused_or_is_gone_is_taken_over(tmp_path, capsys):
    part = tmp_path / "rect-1_mu0.266_key_000000.npz"
    claim = part.with_suffix(".claim")
    other = sleeper()  # a live process that is not the claim's: its PID was reused
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    try:
        host = socket.gethostname()
        for rec, why in (
            ({"pid": other.pid, "host": host, "start": "1", "since": "x"}, "another process"),
            ({"pid": gone.pid, "host": host, "start": "1"}, f"pid {gone.pid} is gone"),
            ("{garbled", "unreadable"),
        ):
            claim.write_text(rec if isinstance(rec, str) else json.dumps(rec))
            assert sweep._claim(part)
            err = capsys.readouterr().err
            assert "warning: taking over sweep slice" in err and why in err, err
            mine = json.loads(claim.read_text())
            assert mine["pid"] == os.getpid() and mine["start"] == _proc_start(os.getpid())
            assert sweep._claim(part)  # ours already
            sweep._release(part)
            assert not claim.exists()
    finally:
        other.kill()
        other.wait()
    assert not list(tmp_path.glob(".*"))  # no temporary claim left


def test_a_live_claim_is_waited_for_then_refused_naming_the_holder(
    tmp_path, capsys, monkeypatch, no_sim
):
    out = tmp_path / "sweep"
    part = sweep.part_path(tiny_cfg(), out, "rect-1", 0.266, 0)
    part.parent.mkdir(parents=True)
    holder = sleeper()
    try:
        rec = {"pid": holder.pid, "host": socket.gethostname(), "start": _proc_start(holder.pid)}
        part.with_suffix(".claim").write_text(json.dumps({**rec, "since": "2026-12-02T04:00Z"}))
        monkeypatch.setattr(sweep, "CLAIM_WAIT_S", 0.3)
        monkeypatch.setattr(sweep, "CLAIM_POLL_S", 0.05)
        rc, _, err = peghole([*TINY, "--out", out], capsys)
        assert rc == 2
        assert "waiting for sweep slice" in err and f"pid {holder.pid}" in err
        assert_one_line(err, "still claimed by", f"pid {holder.pid}", "rerun this command")
        assert json.loads(part.with_suffix(".claim").read_text())["pid"] == holder.pid
        assert not part.exists() and not list(out.glob("compliance_sweep_*"))
    finally:
        holder.kill()
        holder.wait()


def test_a_claim_released_by_its_holder_is_run_here(tmp_path, capsys, monkeypatch, fake_sweep):
    out = tmp_path / "sweep"
    cfg = tiny_cfg(batch_worlds=4)
    part = sweep.part_path(cfg, out, "rect-1", 0.266, 4)
    part.parent.mkdir(parents=True)
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.5)"])
    rec = {"pid": holder.pid, "host": socket.gethostname(), "start": _proc_start(holder.pid)}
    part.with_suffix(".claim").write_text(json.dumps(rec))
    monkeypatch.setattr(sweep, "CLAIM_POLL_S", 0.1)
    try:
        res = sweep.run_sweep(cfg, out, progress=False)
    finally:
        holder.kill()
        holder.wait()
    assert fake_sweep == [(0, 4), (4, 2)]  # the claimed slice last, after its holder ended
    assert "waiting for sweep slice" in capsys.readouterr().err
    assert res["cells"][0]["n_worlds"] == 6
    assert not list(part.parent.glob("*.claim"))


def test_a_failed_slice_releases_its_claim(tmp_path, monkeypatch):
    part = tmp_path / "p_000000.npz"

    def crash(*a):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep, "_simulate_slice", crash)
    assert sweep._claim(part)
    with pytest.raises(KeyboardInterrupt):
        sweep._run_slice(None, {}, 0, 4, 6, "rect", part)
    assert not part.with_suffix(".claim").exists() and not part.exists()


# ---------------------------------------------------------------------- 2. output checked first
COMMANDS = {
    "compliance": ["experiment", "compliance", "--geometry", "rect", "--quick", "--out"],
    "sweep": [*TINY, "--out"],
    "contact-check": ["experiment", "contact-check", "--worlds", "1", "--out"],
}


@pytest.mark.parametrize("command", COMMANDS)
def test_a_read_only_output_is_refused_before_any_simulation(
    command, tmp_path, capsys, monkeypatch, no_sim
):
    out = tmp_path / ("c.json" if command == "contact-check" else "out")
    fsync_fails(monkeypatch, errno.EROFS)
    rc, _, err = peghole([*COMMANDS[command], out], capsys)
    assert rc == 2
    assert_one_line(err, "not writable", "Read-only file system")
    assert not any(p.is_file() for p in tmp_path.rglob("*"))


@pytest.mark.parametrize("command", COMMANDS)
def test_a_disk_without_room_for_the_output_is_refused_before_any_simulation(
    command, tmp_path, capsys, monkeypatch, no_sim
):
    out = tmp_path / ("c.json" if command == "contact-check" else "out")
    monkeypatch.setattr(fileio, "free_bytes", lambda path: 20_000)
    rc, _, err = peghole([*COMMANDS[command], out], capsys)
    assert rc == 2
    assert_one_line(err, "0.0 MiB free", "writes about")
    assert not any(p.is_file() for p in tmp_path.rglob("*"))


# ---------------------------------------------------------------------- 3. contact-check --append
@pytest.mark.parametrize(
    "text, why",
    [
        ('{"runs": [{"preset": "rect-2", ', "not valid JSON"),
        ("[]", "a JSON list, not an object"),
        ('{"runs": 5}', '"runs" is a int'),
        ('{"bounds": {}}', 'no "runs" list'),
        ('{"runs": [{"preset": "rect-2", "variant": "envs"}]}', "runs[0] lacks"),
        ('{"runs": [NaN]}', "not valid JSON"),
    ],
)
def test_append_onto_a_malformed_file_is_refused_before_any_simulation(
    text, why, tmp_path, capsys, no_sim
):
    out = tmp_path / "contact.json"
    out.write_text(text)
    argv = ["experiment", "contact-check", "--worlds", "1", "--append", "--out", out]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, str(out), "not a contact-check JSON", why)
    assert out.read_text() == text  # kept as it was


def test_append_keeps_the_old_runs_and_writes_atomically(tmp_path, capsys, monkeypatch):
    def run(preset, variant, worlds, seed, engine="mjx"):
        return {
            "preset": preset,
            "precision": "float32",
            "variant": dataclasses.asdict(variant),
            "summary": {"pass": {"all": True}},
            "worlds": [{"nan": False}] * worlds,
        }

    monkeypatch.setattr(cc, "run_variant", run)
    monkeypatch.setattr(cc, "table_row", lambda r: "row")
    out = tmp_path / "contact.json"
    old = {"runs": [run("rect-1", cc.VARIANTS["box-1ms"], 1, 0)]}
    out.write_text(json.dumps(old))
    argv = ["experiment", "contact-check", "--preset", "rect-2", "--variant", "envs"]
    rc, _, _ = peghole([*argv, "--worlds", "2", "--append", "--out", out], capsys)
    assert rc == 0
    runs = json.loads(out.read_text())["runs"]
    assert [(r["preset"], r["variant"]["name"]) for r in runs] == [
        ("rect-1", "box-1ms"),
        ("rect-2", "envs"),
    ]
    assert [p.name for p in tmp_path.iterdir()] == ["contact.json"]  # no temporary left


# ---------------------------------------------------------------------- 4, 5. ranges, seeds
@pytest.mark.parametrize(
    "argv, needles",
    [
        ([*TINY, "--speed-mm-s", "inf"], ["--speed-mm-s must be finite", "inf"]),
        ([*TINY, "--speed-mm-s", "nan"], ["--speed-mm-s must be finite"]),
        ([*TINY, "--speed-mm-s", "500"], ["<= 100 mm/s", "speed limit"]),
        ([*TINY, "--k-rot", "30,30"], ["K_theta lists 30 twice"]),
        ([*TINY, "--presets", "rect-1,rect-1"], ["--presets lists 'rect-1' twice"]),
        ([*TINY, "--delta0", "1000"], ["delta0 must be <= 10 mm", "got 1000"]),
        ([*TINY, "--beta0", "-9"], ["|beta0| must be <= 5 deg", "small-angle"]),
        ([*TINY, "--k-rot", "1e4"], ["K_theta must be <= 300 N m/rad", "iiwa"]),
        ([*TINY, "--k-lat", "0"], ["K_lat must be > 0 N/m"]),
        ([*TINY, "--mu", "3"], ["friction must be <= 2"]),
        ([*TINY, "--repeats", "1e7"], ["--repeats", "1000"]),
        ([*TINY, "--repeats", "1"], ["--repeats", "two draws"]),
        ([*TINY, "--batch-worlds", "0"], ["--batch-worlds"]),
        (
            ["experiment", "sweep", "--geometry", "rect", "--grid", "full", "--repeats", "1000"],
            ["sweep's worlds", "480 cells", "1440000", "<= 1000000"],
        ),
        (["experiment", "compliance", "--geometry", "rect", "--repeats", "0"], ["--repeats"]),
        (
            ["experiment", "compliance", "--geometry", "rect", "--presets", "rect-2,rect-2"],
            ["--presets lists rect-2 twice"],
        ),
        (["experiment", "contact-check", "--worlds", "1e9"], ["--worlds"]),
        (
            ["experiment", "contact-check", "--preset", "rect-2", "--preset", "rect-2"],
            ["--preset lists rect-2 twice"],
        ),
        (
            ["experiment", "contact-check", "--preset", "rect-2", "--preset", "dual-1"],
            ["rect preset", "dual-1"],
        ),
    ],
)
def test_out_of_range_experiment_values_are_one_line(argv, needles, tmp_path, capsys, no_sim):
    out = tmp_path / "out"
    if argv[1] != "contact-check":
        argv = [*argv, "--out", out]
    rc, _, err = peghole(argv, capsys)
    assert rc == 2
    assert_one_line(err, *needles)
    assert not out.exists()


@pytest.mark.parametrize("command", COMMANDS)
def test_a_negative_seed_is_an_argparse_line(command, tmp_path, capsys, no_sim):
    rc, _, err = peghole([*COMMANDS[command], tmp_path / "o", "--seed", "-1"], capsys)
    assert rc == 2
    assert_one_line(err, "--seed", "-1")
    assert not (tmp_path / "o").exists()


def test_grid_ranges_come_from_validation_ranges():
    from peghole_mjx.core.validation import RANGES

    for kind, _, _ in sweep.GRID_AXES.values():
        assert kind in RANGES
    for kind in ("speed_mm_s", "repeats", "sweep_repeats", "grid_cells", "sweep_worlds"):
        assert kind in RANGES
    for grids in sweep.GRIDS.values():  # the named grids lie within them
        for g in grids.values():
            g.check()


# ---------------------------------------------------------------------- 6. damaged slices
def saved_part(tmp_path, n=4) -> Path:
    path = tmp_path / "rect-1_mu0.266_key_000000.npz"
    np.savez(path, **fake_summary(n, "rect"))
    return path


@pytest.mark.parametrize(
    "damage, why",
    [
        (lambda p: p.write_bytes(np.random.default_rng(0).bytes(3000)), "not an npz archive"),
        (lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]), "unreadable"),
        (lambda p: p.write_bytes(b""), "not an npz archive"),
        (lambda p: np.save(open(p, "wb"), np.zeros(3)), "not an npz archive"),
        (lambda p: np.savez(p, peak_fz=np.zeros(4)), "lacks"),
        (lambda p: np.savez(p, **{**fake_summary(3, "rect")}), "shape (3,), not (4,)"),
        (lambda p: np.savez(p, **{**fake_summary(4, "rect"), "nan": np.array(["x"] * 4)}), "<U1"),
    ],
)
def test_a_damaged_slice_is_named_and_set_aside(damage, why, tmp_path, capsys):
    path = saved_part(tmp_path)
    assert sweep._read_part(path, 4) is not None
    damage(path)
    damaged = path.read_bytes()
    assert sweep._read_part(path, 4) is None  # to be recomputed
    err = capsys.readouterr().err
    assert str(path) in err and why in err and "set aside" in err, err
    assert not path.exists()
    assert (tmp_path / (path.name + ".damaged")).read_bytes() == damaged  # kept, not deleted


def test_a_sweep_recomputes_a_damaged_slice_and_keeps_it(tmp_path, capsys, fake_sweep):
    out = tmp_path / "sweep"
    cfg = tiny_cfg(batch_worlds=4)
    first = sweep.run_sweep(cfg, out, progress=False)
    assert fake_sweep == [(0, 4), (4, 2)]
    part = sweep.part_path(cfg, out, "rect-1", 0.266, 4)
    part.write_bytes(b"PK\x03\x04garbage")
    fake_sweep.clear()
    again = sweep.run_sweep(cfg, out, progress=False)
    assert fake_sweep == [(4, 2)]  # only the damaged slice ran again
    assert again["cells"] == first["cells"]
    assert str(part) in capsys.readouterr().err
    assert part.with_name(part.name + ".damaged").read_bytes() == b"PK\x03\x04garbage"


def test_a_slice_as_written_passes_the_schema_check(tmp_path):
    res = fake_results()
    n, t = res["fz"].shape
    res.update(
        settle_s=0.1,
        both_frac=np.full((n, t), 0.9),
        penetration_in_hole_mm=np.full(n, 1e-3),
        penetration_two_point_mm=np.full(n, 1e-3),
    )
    summ = sweep._world_summary(res, "rect")
    assert set(summ) == set(fake_summary(n, "rect"))
    path = tmp_path / "p_000000.npz"
    sweep.outputs.write_npz(path, summ)
    back = sweep._read_part(path, n)
    assert back is not None and set(back) == set(summ)


# ---------------------------------------------------------------------- 7, 8. full disk, atomic
def test_a_full_disk_at_the_sweep_results_leaves_no_temporary_and_names_the_file(
    tmp_path, capsys, monkeypatch, fake_sweep
):
    out = tmp_path / "sweep"
    rc, _, _ = peghole([*TINY, "--out", out], capsys)
    assert rc == 0
    before = files_in(out)
    fsync_fails(monkeypatch, errno.ENOSPC, only="compliance_sweep_rect")
    rc, _, err = peghole([*TINY, "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, str(out / "compliance_sweep_rect.json"), "No space left on device")
    assert files_in(out) == before  # no temporary, every file as it was


def test_sweep_slices_and_figures_are_written_atomically_and_flushed(
    tmp_path, capsys, monkeypatch, fake_sweep
):
    synced: list[str] = []
    real = os.fsync

    def fsync(fd):
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        return real(fd)

    monkeypatch.setattr(fileio.os, "fsync", fsync)
    out = tmp_path / "sweep"
    rc, _, _ = peghole([*TINY, "--out", out], capsys)
    assert rc == 0
    part = sweep.part_path(tiny_cfg(), out, "rect-1", 0.266, 0)
    assert any(s.endswith(".tmp") and part.name in s for s in synced)  # the file
    assert str(part.parent) in synced  # and its folder, after the rename
    for name in ("compliance_sweep_rect.csv", "reduction_vs_regime_rect.png"):
        assert any(name in s for s in synced) and (out / name).stat().st_size > 0
    # a figure that fails to write leaves the old one and no temporary
    old = (out / "force_depth_rect.png").read_bytes()
    fsync_fails(monkeypatch, errno.ENOSPC, only="force_depth_rect")
    rc, _, err = peghole([*TINY, "--out", out], capsys)
    assert rc == 2 and "force_depth_rect.png" in err
    assert (out / "force_depth_rect.png").read_bytes() == old
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def fake_results(nan: bool = False) -> dict:
    """One preset's ``Extraction.run`` output (3 L_C x 2 repeats), synthetic."""
    t = np.linspace(0.0, 1.0, 400)
    n = 6
    depth = np.tile(149.0 - 155.0 * t, (n, 1))
    fz = np.abs(np.sin(np.outer(np.arange(1, n + 1), t * 6))) + 0.1
    return {
        "L_C": np.repeat([0.0, 0.075, 0.15], 2),
        "delta0": np.full(n, 2e-3),
        "beta0": np.full(n, 0.003),
        "depth_mm": depth,
        "fx": 0.1 * fz,
        "fy": 0.0 * fz,
        "fz": fz,
        "two_point": fz > 0.8,
        "time_s": t,
        "nan": np.full(n, nan),
        "penetration_mm": np.full(n, 1e-3),
        "h0_mm": 120.0,
    }


class FakeExtraction:
    nan = False

    def __init__(self, preset, cfg, mu=None):
        pass

    def run(self, progress=True, table=None):
        return fake_results(FakeExtraction.nan)


def test_compliance_outputs_are_replaced_atomically_on_a_full_disk(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cx, "Extraction", FakeExtraction)
    FakeExtraction.nan = False
    out = tmp_path / "out"
    argv = ["experiment", "compliance", "--geometry", "rect", "--presets", "rect-1"]
    rc, _, _ = peghole([*argv, "--repeats", "2", "--out", out], capsys)
    assert rc == 0
    before = files_in(out)
    assert set(before) == {"summary.json", "curves.csv", "force_depth.png", "peak_boxplot.png"}
    assert "NaN" not in before["summary.json"].decode()
    for name in sorted(before):  # a full disk at any one of them: that one stays as it was
        before = files_in(out)
        fsync_fails(monkeypatch, errno.ENOSPC, only=name)
        rc, _, err = peghole([*argv, "--repeats", "2", "--out", out], capsys)
        assert rc == 2
        assert_one_line(err, str(out / name), "No space left on device")
        assert files_in(out)[name] == before[name]
        assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
        monkeypatch.undo()
        monkeypatch.setattr(cx, "Extraction", FakeExtraction)


# ---------------------------------------------------------------------- 9. every world NaN
def test_a_compliance_run_with_every_world_nan_is_a_failure(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cx, "Extraction", FakeExtraction)
    FakeExtraction.nan = True
    out = tmp_path / "out"
    argv = ["experiment", "compliance", "--geometry", "rect", "--presets", "rect-1"]
    try:
        rc, _, err = peghole([*argv, "--repeats", "2", "--out", out], capsys)
    finally:
        FakeExtraction.nan = False
    assert rc == 2
    assert_one_line(err, "every one of its 6 worlds went NaN", "likely cause")
    assert files_in(out) == {}  # no result written


def test_a_sweep_with_every_world_nan_is_a_failure(tmp_path, capsys, fake_sweep):
    fake_sweep.nan = True
    out = tmp_path / "sweep"
    rc, _, err = peghole([*TINY, "--out", out, "--no-fix-cone-hessian"], capsys)
    assert rc == 2
    assert_one_line(err, "every one of its 6 worlds went NaN", "likely cause", "cone")
    assert not list(out.glob("compliance_sweep_*")) and not list(out.glob("*.png"))


def test_a_contact_check_with_every_world_nan_is_a_failure(tmp_path, capsys, monkeypatch):
    def run(preset, variant, worlds, seed, engine="mjx"):
        return {
            "preset": preset,
            "precision": "float32",
            "variant": dataclasses.asdict(variant),
            "summary": {"pass": {"all": False}},
            "worlds": [{"nan": True}] * worlds,
        }

    monkeypatch.setattr(cc, "run_variant", run)
    monkeypatch.setattr(cc, "table_row", lambda r: "row")
    out = tmp_path / "contact.json"
    rc, _, err = peghole(["experiment", "contact-check", "--worlds", "2", "--out", out], capsys)
    assert rc == 2
    assert_one_line(err, "contact check", "went NaN", "likely cause")
    assert not out.exists()
