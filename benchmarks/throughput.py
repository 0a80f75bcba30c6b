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
    the env on its ``mujoco`` engine (``peghole_mjx/envs/engine_mujoco.py``: MuJoCo C through
    ``mujoco.batch`` on all threads / one thread, the NumPy impedance law over all worlds at
    every physics step), through the same jitted, scanned ``vmap(env.step)`` as ``mjx-jax``.
``batch-ceiling``
    the ``mujoco`` engine's run (all threads) timed inside its callbacks: env steps per second
    of ``mujoco.batch.Batch.step`` alone on the env's own states, what the engine would reach if
    its host law and callback cost nothing (the share is in the side JSON).
``mujoco-c``
    MuJoCo C (``mj_step``) in ONE thread, worlds stepped one after the other, with the
    impedance law in NumPy run in closed loop at every physics step
    (:func:`peghole_mjx.control.reference.impedance_torque`, tested against the JAX law): the
    same control work per step as the MJX env, paid in Python (so this row is C physics +
    NumPy control).
``mujoco-c-rollout``
    ``mujoco.rollout`` over all cores (one ``MjData`` per thread). Its controls are OPEN LOOP:
    the joint torques of one closed-loop ``mujoco-c`` episode start (recorded), replayed in
    every world. No control law runs, so this is an UPPER BOUND on what MuJoCo C can do for
    this task on this machine (the law's cost and the Python round trip are left out).
``pybullet``
    PyBullet (the thesis's simulator), its bundled ``kuka_iiwa/model.urdf`` with the peg and
    the hole as boxes, the same impedance law in joint-torque control
    (``benchmarks/pybullet_peghole.py``), one process per core (worlds split over them).
    Rect only: the dual peg-hole is the task PyBullet could not run (convex hull, thesis
    Sec 1.6), so no PyBullet dual rows.

The C engines start from the ``inserted`` keyframe at the nominal hole pose with the env's
randomised commanded errors and friction (the hole pose itself is not moved: that needs an IK
per world and does not change the cost of a step); PyBullet also moves the hole, as the env's
reset does (Newton IK per reset). All engines restart finished episodes, and the restarts are
timed with the steps.

Peak memory: on a GPU, ``peak_bytes_in_use`` of the JAX device (XLA buffers; MuJoCo Warp's own
scratch allocations are not counted); on the CPU, the worker process's max RSS (PyBullet: the
sum over its processes). Every row runs in a fresh subprocess, so RSS and threads do not leak
between rows.

The engines are in :mod:`benchmarks.engines`, the roofline arithmetic in
:mod:`benchmarks.roofline`; this module is the runner (sweeps, one fresh process per row, CSV).

Files: ``benchmarks/results/throughput_<device>.csv`` (columns ``bench_common.COLUMNS``) and a
side JSON ``throughput_<device>.json`` (note, load average, command, per-row details).
``--roofline`` prints and writes ``roofline.json``: the per-world state size (bytes of the
``mjx.Data`` leaves) and the memory-bandwidth roofline on an H100 (3.35 TB/s) and H200
(4.8 TB/s), with the arithmetic.

Run ``python -m benchmarks.throughput --quick`` (under 5 minutes on 2 CPU cores: mjx-jax rect
at 1 and 8 worlds, the C engines on both scenes, PyBullet rect; the dual MJX scene compiles for
3-4 minutes on a CPU, so quick leaves it out) or the full sweep without ``--quick``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.bench_common import (
    COLUMNS,
    ENGINES,
    RESULTS,
    SCENE_OVERRIDES,
    SCENES,
    device_label,
    load_average,
    out_file,
    read_csv,
    utc_now,
    versions_str,
    write_csv,
)
from benchmarks.engines import (
    gpu_kind,
    jax_device_str,
    run_env_mujoco,
    run_mjx,
    run_mujoco_c,
    run_pybullet,
    run_rollout,
)
from benchmarks.roofline import print_roofline, roofline

ROOT = Path(__file__).resolve().parents[1]

#: default sweeps (worlds) per engine; GPU sweeps go to 16384
SWEEP_CPU = {
    "mjx-jax": {"rect": [1, 8, 64, 256], "dual": [1, 8]},
    "mujoco-c": {"rect": [1, 16], "dual": [1, 16]},
    "mujoco-c-rollout": {"rect": [1, 16, 256, 1024], "dual": [1, 16, 256, 1024]},
    "pybullet": {"rect": [1, 2, 8, 16]},
}
SWEEP_GPU = {
    "mjx-jax": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mjx-warp": {s: [1, 64, 1024, 4096, 16384] for s in SCENES},
    "mujoco-c": {s: [1, 16] for s in SCENES},
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
    "mujoco-c": {"rect": [1], "dual": [1]},
    "mujoco-c-rollout": {"rect": [1, 64], "dual": [1, 64]},
    "pybullet": {"rect": [1, 2]},
}


# ----------------------------------------------------------------------------- driver
def run_worker(spec: dict) -> dict:
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
    if engine == "mujoco-c":
        return run_mujoco_c(scene, worlds, spec["min_time"])
    if engine == "mujoco-c-rollout":
        return run_rollout(scene, worlds, spec["min_time"])
    if engine == "pybullet":
        return run_pybullet(worlds, spec["min_time"])
    raise ValueError(engine)


def skip_reason(engine: str, scene: str, gpu: str | None) -> str | None:
    if engine == "mjx-jax" and SCENE_OVERRIDES.get(scene, {}).get("representation") == "cylinder":
        return "MJX-JAX has no cylinder-box collision (MuJoCo Warp and C only)"
    if engine == "pybullet" and scene != "rect":
        return "PyBullet models the rect peg-hole only (the dual is the task it could not run)"
    if engine == "mjx-warp":
        if gpu is None:
            return "mjx-warp needs a CUDA GPU (none here): skipped"
        from peghole_mjx._mjx import WARP_AVAILABLE

        if not WARP_AVAILABLE:
            return "mjx-warp needs warp-lang (pip install '.[warp]'): skipped"
    if engine == "pybullet":
        try:
            import pybullet  # noqa: F401
        except ImportError:
            return "pybullet not installed (pip install '.[bench]'): skipped"
    return None


def plan(args, gpu: str | None) -> list[dict]:
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
    cmd = [sys.executable, "-m", "benchmarks.throughput", "--_worker", json.dumps(job)]
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
    bad = [e for e in args.engines if e not in ENGINES] + [
        s for s in args.scenes if s not in SCENES
    ]
    if bad:
        ap.error(f"unknown engine/scene {bad}")
    args.worlds = [int(w) for w in args.worlds.split(",")] if args.worlds else None
    if args.min_time is None:
        args.min_time = 2.0 if args.quick else 8.0

    # the driver only asks which device JAX sees: it must not grab GPU memory (the rows run in
    # worker processes, which keep JAX's default allocator)
    if "XLA_PYTHON_CLIENT_PREALLOCATE" not in os.environ:
        os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
        _DRIVER_ONLY_ENV.add("XLA_PYTHON_CLIENT_PREALLOCATE")
    gpu = gpu_kind()
    label = device_label(gpu)
    stem = "throughput_engines" if args.sweep == "engines" else "throughput"
    out = args.out or RESULTS / (
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
    order = {e: i for i, e in enumerate(ENGINES)}
    rows.sort(key=lambda r: (order[r["engine"]], r["scene"], int(r["worlds"])))
    write_csv(out, rows)
    # the load averages before and after are recorded with each run: say in --note what else ran
    note = args.note
    runs.append(
        {
            "command": "python -m benchmarks.throughput " + " ".join(sys.argv[1:]),
            "date": utc_now(),
            "rows": [f"{j['engine']} {j['scene']} {j['worlds']}" for j in jobs],
            "load_average_before": load0,
            "load_average_after": load_average(),
            "quick": args.quick,
            "min_time_s": args.min_time,
            "total_wall_s": round(time.perf_counter() - t_start, 1),
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
    }
    side.write_text(json.dumps(meta, indent=2, default=float) + "\n")
    print(f"wrote {out} ({len(rows)} rows) and {side}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
