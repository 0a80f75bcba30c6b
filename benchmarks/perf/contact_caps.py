"""Contact caps sized from measurement: the most active contacts per scene.

For each scene and collision representation (rect: edges and box; dual: capsule and mesh), in
the default env and in the hard variant that uses it (RectExtractHard: rect-3, 4 deg tilt
error; DualExtractHard: dual-3, mu 0.266, where the scripted pull jams), the env is built
WITHOUT a contact cap (``contact_cap=0``) and rolled out under the scripted policy (straight
pull) and a uniformly random policy, in

* MuJoCo C (the env on its ``mujoco`` engine, rows ``mujoco``), counting the active contacts
  (distance <= 0) after EVERY physics step: each env step's physics steps replayed from its
  start state with the torques the engine recorded (:func:`count_c`, checked bit for bit
  against the env's end state), and
* MJX-JAX (``jit(vmap(env.step))``), counting the active contacts of the contact buffer
  (``dist <= 0``) after every env step (the last of its physics substeps).

Finished episodes restart. The maximum over worlds, steps, engines and policies is the scene's
``measured_max``; the cap of ``peghole_mjx.geometry.mjcf.CONTACT_CAPS`` must be above it with a
margin (``tests/test_envs.py::test_rollouts_stay_below_the_contact_cap`` fails if a capped
rollout reaches it).

The committed result (2026-11-30) is older: its MuJoCo C rows (``"engine": "mujoco-c"``) came
from the benchmarks' own copy of the env's step, retired on 2026-12-02 (a second implementation
of the task; its episodes started at the nominal hole pose). Those rows rerun on 2026-12-02 with
:func:`count_c` (same 8 worlds, 400 env steps, seed 0; not committed) gave the same maximum in
7 of 12 rows and a lower one in 5 (never higher): rect ``edges`` 14/20/12/20 (all equal), rect
``box`` 10 and 14 (15), dual capsule 13 (16) and 20, DualExtractHard capsule 19 and 22 (26),
dual mesh 9 (12) and 16 (18). The scene maxima stay those committed except dual capsule: 22
instead of 26 (the old loop's random-action episodes; a tail over other episode starts), still
under its cap of 32.

Run ``python -m benchmarks.perf.contact_caps`` (about 15 minutes on 2 CPU cores; the mesh
scene's MJX rollouts are short because its step compiles for minutes and runs at ~100 steps/s);
writes ``benchmarks/results/perf/contact_caps.json`` and a CSV of its rows beside it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.common import PERF_RESULTS, out_file, versions_field, write_rows
from peghole_mjx import envs
from peghole_mjx.envs.contacts import ContactReplay, restart_done
from peghole_mjx.envs.extraction import scripted_action
from peghole_mjx.files.provenance import provenance
from peghole_mjx.geometry.mjcf import CONTACT_CAPS

#: (scene, env, representation) measured
SCENES = (
    ("rect", "RectExtract", "edges"),
    ("rect", "RectExtractHard", "edges"),
    ("rect", "RectExtract", "box"),
    ("dual", "DualExtract", "capsule"),
    ("dual", "DualExtractHard", "capsule"),
    ("dual", "DualExtract", "mesh"),
)
#: the engines counted (row label -> env config entries)
ENGINES = {"mujoco": {"engine": "mujoco"}, "mjx-jax": {"engine": "mjx", "impl": "jax"}}


def _policy_action(kind: str, env, rng: np.random.Generator, worlds: int) -> np.ndarray:
    if kind == "scripted":
        a = scripted_action(env.config, env.compliance_actions)
        return np.broadcast_to(a, (worlds, env.action_size)).copy()
    return rng.uniform(-1.0, 1.0, (worlds, env.action_size))


def _count(env, policy: str, worlds: int, env_steps: int, seed: int, active) -> tuple[dict, Any]:
    """Roll ``worlds`` worlds of ``env`` for ``env_steps`` env steps (finished worlds restart)
    and take the maximum of ``active(state_before, state_after) -> int`` over the env steps."""
    reset = jax.jit(jax.vmap(env.reset))
    step = jax.jit(jax.vmap(env.step))
    keys = jax.random.split(jax.random.PRNGKey(seed), worlds)
    t0 = time.perf_counter()
    s = reset(keys)
    s0 = s
    rng = np.random.default_rng(seed)
    worst, episodes, nan, first_s = 0, 0, 0.0, 0.0
    for i in range(env_steps):
        a = jnp.asarray(_policy_action(policy, env, rng, worlds), jnp.float32)
        prev, s = s, step(s, a)
        worst = max(worst, active(prev, s))
        nan += float(jnp.sum(s.metrics["nan"]))
        done = np.asarray(s.done) > 0
        if done.any():
            episodes += int(done.sum())
            s = restart_done(s, s0)
        if i == 0:
            first_s = time.perf_counter() - t0
    out = {
        "max_active": worst,
        "env_steps_per_world": env_steps,
        "episodes_ended": episodes,
        "nan_worlds": nan,
        "compile_and_first_step_s": round(first_s, 1),
    }
    return out, s


#: the CSV beside the JSON: one row per scene, engine, policy and env
CSV_FIELDS = (
    "scene",
    "env",
    "representation",
    "engine",
    "policy",
    "worlds",
    "env_steps_per_world",
    "max_active",
    "allocated",
    "episodes_ended",
    "nan_worlds",
    "device",
    "versions",
    "date",
)


def csv_rows(result: dict) -> list[dict]:
    """The rows of a contact_caps JSON with its device, versions and date (a field a row does
    not have stays empty)."""
    stamp = {"device": result["device"], "date": result["date"]}
    stamp["versions"] = versions_field(result["versions"])
    return [{k: r.get(k) for k in CSV_FIELDS} | stamp for r in result["rows"]]


def count_c(env, policy: str, worlds: int, env_steps: int, seed: int = 0) -> dict:
    """Max active contacts in MuJoCo C after every physics step, the env run on its ``mujoco``
    engine (``env`` built with ``engine="mujoco"``).

    Each env step runs in the env with the engine's torque record on
    (:attr:`~peghole_mjx.sim.engine_mujoco.MujocoEngine.ctrl_log`); its physics steps are then
    replayed world by world in one ``MjData``, from the step's start state
    (``env.engine.to_mjdata``) with the recorded torques and the world's friction scale, and
    the active contacts counted after every ``mj_step``. The replay is the env's own step: its
    end state must equal the env's bit for bit (checked; a RuntimeError otherwise)."""
    with ContactReplay(env) as replay:
        out, _ = _count(env, policy, worlds, env_steps, seed, replay.max_active)
    return out


def count_mjx(env, policy: str, worlds: int, env_steps: int, seed: int = 0) -> dict:
    """Max active contacts in MJX-JAX after every env step; finished worlds restart."""

    def active(_, s) -> int:
        dist = s.data._impl.contact.dist
        return int(jnp.max(jnp.sum(dist <= 0.0, axis=-1)))

    out, s = _count(env, policy, worlds, env_steps, seed, active)
    return {**out, "allocated": int(s.data._impl.contact.dist.shape[-1])}


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
        over = {"representation": rep, "contact_cap": 0}
        for engine, engine_over in ENGINES.items():
            env = envs.load(name, config_overrides={**over, **engine_over})
            for policy in ("scripted", "random"):
                t0 = time.perf_counter()
                if engine == "mujoco":
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
    write_rows(args.out.with_suffix(".csv"), csv_rows(out), CSV_FIELDS)
    print(json.dumps(summary, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
