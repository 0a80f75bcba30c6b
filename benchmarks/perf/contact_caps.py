"""Contact caps sized from measurement: the most active contacts per scene.

For each scene and collision representation (rect: edges and box; dual: capsule and mesh), in
the default env and in the hard variant that uses it (RectExtractHard: rect-3, 4 deg tilt
error; DualExtractHard: dual-3, mu 0.266, where the scripted pull jams), the env is built
WITHOUT a contact cap (``contact_cap=0``) and rolled out under the scripted policy (straight
pull) and a uniformly random policy, in

* MuJoCo C (``engines.CWorlds``: the env's control step with the NumPy impedance law),
  counting the active contacts (distance <= 0) after EVERY physics step, and
* MJX-JAX (``jit(vmap(env.step))``), counting the active contacts of the contact buffer
  (``dist <= 0``) after every env step (the last of its physics substeps).

Finished episodes restart. The maximum over worlds, steps, engines and policies is the scene's
``measured_max``; the cap of ``peghole_mjx.geometry.mjcf.CONTACT_CAPS`` must be above it with a
margin (``tests/test_envs.py::test_rollouts_stay_below_the_contact_cap`` fails if a capped
rollout reaches it).

Run ``python -m benchmarks.perf.contact_caps`` (about 15 minutes on 2 CPU cores; the mesh
scene's MJX rollouts are short because its step compiles for minutes and runs at ~100 steps/s);
writes ``benchmarks/results/perf/contact_caps.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.common import PERF_RESULTS, out_file
from benchmarks.perf.engines import CWorlds, scripted_action
from peghole_mjx import envs
from peghole_mjx.geometry.mjcf import CONTACT_CAPS
from peghole_mjx.provenance import provenance

#: (scene, env, representation) measured
SCENES = (
    ("rect", "RectExtract", "edges"),
    ("rect", "RectExtractHard", "edges"),
    ("rect", "RectExtract", "box"),
    ("dual", "DualExtract", "capsule"),
    ("dual", "DualExtractHard", "capsule"),
    ("dual", "DualExtract", "mesh"),
)


def _policy_action(kind: str, env, rng: np.random.Generator, worlds: int) -> np.ndarray:
    if kind == "scripted":
        return np.broadcast_to(scripted_action(env), (worlds, env.action_size)).copy()
    return rng.uniform(-1.0, 1.0, (worlds, env.action_size))


def count_c(env, policy: str, worlds: int, env_steps: int, seed: int = 0) -> dict:
    """Max active contacts in MuJoCo C after every physics step (closed-loop env control)."""
    cw = CWorlds(env, worlds, seed=seed)
    mj = cw.mujoco
    worst = 0
    orig_step = mj.mj_step

    def counting_step(model, data):
        nonlocal worst
        orig_step(model, data)
        n = int(np.sum(data.contact.dist[: data.ncon] <= 0.0)) if data.ncon else 0
        worst = max(worst, n)

    cw.mujoco = type("MJ", (), {})()  # a namespace that forwards to mujoco but counts steps
    for name in dir(mj):
        if not name.startswith("__"):
            setattr(cw.mujoco, name, getattr(mj, name))
    cw.mujoco.mj_step = counting_step
    rng = np.random.default_rng(seed)
    episodes = 0
    for _ in range(env_steps):
        acts = _policy_action(policy, env, rng, worlds)
        for w in range(worlds):
            episodes += cw.step(w, acts[w])
    return {"max_active": worst, "env_steps_per_world": env_steps, "episodes_ended": episodes}


def count_mjx(env, policy: str, worlds: int, env_steps: int, seed: int = 0) -> dict:
    """Max active contacts in MJX-JAX after every env step; finished worlds restart."""
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step))
    keys = jax.random.split(jax.random.PRNGKey(seed), worlds)
    t0 = time.perf_counter()
    s = reset(keys)
    s0 = s
    rng = np.random.default_rng(seed)
    worst, episodes, nan = 0, 0, 0.0
    for i in range(env_steps):
        a = jnp.asarray(_policy_action(policy, env, rng, worlds), jnp.float32)
        s = step(s, a)
        dist = s.data._impl.contact.dist
        worst = max(worst, int(jnp.max(jnp.sum(dist <= 0.0, axis=-1))))
        done = np.asarray(s.done) > 0
        nan += float(jnp.sum(s.metrics["nan"]))
        if done.any():
            episodes += int(done.sum())
            d = jnp.asarray(done)

            def pick(n, o, d=d):
                return jnp.where(d.reshape((-1,) + (1,) * (n.ndim - 1)), o, n)

            s = jax.tree.map(pick, s, s0)
        if i == 0:
            first_s = time.perf_counter() - t0
    return {
        "max_active": worst,
        "env_steps_per_world": env_steps,
        "episodes_ended": episodes,
        "nan_worlds": nan,
        "compile_and_first_step_s": round(first_s, 1),
        "allocated": int(s.data._impl.contact.dist.shape[-1]),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worlds", type=int, default=8)
    ap.add_argument("--c-steps", type=int, default=400, help="env steps per world, MuJoCo C")
    ap.add_argument("--mjx-steps", type=int, default=300, help="env steps per world, MJX")
    ap.add_argument("--mesh-mjx-steps", type=int, default=60, help="the same, mesh scene")
    ap.add_argument(
        "--scenes",
        default="RectExtract:edges,RectExtractHard:edges,RectExtract:box,DualExtract:capsule,"
        "DualExtractHard:capsule,DualExtract:mesh",
        help="comma-separated ENV:REPRESENTATION of the SCENES table",
    )
    ap.add_argument("--out", type=out_file, default=PERF_RESULTS / "contact_caps.json")
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    want = {tuple(s.split(":")) for s in args.scenes.split(",")}
    unknown = want - {(name, rep) for _, name, rep in SCENES}
    if unknown:
        raise SystemExit(f"unknown --scenes entries {sorted(unknown)}: see SCENES")
    rows = []
    for scene, name, rep in SCENES:
        if (name, rep) not in want:
            continue
        env = envs.load(name, config_overrides={"representation": rep, "contact_cap": 0})
        for engine in ("mujoco-c", "mjx-jax"):
            for policy in ("scripted", "random"):
                t0 = time.perf_counter()
                if engine == "mujoco-c":
                    res = count_c(env, policy, args.worlds, args.c_steps)
                else:
                    n = args.mesh_mjx_steps if rep == "mesh" else args.mjx_steps
                    res = count_mjx(env, policy, args.worlds, n)
                row = {
                    "scene": scene,
                    "env": name,
                    "representation": rep,
                    "engine": engine,
                    "policy": policy,
                    "worlds": args.worlds,
                    **res,
                    "wall_s": round(time.perf_counter() - t0, 1),
                }
                print(json.dumps(row), flush=True)
                rows.append(row)
    summary = {}
    for scene, rep in dict.fromkeys((scene, rep) for scene, _, rep in SCENES):
        got = [r for r in rows if (r["scene"], r["representation"]) == (scene, rep)]
        if not got:
            continue
        cap = CONTACT_CAPS.get((scene, rep))
        summary[f"{scene}/{rep}"] = {
            "measured_max": max(r["max_active"] for r in got),
            "envs": sorted({r["env"] for r in got}),
            "cap": cap.cap if cap else 0,
            "recorded_measured_max": cap.measured_max if cap else None,
        }
    out = {
        **provenance(),
        "note": args.note,
        "method": __doc__.split("\n\n")[1],
        "summary": summary,
        "rows": rows,
    }
    args.out.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
