"""``peghole experiment sweep``: the compliance experiment as a batched regime sweep.

The thesis never states the rotational stiffness of its Ch 2-3 experiments (erratum E12), and
the L_C effect scales with ``K_lat L_C^2 / K_theta``; so the experiment is mapped over a grid
(:data:`GRIDS`) instead of run at one guessed value. A cell fixes the preset, friction,
K_theta, K_lat, beta0 (its sign included), theta0 and delta0; its worlds are L_C at tip /
centre / top x ``repeats`` draws that scale delta0 and beta0 by factors in [0.75, 1.25]. The
draws depend only on the seed and the repeat index, so the worlds are paired across L_C (and
across cells). Per cell: the mean peak extraction force F_z per L_C, with and without the first
millimetres of the pull (:data:`~peghole_mjx.experiments.compliance.EARLY_MM`), the same for
|F|, the tip-vs-top and tip-vs-centre reductions with paired 95 % bootstrap intervals, and the
quasi-static oracle's prediction for the same worlds.

All worlds of one (preset, friction) pair run in one compiled batch, in slices of
``batch_worlds``; each finished slice is saved under ``OUT/parts/`` and found again on a rerun
(resume), keyed by the sweep's settings. The experiment's engine
(``ExperimentConfig.engine``: ``mjx``, batched, or ``mujoco``, MuJoCo C float64 one world at a
time) is one of those settings when it is not ``mjx``, and the result records it (``engine``).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import io
import itertools
import json
import math
import os
import socket
import sys
import time
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from tqdm import tqdm

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import RANGES, _num
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.experiments import outputs
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import OutputLock, _alive, _proc_start
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.specs import MM, PRESETS

#: thesis R1 (Sec 3.5): reductions of the mean peak extraction force, %
R1 = {"tip_vs_top": 77.1, "tip_vs_centre": 55.6}
BOOTSTRAP = 2000
#: force-depth curves are kept binned on the tip depth, mm per bin
CURVE_BIN_MM = {"rect": 2.5, "dual": 1.0}


@dataclass(frozen=True)
class Grid:
    """The sweep's parameter values (SI units in the names; angles in deg, thesis sign)."""

    presets: tuple[str, ...]
    k_rot_Nm_rad: tuple[float, ...]
    beta0_deg: tuple[float, ...]
    mu: tuple[float, ...]
    k_lat_N_m: tuple[float, ...] = (300.0,)
    delta0_mm: tuple[float, ...] = (2.0,)
    #: one extra arm per (K_theta, K_lat, delta0, mu) with this commanded tilt and beta0 = 0
    theta0_arm_deg: float | None = None
    repeats: int = 16
    #: the commanded tilt of the beta0 arms (thesis Table 2.2: -0.9 deg, erratum E3), deg
    theta0_deg: float = 0.0

    def cells(self) -> list[dict]:
        """Every cell of the grid, in a fixed order."""
        out = []
        for preset, mu, kr, kl, d0 in itertools.product(
            self.presets, self.mu, self.k_rot_Nm_rad, self.k_lat_N_m, self.delta0_mm
        ):
            arms = [(b, self.theta0_deg) for b in self.beta0_deg]
            if self.theta0_arm_deg is not None:
                arms.append((0.0, self.theta0_arm_deg))
            for b, th in arms:
                out.append(
                    {
                        "preset": preset,
                        "mu": mu,
                        "k_rot_Nm_rad": kr,
                        "k_lat_N_m": kl,
                        "delta0_mm": d0,
                        "beta0_deg": b,
                        "theta0_deg": th,
                    }
                )
        return out

    def check(self) -> Grid:
        """Validate the values against :data:`~peghole_mjx.core.validation.RANGES` (one clear line
        per problem): finite, in range, no value twice, a bounded number of cells and worlds."""
        if not self.presets:
            raise UserInputError("the sweep grid is empty: no presets")
        _no_duplicates("--presets", self.presets)
        for name, (kind, label, unit) in GRID_AXES.items():
            vals = getattr(self, name)
            if len(vals) == 0:
                raise UserInputError(f"the sweep grid is empty: no {name} values")
            _no_duplicates(label, vals)
            for v in vals:
                check_value(kind, v, label, unit)
        kinds = set()
        for p in self.presets:
            if p not in PRESETS:
                raise UserInputError(f"unknown preset {p!r}; known: {', '.join(PRESETS)}")
            kinds.add(PRESETS[p].kind)
        if len(kinds) > 1:
            raise UserInputError("a sweep runs one geometry: rect or dual presets, not both")
        check_value("sweep_repeats", self.repeats, "--repeats")
        check_value("theta0_deg", self.theta0_deg, "theta0", "deg")
        if self.theta0_arm_deg is not None:
            check_value("theta0_deg", self.theta0_arm_deg, "theta0 arm", "deg")
        n_cells = len(self.cells())
        what = "the grid's cells (presets x mu x K_theta x K_lat x delta0 x beta0 arms)"
        check_value("grid_cells", n_cells, what)
        what = f"the sweep's worlds ({n_cells} cells x 3 L_C x {self.repeats} repeats)"
        check_value("sweep_worlds", n_cells * 3 * self.repeats, what)
        return self

    @property
    def geometry(self) -> str:
        return PRESETS[self.presets[0]].kind


#: the grid's value axes: field -> (RANGES name, option, unit)
GRID_AXES = {
    "k_rot_Nm_rad": ("k_rot_Nm_rad", "K_theta", "N m/rad"),
    "beta0_deg": ("beta0_deg", "beta0", "deg"),
    "mu": ("friction", "friction", ""),
    "k_lat_N_m": ("k_lat_N_m", "K_lat", "N/m"),
    "delta0_mm": ("delta0_mm", "delta0", "mm"),
}


def check_value(kind: str, value, label: str, unit: str = "") -> float | int:
    """``value`` if it lies in ``RANGES[kind]``, else :class:`UserInputError` in one line that
    states the bound with its unit and reason (``K_theta must be > 0 N m/rad, got -3``)."""
    rng = RANGES[kind]
    if rng.problem(value) is None:
        return int(value) if rng.integer else float(value)
    u = f" {unit}" if unit else ""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise UserInputError(f"{label} must be finite, got {value!r}")
    if rng.integer and value != int(value):
        raise UserInputError(f"{label} must be a whole number, got {value!r}")
    got = f"{value:g}" if isinstance(value, float) else str(value)
    lo, hi = rng.lo, rng.hi
    if lo is not None and (value <= lo if rng.lo_open else value < lo):
        bound, why = f"{'>' if rng.lo_open else '>='} {_num(lo)}{u}", rng.why_lo
        if hi is not None and lo == -hi:  # a symmetric range: state the magnitude
            label, bound, why = f"|{label}|", f"<= {_num(hi)}{u}", rng.why_hi
    else:
        bound, why = f"{'<' if rng.hi_open else '<='} {_num(hi)}{u}", rng.why_hi
        if lo is not None and lo == -hi:
            label = f"|{label}|"
    raise UserInputError(f"{label} must be {bound}" + (f" ({why})" if why else "") + f", got {got}")


def _no_duplicates(label: str, values) -> None:
    seen = set()
    for v in values:
        if v in seen:
            raise UserInputError(
                f"{label} lists {v:g} twice"
                if isinstance(v, float)
                else f"{label} lists {v!r} twice"
            )
        seen.add(v)


#: named grids: "cpu" holds the cells that decide the question (issue's CPU subset), "full" the
#: whole grid (one command for a GPU), "tiny" is for tests
GRIDS: dict[str, dict[str, Grid]] = {
    "rect": {
        "cpu": Grid(("rect-2",), (300.0, 30.0, 3.0), (-0.2, 0.2), (0.266,)),
        "full": Grid(
            ("rect-2", "rect-3"),
            (300.0, 100.0, 30.0, 10.0, 3.0),
            (-0.2, 0.0, 0.2),
            (0.1, 0.266),
            k_lat_N_m=(300.0, 2000.0, 5000.0),
            delta0_mm=(1.0, 2.0),
            theta0_arm_deg=-0.9,
        ),
        "tiny": Grid(("rect-1",), (30.0,), (-0.2,), (0.266,), repeats=2),
    },
    "dual": {
        "cpu": Grid(("dual-2",), (300.0, 30.0, 3.0), (-0.2, 0.2), (0.266,)),
        "full": Grid(
            ("dual-2", "dual-3"),
            (300.0, 100.0, 30.0, 10.0, 3.0),
            (-0.2, 0.0, 0.2),
            (0.01, 0.266),
            k_lat_N_m=(300.0, 2000.0, 5000.0),
            delta0_mm=(1.0, 2.0),
            theta0_arm_deg=-0.9,
        ),
        "tiny": Grid(("dual-1",), (30.0,), (-0.2,), (0.266,), repeats=2),
    },
}


def repeat_factors(repeats: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The per-repeat scale factors of delta0 and beta0 (the same for every cell and L_C)."""
    rng = np.random.default_rng([seed, 2026])
    return rng.uniform(0.75, 1.25, repeats), rng.uniform(0.75, 1.25, repeats)


def cell_table(
    cell: dict, repeats: int, seed: int, exp: cx.ExperimentConfig | None = None
) -> dict[str, np.ndarray]:
    """The cell's worlds: L_C (tip, centre, top: ``exp``'s positions for the preset's geometry,
    the default config's when None) x repeats, SI, angles in rad."""
    md, mb = repeat_factors(repeats, seed)
    exp = exp or cx.ExperimentConfig()
    lc = np.array(exp.setup(PRESETS[cell["preset"]].kind).lc_mm) * MM
    n = len(lc) * repeats
    return {
        "L_C": np.repeat(lc, repeats),
        "delta0": np.tile(cell["delta0_mm"] * MM * md, len(lc)),
        "beta0": np.tile(np.radians(cell["beta0_deg"]) * mb, len(lc)),
        "theta0": np.full(n, math.radians(cell["theta0_deg"])),
        "k_lat": np.full(n, cell["k_lat_N_m"]),
        "k_rot": np.full(n, cell["k_rot_Nm_rad"]),
    }


def reduction_pct(tip: np.ndarray, ref: np.ndarray) -> float:
    """Reduction of the mean peak at the tip against a reference L_C, %."""
    return float(100.0 * (1.0 - np.mean(tip) / np.mean(ref)))


def paired_bootstrap(
    tip: np.ndarray, ref: np.ndarray, n: int = BOOTSTRAP, seed: int = 0
) -> list[float]:
    """95 % percentile interval of :func:`reduction_pct`, resampling repeats jointly."""
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(tip), size=(n, len(tip)))
    vals = 100.0 * (1.0 - tip[idx].mean(1) / ref[idx].mean(1))
    return [float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5))]


def _key(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:12]


def _world_summary(res: dict, geometry: str) -> dict[str, np.ndarray]:
    """What a slice keeps per world: peaks, contact statistics and a binned F_z curve."""
    early = cx.EARLY_MM[geometry]
    pk_all, pk_late = cx.peaks(res), cx.peaks(res, early)
    nw = len(res["L_C"])
    tp = res["two_point"]
    both = np.array(
        [float(np.mean(res["both_frac"][w][tp[w]])) if tp[w].any() else np.nan for w in range(nw)]
    )
    edges = np.arange(0.0, PRESETS_LENGTH[geometry] + 1e-9, CURVE_BIN_MM[geometry])
    curve = np.full((nw, len(edges) - 1), np.nan)
    moving = res["time_s"] > res["settle_s"]
    for w in range(nw):
        idx = np.digitize(res["depth_mm"][w], edges) - 1
        for i in np.unique(idx[moving & (idx >= 0) & (idx < len(edges) - 1)]):
            curve[w, i] = np.mean(res["fz"][w][moving & (idx == i)])
    return {
        "peak_fz": pk_all["fz"],
        "peak_fz_late": pk_late["fz"],
        "peak_mag": pk_all["mag"],
        "peak_mag_late": pk_late["mag"],
        "nan": res["nan"],
        "penetration_mm": res["penetration_mm"],
        "penetration_in_hole_mm": res["penetration_in_hole_mm"],
        "penetration_two_point_mm": res["penetration_two_point_mm"],
        "two_point_samples": tp.sum(1),
        "both_frac": both,
        "curve_fz": curve,
        "curve_edges_mm": edges,
    }


PRESETS_LENGTH = {
    "rect": max(s.length_mm for s in PRESETS.values() if s.kind == "rect"),
    "dual": max(s.length_mm for s in PRESETS.values() if s.kind == "dual"),
}


@dataclass(frozen=True)
class SweepConfig:
    """How a sweep runs: the grid, the seed, the slice size and the experiment's settings."""

    grid: Grid
    seed: int = 0
    batch_worlds: int = 96
    experiment: cx.ExperimentConfig = dataclasses.field(default_factory=cx.ExperimentConfig)
    #: the sweep runs with ``jax_enable_x64`` (set by the caller before any JAX work)
    x64: bool = False

    def settings(self) -> dict:
        """Everything that determines the results (the resume key)."""
        grid = dataclasses.asdict(self.grid)
        if grid["theta0_deg"] == 0.0:  # untilted sweeps keep the keys they had before it
            del grid["theta0_deg"]
        out = {
            "grid": grid,
            "seed": self.seed,
            "batch_worlds": self.batch_worlds,
            "experiment": cx.config_dict(self.experiment),
        }
        if self.x64:  # float32 sweeps keep the keys they had before this option existed
            out["precision"] = "float64"
        return out


def group_key(cfg: SweepConfig, preset: str, mu: float) -> str:
    """Resume key of the slices of one (preset, mu) scene: the settings with the grid narrowed
    to that preset and friction, so that widening a grid (another mu, another preset) reuses
    the slices already run. For a one-preset, one-mu grid it is the key of the whole sweep."""
    settings = cfg.settings()
    settings["grid"] = {**settings["grid"], "presets": [preset], "mu": [mu]}
    return _key(settings)


def part_path(cfg: SweepConfig, out: Path, preset: str, mu: float, s0: int) -> Path:
    """The file of the slice of worlds ``s0 ..`` of the (preset, mu) scene."""
    return Path(out) / "parts" / f"{preset}_mu{mu:g}_{group_key(cfg, preset, mu)}_{s0:06d}.npz"


def output_bytes(cfg: SweepConfig) -> int:
    """An upper estimate of what the sweep writes, bytes: per world its slice summary (peaks,
    flags and a binned F_z curve in float64), per cell its rows in the JSON and CSV, and the
    figures."""
    g = cfg.grid.geometry
    bins = math.ceil(PRESETS_LENGTH[g] / CURVE_BIN_MM[g])
    cells = len(cfg.grid.cells())
    worlds = cells * 3 * cfg.grid.repeats
    return 2 * 2**20 + worlds * (8 * bins + 2 * 2**10) + cells * (3 * 12 * bins + 16 * 2**10)


def settings_path(out: Path, geometry: str) -> Path:
    """The record of the parameters of the ``geometry`` sweep in ``out`` (written at its
    start: what a rerun must match to resume)."""
    return Path(out) / f".compliance_sweep_{geometry}.settings.json"


def _recorded_settings(out: Path, geometry: str) -> tuple[dict | None, dict]:
    """``(settings, holder)`` recorded for the sweep in ``out``: its settings record, else the
    ``settings`` of its results (written before 2026-12-04); ``(None, {})`` if neither."""
    for path, key in (
        (settings_path(out, geometry), "settings"),
        (Path(out) / f"compliance_sweep_{geometry}.json", "settings"),
    ):
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError, RecursionError):
            continue
        if isinstance(doc, dict) and isinstance(doc.get(key), dict):
            holder = doc.get("written_by")
            return doc[key], holder if isinstance(holder, dict) else {}
    return None, {}


def check_settings(cfg: SweepConfig, out: Path, force: bool, record: bool = True) -> None:
    """One set of parameters per sweep output (decided 2026-12-04): a sweep into ``out`` whose
    parameters differ from those recorded there is refused in one line naming the first
    differences (a rerun with the same ones resumes; ``force`` replaces the record, and at
    the end the results). ``record``: write this sweep's parameters as the record."""
    geometry = cfg.grid.geometry
    mine = json.loads(json.dumps(clean_json(cfg.settings())))
    recorded, holder = _recorded_settings(out, geometry)
    if recorded is not None and recorded != mine and not force:
        diff = fileio.differences(mine, recorded, whole="settings")
        by = f" by pid {holder['pid']} on {holder.get('host', '?')}" if "pid" in holder else ""
        raise UserInputError(
            f"--out {out} holds a {geometry} sweep of other parameters (recorded{by}; "
            f"differing: {fileio.describe_files(diff, 4)}): nothing was run; rerun with the same "
            "parameters to resume it, give another --out, or pass --force to replace its results"
        )
    if record and (recorded != mine or force):
        doc = {
            "settings": mine,
            "written_by": {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "command": "peghole experiment sweep",
            },
        }
        fileio.write_text(settings_path(out, geometry), json.dumps(doc, indent=1) + "\n")


def _lock(out: Path, geometry: str) -> OutputLock:
    return OutputLock(
        Path(out) / f"compliance_sweep_{geometry}.json",
        f"peghole experiment sweep --geometry {geometry}",
    )


def run_sweep(cfg: SweepConfig, out: Path, progress: bool = True, force: bool = False) -> dict:
    """Run (or resume) the sweep into ``out``; returns the result dict (also written as
    ``out/compliance_sweep_<geometry>.json`` and ``.csv``).

    Before the first simulation step the grid and ``out`` are checked (a writable folder with
    room for an estimate of the output). A damaged slice file is set aside (renamed
    ``*.damaged``) and recomputed; a slice claimed by a live process is waited for (at most
    :data:`CLAIM_WAIT_S`, with a notice naming the holder). A sweep whose every world went NaN
    raises :class:`~peghole_mjx.experiments.compliance.DivergedError` instead of writing a
    result. Parameters that differ from those recorded in ``out`` are refused unless ``force``
    (:func:`check_settings`); processes of the same parameters share the folder (slice
    claims), and the results are written under the output's lock
    (:class:`~peghole_mjx.files.lock.OutputLock`)."""
    grid = cfg.grid.check()
    geometry = grid.geometry
    exp = dataclasses.replace(cfg.experiment, geometry=geometry)
    cfg = dataclasses.replace(cfg, experiment=exp)
    check_value("batch_worlds", cfg.batch_worlds, "--batch-worlds")
    check_value("seed", cfg.seed, "--seed")
    check_value("speed_mm_s", exp.speed_m_s * 1e3, "--speed-mm-s", "mm/s")
    out = outputs.check_out(out, output_bytes(cfg))
    fileio.check_out_dir(out / "parts", "--out")
    with _lock(out, geometry):
        check_settings(cfg, out, force)
    cells = grid.cells()
    t0 = time.time()
    # group the cells by (preset, mu): one compiled scene each
    groups: dict[tuple[str, float], list[int]] = {}
    for i, c in enumerate(cells):
        groups.setdefault((c["preset"], c["mu"]), []).append(i)
    per_cell: dict[int, dict[str, np.ndarray]] = {}
    n_slices = sum(
        math.ceil(len(ix) * 3 * grid.repeats / cfg.batch_worlds) for ix in groups.values()
    )
    bar = tqdm(total=n_slices, desc=f"sweep {geometry}", disable=not progress)
    try:  # the bar is closed before an error line is printed
        for (preset, mu), ix in groups.items():
            tabs = [cell_table(cells[i], grid.repeats, cfg.seed, cfg.experiment) for i in ix]
            table = {k: np.concatenate([t[k] for t in tabs]) for k in cx.WORLD_KEYS}
            owner = np.repeat(np.arange(len(ix)), 3 * grid.repeats)
            nw = len(owner)
            summaries: dict[int, dict] = {}
            deferred: list[int] = []
            ex = None
            for s0 in range(0, nw, cfg.batch_worlds):
                path = part_path(cfg, out, preset, mu, s0)
                n = min(cfg.batch_worlds, nw - s0)
                summ = _read_part(path, n)
                if summ is None:
                    if not _claim(path):  # another process of the same sweep is running this slice
                        deferred.append(s0)
                        continue
                    ex = cx.Extraction(preset, exp, mu=mu) if ex is None else ex
                    summ = _run_slice(ex, table, s0, cfg.batch_worlds, nw, geometry, path)
                summaries[s0] = summ
                bar.update()
            for s0 in deferred:
                path = part_path(cfg, out, preset, mu, s0)
                n = min(cfg.batch_worlds, nw - s0)
                summ = None
                while summ is None:
                    if _wait_for_slice(path):  # written by its holder
                        summ = _read_part(path, n)  # None: damaged, set aside
                    else:  # its holder ended without writing it: the claim is ours
                        ex = cx.Extraction(preset, exp, mu=mu) if ex is None else ex
                        summ = _run_slice(ex, table, s0, cfg.batch_worlds, nw, geometry, path)
                summaries[s0] = summ
                bar.update()
            summaries = [summaries[k] for k in sorted(summaries)]
            merged = {
                k: (
                    summaries[0][k]
                    if k == "curve_edges_mm"
                    else np.concatenate([s[k] for s in summaries])
                )
                for k in summaries[0]
                if all(k in s for s in summaries)  # a key added to the summaries since a part ran
            }
            for j, i in enumerate(ix):
                sel = owner == j
                per_cell[i] = {
                    k: (v if k == "curve_edges_mm" else v[sel]) for k, v in merged.items()
                }
                per_cell[i]["table"] = tabs[j]
    finally:
        bar.close()
    cx.check_not_all_nan(
        np.concatenate([per_cell[i]["nan"] for i in range(len(cells))]),
        f"the {geometry} sweep in {out}",
        cx.nan_cause(exp, x64=cfg.x64, k_rot_min=min(grid.k_rot_Nm_rad)),
    )
    rows = [_cell_result(cells[i], per_cell[i], grid, cfg.seed, exp) for i in range(len(cells))]
    result = {
        "geometry": geometry,
        "engine": exp.engine,
        "cells": rows,
        "best_match_R1": best_match(rows),
        "thesis": {"R1_reduction_pct": R1, "source": cx.THESIS["source"]},
        "settings": cfg.settings(),
        "runtime_s": round(time.time() - t0, 1),
        **provenance(),
    }
    with _lock(out, geometry):
        # a sweep of other parameters started with --force meanwhile owns the output now
        check_settings(cfg, out, force=False, record=False)
        write_results(result, out)
    return result


#: what a slice file holds per world (besides ``curve_edges_mm``, the curve bins' edges);
#: parts written before a key existed may lack the optional ones
PART_KEYS = (
    "peak_fz",
    "peak_fz_late",
    "peak_mag",
    "peak_mag_late",
    "nan",
    "penetration_mm",
    "two_point_samples",
    "curve_fz",
)
PART_OPTIONAL_KEYS = ("penetration_in_hole_mm", "penetration_two_point_mm", "both_frac")
#: what reading a damaged npz can raise (random bytes: "pickled data"; truncated: zip errors)
_NPZ_ERRORS = (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def _part_problem(d: dict[str, np.ndarray], n: int) -> str | None:
    """What is wrong with the arrays of a slice of ``n`` worlds, or None."""
    missing = [k for k in (*PART_KEYS, "curve_edges_mm") if k not in d]
    if missing:
        return f"it lacks {', '.join(missing)}"
    for k, v in d.items():
        if v.dtype.kind not in "biuf":
            return f"{k} holds {v.dtype} values, not numbers"
    edges = d["curve_edges_mm"]
    if edges.ndim != 1 or len(edges) < 2 or not np.all(np.diff(edges) > 0):
        return "curve_edges_mm is not an increasing list of bin edges"
    for k in (*PART_KEYS, *PART_OPTIONAL_KEYS):
        if k not in d:
            continue
        want = (n, len(edges) - 1) if k == "curve_fz" else (n,)
        if d[k].shape != want:
            return f"{k} has shape {d[k].shape}, not {want} ({n} worlds)"
    return None


def _read_part(path: Path, n: int) -> dict[str, np.ndarray] | None:
    """The slice saved in ``path`` (``n`` worlds), schema-checked; None if there is none. A
    damaged file is set aside (renamed ``*.damaged``, not deleted) with a warning naming it,
    and None returned, so that the slice is recomputed."""
    try:
        with open(path, "rb") as f:
            is_zip = f.read(4) == b"PK\x03\x04"
        z = np.load(path, allow_pickle=False) if is_zip else None
    except FileNotFoundError:
        return None
    except _NPZ_ERRORS as exc:
        problem = f"unreadable: {' '.join(str(exc).split()) or type(exc).__name__}"
    else:
        if not isinstance(z, np.lib.npyio.NpzFile):
            problem = "not an npz archive"
        else:
            try:
                with z:
                    d = {k: z[k] for k in z.files}
            except _NPZ_ERRORS as exc:
                problem = f"unreadable: {' '.join(str(exc).split()) or type(exc).__name__}"
            else:
                problem = _part_problem(d, n)
                if problem is None:
                    return d
    _set_aside(path, problem)
    return None


def _set_aside(path: Path, problem: str) -> None:
    dest = path.with_name(path.name + ".damaged")
    k = 1
    while dest.exists():
        dest = path.with_name(f"{path.name}.damaged{k}")
        k += 1
    try:
        os.rename(path, dest)
    except FileNotFoundError:  # another process of the sweep set it aside first
        return
    fileio.fsync_dir(path.parent)
    tqdm.write(
        f"warning: sweep slice {path} is damaged ({problem}); set aside as {dest.name}, "
        "recomputing it",
        file=sys.stderr,
    )


#: a slice claimed by a live process is waited for at most this long, s, polled every
#: CLAIM_POLL_S, with a notice every CLAIM_NOTICE_S; then the sweep stops naming the holder
#: (rerun the command once that process has ended: it resumes from the saved slices)
CLAIM_WAIT_S = 3 * 3600.0
CLAIM_POLL_S = 5.0
CLAIM_NOTICE_S = 600.0


class SliceClaimedError(UserInputError):
    """A slice stayed claimed by a live process for longer than :data:`CLAIM_WAIT_S`."""


def _claim_record() -> dict:
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "start": _proc_start(os.getpid()),
        "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def _claim_holder(claim: Path) -> dict | None:
    """A claim's record: ``{"pid", "host", "start", "since"}`` (a claim of an older version
    holds only the PID), ``{}`` if unreadable, None if there is no claim."""
    try:
        text = claim.read_text()
    except FileNotFoundError:
        return None
    except OSError:
        return {}
    try:
        rec = json.loads(text)
    except ValueError:
        return {}
    if isinstance(rec, int) and not isinstance(rec, bool):
        return {"pid": rec}  # an older version's claim: the PID only
    return rec if isinstance(rec, dict) else {}


def _claim_is_ours(rec: dict) -> bool:
    return rec.get("pid") == os.getpid() and rec.get("host", socket.gethostname()) == (
        socket.gethostname()
    )


def _claim_stale(rec: dict) -> str | None:
    """Why the claim ``rec`` is stale (its process is gone or its PID now names another
    process), or None while its process may still be running (or cannot be checked)."""
    pid = rec.get("pid")
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return "the claim is unreadable"
    if rec.get("host", socket.gethostname()) != socket.gethostname():
        return None  # another host's processes cannot be checked from here
    if not _alive(pid) or _zombie(pid):
        return f"pid {pid} is gone"
    start = _proc_start(pid)
    if rec.get("start") is not None and start is not None and start != rec["start"]:
        return f"pid {pid} now belongs to another process (started later)"
    return None


def _zombie(pid: int) -> bool:
    """Whether ``pid`` has ended but not been reaped by its parent (Linux ``/proc``)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[-1].split()[0] == "Z"


def _describe_holder(rec: dict) -> str:
    host = f" on {rec['host']}" if rec.get("host") else ""
    since = f", since {rec['since']}" if rec.get("since") else ""
    return f"pid {rec.get('pid', '?')}{host}{since}"


def _claim(path: Path) -> bool:
    """Take the slice ``path`` for this process, so that several processes can share one
    sweep folder. The claim (``.claim`` beside it) records the PID, host and start time of the
    process, and is created complete (written under a temporary name, then hard-linked). A
    claim whose process is gone, or whose PID now belongs to a later process, is taken over
    with a warning. False while a live process holds it."""
    claim = path.with_suffix(".claim")
    tmp = claim.with_name(f".{claim.name}.{os.getpid()}")
    tmp.write_text(json.dumps(_claim_record()) + "\n")
    try:
        for _ in range(3):
            try:
                os.link(tmp, claim)  # atomic: fails if a claim exists
                return True
            except FileExistsError:
                pass
            rec = _claim_holder(claim)
            if rec is None:
                continue  # released meanwhile
            if _claim_is_ours(rec):
                return True
            why = _claim_stale(rec)
            if why is None:
                return False
            # set the stale claim aside under a private name, then check it is the one read
            # (not a fresh claim another process made meanwhile)
            mine = claim.with_name(f".{claim.name}.stale.{os.getpid()}")
            try:
                os.rename(claim, mine)
            except FileNotFoundError:
                continue
            if _claim_holder(mine) != rec:
                with contextlib.suppress(OSError):
                    os.link(mine, claim)  # put it back
                mine.unlink(missing_ok=True)
                continue
            mine.unlink(missing_ok=True)
            tqdm.write(
                f"warning: taking over sweep slice {path.name}: its claim ({_describe_holder(rec)}"
                f") is stale, {why}",
                file=sys.stderr,
            )
        return False
    finally:
        tmp.unlink(missing_ok=True)


def _release(path: Path) -> None:
    """Remove this process's claim of the slice ``path``."""
    claim = path.with_suffix(".claim")
    rec = _claim_holder(claim)
    if rec and _claim_is_ours(rec):
        claim.unlink(missing_ok=True)


def _wait_for_slice(path: Path) -> bool:
    """Wait for the live process that claimed the slice ``path``: True once its file exists,
    False once the claim is ours (its holder ended without writing it). A notice naming the
    holder is printed when the wait starts and every :data:`CLAIM_NOTICE_S`; after
    :data:`CLAIM_WAIT_S` :class:`SliceClaimedError` names it."""
    t0 = last = time.monotonic()
    first = True
    while True:
        if path.exists():
            return True
        if _claim(path):
            return False
        rec = _claim_holder(path.with_suffix(".claim")) or {}
        now = time.monotonic()
        if now - t0 >= CLAIM_WAIT_S:
            raise SliceClaimedError(
                f"sweep slice {path} is still claimed by {_describe_holder(rec)} after "
                f"{now - t0:.0f} s: rerun this command when that process has ended (it resumes "
                f"from the saved slices), or delete {path.with_suffix('.claim')} if that process "
                "is not a peghole sweep"
            )
        if first or now - last >= CLAIM_NOTICE_S:
            tqdm.write(
                f"waiting for sweep slice {path.name}, claimed by {_describe_holder(rec)} "
                f"(at most {CLAIM_WAIT_S:.0f} s)",
                file=sys.stderr,
            )
            first, last = False, now
        time.sleep(CLAIM_POLL_S)


def _simulate_slice(
    ex: cx.Extraction,
    table: dict[str, np.ndarray],
    s0: int,
    batch: int,
    nw: int,
    geometry: str,
) -> dict[str, np.ndarray]:
    """Run worlds ``s0 .. s0 + batch`` (on ``mjx`` the last slice is padded to the compiled
    batch size; the ``mujoco`` engine needs no padding)."""
    n = min(batch, nw - s0)
    pad = np.r_[np.arange(s0, s0 + n), np.full(batch - n if ex.engine == "mjx" else 0, s0)]
    res = ex.run(progress=False, table={k: v[pad] for k, v in table.items()})
    summ = _world_summary(res, geometry)
    return {k: (v if k == "curve_edges_mm" else v[:n]) for k, v in summ.items()}


def _run_slice(
    ex: cx.Extraction,
    table: dict[str, np.ndarray],
    s0: int,
    batch: int,
    nw: int,
    geometry: str,
    path: Path,
) -> dict[str, np.ndarray]:
    """Run a slice (:func:`_simulate_slice`), save its summaries atomically to ``path`` (file
    and folder flushed to disk) and release the claim, also when it fails."""
    try:
        summ = _simulate_slice(ex, table, s0, batch, nw, geometry)
        outputs.write_npz(path, summ)
    finally:
        _release(path)
    return summ


def h0_mm(preset: str, exp: cx.ExperimentConfig) -> float:
    """Start depth of the tip: the hole depth less the start gap above the floor."""
    return PRESETS[preset].hole_depth_mm - exp.sim_options().tip_gap_mm


def _cell_result(cell: dict, d: dict, grid: Grid, seed: int, exp: cx.ExperimentConfig) -> dict:
    geometry = PRESETS[cell["preset"]].kind
    lcs = exp.setup(geometry).lc_mm
    r = grid.repeats
    tab = d["table"]
    h0 = h0_mm(cell["preset"], exp)
    qs = cx.quasi_static(cell["preset"], cell["mu"], tab, h0)
    qs_late = cx.quasi_static_peaks(qs, h0, cx.EARLY_MM[geometry])
    qs_all = cx.quasi_static_peaks(qs, h0, 0.0)
    out = dict(cell)
    out["n_worlds"] = len(tab["L_C"])
    out["nan_worlds"] = int(np.sum(d["nan"]))
    out["max_penetration_um"] = float(np.nanmax(d["penetration_mm"]) * 1e3)
    if "penetration_in_hole_mm" in d:
        out["max_penetration_in_hole_um"] = float(np.nanmax(d["penetration_in_hole_mm"]) * 1e3)
    if "penetration_two_point_mm" in d:
        tp = np.asarray(d["penetration_two_point_mm"], float)
        out["max_penetration_two_point_um"] = (
            float(np.nanmax(tp) * 1e3) if np.isfinite(tp).any() else None
        )
    out["penetration_limit_um"] = 0.25 * PRESETS[cell["preset"]].radial_clearance_mm * 1e3
    out["two_point_worlds"] = {
        f"{lc:g}": int(np.sum(d["two_point_samples"][k * r : (k + 1) * r] > 0))
        for k, lc in enumerate(lcs)
    }
    for metric, label in (
        ("peak_fz_late", "peak_fz_N"),
        ("peak_fz", "peak_fz_all_N"),
        ("peak_mag_late", "peak_mag_N"),
        ("peak_mag", "peak_mag_all_N"),
    ):
        by = [d[metric][k * r : (k + 1) * r] for k in range(3)]
        out[label] = {f"{lc:g}": float(np.nanmean(v)) for lc, v in zip(lcs, by, strict=True)}
        ok = np.all(np.isfinite(np.stack(by)), axis=0)
        tip, ctr, top = (v[ok] for v in by)
        sfx = label.replace("peak_", "").replace("_N", "")
        pairs = [("tip_vs_top", tip, top), ("tip_vs_centre", tip, ctr)]
        if sfx == "fz":  # R2's full ordering (tip < centre < top) needs the centre vs the top
            pairs.append(("centre_vs_top", ctr, top))
        for name, a, ref in pairs:
            k = f"reduction_{name}_pct" + ("" if sfx == "fz" else f"_{sfx}")
            out[k] = (
                {
                    "value": reduction_pct(a, ref),
                    "ci95": paired_bootstrap(a, ref, seed=seed),
                    "n_pairs": int(ok.sum()),
                }
                if ok.sum() >= 2
                else {"value": None, "ci95": None, "n_pairs": int(ok.sum())}
            )
    qby = [qs_late[k * r : (k + 1) * r] for k in range(3)]
    qall = [qs_all[k * r : (k + 1) * r] for k in range(3)]
    out["quasi_static"] = {
        "peak_fz_N": {f"{lc:g}": float(np.nanmean(v)) for lc, v in zip(lcs, qby, strict=True)},
        "reduction_tip_vs_top_pct": reduction_pct(qby[0], qby[2]),
        "reduction_tip_vs_centre_pct": reduction_pct(qby[0], qby[1]),
        "reduction_centre_vs_top_pct": reduction_pct(qby[1], qby[2]),
        "reduction_tip_vs_top_all_pct": reduction_pct(qall[0], qall[2]),
    }
    top_lc = lcs[-1] * MM
    out["regime_KxLc2_over_Ktheta"] = cell["k_lat_N_m"] * top_lc**2 / cell["k_rot_Nm_rad"]
    out["curve_fz_N"] = {
        f"{lc:g}": np.round(np.nanmean(d["curve_fz"][k * r : (k + 1) * r], axis=0), 4).tolist()
        for k, lc in enumerate(lcs)
    }
    out["curve_edges_mm"] = np.round(d["curve_edges_mm"], 3).tolist()
    return out


def best_match(rows: list[dict]) -> dict | None:
    """The cell whose simulated reductions are closest to R1 (Euclidean, in points)."""
    best, dist = None, math.inf
    for row in rows:
        a = row["reduction_tip_vs_top_pct"]["value"]
        b = row["reduction_tip_vs_centre_pct"]["value"]
        if a is None or b is None:
            continue
        dd = math.hypot(a - R1["tip_vs_top"], b - R1["tip_vs_centre"])
        if dd < dist:
            best, dist = row, dd
    if best is None:
        return None
    keys = ("preset", "mu", "k_rot_Nm_rad", "k_lat_N_m", "delta0_mm", "beta0_deg", "theta0_deg")
    return {
        "cell": {k: best[k] for k in keys},
        "reduction_tip_vs_top_pct": best["reduction_tip_vs_top_pct"],
        "reduction_tip_vs_centre_pct": best["reduction_tip_vs_centre_pct"],
        "quasi_static": best["quasi_static"],
        "distance_points": dist,
        "r1_in_ci95_tip_vs_top": bool(
            best["reduction_tip_vs_top_pct"]["ci95"][0]
            <= R1["tip_vs_top"]
            <= best["reduction_tip_vs_top_pct"]["ci95"][1]
        ),
    }


CSV_COLUMNS = (
    "preset",
    "mu",
    "k_rot_Nm_rad",
    "k_lat_N_m",
    "delta0_mm",
    "beta0_deg",
    "theta0_deg",
    "n_worlds",
    "nan_worlds",
    "max_penetration_um",
    "regime_KxLc2_over_Ktheta",
)


def write_results(result: dict, out: Path) -> list[Path]:
    """``compliance_sweep_<geometry>.json`` (everything) and ``.csv`` (one row per cell)."""
    g = result["geometry"]
    jpath = out / f"compliance_sweep_{g}.json"
    cpath = out / f"compliance_sweep_{g}.csv"
    lcs = lc_positions(result)
    f = io.StringIO()
    w = csv.writer(f)
    w.writerow(
        [*CSV_COLUMNS]
        + [f"peak_fz_N_LC{lc:g}" for lc in lcs]
        + ["red_tip_top_pct", "red_tip_top_lo", "red_tip_top_hi"]
        + ["red_tip_centre_pct", "red_tip_centre_lo", "red_tip_centre_hi"]
        + ["qs_red_tip_top_pct", "qs_red_tip_centre_pct"]
    )
    for row in result["cells"]:
        t, c = row["reduction_tip_vs_top_pct"], row["reduction_tip_vs_centre_pct"]
        w.writerow(
            [_fmt(row[k]) for k in CSV_COLUMNS]
            + [_fmt(row["peak_fz_N"][f"{lc:g}"]) for lc in lcs]
            + [_fmt(t["value"]), *(_fmt(x) for x in (t["ci95"] or [None, None]))]
            + [_fmt(c["value"]), *(_fmt(x) for x in (c["ci95"] or [None, None]))]
            + [
                _fmt(row["quasi_static"]["reduction_tip_vs_top_pct"]),
                _fmt(row["quasi_static"]["reduction_tip_vs_centre_pct"]),
            ]
        )
    outputs.write_text(jpath, json.dumps(clean_json(result), indent=1, allow_nan=False))
    outputs.write_text(cpath, f.getvalue())
    return [jpath, cpath]


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def clean_json(o):
    """``o`` with NaN/inf floats as None and NumPy scalars as Python ones (valid JSON)."""
    if isinstance(o, dict):
        return {k: clean_json(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [clean_json(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


def lc_positions(result: dict) -> tuple[float, ...]:
    """The L_C positions (mm above the tip) of a sweep result: its experiment's, recorded in
    its settings when they are not the defaults (``compliance.config_dict``)."""
    g = result["geometry"]
    recorded = result.get("settings", {}).get("experiment", {}).get(g)
    return tuple(recorded["lc_mm"]) if recorded else cx.ExperimentConfig().setup(g).lc_mm


def summary_table(result: dict) -> str:
    """A markdown table of the cells: simulated reductions with intervals beside the oracle's."""
    lcs = lc_positions(result)

    def red(d):
        if d["value"] is None:
            return "-"
        lo, hi = d["ci95"]
        return f"{d['value']:.1f} [{lo:.1f}, {hi:.1f}]"

    head = (
        "| preset | mu | K_theta N m/rad | K_lat N/m | delta0 mm | beta0 deg | theta0 deg | "
        + " | ".join(f"peak F_z L_C={lc:g} N" for lc in lcs)
        + " | tip vs top % (95 % CI) | oracle | tip vs centre % (95 % CI) | oracle |\n|"
        + "---|" * (11 + len(lcs))
    )
    rows = [head]
    for c in result["cells"]:
        q = c["quasi_static"]
        rows.append(
            f"| {c['preset']} | {c['mu']:g} | {c['k_rot_Nm_rad']:g} | {c['k_lat_N_m']:g} | "
            f"{c['delta0_mm']:g} | {c['beta0_deg']:g} | {c['theta0_deg']:g} | "
            + " | ".join(f"{c['peak_fz_N'][f'{lc:g}']:.3g}" for lc in lcs)
            + f" | {red(c['reduction_tip_vs_top_pct'])} | {q['reduction_tip_vs_top_pct']:.1f} | "
            f"{red(c['reduction_tip_vs_centre_pct'])} | {q['reduction_tip_vs_centre_pct']:.1f} |"
        )
    return "\n".join(rows)


def _force_depth_cells(result: dict) -> list[dict]:
    """The cells whose force-depth curves are drawn: one friction in the grid: the cell
    nearest R1 and a stiffest-K_theta cell; several: the cell where the oracle predicts the
    largest tip-vs-top reduction, the same cell at every other friction, and the stiffest
    K_theta at its friction (R2: mu 0.01 against 0.266)."""
    cells = result["cells"]
    stiff_k = max(c["k_rot_Nm_rad"] for c in cells)
    mus = sorted({c["mu"] for c in cells})
    if len(mus) == 1:
        best = result.get("best_match_R1")
        shown = []
        if best is not None:
            shown.append(next(c for c in cells if all(c[k] == v for k, v in best["cell"].items())))
        shown += [c for c in cells if c["k_rot_Nm_rad"] == stiff_k][:1]
        return shown
    focus = max(cells, key=lambda c: c["quasi_static"]["reduction_tip_vs_top_pct"])
    keys = ("preset", "k_rot_Nm_rad", "k_lat_N_m", "delta0_mm", "beta0_deg", "theta0_deg")
    shown = [focus]
    for mu in mus:
        if mu != focus["mu"]:
            shown += [c for c in cells if c["mu"] == mu and all(c[k] == focus[k] for k in keys)]
    shown += [
        c
        for c in cells
        if c["mu"] == focus["mu"]
        and c["k_rot_Nm_rad"] == stiff_k
        and c["beta0_deg"] == focus["beta0_deg"]
        and c is not focus
    ][:1]
    return shown


def write_figures(result: dict, out: Path) -> list[Path]:
    """``reduction_vs_regime_<g>.png`` (simulated reductions with intervals over the oracle's,
    against K_lat L_C,top^2 / K_theta, R1 marked) and ``force_depth_<g>.png`` (mean F_z against
    depth per L_C: the cell nearest R1 beside a K_theta = 300 N m/rad cell)."""
    matplotlib.use("Agg")

    g = result["geometry"]
    out = Path(out)
    cells = result["cells"]
    paths = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    arms = sorted({(c["beta0_deg"], c["theta0_deg"], c["mu"], c["preset"]) for c in cells})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (key, thesis) in zip(
        axes,
        (("tip_vs_top", R1["tip_vs_top"]), ("tip_vs_centre", R1["tip_vs_centre"])),
        strict=True,
    ):
        for i, arm in enumerate(arms):
            sel = sorted(
                (
                    c
                    for c in cells
                    if (c["beta0_deg"], c["theta0_deg"], c["mu"], c["preset"]) == arm
                ),
                key=lambda c: c["regime_KxLc2_over_Ktheta"],
            )
            x = np.array([c["regime_KxLc2_over_Ktheta"] for c in sel])
            sim = [c[f"reduction_{key}_pct"] for c in sel]
            y = np.array([s["value"] if s["value"] is not None else np.nan for s in sim])
            lo = np.array([s["ci95"][0] if s["ci95"] else np.nan for s in sim])
            hi = np.array([s["ci95"][1] if s["ci95"] else np.nan for s in sim])
            qs = np.array([c["quasi_static"][f"reduction_{key}_pct"] for c in sel])
            col = colours[i % len(colours)]
            label = f"{arm[3]} mu {arm[2]:g}, beta0 {arm[0]:+g} deg" + (
                f", theta0 {arm[1]:g} deg" if arm[1] else ""
            )
            ax.plot(x, qs, "--", color=col, alpha=0.7)
            ax.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o", color=col, capsize=3, label=label)
        if g == "rect":
            ax.axhline(thesis, color="k", lw=1, ls=":", label=f"thesis R1 {thesis} %")
        ax.set_xscale("log")
        ax.set_xlabel("K_lat L_C,top^2 / K_theta  (dimensionless)")
        ax.set_title(f"{g}: peak F_z reduction, L_C tip vs {key.split('_')[-1]}")
        ax.axhline(0.0, color="grey", lw=0.5)
    axes[0].set_ylabel("peak F_z reduction, % (dashed: oracle)")
    axes[1].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    paths.append(outputs.write_png(fig, out / f"reduction_vs_regime_{g}.png", dpi=110))
    plt.close(fig)

    shown = _force_depth_cells(result)
    if shown:
        fig, axes = plt.subplots(1, len(shown), figsize=(5.5 * len(shown), 4), squeeze=False)
        for ax, c in zip(axes[0], shown, strict=True):
            e = np.array(c["curve_edges_mm"])
            mid = 0.5 * (e[1:] + e[:-1])
            for lc, curve in c["curve_fz_N"].items():
                ax.plot(mid, np.array(curve, float), label=f"L_C = {lc} mm")
            ax.invert_xaxis()
            ax.set_xlabel("tip depth below the mouth, mm")
            ax.set_ylabel("mean F_z over the repeats, N")
            ax.set_title(
                f"{c['preset']} K_theta {c['k_rot_Nm_rad']:g} N m/rad, beta0 {c['beta0_deg']:+g}"
                f" deg, mu {c['mu']:g}",
                fontsize=9,
            )
            ax.legend(fontsize=8)
        fig.tight_layout()
        paths.append(outputs.write_png(fig, out / f"force_depth_{g}.png", dpi=110))
        plt.close(fig)
    return paths
