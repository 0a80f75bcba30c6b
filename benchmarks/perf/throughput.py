"""Throughput of the extraction scenes vs the number of worlds, per engine.

Measures physics steps/s and env (control) steps/s (one env step = ``env.n_substeps`` = 10
physics steps of 2 ms) of the ``rect`` (RectExtract, rect-2) and ``dual`` (DualExtract,
dual-2) scenes, with the iiwa and the impedance law, for these engines:

``mjx-jax``
    ``jit(vmap(env.step))`` inside a ``lax.scan`` chunk (the pattern of
    ``peghole_mjx/envs/rollout.py``), the scripted action (``scripted_policy``: straight pull
    at 20 mm/s), finished worlds reset in place to their start state (as Brax's auto-reset).
    Worlds are the start states of 8 randomised resets, tiled (all worlds cost the same in
    MJX-JAX). ``compile_s``: lowering + XLA compilation of the chunk (ahead of time); the
    reset's compile is logged in the side JSON, not in the CSV. CPU or GPU: JAX's default.
``mjx-warp``
    the same with ``impl="warp"`` (MuJoCo Warp); CUDA GPU only, skipped with a message
    otherwise.
``mujoco`` / ``mujoco-1t``
    the env on its ``mujoco`` engine (``peghole_mjx/sim/engine_mujoco.py``: MuJoCo C through
    ``mujoco.batch`` on all threads / one thread, the NumPy impedance law over all worlds at
    every physics step), through the same jitted, scanned ``vmap(env.step)`` as ``mjx-jax``.
``batch-ceiling``
    the ``mujoco`` engine's run (all threads) timed inside its callbacks: env steps per second
    of ``mujoco.batch.Batch.step`` alone on the env's own states, what the engine would reach if
    its host law and callback cost nothing (the share is in the side JSON).
``mujoco-c-rollout``
    ``mujoco.rollout`` over all cores (one ``MjData`` per thread). Its controls are OPEN LOOP:
    the joint torques of up to 8 randomised episode starts run closed loop on the env's
    ``mujoco`` engine (recorded through ``MujocoEngine.ctrl_log``), each replayed from its own
    start state (bit for bit the env's trajectory). No control law runs, so this is an UPPER
    BOUND on what MuJoCo C can do for this task on this machine (the law's cost and the
    Python round trip are left out).

Retired on 2026-12-02: ``mujoco-c`` (MuJoCo C in one thread, worlds one after the other, the
NumPy law in a per-world Python loop), a second copy of the env's step (reset draw, action
decoding, law call, done test) in ``benchmarks/perf/engines.py``; the ``mujoco`` /
``mujoco-1t`` rows run the env's own step on MuJoCo C instead. Its committed rows stay in the
CSVs as measured and the tables label them retired (``common.RETIRED_ENGINES``); it can no
longer be run. The ``mujoco-c-rollout`` rows measured before that date replayed the torques of
one start recorded by that loop.
``pybullet``
    PyBullet (the thesis's simulator), its bundled ``kuka_iiwa/model.urdf`` with the peg and
    the hole as boxes, the same impedance law in joint-torque control
    (``benchmarks/baselines/pybullet_peghole.py``), one process per core (worlds split over them).
    Rect only: the dual peg-hole is the task PyBullet could not run (convex hull, thesis
    Sec 1.6), so no PyBullet dual rows.

Every MuJoCo row starts from the env's own randomised resets (``env.reset``: the moved hole,
the commanded errors, the friction draw); PyBullet also moves the hole, as the env's reset
does (Newton IK per reset). All engines but the open-loop rollout restart finished episodes,
and the restarts are timed with the steps.

Peak memory: on a GPU, ``peak_bytes_in_use`` of the JAX device (XLA buffers; MuJoCo Warp's own
scratch allocations are not counted); on the CPU, the worker process's max RSS (PyBullet: the
sum over its processes). Every row runs in a fresh subprocess, so RSS and threads do not leak
between rows.

The engines are in :mod:`benchmarks.perf.engines`, the roofline arithmetic in
:mod:`benchmarks.perf.roofline`; this module is the runner (sweeps, one fresh process per row, CSV).

Files: ``benchmarks/results/perf/throughput_<device>.csv`` (columns ``common.COLUMNS``) and a
side JSON ``throughput_<device>.json`` (note, load average, command, per-row details).
``--roofline`` prints and writes ``roofline.json``: the per-world state size (bytes of the
``mjx.Data`` leaves) and the memory-bandwidth roofline on an H100 (3.35 TB/s) and H200
(4.8 TB/s), with the arithmetic.

Run ``python -m benchmarks.perf.throughput --quick`` (mjx-jax rect at 1 and 8 worlds, the C
engines on both scenes, PyBullet rect; the dual MJX scene compiles for 3-4 minutes on a CPU, so
quick leaves it out) or the full sweep without ``--quick``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.common import (
    COLUMNS,
    ENGINES,
    PERF_RESULTS,
    RETIRED_ENGINES,
    ROOT,
    SCENE_OVERRIDES,
    SCENES,
    device_label,
    fmt_num,
    load_average,
    out_file,
    read_csv,
    rel,
    table,
    utc_now,
    versions_str,
    write_csv,
)
from benchmarks.perf.engines import (
    gpu_kind,
    jax_device_str,
    run_env_mujoco,
    run_mjx,
    run_pybullet,
    run_rollout,
)
from benchmarks.perf.roofline import print_roofline, roofline
from peghole_mjx.core._mjx import WARP_AVAILABLE
from peghole_mjx.files.provenance import commit

#: this module, as run: ``python -m benchmarks.perf.throughput``
MODULE = "benchmarks.perf.throughput"

#: default sweeps (worlds) per engine; GPU sweeps go to 16384
SWEEP_CPU = {
    "mjx-jax": {"rect": [1, 8, 64, 256], "dual": [1, 8]},
    "mujoco-1t": {"rect": [1, 16], "dual": [1, 16]},
    "mujoco-c-rollout": {"rect": [1, 16, 256, 1024], "dual": [1, 16, 256, 1024]},
    "pybullet": {"rect": [1, 2, 8, 16]},
}
SWEEP_GPU = {
    "mjx-jax": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mjx-warp": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mujoco-c-rollout": {s: [1, 16, 256, 1024, 4096] for s in SCENES},
    "pybullet": {"rect": [1, 16, 64]},
}
#: ``--sweep engines``: the two engines of the env side by side (issue of 2026-12-02), every
#: row in one run; PyBullet as ONE process (worlds 1)
SWEEP_ENGINES = {
    "mjx-jax": {"rect": [1, 8, 64, 256], "dual": [1, 8, 64, 256]},
    "mujoco-1t": {"rect": [1, 8, 64, 256], "dual": [1, 8, 64, 256]},
    "mujoco": {"rect": [1, 8, 64, 256], "dual": [1, 8, 64, 256]},
    "batch-ceiling": {"rect": [1, 8, 64, 256], "dual": [1, 8, 64, 256]},
    "pybullet": {"rect": [1]},
}
SWEEP_QUICK = {
    "mjx-jax": {"rect": [1, 8]},
    "mujoco-1t": {"rect": [1], "dual": [1]},
    "mujoco-c-rollout": {"rect": [1, 64], "dual": [1, 64]},
    "pybullet": {"rect": [1, 2]},
}


# ----------------------------------------------------------------------------- driver
def run_worker(spec: dict) -> dict:
    """Measure one row (``spec``: engine, scene, worlds, chunk, min_time) in this process."""
    engine, scene, worlds = spec["engine"], spec["scene"], spec["worlds"]
    if engine in ("mjx-jax", "mjx-warp"):
        return run_mjx(
            scene,
            worlds,
            "jax" if engine == "mjx-jax" else "warp",
            spec["chunk"],
            spec["min_time"],
            spec.get("representation"),
        )
    if engine in ("mujoco", "mujoco-1t"):
        threads = 1 if engine == "mujoco-1t" else 0
        return run_env_mujoco(scene, worlds, spec["chunk"], spec["min_time"], threads)
    if engine == "batch-ceiling":
        return run_env_mujoco(scene, worlds, spec["chunk"], spec["min_time"], 0, ceiling=True)
    if engine == "mujoco-c-rollout":
        return run_rollout(scene, worlds, spec["min_time"])
    if engine == "pybullet":
        return run_pybullet(worlds, spec["min_time"])
    raise ValueError(engine)


def skip_reason(engine: str, scene: str, gpu: str | None) -> str | None:
    """Why (engine, scene) cannot run here, or None."""
    if engine == "mjx-jax" and SCENE_OVERRIDES.get(scene, {}).get("representation") == "cylinder":
        return "MJX-JAX has no cylinder-box collision (MuJoCo Warp and C only)"
    if engine == "pybullet" and scene != "rect":
        return "PyBullet models the rect peg-hole only (the dual is the task it could not run)"
    if engine == "mjx-warp":
        if gpu is None:
            return "mjx-warp needs a CUDA GPU (none here): skipped"
        if not WARP_AVAILABLE:
            return "mjx-warp needs warp-lang (pip install '.[warp]'): skipped"
    if engine == "pybullet" and importlib.util.find_spec("pybullet") is None:
        return "pybullet not installed (pip install '.[bench]'): skipped"
    return None


def plan(args, gpu: str | None) -> list[dict]:
    """The rows to measure: one job per (engine, scene, worlds) of the chosen sweep."""
    if args.quick:
        sweep = SWEEP_QUICK
    elif args.sweep == "engines":
        sweep = SWEEP_ENGINES
    else:
        sweep = SWEEP_GPU if gpu else SWEEP_CPU
    jobs = []
    for engine in args.engines:
        for scene in args.scenes:
            worlds = args.worlds or sweep.get(engine, {}).get(scene, [])
            reason = skip_reason(engine, scene, gpu)
            if reason:
                print(f"[skip] {engine} {scene}: {reason}", flush=True)
                continue
            if not worlds:
                print(f"[skip] {engine} {scene}: not in this sweep", flush=True)
            for w in worlds:
                jobs.append(
                    {
                        "engine": engine,
                        "scene": scene,
                        "worlds": int(w),
                        "chunk": args.chunk or (20 if gpu else 5),
                        "min_time": args.min_time,
                    }
                )
    return jobs


#: environment variables the driver set for itself only (not passed on to the workers)
_DRIVER_ONLY_ENV: set[str] = set()


def run_job(job: dict, timeout: float) -> dict | None:
    """Run one row in a fresh process (``--_worker``); its result, or None on failure."""
    cmd = [sys.executable, "-m", MODULE, "--_worker", json.dumps(job)]
    env = {k: v for k, v in os.environ.items() if k not in _DRIVER_ONLY_ENV}
    t0 = time.perf_counter()
    try:
        res = subprocess.run(
            cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=ROOT
        )
    except subprocess.TimeoutExpired:
        print(f"[fail] {job['engine']} {job['scene']} x{job['worlds']}: timeout", flush=True)
        return None
    for line in res.stdout.splitlines():
        if line.startswith("ROW "):
            out = json.loads(line[4:])
            out["wall_s"] = round(time.perf_counter() - t0, 1)
            return out
    print(
        f"[fail] {job['engine']} {job['scene']} x{job['worlds']}: rc={res.returncode}\n"
        + res.stderr[-2000:],
        flush=True,
    )
    return None


def _fmt(x, nd=1):
    return "" if x is None else round(float(x), nd)


# ----------------------------------------------------------------------------- docs tables
#: every engine a committed CSV may hold: the runnable ones, then the retired ones
CSV_ENGINES = (*ENGINES, *RETIRED_ENGINES)


def engine_label(engine: str) -> str:
    """The engine's name in the tables; a retired one with its date (its rows are kept)."""
    date = RETIRED_ENGINES.get(engine)
    return f"{engine} (retired {date})" if date else engine


def throughput_csvs(results: Path = PERF_RESULTS) -> list[Path]:
    """The committed full-sweep throughput CSVs, one per device (``--quick`` ones left out)."""
    return sorted(
        p
        for p in results.glob("throughput_*.csv")
        if not p.stem.endswith("_quick") and not p.stem.startswith("throughput_engines")
    )


@table("throughput")
def throughput_table(results: Path = PERF_RESULTS) -> str:
    """One table per device CSV, every row with the command that re-measures it."""
    csvs = throughput_csvs(results)
    if not csvs:
        return f"No throughput results committed yet: run `python -m {MODULE}`."
    out: list[str] = []
    for path in csvs:
        rows = read_csv(path)
        side = path.with_suffix(".json")
        meta = json.loads(side.read_text()) if side.exists() else {}
        dates = sorted(r["date"] for r in rows)
        vers = sorted({r["versions"] for r in rows})
        where = rel(path)
        out += [
            f"[`{where}`]({where}): {meta.get('device', '?')}; "
            f"{dates[0]} to {dates[-1]}; {' | '.join(vers)}."
            + (f" Note: {meta['note']}." if meta.get("note") else "")
            + (
                f" GPU rows: {meta['gpu_rows']}."
                if meta.get("gpu_rows", "measured") != "measured"
                else ""
            ),
            "",
            "| engine | scene | worlds | physics steps/s | env steps/s | compile s | peak MB "
            "| device | reproduce |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            cmd = (
                f"`python -m {MODULE} --engines {r['engine']} --scenes {r['scene']} "
                f"--worlds {r['worlds']} --merge`"
            )
            if r["engine"] in RETIRED_ENGINES:
                cmd = "retired code: no longer runs"
            out.append(
                f"| {engine_label(r['engine'])} | {r['scene']} | {r['worlds']} | "
                f"{fmt_num(r['physics_steps_per_s'])} | {fmt_num(r['env_steps_per_s'])} | "
                f"{fmt_num(r['compile_s'])} | {fmt_num(r['peak_mem_mb'])} | {r['device']} "
                f"| {cmd} |"
            )
        out.append("")
        for scene in sorted({r["scene"] for r in rows}):
            best = {}
            for e in CSV_ENGINES:
                pts = [
                    (r["physics_steps_per_s"], r["worlds"])
                    for r in rows
                    if r["engine"] == e and r["scene"] == scene and r["physics_steps_per_s"]
                ]
                if pts:
                    best[e] = max(pts)
            one_pb = [
                r["physics_steps_per_s"]
                for r in rows
                if r["engine"] == "pybullet" and r["scene"] == scene and r["worlds"] == 1
            ]
            parts = [f"{engine_label(e)} {v:.1f} (worlds={w})" for e, (v, w) in best.items()]
            ratios = []
            for mjx in ("mjx-jax", "mjx-warp"):
                if mjx not in best:
                    continue
                if "mujoco-c-rollout" in best:
                    ratios.append(
                        f"{mjx} / mujoco-c-rollout = "
                        f"{best[mjx][0] / best['mujoco-c-rollout'][0]:.3g}"
                    )
                if one_pb:
                    ratios.append(f"{mjx} / one PyBullet process = {best[mjx][0] / one_pb[0]:.3g}")
            out.append(
                f"Best physics steps/s, {scene}: "
                + "; ".join(parts)
                + (f". Ratios: {'; '.join(ratios)}." if ratios else ".")
            )
            out.append("")
    return "\n".join(out).rstrip()


#: the ``--sweep engines`` result (the env's two engines side by side)
ENGINES_CSV = PERF_RESULTS / "throughput_engines_cpu-2core.csv"
ENGINE_LABELS = {
    "mjx-jax": "MJX-JAX (engine mjx)",
    "mujoco-1t": "engine mujoco, 1 thread",
    "mujoco": "engine mujoco, all threads",
    "batch-ceiling": "Batch.step, no law (ceiling)",
    "pybullet": "PyBullet, one process",
}


def engine_rows(path: Path = ENGINES_CSV) -> dict[tuple[str, str, int], dict]:
    """The rows of a ``--sweep engines`` CSV by (engine, scene, worlds)."""
    return {(r["engine"], r["scene"], int(r["worlds"])): r for r in read_csv(path)}


def engine_rate(rows: dict, engine: str, scene: str, worlds: int = 64) -> float:
    """Env steps/s of one ``--sweep engines`` row (NaN when it was not measured)."""
    row = rows.get((engine, scene, worlds))
    return float(row["env_steps_per_s"]) if row else float("nan")


@table("engines_throughput")
def engines_throughput() -> str:
    """The env's two engines side by side (``--sweep engines``): env steps/s per row."""
    path = ENGINES_CSV
    if not path.exists():
        return f"Not measured yet: `python -m {MODULE} --sweep engines`."
    rows = engine_rows(path)
    meta = json.loads(path.with_suffix(".json").read_text())
    worlds = sorted({w for (_, _, w) in rows})
    out = [
        f"Env steps/s (one env step = 10 physics steps), {meta['device']}, {meta['date'][:10]}, "
        f"one run (`python -m {MODULE} --sweep engines`; "
        f"[{path.name}]({rel(path)})):",
        "",
        "| scene | engine | " + " | ".join(f"{w} worlds" for w in worlds) + " |",
        "|---|---|" + "---:|" * len(worlds),
    ]
    for scene in ("rect", "dual"):
        for eng, label in ENGINE_LABELS.items():
            cells = [rows.get((eng, scene, w)) for w in worlds]
            if not any(cells):
                continue
            vals = [fmt_num(float(c["env_steps_per_s"]), ".0f") if c else "-" for c in cells]
            out.append(f"| {scene} | {label} | " + " | ".join(vals) + " |")
    return "\n".join(out)


@table("engines_ratio")
def engines_ratio() -> str:
    """The README's engine ratios at 64 worlds, from the same run."""
    if not ENGINES_CSV.exists():
        return f"Not measured yet: `python -m {MODULE} --sweep engines`."
    rows = engine_rows()

    def r(eng, scene, w=64):
        return engine_rate(rows, eng, scene, w)

    out = [
        "| at 64 worlds, 2-core CPU, one run | rect | dual (capsule) |",
        "|---|---:|---:|",
        "| engine mujoco / MJX-JAX | "
        + " | ".join(f"{r('mujoco', s) / r('mjx-jax', s):.1f}x" for s in ("rect", "dual"))
        + " |",
        "| engine mujoco / Batch.step ceiling | "
        + " | ".join(f"{r('mujoco', s) / r('batch-ceiling', s):.2f}" for s in ("rect", "dual"))
        + " |",
        "| engine mujoco / one PyBullet process | "
        f"{r('mujoco', 'rect') / r('pybullet', 'rect', 1):.1f}x | - |",
    ]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="small sweep, < 5 min on 2 CPU cores")
    ap.add_argument("--engines", default=None, help="comma list of " + str(ENGINES))
    ap.add_argument(
        "--sweep",
        choices=("default", "engines"),
        default="default",
        help="engines: MJX-JAX, the mujoco engine (1 and all threads), the no-law Batch.step "
        "ceiling and one PyBullet process, rect and dual at 1/8/64/256 worlds, one run",
    )
    ap.add_argument("--scenes", default="rect,dual", help="comma list: rect, dual")
    ap.add_argument("--worlds", default=None, help="comma list overriding the default sweep")
    ap.add_argument("--out", type=out_file, default=None, help="CSV path (default per device)")
    ap.add_argument("--min-time", type=float, default=None, help="timed seconds per row")
    ap.add_argument("--chunk", type=int, default=None, help="env steps per scan chunk (MJX)")
    ap.add_argument("--timeout", type=float, default=900, help="seconds per row")
    ap.add_argument("--merge", action="store_true", help="keep rows of --out not re-measured")
    ap.add_argument("--roofline", action="store_true", help="print/write the roofline JSON")
    ap.add_argument("--roofline-only", action="store_true", help="roofline, no measurements")
    ap.add_argument("--note", default="", help="free text stored in the side JSON's note")
    ap.add_argument("--_worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args._worker:
        spec = json.loads(args._worker)
        row = run_worker(spec)
        print("ROW " + json.dumps(row, default=float), flush=True)
        return 0

    if args.engines is None:
        args.engines = ",".join(SWEEP_ENGINES if args.sweep == "engines" else ENGINES)
    args.engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    args.scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    retired = [e for e in args.engines if e in RETIRED_ENGINES]
    if retired:
        ap.error(
            f"engine {retired[0]} was retired on {RETIRED_ENGINES[retired[0]]} (a second copy "
            "of the env's step): run the env's engine, mujoco-1t (one thread) or mujoco"
        )
    bad = [e for e in args.engines if e not in ENGINES] + [
        s for s in args.scenes if s not in SCENES
    ]
    if bad:
        ap.error(f"unknown engine/scene {bad}")
    args.worlds = [int(w) for w in args.worlds.split(",")] if args.worlds else None
    if args.min_time is None:
        args.min_time = 2.0 if args.quick else 8.0

    # the driver only asks which device JAX sees: it must not grab GPU memory (the rows run in
    # worker processes, which keep JAX's default allocator). jax 0.10.2 reads this variable
    # when its backends start (the first jax.devices()), not when it is imported
    if "XLA_PYTHON_CLIENT_PREALLOCATE" not in os.environ:
        os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
        _DRIVER_ONLY_ENV.add("XLA_PYTHON_CLIENT_PREALLOCATE")
    gpu = gpu_kind()
    label = device_label(gpu)
    stem = "throughput_engines" if args.sweep == "engines" else "throughput"
    out = args.out or PERF_RESULTS / (
        f"{stem}_{label}_quick.csv" if args.quick else f"{stem}_{label}.csv"
    )
    side = out.with_suffix(".json")

    if args.roofline or args.roofline_only:
        r = roofline(args.scenes)
        r.update(date=utc_now(), versions=versions_str())
        print_roofline(r)
        rpath = out.parent / "roofline.json"
        rpath.parent.mkdir(parents=True, exist_ok=True)
        rpath.write_text(json.dumps(r, indent=2) + "\n")
        print(f"[roofline] wrote {rpath}")
        if args.roofline_only:
            return 0

    load0 = load_average()
    jobs = plan(args, gpu)
    rows, details, runs = [], [], []
    if args.merge and out.exists():
        keep = {(j["engine"], j["scene"], j["worlds"]) for j in jobs}
        rows = [
            {k: r[k] if r[k] is not None else "" for k in COLUMNS}
            for r in read_csv(out)
            if (r["engine"], r["scene"], r["worlds"]) not in keep
        ]
        if side.exists():
            old = json.loads(side.read_text())
            runs = old.get("runs", [])
            details = [
                d for d in old.get("rows", []) if (d["engine"], d["scene"], d["worlds"]) not in keep
            ]
    vers = versions_str()
    t_start = time.perf_counter()
    for job in jobs:
        res = run_job(job, args.timeout)
        if res is None:
            continue
        row = {
            "engine": job["engine"],
            "device": res["device"],
            "scene": job["scene"],
            "worlds": job["worlds"],
            "physics_steps_per_s": _fmt(res["physics_steps_per_s"]),
            "env_steps_per_s": _fmt(res["env_steps_per_s"]),
            "compile_s": _fmt(res["compile_s"]),
            "peak_mem_mb": _fmt(res["peak_mem_mb"]),
            "versions": vers,
            "date": utc_now(),
        }
        print(
            f"[row] {row['engine']:17s} {row['scene']:4s} worlds={row['worlds']:<6d} "
            f"physics/s={row['physics_steps_per_s']:<10} env/s={row['env_steps_per_s']:<9} "
            f"compile_s={row['compile_s']} peak_mb={row['peak_mem_mb']} "
            f"(row wall {res['wall_s']} s)",
            flush=True,
        )
        rows.append(row)
        details.append({**{k: row[k] for k in ("engine", "scene", "worlds")}, **res["extra"]})
    order = {e: i for i, e in enumerate(CSV_ENGINES)}  # --merge keeps retired rows
    rows.sort(key=lambda r: (order[r["engine"]], r["scene"], int(r["worlds"])))
    write_csv(out, rows)
    # the load averages before and after are recorded with each run: say in --note what else ran
    note = args.note
    runs.append(
        {
            "command": f"python -m {MODULE} " + " ".join(sys.argv[1:]),
            "date": utc_now(),
            "rows": [f"{j['engine']} {j['scene']} {j['worlds']}" for j in jobs],
            "load_average_before": load0,
            "load_average_after": load_average(),
            "quick": args.quick,
            "min_time_s": args.min_time,
            "total_wall_s": round(time.perf_counter() - t_start, 1),
            "commit": commit(),
            "config": {
                k: str(v) if isinstance(v, Path) else v
                for k, v in vars(args).items()
                if not k.startswith("_")
            },
        }
    )
    meta = {
        "device": jax_device_str(),
        "date": utc_now(),
        "versions": vers,
        "note": note.strip(),
        "runs": runs,
        "gpu_rows": "measured"
        if gpu
        else "unmeasured here (no GPU): run the same command on "
        "a GPU machine (pip install -e '.[bench,warp]'), it writes throughput_gpu-<kind>.csv",
        "rows": details,
        # the newest run's (each run keeps its own in ``runs``)
        "command": runs[-1]["command"],
        "commit": runs[-1]["commit"],
        "config": "see runs; each run records its config, command and commit",
    }
    side.write_text(json.dumps(meta, indent=2, default=float) + "\n")
    print(f"wrote {out} ({len(rows)} rows) and {side}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
