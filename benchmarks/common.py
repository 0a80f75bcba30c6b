"""The lowest layer of the benchmarks: what every kind shares.

* where results go: ``benchmarks/results/<kind>/`` (:data:`PERF_RESULTS`, ...), one folder
  per kind of script (perf, baselines, evals, studies);
* the table registry: a script module registers the docs tables built from its results with
  :func:`table`; ``python -m benchmarks.tables`` collects them and rewrites the docs;
* the throughput CSV's columns and scenes, versions, devices, output checks, parts stores;
* small statistics and formatting shared by several kinds (:func:`wilson`, :func:`fmt_ci`).

The MuJoCo C and PyBullet baselines run the NumPy twin of the impedance law,
:mod:`peghole_mjx.control.reference` (tested against the JAX law in ``tests/test_control.py``).
"""

from __future__ import annotations

import argparse
import csv
import importlib.metadata
import io
import json
import math
import multiprocessing as mp
import os
import platform
import resource
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from tqdm import tqdm

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import key_value
from peghole_mjx.files import fileio
from peghole_mjx.files.provenance import cpu_device as cpu_device  # re-exported
from peghole_mjx.files.provenance import utc_now as utc_now  # re-exported

#: the repository root (links in the docs tables are written relative to it)
ROOT = Path(__file__).resolve().parents[1]
#: the committed results, one folder per kind of script
RESULTS = ROOT / "benchmarks" / "results"
PERF_RESULTS = RESULTS / "perf"
BASELINES_RESULTS = RESULTS / "baselines"
EVALS_RESULTS = RESULTS / "evals"
STUDIES_RESULTS = RESULTS / "studies"
#: the kinds of script, each a subpackage with its own results folder
KINDS = ("perf", "baselines", "evals", "studies")

#: the docs tables: name -> function returning the table's Markdown (see :func:`table`)
TABLES: dict[str, Callable[[], str]] = {}


def table(name: str) -> Callable[[Callable[[], str]], Callable[[], str]]:
    """Register the decorated function as the generator of the docs table ``name``.

    The table sits between ``<!-- table:NAME -->`` and ``<!-- /table:NAME -->`` in one
    Markdown file (README.md or docs/**); its links are written relative to the repository
    root. A name registered by two different functions is an error; the same function
    registered again (a module run as ``__main__`` and imported) replaces itself.
    """

    def register(fn: Callable[[], str]) -> Callable[[], str]:
        old = TABLES.get(name)
        same = old is not None and old.__qualname__ == fn.__qualname__
        if same and "__main__" not in (old.__module__, fn.__module__):
            same = old.__module__ == fn.__module__
        if old is not None and not same:
            raise ValueError(
                f"table {name!r} registered twice: {old.__module__}.{old.__qualname__} and "
                f"{fn.__module__}.{fn.__qualname__}"
            )
        TABLES[name] = fn
        return fn

    return register


def rel(path: Path) -> str:
    """``path`` relative to the repository root, POSIX separators (its name if outside)."""
    path = Path(path)
    return path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name


def fmt_num(x: float | None, fmt: str = ".1f") -> str:
    """``x`` formatted, ``-`` for None."""
    return "-" if x is None else format(x, fmt)


def fmt_ci(x: dict) -> str:
    """``value % [lo, hi]`` of a ``{"value", "ci95"}`` reduction."""
    return f"{x['value']:.1f} % [{x['ci95'][0]:.1f}, {x['ci95'][1]:.1f}]"


def _wilson(k: int, n: int, z: float) -> tuple[float, float]:
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def wilson(k: int, n: int, z: float = 1.96) -> list[float]:
    """Wilson score interval of a binomial proportion k / n."""
    lo, hi = _wilson(k, n, z)
    return [round(lo, 4), round(hi, 4)]


def newcombe(k1: int, n1: int, k2: int, n2: int, z: float = 1.96) -> list[float]:
    """Newcombe's hybrid score interval (his method 10, Stat. Med. 1998) of the difference
    k1/n1 - k2/n2 of two independent proportions, from their Wilson intervals."""
    p1, p2 = k1 / n1, k2 / n2
    (l1, u1), (l2, u2) = _wilson(k1, n1, z), _wilson(k2, n2, z)
    d = p1 - p2
    lo = d - math.sqrt((p1 - l1) ** 2 + (u2 - p2) ** 2)
    hi = d + math.sqrt((u1 - p1) ** 2 + (p2 - l2) ** 2)
    return [round(lo, 4), round(hi, 4)]


def parse_overrides(items: list[str] | None) -> dict:
    """``KEY=VALUE`` strings -> flat config overrides, each value read as ``peghole --set``
    reads it (:func:`peghole_mjx.core.validation.key_value`: JSON, else a Python literal,
    else text), so a benchmark's ``--set`` means what the CLI's does."""
    out = {}
    for item in items or []:
        try:
            key, value = key_value(item)
        except argparse.ArgumentTypeError as exc:
            raise UserInputError(f"--set {item!r}: {exc}") from None
        out[key] = value
    return out


def per_geometry(folder: Path, name: str) -> list[dict]:
    """The result file ``name`` (with ``{geom}`` in it) under ``folder`` of each geometry,
    rect first; a geometry without one is left out."""
    paths = [folder / name.format(geom=g) for g in ("rect", "dual")]
    return [json.loads(p.read_text()) for p in paths if p.exists()]


#: the throughput CSV's columns, in order
COLUMNS = (
    "engine",
    "device",
    "scene",
    "worlds",
    "physics_steps_per_s",
    "env_steps_per_s",
    "compile_s",
    "peak_mem_mb",
    "versions",
    "date",
)
ENGINES = (
    "mjx-jax",
    "mjx-warp",
    # the env on its mujoco engine (MuJoCo C, mujoco.batch): all threads, one thread
    "mujoco",
    "mujoco-1t",
    "batch-ceiling",  # mujoco.batch.Batch.step with no law: the mujoco engine's ceiling
    "mujoco-c-rollout",
    "pybullet",
)
#: engines no longer run whose committed rows are kept as measured, with their retirement date:
#: ``mujoco-c`` (MuJoCo C one world after the other in one thread, through a second copy of
#: the env's step in benchmarks/perf/engines.py), superseded by the env's ``mujoco`` engine
RETIRED_ENGINES = {"mujoco-c": "2026-12-02"}
SCENES = {
    "rect": "RectExtract",
    "dual": "DualExtract",  # the env's default collision representation: capsule
    "dual-mesh": "DualExtract",
    "dual-cylinder": "DualExtract",
}
#: env config overrides of the scene variants (collision representations)
SCENE_OVERRIDES: dict[str, dict] = {
    "dual-mesh": {"representation": "mesh"},
    "dual-cylinder": {"representation": "cylinder"},  # MuJoCo Warp (and C) only
}

#: packages named in the compact ``versions`` string (short name, distribution name)
_VERSION_PACKAGES = (
    ("mujoco", "mujoco"),
    ("mjx", "mujoco-mjx"),
    ("jax", "jax"),
    ("warp", "warp-lang"),
    ("pybullet", "pybullet"),
    ("sb3", "stable-baselines3"),
    ("torch", "torch"),
    ("numpy", "numpy"),
)


def versions_dict(names: Iterable[str] | None = None) -> dict[str, str]:
    """Installed versions (python first); packages that are missing are left out."""
    out = {"python": platform.python_version()}
    for short, dist in _VERSION_PACKAGES:
        if names is not None and short not in names:
            continue
        try:
            out[short] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


def versions_field(versions: dict[str, str]) -> str:
    """``name=version`` pairs separated by ``;`` (no commas: it is a CSV field)."""
    return ";".join(f"{k}={v}" for k, v in versions.items())


def versions_str(names: Iterable[str] | None = None) -> str:
    """This host's versions as one CSV field (:func:`versions_field`)."""
    return versions_field(versions_dict(names))


def cpu_label() -> str:
    """``cpu-2core``: the file-name label of this host's CPU."""
    return f"cpu-{os.cpu_count()}core"


def device_label(kind: str | None) -> str:
    """File label: ``cpu-2core`` or e.g. ``gpu-h100`` (one results file per device)."""
    if kind is None:
        return cpu_label()
    for short in ("h200", "h100", "a100", "l40s", "l4", "a10g", "v100", "t4"):
        if short in kind.lower().replace(" ", ""):
            return f"gpu-{short}"
    return "gpu-" + "".join(ch for ch in kind.lower() if ch.isalnum())[:16]


def max_rss_mb() -> float:
    """Peak resident set size of this process image, MiB.

    Linux's ``VmHWM`` (``/proc/self/status``): ``getrusage``'s ``ru_maxrss`` is not used
    because it keeps the parent's peak across fork + exec, so a worker started by a large
    driver would report the driver's memory.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # not Linux


def load_average() -> tuple[float, float, float] | None:
    """The 1, 5 and 15 min load averages (None where the OS has none)."""
    try:
        return os.getloadavg()
    except OSError:
        return None


#: the room a benchmark's output needs by default (its JSON/CSV results are a few MB at most)
OUT_BYTES = 16 << 20


def check_out(path: Path | str, need_bytes: int = OUT_BYTES, what: str = "--out") -> Path:
    """Before a benchmark's work: ``path`` can be written as a file (its folder created,
    a real write probed) and its disk has ``need_bytes`` free; else a one-line
    :class:`~peghole_mjx.core.errors.UserInputError`."""
    path = fileio.check_out_file(path, what)
    fileio.check_room(path, need_bytes, what)
    return path


def out_file(text: str) -> Path:
    """An argparse ``type`` for a benchmark's ``--out`` file: :func:`check_out` at parse
    time, so a bad path is one usage line before any work."""
    try:
        return check_out(text)
    except UserInputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def write_csv(path: Path | str, rows: Sequence[dict]) -> Path:
    """Write throughput rows with exactly :data:`COLUMNS` (extra keys are an error),
    atomically: a failed write (a bad row, a full disk) leaves the old file as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for r in rows:  # every row checked before anything is written
        missing, extra = set(COLUMNS) - set(r), set(r) - set(COLUMNS)
        if missing or extra:
            raise ValueError(
                f"row misses columns {sorted(missing)} / has extra {sorted(extra)}: {r}"
            )
    with fileio.atomic_open(path, "w") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="raise", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    return path


def write_rows(path: Path | str, rows: Iterable[dict], fields: Sequence[str] | None = None) -> Path:
    """Write any result rows as a CSV (``fields``: the columns, default the first row's keys;
    a row with another key is an error), atomically. The throughput rows have their own
    checked writer, :func:`write_csv`."""
    rows = list(rows)
    fields = list(fields if fields is not None else rows[0])
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=fields, extrasaction="raise", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    path = Path(path)
    fileio.write_text(path, text.getvalue())
    return path


def read_csv(path: Path | str) -> list[dict]:
    """Rows of a throughput CSV, numbers parsed (empty fields become None)."""
    out = []
    with Path(path).open(newline="") as f:
        for r in csv.DictReader(f):
            row: dict = dict(r)
            row["worlds"] = int(r["worlds"])
            for k in ("physics_steps_per_s", "env_steps_per_s", "compile_s", "peak_mem_mb"):
                row[k] = float(r[k]) if r[k] not in ("", None) else None
            out.append(row)
    return out


def read_parts(parts: Path) -> dict[str, dict]:
    """The rows of a ``.parts.jsonl`` store, by their ``key`` (empty if there is none)."""
    rows: dict[str, dict] = {}
    if parts.exists():
        for line in parts.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                rows[r["key"]] = r
    return rows


def run_to_parts(
    job: Callable[[tuple], dict],
    todo: list[tuple],
    parts: Path,
    rows: dict[str, dict],
    processes: int,
    desc: str,
) -> None:
    """Run ``job`` on every item of ``todo`` in ``processes`` fresh processes, appending each
    finished row (a dict with a ``key``) to the ``parts`` store as it arrives and to ``rows``:
    an interrupted run loses at most the rows still running."""
    with mp.get_context("spawn").Pool(processes) as pool, parts.open("a") as f:
        for r in tqdm(pool.imap_unordered(job, todo), total=len(todo), desc=desc):
            rows[r["key"]] = r
            f.write(json.dumps(r) + "\n")
            f.flush()


def flat_settings(settings: dict, prefix: str = "") -> dict[str, object]:
    """A nested settings dict as ``{"a.b.c": value}`` (an empty dict is kept as a value)."""
    out: dict[str, object] = {}
    for key, value in settings.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out.update(flat_settings(value, f"{name}."))
        else:
            out[name] = value
    return out


_UNSET = object()


def settings_diff(a: dict, b: dict, ignore: Iterable[str] = ()) -> list[tuple[str, object, object]]:
    """The settings that differ between two recorded configs: ``(dotted key, a's value, b's
    value)`` in the order they first appear, a value one of them does not record as None.
    Keys in ``ignore`` (dotted, or a prefix ending in ``.``) are left out."""
    fa, fb = flat_settings(a), flat_settings(b)
    skip = tuple(ignore)
    out = []
    for key in dict.fromkeys([*fa, *fb]):
        if key in skip or any(s.endswith(".") and key.startswith(s) for s in skip):
            continue
        va, vb = fa.get(key, _UNSET), fb.get(key, _UNSET)
        if va != vb:
            out.append((key, None if va is _UNSET else va, None if vb is _UNSET else vb))
    return out


def fmt_settings_diff(diffs: list[tuple[str, object, object]], unset: str = "unset") -> str:
    """``key a vs b; ...`` of :func:`settings_diff` (a value not recorded shown as ``unset``);
    ``nothing`` when no setting differs."""
    if not diffs:
        return "nothing"

    def fmt(v: object) -> str:
        return unset if v is None else f"{v:g}" if isinstance(v, float) else str(v)

    return "; ".join(f"{k} {fmt(a)} vs {fmt(b)}" for k, a, b in diffs)
