"""Memory-bandwidth roofline of the MJX env step (``python -m benchmarks.perf.throughput
--roofline``).

The per-world state size (bytes of the ``mjx.Data`` leaves), XLA's own count of the bytes one
env step touches, and the throughput bound that an H100 (3.35 TB/s) or H200 (4.8 TB/s) puts on
a step that reads and writes the state once per physics step; written to
``benchmarks/results/perf/roofline.json`` by :mod:`benchmarks.perf.throughput`.
"""

from __future__ import annotations

import json
import time

import jax
import numpy as np

from benchmarks.common import PERF_RESULTS, SCENE_OVERRIDES, SCENES, table
from peghole_mjx import envs

#: memory bandwidth of the target GPUs (data-sheet HBM bandwidth), bytes/s
GPU_BANDWIDTH = {"H100 SXM (HBM3)": 3.35e12, "H200 (HBM3e)": 4.8e12}


# ----------------------------------------------------------------------------- roofline
def roofline_estimate(data_bytes: int, bandwidth: float, n_substeps: int = 10) -> dict:
    """Memory-bandwidth roofline for a per-world state of ``data_bytes`` bytes.

    Every physics step must at least read and write each world's ``mjx.Data`` once, so it
    moves >= ``2 * data_bytes``; at ``bandwidth`` bytes/s no engine can exceed
    ``bandwidth / (2 * data_bytes)`` physics steps/s (env steps: that / ``n_substeps``).
    The real traffic is larger (contacts, constraint Jacobians, solver iterations): an upper
    bound on throughput, not a prediction.
    """
    per_step = 2 * int(data_bytes)
    rate = bandwidth / per_step
    return {
        "bytes_per_physics_step": per_step,
        "bandwidth_B_per_s": bandwidth,
        "max_physics_steps_per_s": rate,
        "max_env_steps_per_s": rate / n_substeps,
        "arithmetic": (
            f"{bandwidth:.3g} B/s / (2 x {int(data_bytes)} B read+write per world-step) "
            f"= {rate:.4g} physics steps/s"
        ),
    }


def roofline_fraction(physics_steps_per_s: float, data_bytes: int, bandwidth: float) -> float:
    """Share of the state-traffic roofline a measured rate reaches."""
    return physics_steps_per_s * 2 * data_bytes / bandwidth


def tree_bytes(tree) -> int:
    """Bytes of all leaves of ``tree`` (arrays or shape structs)."""
    return int(sum(x.size * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree)))


def roofline(scenes: list[str], hlo: bool = True) -> dict:
    """Per-world state size of each scene and the H100/H200 rooflines (printed + returned)."""
    out: dict = {"gpus": GPU_BANDWIDTH, "scenes": {}}
    for scene in scenes:
        over = {**(SCENE_OVERRIDES.get(scene) or {}), "engine": "mjx"}  # the MJX-JAX state
        env = envs.load(SCENES[scene], config_overrides=over)
        shape = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
        data_b = tree_bytes(shape.data)
        state_b = tree_bytes(shape)
        entry: dict = {
            "env": SCENES[scene],
            "mjx_data_bytes_per_world": data_b,
            "env_state_bytes_per_world": state_b,
            "n_substeps": env.n_substeps,
            "roofline": {
                g: roofline_estimate(data_b, bw, env.n_substeps) for g, bw in GPU_BANDWIDTH.items()
            },
        }
        if hlo:
            entry.update(hlo_traffic(env, shape))
        out["scenes"][scene] = entry
    return out


def hlo_traffic(env, shape, n: int = 9) -> dict:
    """XLA's own count of the bytes one env step touches, per world (un-optimised HLO).

    ``jit(vmap(env.step))`` is lowered for 1 and ``n`` worlds; the difference / (n - 1) is
    the per-world part (the model's arrays, read once per batch, cancel). XLA counts every
    loop body once (one of the 10 substeps, one solver iteration) and the HLO is not yet
    fused, so this is an order-of-magnitude traffic figure for about one physics step, far
    above what fused GPU kernels move: a pessimistic roofline, next to the state-only one.
    """
    t0 = time.perf_counter()
    counts = {}
    for w in (1, n):
        a = jax.ShapeDtypeStruct((w, env.action_size), np.float32)
        batched = jax.tree.map(lambda x, w=w: jax.ShapeDtypeStruct((w, *x.shape), x.dtype), shape)
        ca = jax.jit(jax.vmap(env.step)).lower(batched, a).cost_analysis()
        ca = ca[0] if isinstance(ca, list | tuple) else ca
        counts[w] = float((ca or {}).get("bytes accessed", float("nan")))
    per_world = (counts[n] - counts[1]) / (n - 1)
    out: dict = {
        "xla_hlo_bytes": {f"{w}_worlds": b for w, b in counts.items()},
        "xla_hlo_bytes_per_world_step": per_world,
        "xla_hlo_note": (
            f"bytes accessed by XLA's cost analysis of jit(vmap(env.step)), un-optimised HLO, "
            f"(B({n} worlds) - B(1 world)) / {n - 1}: loop bodies (substeps, solver "
            "iterations) counted once, no fusion: order of magnitude only, pessimistic"
        ),
        "lower_s": round(time.perf_counter() - t0, 1),
    }
    if per_world == per_world and per_world > 0:
        out["xla_hlo_roofline"] = {
            g: {
                "max_physics_steps_per_s": bw / per_world,
                "arithmetic": (
                    f"{bw:.3g} B/s / {per_world:.4g} B per world-step = "
                    f"{bw / per_world:.4g} physics steps/s"
                ),
            }
            for g, bw in GPU_BANDWIDTH.items()
        }
    return out


def print_roofline(r: dict) -> None:
    """Print the roofline of :func:`roofline`, one block per scene."""
    for scene, e in r["scenes"].items():
        print(
            f"[roofline] {scene}: mjx.Data {e['mjx_data_bytes_per_world']} B/world, "
            f"env State {e['env_state_bytes_per_world']} B/world"
        )
        for g, est in e["roofline"].items():
            print(f"  {g}: {est['arithmetic']} ({est['max_env_steps_per_s']:.4g} env steps/s)")
        for g, est in e.get("xla_hlo_roofline", {}).items():
            print(f"  {g} (XLA HLO bytes): {est['arithmetic']}")


@table("roofline")
def roofline_table() -> str:
    """The committed roofline estimate (``throughput --roofline``), one row per scene and GPU."""
    path = PERF_RESULTS / "roofline.json"
    if not path.exists():
        return (
            "No roofline estimate committed yet: `python -m benchmarks.perf.throughput --roofline`."
        )
    r = json.loads(path.read_text())
    lines = [
        f"From [`benchmarks/results/perf/roofline.json`](benchmarks/results/perf/roofline.json) "
        f"({r['date']}).",
        "",
        "| scene | mjx.Data B/world | GPU | state-traffic bound, physics steps/s | arithmetic "
        "| XLA-HLO-traffic estimate, physics steps/s |",
        "|---|---|---|---|---|---|",
    ]
    for scene, e in r["scenes"].items():
        for gpu, est in e["roofline"].items():
            hlo = e.get("xla_hlo_roofline", {}).get(gpu)
            hlo_txt = f"{hlo['max_physics_steps_per_s']:.3g} ({hlo['arithmetic']})" if hlo else "-"
            lines.append(
                f"| {scene} | {e['mjx_data_bytes_per_world']} | {gpu} | "
                f"{est['max_physics_steps_per_s']:.3g} | {est['arithmetic']} | {hlo_txt} |"
            )
    return "\n".join(lines)
