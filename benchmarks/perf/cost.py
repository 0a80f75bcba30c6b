"""Cost measures that need no GPU, per scene and collision representation.

For RectExtract (edges, the default, and box) and DualExtract in each MJX-JAX representation
(capsule, mesh):

* ``mjx.Data`` bytes per world and the state-traffic roofline (``roofline.roofline_estimate``);
* XLA's cost analysis (bytes accessed and FLOPs) per world, as ``(C(n worlds) - C(1)) / (n-1)``
  of the un-optimised HLO, for

  - ``env_step``: ``jit(vmap(env.step))``, one control step (the 10-substep scan body and the
    solver loop body are counted ONCE: about one physics step plus the control law; the figure
    of ``roofline.json`` and of the 66.7 MB target),
  - ``physics_step``: ``mjx.step`` alone,
  - stages of it: ``kinematics`` (``mjx.kinematics`` + ``com_pos``), ``collision``
    (``mjx.collision``), ``solver_iteration`` (``mjx.solve``: its loop body counted once, so
    about one Newton iteration with its line search), on the env's start state;

* the HBM roofline derived from the env-step bytes for an H100 (3.35 TB/s) and an H200
  (4.8 TB/s): ``bandwidth / bytes per world-step`` physics steps/s, an ESTIMATE (un-fused HLO
  over-counts what fused GPU kernels move; the solver's 20 iterations are counted once);
* compile time of ``jit(vmap(env.step))`` for 8 worlds (lowering + XLA compile, CPU; wall
  clock and the process's CPU time; the persistent compilation cache off);
* with ``--speed``: CPU physics steps/s of the dual representations side by side in ONE run
  (``throughput.run_job``, each row a fresh subprocess: mjx-jax at 1 and 8 worlds, the
  throughput sweep's own chunked scan, its compile time), and the capsule/mesh ratio.

Run ``python -m benchmarks.perf.cost --speed --note "..."`` (about 15 minutes on 2 shared CPU
cores, most of it the mesh scene); writes ``benchmarks/results/perf/cost_<device>.json`` and a
CSV of the speed rows ``cost_<device>_speed.csv``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import jax
import numpy as np

from benchmarks.common import (
    PERF_RESULTS,
    device_label,
    load_average,
    out_file,
    rel,
    table,
    utc_now,
)
from benchmarks.perf.engines import gpu_kind
from benchmarks.perf.roofline import GPU_BANDWIDTH, roofline_estimate, tree_bytes
from benchmarks.perf.throughput import run_job
from peghole_mjx import envs
from peghole_mjx.core._mjx import mjx
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry import mjcf
from peghole_mjx.geometry.parts import DUAL_DEFAULT_REPRESENTATION, RECT_DEFAULT_REPRESENTATION

#: (scene, env name, representation) measured
VARIANTS = (
    ("rect", "RectExtract", "edges"),
    ("rect", "RectExtract", "box"),
    ("dual", "DualExtract", "capsule"),
    ("dual", "DualExtract", "mesh"),
)


def _cost(fn, args_for) -> dict:
    """Per-world XLA bytes and FLOPs of ``jit(fn)`` from its 1- and n-world lowerings."""
    n = 9
    got = {}
    for w in (1, n):
        ca = jax.jit(fn).lower(*args_for(w)).cost_analysis()
        ca = ca[0] if isinstance(ca, list | tuple) else ca
        got[w] = (float(ca.get("bytes accessed", np.nan)), float(ca.get("flops", np.nan)))
    return {
        "bytes_per_world": (got[n][0] - got[1][0]) / (n - 1),
        "flops_per_world": (got[n][1] - got[1][1]) / (n - 1),
    }


def _batched(shape, w: int):
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct((w, *x.shape), x.dtype), shape)


def measure(
    name: str,
    rep: str,
    compile_worlds: int = 8,
    contact_cap: int | None = None,
    geometry: str = "",
) -> dict:
    """The cost entry of one env in one representation (see the module docstring);
    ``contact_cap``: another ``max_contact_points`` than the scene's measured default;
    ``geometry``: the env config's geometry changes (JSON, e.g. ``{"n_sides": 12}``)."""
    over = {"representation": rep, "engine": "mjx"}  # an MJX env (not the auto default)
    if geometry:
        over["geometry"] = geometry
    saved = dict(mjcf.CONTACT_CAPS)
    if contact_cap is not None:
        over["contact_cap"] = contact_cap
        # a trade-off measurement may go below the measured maximum (the env refuses that)
        kind = "dual" if name == "DualExtract" else "rect"
        mjcf.CONTACT_CAPS[(kind, rep)] = mjcf.ContactCap(measured_max=0, cap=contact_cap)
    try:
        env = envs.load(name, config_overrides=over)
    finally:
        mjcf.CONTACT_CAPS.clear()
        mjcf.CONTACT_CAPS.update(saved)
    return {
        "env": name,
        "representation": rep,
        "contact_cap": contact_cap if contact_cap is not None else "default",
        "geometry": geometry,
        **measure_env(env, compile_worlds),
    }


def measure_env(env, compile_worlds: int = 8) -> dict:
    """The cost measures of a built MJX env (any scene; see the module docstring): its sizes,
    ``mjx.Data`` bytes per world, XLA bytes and FLOPs per world of the env step, the physics
    step and its stages, the roofline estimates and the env step's compile time for
    ``compile_worlds`` worlds."""
    mx = env.mjx_model
    key = jax.random.PRNGKey(0)
    shape = jax.eval_shape(env.reset, key)
    data_b = tree_bytes(shape.data)
    act = jax.ShapeDtypeStruct((env.action_size,), np.float32)
    t0 = time.perf_counter()
    out: dict = {
        "n_geoms": int(env.mj_model.ngeom),
        "n_pairs": int(env.mj_model.npair),
        "contacts_allocated": int(shape.data._impl.contact.dist.shape[0]),
        "constraint_rows": int(shape.data._impl.efc_J.shape[0]),
        "mjx_data_bytes_per_world": data_b,
        "n_substeps": env.n_substeps,
    }
    stages = {
        "env_step": (jax.vmap(env.step), lambda w: (_batched(shape, w), _batched(act, w))),
        "physics_step": (jax.vmap(lambda d: mjx.step(mx, d)), lambda w: (_batched(shape.data, w),)),
        "kinematics": (
            jax.vmap(lambda d: mjx.com_pos(mx, mjx.kinematics(mx, d))),
            lambda w: (_batched(shape.data, w),),
        ),
        "collision": (
            jax.vmap(lambda d: mjx.collision(mx, d)),
            lambda w: (_batched(shape.data, w),),
        ),
        "solver_iteration": (
            jax.vmap(lambda d: mjx.solve(mx, d)),
            lambda w: (_batched(shape.data, w),),
        ),
    }
    out["xla"] = {k: _cost(fn, args) for k, (fn, args) in stages.items()}
    out["lower_s"] = round(time.perf_counter() - t0, 1)
    step_b = out["xla"]["env_step"]["bytes_per_world"]
    out["roofline"] = {
        g: {
            "state_bound": roofline_estimate(data_b, bw, env.n_substeps),
            "xla_traffic_estimate_physics_steps_per_s": bw / step_b,
            "arithmetic": f"{bw:.3g} B/s / {step_b:.4g} B per world-step = {bw / step_b:.4g} "
            "physics steps/s",
        }
        for g, bw in GPU_BANDWIDTH.items()
    }
    batched = _batched(shape, compile_worlds)
    t0, c0 = time.perf_counter(), time.process_time()
    jax.jit(jax.vmap(env.step)).lower(batched, _batched(act, compile_worlds)).compile()
    out["env_step_compile_s"] = round(time.perf_counter() - t0, 1)
    # the process's CPU time (all its threads): less sensitive than the wall clock to the load
    out["env_step_compile_cpu_s"] = round(time.process_time() - c0, 1)
    out["env_step_compile_worlds"] = compile_worlds
    return out


def without_persistent_cache() -> None:
    """Turn JAX's persistent compilation cache (on by default in peghole_mjx) off in this
    process, before anything compiles: a compile time measured is then a compile, not a load
    of an earlier run's result."""
    jax.config.update("jax_enable_compilation_cache", False)


def speed(worlds: list[int], min_time: float, chunk: int, timeout: float) -> list[dict]:
    """mjx-jax physics steps/s of the dual representations, side by side (fresh processes)."""
    rows = []
    for rep in ("capsule", "mesh"):
        for w in worlds:
            job = {
                "engine": "mjx-jax",
                "scene": "dual",
                "worlds": w,
                "chunk": chunk,
                "min_time": min_time,
                "representation": rep,
            }
            res = run_job(job, timeout)
            if res is None:
                continue
            row = {
                "scene": "dual",
                "representation": rep,
                "engine": "mjx-jax",
                "worlds": w,
                "physics_steps_per_s": round(res["physics_steps_per_s"], 1),
                "env_steps_per_s": round(res["env_steps_per_s"], 2),
                "compile_s": round(res["compile_s"], 1),
                "peak_mem_mb": round(res["peak_mem_mb"], 1),
                "device": res["device"],
                "date": utc_now(),
            }
            print("[speed]", json.dumps(row), flush=True)
            rows.append(row)
    return rows


# ----------------------------------------------------------------------------- docs tables
#: the committed cost measurement (2-core CPU) that the docs tables read
COST_JSON = PERF_RESULTS / "cost_cpu-2core.json"


def cost_variant(e: dict) -> str:
    """How a cost entry departs from its scene's defaults: "" or e.g. " (cap 28)"."""
    out = ""
    if e.get("contact_cap", "default") != "default":
        out += f" (cap {e['contact_cap']})"
    if e.get("geometry"):
        out += f" (geometry {e['geometry']})"
    return out


@table("cost")
def cost_table() -> str:
    """Per-world cost by collision representation (this module's result)."""
    path = COST_JSON
    data = json.loads(path.read_text())
    lines = [
        f"From [`{rel(path)}`]({rel(path)}) "
        f"({data['device']}; {data['date']}; mujoco {data['versions'].get('mujoco')}, "
        f"mujoco-mjx {data['versions'].get('mujoco-mjx')}, jax {data['versions'].get('jax')}). "
        f"{data.get('note', '')}",
        "",
        "| scene | representation | MJX contacts | constraint rows | mjx.Data B/world "
        "| XLA MB per world: env step | physics step | kinematics | collision "
        "| one solver iteration | XLA MFLOP per env step | env-step compile s (8 worlds) "
        "| H100 estimate, physics steps/s | H200 estimate | GPU measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    gpus = list(data["gpus"])
    for e in data["entries"] + data.get("extra_entries", []):
        x = e["xla"]
        rep = e["representation"] + cost_variant(e)

        def mb(k, x=x):
            return f"{x[k]['bytes_per_world'] / 1e6:.2f}"

        est = [f"{e['roofline'][g]['xla_traffic_estimate_physics_steps_per_s']:.3g}" for g in gpus]
        lines.append(
            f"| {e['scene']} | {rep} | {e['contacts_allocated']} | "
            f"{e['constraint_rows']} | {e['mjx_data_bytes_per_world']} | {mb('env_step')} | "
            f"{mb('physics_step')} | {mb('kinematics')} | {mb('collision')} | "
            f"{mb('solver_iteration')} | {x['env_step']['flops_per_world'] / 1e6:.1f} | "
            f"{e['env_step_compile_s']} | {est[0]} | {est[1]} | unmeasured (no GPU run yet) |"
        )
    added = data.get("extra_entries", [])
    if added:
        lines += [
            "",
            "Rows added to the file later (`--append`): "
            + "; ".join(
                f"{e['scene']} {e['representation']}{cost_variant(e)} measured "
                f"{e.get('measured', '?')}"
                for e in added
            )
            + ".",
        ]
    speed_rows = data.get("speed") or []
    if speed_rows:
        lines += [
            "",
            "Side by side in one run (`python -m benchmarks.perf.cost --speed`, each row a fresh "
            "process, the throughput sweep's chunked scan of the env step):",
            "",
            "| scene | representation | worlds | physics steps/s | env steps/s | compile s |",
            "|---|---|---|---|---|---|",
        ]
        for r in speed_rows:
            lines.append(
                f"| {r['scene']} | {r['representation']} | {r['worlds']} | "
                f"{r['physics_steps_per_s']:.1f} | {r['env_steps_per_s']:.2f} | "
                f"{r['compile_s']:.1f} |"
            )
        ratios = data.get("speed_ratio_capsule_over_mesh", {})
        if ratios:
            lines += [
                "",
                "Capsule / mesh physics steps/s: "
                + "; ".join(f"{w} worlds {v:.1f}x" for w, v in ratios.items())
                + ".",
            ]
    return "\n".join(lines)


@table("cost_brief")
def cost_brief() -> str:
    """README summary of the per-world cost: each env's representation, its XLA traffic and
    the roofline estimates beside the (unmeasured) GPU rows."""
    path = COST_JSON
    data = json.loads(path.read_text())
    used = {
        ("rect", RECT_DEFAULT_REPRESENTATION): "RectExtract, RectExtractHard",
        ("dual", DUAL_DEFAULT_REPRESENTATION): "DualExtract, DualExtractHard",
    }
    other = "option (env config `representation`)"
    gpus = list(data["gpus"])
    lines = [
        f"Per-world cost from [`{rel(path)}`]({rel(path)}) "
        f"({data['device']}; XLA's byte count of one env step, un-optimised HLO; the roofline "
        "estimate is bandwidth / bytes, an estimate, not a measurement):",
        "",
        f"| scene | representation | used by | XLA MB per world-step | {gpus[0]} estimate, "
        f"physics steps/s | {gpus[1]} estimate | GPU measured |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in data["entries"] + data.get("extra_entries", []):
        if cost_variant(e):
            continue  # the trade-off rows: the full cost table
        key = (e["scene"], e["representation"])
        est = [f"{e['roofline'][g]['xla_traffic_estimate_physics_steps_per_s']:.3g}" for g in gpus]
        lines.append(
            f"| {e['scene']} | {e['representation']} | {used.get(key, other)} | "
            f"{e['xla']['env_step']['bytes_per_world'] / 1e6:.2f} | {est[0]} | {est[1]} | "
            "unmeasured (no GPU run yet) |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--variants",
        default="rect:edges,rect:box,dual:capsule,dual:mesh",
        help="comma list of scene:representation[:contact cap]",
    )
    ap.add_argument(
        "--geometry",
        default="",
        help="geometry changes for every variant (env config JSON, e.g. '{\"n_sides\": 12}')",
    )
    ap.add_argument("--append", action="store_true", help="add the entries to --out's")
    ap.add_argument("--speed", action="store_true", help="also the side-by-side CPU speed rows")
    ap.add_argument("--worlds", default="1,8", help="speed rows: worlds")
    ap.add_argument("--min-time", type=float, default=8.0)
    ap.add_argument("--chunk", type=int, default=5)
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--out", type=out_file, default=None)
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    without_persistent_cache()
    label = device_label(gpu_kind())
    out_path = args.out or PERF_RESULTS / f"cost_{label}.json"
    want = [v.split(":") for v in args.variants.split(",")]
    names = {(s, r): n for s, n, r in VARIANTS}
    load0 = load_average()
    t_start = time.perf_counter()
    entries = []
    for scene, rep, *cap in want:
        if (scene, rep) not in names:
            ap.error(f"unknown variant {scene}:{rep}")
        name = names[(scene, rep)]
        cap_n = int(cap[0]) if cap else None
        e = {"scene": scene, **measure(name, rep, contact_cap=cap_n, geometry=args.geometry)}
        x = e["xla"]
        print(
            f"[cost] {scene}/{rep} cap {e['contact_cap']}: env step "
            f"{x['env_step']['bytes_per_world'] / 1e6:.2f} MB, "
            f"physics step {x['physics_step']['bytes_per_world'] / 1e6:.2f} MB, collision "
            f"{x['collision']['bytes_per_world'] / 1e6:.2f} MB, solver iteration "
            f"{x['solver_iteration']['bytes_per_world'] / 1e6:.2f} MB per world; compile "
            f"{e['env_step_compile_s']} s",
            flush=True,
        )
        entries.append(e)
    if args.append and out_path.exists():
        old = json.loads(out_path.read_text())
        old.setdefault("extra_entries", []).extend(
            {**e, "measured": utc_now(), "note": args.note} for e in entries
        )
        out_path.write_text(json.dumps(old, indent=2, default=float) + "\n")
        print(f"appended {len(entries)} entries to {out_path}")
        return 0
    result: dict = {
        **provenance(),
        "note": args.note,
        "gpus": GPU_BANDWIDTH,
        "method": __doc__.split("\n\n", 1)[1].split("Run ``")[0].strip(),
        "entries": entries,
        "gpu_rows": "unmeasured (no GPU lent): benchmarks/perf/gpu_suite.sh measures them",
    }
    if args.speed:
        rows = speed([int(w) for w in args.worlds.split(",")], args.min_time, args.chunk, 900)
        result["speed"] = rows
        by = {(r["representation"], r["worlds"]): r["physics_steps_per_s"] for r in rows}
        result["speed_ratio_capsule_over_mesh"] = {
            str(w): by[("capsule", w)] / by[("mesh", w)]
            for w in sorted({r["worlds"] for r in rows})
            if ("capsule", w) in by and ("mesh", w) in by
        }
        csv_path = out_path.with_name(out_path.stem + "_speed.csv")
        cols = list(rows[0]) if rows else []
        csv_path.write_text(
            ",".join(cols) + "\n" + "".join(",".join(str(r[c]) for c in cols) + "\n" for r in rows)
        )
        print(f"wrote {csv_path}")
    result["load_average_before"] = load0
    result["load_average_after"] = load_average()
    result["total_wall_s"] = round(time.perf_counter() - t_start, 1)
    out_path.write_text(json.dumps(result, indent=2, default=float) + "\n")
    print(f"wrote {out_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
