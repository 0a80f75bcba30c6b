"""Why the engines' forces differ: the same states forwarded in MuJoCo C and in MJX.

The cross-engine comparison (``benchmarks.evals.cross_engine``) found the scripted baseline's
mean |F_z| a little apart on the two engines (RectExtract +2.2 %, DualExtract -20 % of 0.1 N).
Trajectories diverge once they differ, so this study removes the trajectory: it records the
states of a scripted pull on the ``mujoco`` engine (``--worlds`` worlds, seed 0, at the control
steps ``--steps``), then runs one forward pass on each state in MuJoCo C (``mj_forward``,
float64) and in MJX-JAX (``mjx.forward``) twice, in float32 (the envs' precision) and in float64
(``jax_enable_x64``). Per env and MJX precision: the mean and largest |F_z| difference of the
F/T sensor (raw sensor force, peg weight included) against MuJoCo C, and the share of states
whose count of active contacts (distance <= 0) differs.

Reading: where MJX in float64 meets MuJoCo C, the difference is float32 arithmetic; where it
does not, the engines generate different contacts (their collision routines differ).

Writes ``benchmarks/results/studies/engine_contacts_<device>.json``; the docs table
``engine_contacts`` is generated here::

    python -m benchmarks.studies.engine_contacts
    python -m benchmarks.studies.engine_contacts --envs DualExtract --steps 20 --out /tmp/e.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from tqdm import tqdm

from benchmarks.common import STUDIES_RESULTS, cpu_label, rel, table
from peghole_mjx import envs
from peghole_mjx.core._mjx import mjx
from peghole_mjx.envs.rollout import scripted_policy
from peghole_mjx.files.provenance import provenance
from peghole_mjx.sim.engine_mujoco import STATE_SPEC

PRECISIONS = ("float32", "float64")


def record_states(name: str, worlds: int, steps: list[int], seed: int = 0) -> np.ndarray:
    """The integration state rows (float64) of a scripted pull on the ``mujoco`` engine at the
    control steps ``steps``: ``(len(steps) * worlds, nstate)``."""
    env = envs.load(name, config_overrides={"engine": "mujoco"})
    reset, step = jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))
    s = reset(jax.random.split(jax.random.PRNGKey(seed), worlds))
    a = jnp.broadcast_to(scripted_policy(env)(None, None), (worlds, env.action_size))
    rows = []
    for k in range(max(steps) + 1):
        if k in steps:
            rows += [np.ascontiguousarray(w).view(np.float64) for w in np.asarray(s.data.state)]
        s = step(s, a)
    return np.stack(rows)


def compare(name: str, rows: np.ndarray, precision: str) -> dict:
    """Forward every state in MuJoCo C and in MJX at ``precision``; the F_z and contact-count
    differences."""
    jax.config.update("jax_enable_x64", precision == "float64")
    try:
        env = envs.load(name, config_overrides={"engine": "mujoco"})
        m, ids = env.mj_model, env.engine.ids
        mx = mjx.put_model(m, impl="jax")
        fwd = jax.jit(mjx.forward)
        fz = slice(ids.force_adr + 2, ids.force_adr + 3)
        d_fz, count_differs, fz_c = [], [], []
        for row in tqdm(rows, desc=f"{name} {precision}", leave=False):
            d = mujoco.MjData(m)
            mujoco.mj_setState(m, d, row, STATE_SPEC)
            mujoco.mj_forward(m, d)
            dx = fwd(mx, mjx.put_data(m, d, impl="jax"))
            c, x = float(d.sensordata[fz][0]), float(np.asarray(dx.sensordata[fz])[0])
            active_c = int((d.contact.dist[: d.ncon] <= 0).sum())
            active_x = int((np.asarray(dx._impl.contact.dist) <= 0).sum())
            d_fz.append(abs(x - c))
            fz_c.append(abs(c))
            count_differs.append(active_c != active_x)
    finally:
        jax.config.update("jax_enable_x64", False)
    return {
        "env": name,
        "mjx_precision": precision,
        "states": len(rows),
        "mean_abs_fz_N_mujoco": round(float(np.mean(fz_c)), 4),
        "mean_abs_dfz_N": round(float(np.mean(d_fz)), 5),
        "max_abs_dfz_N": round(float(np.max(d_fz)), 5),
        "contact_count_differs_share": round(float(np.mean(count_differs)), 4),
    }


@table("engine_contacts")
def engine_contacts_table() -> str:
    """One row per env and MJX precision."""
    paths = sorted(STUDIES_RESULTS.glob("engine_contacts_*.json"))
    if not paths:
        return "Pending: run `python -m benchmarks.studies.engine_contacts`."
    lines = []
    for path in paths:
        d = json.loads(path.read_text())
        lines += [
            f"Same states in both engines: {d['worlds']} worlds x control steps {d['steps']} of "
            f"a scripted pull (seed {d['seed']}), {d['device']}, {d['date'][:10]} "
            f"([`{path.name}`]({rel(path)})):",
            "",
            "| env | MJX precision | states | mean \\|F_z\\| MuJoCo C N | mean \\|dF_z\\| N "
            "| max \\|dF_z\\| N | active-contact count differs |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for r in d["rows"]:
            lines.append(
                f"| {r['env']} | {r['mjx_precision']} | {r['states']} "
                f"| {r['mean_abs_fz_N_mujoco']:.3f} | {r['mean_abs_dfz_N']:.4f} "
                f"| {r['max_abs_dfz_N']:.4f} | {100 * r['contact_count_differs_share']:.0f} % |"
            )
        lines.append("")
    return "\n".join(lines).rstrip()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", nargs="+", default=list(envs.ALL_ENVS))
    p.add_argument("--worlds", type=int, default=8)
    p.add_argument("--steps", default="20,60,100", help="control steps, comma separated")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, help="result file (default: the committed results folder)")
    args = p.parse_args(argv)
    unknown = [e for e in args.envs if e not in envs.ALL_ENVS]
    if unknown:
        raise SystemExit(f"unknown env {unknown[0]!r}; choose from {list(envs.ALL_ENVS)}")
    steps = sorted({int(s) for s in args.steps.split(",")})
    if args.worlds < 1 or steps[0] < 0:
        raise SystemExit("--worlds must be >= 1 and --steps >= 0")
    rows = []
    for name in args.envs:
        states = record_states(name, args.worlds, steps, args.seed)
        for precision in PRECISIONS:
            r = compare(name, states, precision)
            print(
                f"{name:16s} MJX {precision}: mean |dF_z| {r['mean_abs_dfz_N']:.4f} N, max "
                f"{r['max_abs_dfz_N']:.4f} N, contact count differs in "
                f"{100 * r['contact_count_differs_share']:.0f} % of {r['states']} states",
                flush=True,
            )
            rows.append(r)
    out = args.out or STUDIES_RESULTS / f"engine_contacts_{cpu_label()}.json"
    result = {
        "benchmark": "engine_contacts",
        "worlds": args.worlds,
        "steps": steps,
        "seed": args.seed,
        **provenance(),
        "rows": rows,
    }
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
