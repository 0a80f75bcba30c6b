"""Where the extraction force comes from: the scripted baseline with one setting changed.

The scripted baseline (the thesis's Ch 2-3 method: compliance centre at the tip, fixed gains,
straight pull at 20 mm/s) is run on the same randomised episodes (same seed) with one setting
changed at a time: the lateral stiffness k_xy, the rotational stiffness K_theta, the commanded
angular or lateral error, the pulling speed. The mean |F_z| of each variant shows which
stiffness the compliance strategy must modulate to lower the force (docs/guide/training.md,
"Compliance strategy").

Writes ``benchmarks/results/studies/force_sources_<env>_<device>.json``::

    python -m benchmarks.studies.force_sources        # RectExtract, 32 episodes per variant
    python -m benchmarks.studies.force_sources --env dual --episodes 16

The committed dual file was measured on the mesh scene (then the only one): reproduce it with
``--representation mesh`` (DualExtract's default is now the capsule scene; docs/research/models.md,
"Fidelity of the capsule representation"). The docs table ``force_sources`` is generated here.
"""

from __future__ import annotations

import argparse
import json
import time

from benchmarks.common import (
    STUDIES_RESULTS,
    cpu_device,
    cpu_label,
    rel,
    table,
    utc_now,
    versions_dict,
)
from peghole_mjx import envs
from peghole_mjx.control import GAINS
from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S, rollout, scripted_policy

#: name -> (env config overrides, pulling speed m/s, what changes)
VARIANTS: dict[str, tuple[dict, float, str]] = {
    "baseline": ({}, SCRIPTED_SPEED_M_S, "the Ch 2-3 method as the envs define it"),
    "k_xy_50": ({"stiffness.k_xy_N_m": 50.0}, SCRIPTED_SPEED_M_S, "k_xy 300 -> 50 N/m"),
    "k_theta_100": (
        {"stiffness.k_rot_Nm_rad": 100.0},
        SCRIPTED_SPEED_M_S,
        f"K_theta {GAINS.rotational_stiffness_Nm_rad:g} -> 100 N m/rad",
    ),
    "k_theta_30": ({"stiffness.k_rot_Nm_rad": 30.0}, SCRIPTED_SPEED_M_S, "K_theta -> 30 N m/rad"),
    "k_theta_10": ({"stiffness.k_rot_Nm_rad": 10.0}, SCRIPTED_SPEED_M_S, "K_theta -> 10 N m/rad"),
    "no_angular_error": (
        {"randomization.angular_error_deg": 0.0},
        SCRIPTED_SPEED_M_S,
        "commanded tilt error 0.5 -> 0 deg",
    ),
    "no_lateral_error": (
        {"randomization.lateral_error_mm": 0.0},
        SCRIPTED_SPEED_M_S,
        "commanded lateral error 1 -> 0 mm",
    ),
    "speed_100": ({}, 0.1, "pulling speed 20 -> 100 mm/s (the action's limit)"),
    "speed_100_k_theta_10": (
        {"stiffness.k_rot_Nm_rad": 10.0},
        0.1,
        "100 mm/s and K_theta 10 N m/rad",
    ),
    "speed_25_k_theta_10": (
        {"stiffness.k_rot_Nm_rad": 10.0},
        0.025,
        "25 mm/s and K_theta 10 N m/rad",
    ),
}


@table("force_sources")
def force_sources_table() -> str:
    """The scripted baseline with one setting changed, one table per committed file."""
    paths = sorted(STUDIES_RESULTS.glob("force_sources_*.json"), key=lambda p: "dual" in p.name)
    if not paths:
        return "Pending: run `python -m benchmarks.studies.force_sources`."
    lines = []
    for path in paths:
        d = json.loads(path.read_text())
        lines += [
            f"{d['env']}, {d['episodes']} episodes (seed {d['seed']}) per variant; {d['device']}; "
            f"{d['date']}; from [`{rel(path)}`]({rel(path)}).",
            "",
            "| variant | change | success | mean F_z N | vs baseline | peak F_z N | mean F_xy N |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in d["variants"]:
            lines.append(
                f"| {r['variant']} | {r['change']} | {r['success_rate']:.3f} "
                f"| {r['mean_fz_N']:.3f} | {r['fz_vs_baseline_pct']:+.1f} % | {r['peak_fz_N']:.2f} "
                f"| {r['mean_fxy_N']:.2f} |"
            )
        lines.append("")
    return "\n".join(lines).rstrip()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", choices=("rect", "dual"), default="rect")
    p.add_argument("--episodes", type=int, default=32)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", nargs="*", choices=list(VARIANTS), help="run these variants only")
    p.add_argument(
        "--representation", help="dual collision representation (default: the env's, capsule)"
    )
    args = p.parse_args(argv)
    if args.episodes < 1:
        raise SystemExit("--episodes must be >= 1")
    name = {"rect": "RectExtract", "dual": "DualExtract"}[args.env]
    rows = []
    for variant in args.only or list(VARIANTS):
        overrides, speed, what = VARIANTS[variant]
        if args.representation:
            overrides = {**overrides, "representation": args.representation}
        # MJX pinned: the engine of the committed results (the env default became auto)
        env = envs.load(name, config_overrides={"engine": "mjx", **overrides})
        t0 = time.perf_counter()
        res = rollout(env, scripted_policy(env, speed), args.episodes, seed=args.seed)
        s = res.summary().as_dict()
        rows.append({"variant": variant, "change": what, "speed_m_s": speed, **s})
        print(
            f"{variant:18s} F_z {s['mean_fz_N']:7.3f} N  peak {s['peak_fz_N']:7.3f} N  "
            f"F_xy {s['mean_fxy_N']:6.3f} N  success {s['success_rate']:.3f}  "
            f"({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    base = next((r for r in rows if r["variant"] == "baseline"), None)
    for r in rows:
        r["fz_vs_baseline_pct"] = (
            100.0 * (r["mean_fz_N"] / base["mean_fz_N"] - 1.0) if base else float("nan")
        )
    out = STUDIES_RESULTS / f"force_sources_{args.env}_{cpu_label()}.json"
    result = {
        "benchmark": "force_sources",
        "env": name,
        "representation": env.representation,
        "episodes": args.episodes,
        "seed": args.seed,
        "device": cpu_device(),
        "date": utc_now(),
        "versions": versions_dict(("mujoco", "mjx", "jax")),
        "variants": rows,
    }
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
