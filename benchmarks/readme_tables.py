"""Regenerate the result tables of the docs from the committed files in benchmarks/results/.

Each table sits between ``<!-- table:NAME -->`` and ``<!-- /table:NAME -->`` markers in the
Markdown file that :data:`TABLE_FILES` names, so every number in the docs traces to a committed
result file. Links in a table are written relative to the repository root and rewritten
relative to the file that holds it. Run: ``python -m benchmarks.readme_tables`` (``--check``
exits 1 if a file is out of date; the test suite runs that check).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks.bench_common import ENGINES, read_csv  # noqa: E402


def models_check() -> str:
    data = json.loads((RESULTS / "models_check.json").read_text())
    lines = [
        f"Device: {data['device']}; mujoco {data['versions'].get('mujoco')}, "
        f"mujoco-mjx {data['versions'].get('mujoco-mjx')}, jax {data['versions'].get('jax')}; "
        f"{data['date']}.",
        "",
        "| preset | representation | nominal mm | effective mm (min..max over directions) "
        "| error % | drop gap mm (C / MJX) | geoms | pairs | MJX contacts | constraint rows "
        "| contact cap | result |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["presets"]:
        mjx_gap = "-" if r["drop_test_gap_mjx_mm"] is None else f"{r['drop_test_gap_mjx_mm']:.3f}"
        rep = r.get("representation", "-")
        hi = r.get("effective_clearance_max_mm", r["effective_clearance_mm"])
        err_hi = r.get("clearance_error_max_pct", r["clearance_error_pct"])
        err = (
            f"{r['clearance_error_pct']:+.2f}..{err_hi:+.2f}"
            if rep != "box"
            else f"{r['clearance_error_pct']:+.2f} (axes)"
        )
        eff = (
            f"{r['effective_clearance_mm']:.4f}..{hi:.4f}"
            if rep != "box"
            else f"{r['effective_clearance_mm']:.4f}"
        )
        lines.append(
            f"| {r['preset']} | {rep} | {r['nominal_clearance_mm']:.3f} | {eff} | {err} | "
            f"{r['drop_test_gap_mujoco_mm']:.3f} / {mjx_gap} | {r.get('n_geoms', '-')} | "
            f"{r.get('n_pairs', '-')} | {r.get('contacts_allocated') or '-'} | "
            f"{r.get('constraint_rows') or '-'} | {r.get('contact_cap') or 'none'} | "
            f"{'pass' if r['passed'] else 'FAIL'} |"
        )
    return "\n".join(lines)


def env_rollouts() -> str:
    data = json.loads((RESULTS / "env_rollouts.json").read_text())
    lines = [
        f"Device: {data['device']}; {data['date']}.",
        "",
        "| env | preset | policy | episodes | success | mean time s | mean F_z N | peak F_z N | "
        "mean F_xy N | jammed | NaN worlds | compile s | env steps/s | physics steps/s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        lines.append(
            f"| {r['env']} | {r['preset']} | {r['policy']} | {r['episodes']} | "
            f"{r['success_rate']:.3f} | "
            f"{r['mean_time_s']:.2f} | {r['mean_fz_N']:.2f} | {r['peak_fz_N']:.2f} | "
            f"{r['mean_fxy_N']:.2f} | {r['jammed']} | {r['nan_worlds']} | {r['compile_s']} | "
            f"{r['env_steps_per_s']} | {r['physics_steps_per_s']} |"
        )
    return "\n".join(lines)


def _num(x, fmt: str = ".1f") -> str:
    return "-" if x is None else format(x, fmt)


def throughput_csvs(results: Path = RESULTS) -> list[Path]:
    """The committed full-sweep throughput CSVs, one per device (``--quick`` ones left out)."""
    return sorted(
        p
        for p in results.glob("throughput_*.csv")
        if not p.stem.endswith("_quick") and not p.stem.startswith("throughput_engines")
    )


def throughput(results: Path = RESULTS) -> str:
    """One table per device CSV, every row with the command that re-measures it."""
    csvs = throughput_csvs(results)
    if not csvs:
        return "No throughput results committed yet: run `python -m benchmarks.throughput`."
    out: list[str] = []
    for path in csvs:
        rows = read_csv(path)
        side = path.with_suffix(".json")
        meta = json.loads(side.read_text()) if side.exists() else {}
        dates = sorted(r["date"] for r in rows)
        vers = sorted({r["versions"] for r in rows})
        rel = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path.name
        out += [
            f"[`{rel}`]({rel}): {meta.get('device', '?')}; "
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
                f"`python -m benchmarks.throughput --engines {r['engine']} --scenes {r['scene']} "
                f"--worlds {r['worlds']} --merge`"
            )
            out.append(
                f"| {r['engine']} | {r['scene']} | {r['worlds']} | "
                f"{_num(r['physics_steps_per_s'])} | {_num(r['env_steps_per_s'])} | "
                f"{_num(r['compile_s'])} | {_num(r['peak_mem_mb'])} | {r['device']} | {cmd} |"
            )
        out.append("")
        for scene in sorted({r["scene"] for r in rows}):
            best = {}
            for e in ENGINES:
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
            parts = [f"{e} {v:.1f} (worlds={w})" for e, (v, w) in best.items()]
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


def roofline() -> str:
    path = RESULTS / "roofline.json"
    if not path.exists():
        return "No roofline estimate committed yet: `python -m benchmarks.throughput --roofline`."
    r = json.loads(path.read_text())
    lines = [
        f"From [`benchmarks/results/roofline.json`](benchmarks/results/roofline.json) "
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


# the hook for "ours" (the Brax SAC stack, peghole_mjx/training): where its time-to-success
# JSON is committed and which keys are read, shared with the plot
from benchmarks.plot import OURS_GLOB  # noqa: E402
from benchmarks.plot import TIME_KEYS as _TIME_KEYS  # noqa: E402


def _tts_row(label: str, path: Path) -> str:
    if not path.exists():
        return f"| {label} | pending | - | - | - | - | - | - | - |"
    d = json.loads(path.read_text())
    t = next((d[k] for k in _TIME_KEYS if d.get(k) is not None), None)
    thr = d.get("success_threshold", 0.95)
    reached = f"{t:.0f}" if t is not None else f"not reached in {d.get('budget_s', '?')} s"
    steps = d.get("env_steps", "-")
    rate = d.get("train_env_steps_per_s", "-")
    succ = d.get("final_success_rate")
    cmd = f"`{d['command']}`" if d.get("command") else "-"
    return (
        f"| {label} | {d.get('device', '?')} | {d.get('train_wall_s', '-')} | {steps} | {rate} | "
        f"{'-' if succ is None else f'{succ:.2f}'} | {reached} (threshold {thr}) | "
        f"{d.get('date', '?')} | {cmd} |"
    )


def time_to_success() -> str:
    lines = [
        "| stack | device | training wall s | env steps | env steps/s | success reached "
        "| time to threshold s | date | reproduce |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    from benchmarks.seed_stack import result_files

    for p in result_files():  # RectExtract's (the hard variant's rows follow)
        lines.append(_tts_row(f"seed stack: PyBullet + SB3 SAC (`{p.name}`)", p))
    ours = sorted(RESULTS.glob(OURS_GLOB))
    for p in ours:
        lines.append(_tts_row(f"ours: MJX + Brax SAC (`{p.name}`)", p))
    if not ours:
        lines.append(_tts_row("ours: MJX + Brax SAC", RESULTS / "pending.json"))
    for p in result_files(HARD_ENV):
        lines.append(_tts_row(f"seed stack: PyBullet + SB3 SAC (`{p.name}`)", p))
    for p in sorted(RESULTS.glob(f"train_{HARD_ENV}_*.json")):
        lines.append(_tts_row(f"ours: MJX + Brax SAC (`{p.name}`)", p))
    return "\n".join(lines)


#: the hard variant of the seed-stack comparison (docs/benchmarks.md, "The hard rect variant")
HARD_ENV = "RectExtractHard"


def time_to_success_hard() -> str:
    """The hard-rect comparison: threshold rule, each stack's time, the ratio per device.

    The seed stack runs on the CPU only; ours' GPU ratio is "unmeasured" until a
    ``train_RectExtractHard_gpu-*.json`` is committed.
    """
    from benchmarks.seed_stack import result_path
    from benchmarks.time_to_success import compare

    seed_p = result_path(HARD_ENV, "cpu-2core")
    if not seed_p.exists():
        return f"{HARD_ENV}: pending (no `{seed_p.name}`)."
    seed = json.loads(seed_p.read_text())
    out = []
    ours_files = sorted(RESULTS.glob(f"train_{HARD_ENV}_*.json"))
    for p in ours_files:
        ours = json.loads(p.read_text())
        c = compare(seed, ours)

        def t(x):
            return "not reached" if x is None else f"{x:.0f} s"

        ratio = c["ratio_seed_over_ours"]
        ratio_s = f"**{ratio:.2f}x**" if ratio is not None else "none"
        out.append(
            f"- {HARD_ENV}, seed stack on {seed['device']} vs ours on {ours['device']} "
            f"(`{seed_p.name}`, `{p.name}`): threshold {c['rule']}; time to it: seed stack "
            f"{t(c['seed_time_s'])}, ours {t(c['ours_time_s'])} of training clock; ratio "
            f"seed stack / ours {ratio_s} ({c['verdict']}; best success in the budget: seed "
            f"stack {c['seed_best_success']:.2f}, ours {c['ours_best_success']:.2f})."
        )
    if not ours_files:
        out.append(f"- {HARD_ENV}, ours on the CPU: pending.")
    if not any("_gpu-" in p.name for p in ours_files):
        out.append(
            f"- {HARD_ENV}, ours on a GPU: **unmeasured** (no `train_{HARD_ENV}_gpu-*.json`)."
        )
    return "\n".join(out)


def seed_stack_dual_hull() -> str:
    """The dual peg in PyBullet, one mesh (hull) vs convex pieces (seed_stack_dual_hull.json)."""
    d = json.loads((RESULTS / "seed_stack_dual_hull.json").read_text())
    names = {
        "hull": "one mesh (PyBullet's hull, the seed stack)",
        "compound": "compound of convex pieces (ours)",
    }
    lines = [
        "| peg model | collision volume cm^3 | penetration at the start pose mm | contact normal "
        "force, first step N | pushed off the start pose after the hold mm | placed inserted "
        "| tip out of the hole at s | extracted from the inserted start |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in d["runs"]:
        out = "-" if r["tip_out_at_s"] is None else f"{r['tip_out_at_s']:.2f}"
        lines.append(
            f"| {names[r['peg_model']]} | {r['peg_collision_volume_cm3']:.2f} | "
            f"{r['start_penetration_mm']:.2f} | {r['first_step_normal_force_N']:.0f} | "
            f"{r['displacement_after_hold_mm']:.2f} | {'yes' if r['placed_inserted'] else 'no'} "
            f"| {out} | {'yes' if r['extracted'] else 'no'} |"
        )
    lines.append("")
    lines.append(
        f"{d['device']}; {d['date'][:10]}; hold {d['hold_s']:g} s; `{d['command'].strip()}`."
    )
    return "\n".join(lines)


def contact_check() -> str:
    """The contact-settings table: step x settings -> contact quality (contact_check.json)."""
    from peghole_mjx.experiments.contact_check import TABLE_HEADER, table_row

    d = json.loads((RESULTS / "contact_check.json").read_text())
    rows = [table_row(r) for r in d["runs"]]
    return "\n".join(
        [
            f"Device: {d['device']}; {d['date'][:10]}; "
            f"{len(d['runs'][0]['worlds'])} worlds per row.",
            "",
            TABLE_HEADER,
            *rows,
        ]
    )


def _per_geometry(name: str) -> list[dict]:
    """The committed result file ``name`` (with ``{geom}`` in it) of each geometry, rect first."""
    paths = [RESULTS / name.format(geom=g) for g in ("rect", "dual")]
    return [json.loads(p.read_text()) for p in paths if p.exists()]


def _sweep_rows(d: dict) -> list[str]:

    def red(x):
        if x["value"] is None:
            return "-"
        return f"{x['value']:.1f} [{x['ci95'][0]:.1f}, {x['ci95'][1]:.1f}]"

    def pen_tp(c):
        # recorded since 2026-11-29 (inside the two-point windows); older files: "-"
        v = c.get("max_penetration_two_point_um")
        return "-" if v is None else f"{v:.1f}"

    out = []
    for c in d["cells"]:
        q = c["quasi_static"]
        pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
        out.append(
            f"| {c['preset']} | {c['k_rot_Nm_rad']:g} | {c['beta0_deg']:+g} | {c['mu']:g} | "
            f"{c['regime_KxLc2_over_Ktheta']:.3g} | {pk} | {red(c['reduction_tip_vs_top_pct'])} | "
            f"{q['reduction_tip_vs_top_pct']:.1f} | {red(c['reduction_tip_vs_centre_pct'])} | "
            f"{q['reduction_tip_vs_centre_pct']:.1f} | "
            f"{pen_tp(c)} / {c.get('max_penetration_in_hole_um', c['max_penetration_um']):.1f} "
            f"({c['penetration_limit_um']:.1f}) | "
            f"{c['nan_worlds']} |"
        )
    return out


def _sweep_table(pattern: str) -> str:
    """The sweep table of the result files ``pattern`` (with ``{geom}``) under results/."""
    head = [
        "| preset | K_theta N m/rad | beta0 deg | mu | K_lat L_C,top^2 / K_theta | "
        "mean peak F_z N: tip / centre / top | tip vs top % [95 % CI] (R1: 77.1) | oracle | "
        "tip vs centre % [95 % CI] (R1: 55.6) | oracle | max penetration um: two-point windows / "
        "tip in the hole (limit) | NaN worlds |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines = list(head)
    notes = []
    for d in _per_geometry(pattern):
        lines += _sweep_rows(d)
        x = d["settings"]
        notes.append(
            f"{d['geometry']}: {sum(c['n_worlds'] for c in d['cells'])} worlds, "
            f"{x['experiment']['speed_m_s'] * 1e3:g} mm/s, {x.get('precision', 'float32')}, "
            f"{d['device']}, {d['date'][:10]}, {d['runtime_s'] / 60:.0f} min in the invocation "
            "that wrote the file"
        )
    return "\n".join([*lines, "", "Runs: " + "; ".join(notes) + "."])


def compliance_sweep() -> str:
    """The regime sweep: simulated reductions (95 % CI) beside the quasi-static oracle's."""
    return _sweep_table("compliance_sweep_{geom}.json")


def compliance_sweep_quasi_static() -> str:
    """Sweep cells run at a slow pull in float64 (``--speed-mm-s ... --x64``), from
    ``benchmarks/results/quasi_static/``."""
    return _sweep_table("quasi_static/compliance_sweep_{geom}.json")


def compliance_sweep_envs_law() -> str:
    """The same sweep run with the envs' law and MJX as shipped (``--no-compensate-joint-damping
    --no-fix-cone-hessian``)."""
    return _sweep_table("compliance_sweep_{geom}_envs_law.json")


def low_stiffness_check() -> str:
    """Why K_theta = 3 N m/rad departs from the oracle (benchmarks/low_stiffness_check.py)."""
    d = json.loads((RESULTS / "low_stiffness_check.json").read_text())
    c = d["cell"]
    lines = [
        f"{c['preset']}, K_theta {c['k_rot_Nm_rad']:g} N m/rad, K_lat {c['k_lat_N_m']:g} N/m, "
        f"delta0 {c['delta0_mm']:g} mm, beta0 {c['beta0_deg']:+g} deg, mu {c['mu']:g}, "
        f"L_C {d['L_C_mm']:g} mm, {d['repeats']} worlds; {d['device']}, {d['date'][:10]}.",
        "",
        "| variant | late peak F_z N (per world) | oracle N | both walls loaded in two-point "
        "windows | NaN worlds |",
        "|---|---|---|---|---|",
    ]
    for r in d["rows"]:
        pk, orc, both = _per_world(r)
        lines.append(f"| {r['variant']} | {pk} | {orc} | {both} | {sum(r['nan'])} |")
    return "\n".join(lines)


def _per_world(r: dict) -> tuple[str, str, str]:
    """Per-world late peak, oracle peak and both-walls fraction of a check row, as text."""
    pk = " / ".join("NaN" if v is None else f"{v:.3f}" for v in r["peak_fz_late_N"])
    orc = " / ".join(f"{v:.3f}" for v in r["oracle_peak_fz_late_N"])
    both = " / ".join("-" if v is None else f"{v:.2f}" for v in r["both_walls_frac_in_two_point"])
    return pk, orc, both


def pull_speed() -> str:
    """The regime-sweep cells pulled at several speeds in MuJoCo C, float64
    (benchmarks/pull_speed.py), one world's rate-dependent terms, and the MJX spot checks."""
    lines = [
        "| preset | K_theta N m/rad | beta0 deg | pull mm/s | mean peak F_z N: tip / centre / "
        "top (oracle) | tip vs top % [95 % CI] | oracle | tip vs centre % [95 % CI] | oracle | "
        "both walls loaded, median |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for d in _per_geometry("pull_speed_{geom}.json"):
        notes.append(
            f"{d['preset']}: {d['engine'].split(';')[0]}, "
            f"{d['settings']['repeats']} paired repeats per L_C, {d['device']}, "
            f"{d['date'][:10]}, {d['pulls_wall_s'] / 60:.0f} min of pulls (one core each)"
        )
        for c in d["cells"]:
            pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
            orc = " / ".join(f"{v:.3g}" for v in c["oracle_peak_fz_N"].values())
            top, cen = c["reduction_tip_vs_top_pct"], c["reduction_tip_vs_centre_pct"]
            both = c["both_walls_frac_median"]
            lines.append(
                f"| {d['preset']} | {c['k_rot_Nm_rad']:g} | {c['beta0_deg']:+g} | "
                f"{c['speed_mm_s']:g} | {pk} ({orc}) | {_ci(top)} | {top['oracle']:.1f} | "
                f"{_ci(cen)} | {cen['oracle']:.1f} | {'-' if both is None else f'{both:.2f}'} |"
            )
    head = "mu 0.266, K_lat 300 N/m, delta0 2 mm; "
    lines += ["", head + "; ".join(notes) + "."]
    for name, more in (
        ("pull_speed_rect_mechanism.json", _pull_speed_mechanism),
        ("pull_speed_mjx.json", _pull_speed_mjx),
    ):
        if (RESULTS / name).exists():
            lines += ["", *more(json.loads((RESULTS / name).read_text()))]
    return "\n".join(lines)


def r2_map() -> str:
    """Where the quasi-static oracle predicts R2 over the full dual grid (benchmarks/r2_map.py),
    and the thesis's tilted dual experiment pulled in MuJoCo C (``pull_speed --plan
    dual_tilt``) beside the oracle."""
    from benchmarks.r2_map import ordered

    lines = []
    path = RESULTS / "r2_map.json"
    if path.exists():
        m = json.loads(path.read_text())
        lines += [
            "| preset | mu | cells | within the law's caps | ordered | tip below top only | "
            "unresolved | reversed | ordered, over a cap |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for s in m["summary"]:
            lines.append(
                f"| {s['preset']} | {s['mu']:g} | {s['cells']} | {s['within_caps']} | "
                f"{s['ordered']} | {s['tip_below_top']} | {s['unresolved']} | "
                f"{s['reversed']} | {s['ordered_over_caps']} |"
            )
        lines += [
            "",
            f"Quasi-static oracle, {m['repeats']} paired draws per cell (seed {m['seed']}), "
            f"95 % paired bootstrap intervals; caps: axial force {m['force_cap_N']:g} N, "
            f"torque {m['torque_cap_Nm']:g} N m; {m['device']}, {m['date'][:10]}.",
        ]
    stores = [
        (RESULTS / f"pull_speed_{n}.json", rows)
        for n, rows in (
            ("dual_tilt", "the experiment's"),
            ("dual_tilt_coulomb", "Coulomb"),
            ("dual_tilt_mu001", "the experiment's"),
            ("dual_tilt_mu001_k3", "the experiment's"),
            ("dual3_tilt_mu001", "the experiment's"),
        )
    ]
    stores = [(json.loads(p.read_text()), rows) for p, rows in stores if p.exists()]

    def red(x: dict) -> str:
        lo, hi = x["oracle_ci95"]
        return f"{_ci(x)} ({x['oracle']:.1f} [{lo:.1f}, {hi:.1f}])"

    def resolved(c: dict, ci: str) -> str:
        ok = ordered(c["reduction_tip_vs_centre_pct"][ci], c["reduction_centre_vs_top_pct"][ci])
        return "yes" if ok else "no"

    if stores:
        lines += [
            "",
            "| preset | K_theta N m/rad | pull mm/s | mu, frictional rows | mean peak F_z N: tip / "
            "centre / top (oracle) | tip vs top % [95 % CI] (oracle [its CI]) | tip vs centre | "
            "centre vs top | ordering resolved: simulation / oracle | two-point region mm: "
            "tip / centre / top (oracle) | both walls loaded, median |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
    notes = []
    for d, rows in stores:
        for c in d["cells"]:
            pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
            orc = " / ".join(f"{v:.3g}" for v in c["oracle_peak_fz_N"].values())
            tp = " / ".join(f"{v:.1f}" for v in c["two_point_mm"].values())
            otp = " / ".join(f"{v:.1f}" for v in c["oracle_two_point_mm"].values())
            both = c["both_walls_frac_median"]
            lines.append(
                f"| {d['preset']} | {c['k_rot_Nm_rad']:g} | {c['speed_mm_s']:g} | "
                f"{d['mu']:g}, {rows} | "
                f"{pk} ({orc}) | "
                f"{red(c['reduction_tip_vs_top_pct'])} | {red(c['reduction_tip_vs_centre_pct'])} "
                f"| {red(c['reduction_centre_vs_top_pct'])} | {resolved(c, 'ci95')} / "
                f"{resolved(c, 'oracle_ci95')} | {tp} ({otp}) | "
                f"{'-' if both is None else f'{both:.2f}'} |"
            )
        notes.append(
            f"{d['preset']}, mu {d['mu']:g}, {rows} rows: {d['settings']['repeats']} paired "
            f"repeats per L_C, "
            f"{d['device']}, "
            f"{d['date'][:10]}, {d['pulls_wall_s'] / 60:.0f} min of pulls (one core each)"
        )
    if stores:
        d = stores[0][0]
        lines += [
            "",
            f"K_lat 300 N/m, delta0 2 mm, beta0 0, theta0 {d['theta0_deg']:g} deg; "
            f"{d['engine'].split(';')[0]}; " + "; ".join(notes) + ".",
        ]
    # the experiment itself in MJX: float32 (the sweep's precision) and the float64 rerun
    sweeps = [
        RESULTS / f / "compliance_sweep_dual.json"
        for f in ("dual_tilt", "dual_tilt_x64", "dual3_tilt_mu001")
    ]
    sweeps = [json.loads(p.read_text()) for p in sweeps if p.exists()]
    if sweeps:

        def sred(c: dict, n: str) -> str:
            x = c[f"reduction_{n}_pct"]
            return f"{_ci(x)} ({c['quasi_static'][f'reduction_{n}_pct']:.1f})"

        lines += [
            "",
            "| preset, mu, precision | K_theta N m/rad | mean peak F_z N: tip / centre / top "
            "(oracle) | tip vs "
            "top % [95 % CI] (oracle) | tip vs centre | centre vs top | ordering resolved | "
            "deepest contact in two-point windows um (limit) | NaN worlds |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        notes = []
        for d in sweeps:
            x = d["settings"]
            prec = x.get("precision", "float32")
            for c in d["cells"]:
                pk = " / ".join(f"{v:.3g}" for v in c["peak_fz_N"].values())
                orc = " / ".join(f"{v:.3g}" for v in c["quasi_static"]["peak_fz_N"].values())
                ok = ordered(
                    c["reduction_tip_vs_centre_pct"]["ci95"],
                    c["reduction_centre_vs_top_pct"]["ci95"],
                )
                pen = c.get("max_penetration_two_point_um")
                lines.append(
                    f"| {c['preset']}, {c['mu']:g}, {prec} | {c['k_rot_Nm_rad']:g} | "
                    f"{pk} ({orc}) | "
                    f"{sred(c, 'tip_vs_top')} | "
                    f"{sred(c, 'tip_vs_centre')} | {sred(c, 'centre_vs_top')} | "
                    f"{'yes' if ok else 'no'} | {_num(pen, '.1f')} "
                    f"({c['penetration_limit_um']:.1f}) | {c['nan_worlds']} |"
                )
            notes.append(
                f"{d['cells'][0]['preset']}, mu {d['cells'][0]['mu']:g}, {prec}: "
                f"{sum(c['n_worlds'] for c in d['cells'])} worlds, "
                f"{x['experiment']['speed_m_s'] * 1e3:g} mm/s, {d['device']}, {d['date'][:10]}"
            )
        lines += [
            "",
            "The experiment itself (MJX-JAX, `peghole experiment sweep`), the tilted cells: "
            + "; ".join(notes)
            + ".",
        ]
    return "\n".join(lines)


def friction_frontier() -> str:
    """The friction model between relaxed and Coulomb rows (benchmarks/friction_frontier.py)."""
    d = json.loads((RESULTS / "friction_frontier.json").read_text())
    slow, fast = min(c["speed_mm_s"] for c in d["cells"]), max(c["speed_mm_s"] for c in d["cells"])
    by = {(c["variant"], c["k_rot_Nm_rad"], c["speed_mm_s"]): c for c in d["cells"]}
    lines = [
        f"| variant | engines | K_theta N m/rad | mu_eff: {slow:g} / {fast:g} mm/s | both walls "
        f"loaded: {slow:g} / {fast:g} mm/s | late peak / oracle at {slow:g} mm/s (worlds within "
        f"15 %) | tip vs top % at {slow:g} mm/s [95 % CI] (oracle) | deepest contact um | "
        "admissible |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, v in d["variants"].items():
        for k in sorted({c["k_rot_Nm_rad"] for c in d["cells"]}, reverse=True):
            s_, f_ = by.get((name, k, slow)), by.get((name, k, fast))
            if s_ is None or f_ is None:
                continue
            red = s_["reduction_tip_vs_top_pct"]
            pen = max(s_["penetration_um_max"], f_["penetration_um_max"])
            adm = d["admissible"].get(name, {}).get("admissible")
            lines.append(
                f"| {name} | {v['engines']} | {k:g} | {s_['mu_eff_median']:.3f} / "
                f"{f_['mu_eff_median']:.3f} | {_num(s_['both_walls_frac_median'], '.2f')} / "
                f"{_num(f_['both_walls_frac_median'], '.2f')} | "
                f"{s_['peak_over_oracle_median']:.2f} "
                f"({s_['oracle_within_15pct_frac'] * 100:.0f} %) | "
                f"{_ci(red)} ({red['oracle']:.1f}) | {pen:.1f} | {'yes' if adm else 'no'} |"
            )
    r = d["rule"]
    lines += [
        "",
        f"{d['preset']}, mu {d['mu']:g}, K_lat 300 N/m, delta0 2 mm, beta0 0, theta0 "
        f"{d['cell']['theta0_deg']:g} deg, L_C at the tip and the top, the first {d['repeats']} "
        f"paired draws of the sweep's 16 (seed 0); {d['engine'].split(';')[0]}; {d['device']}, "
        f"{d['date'][:10]}, {d['pulls_wall_s'] / 60:.0f} min of pulls (one core each). "
        f"Admissible: both walls loaded in >= {r['both_walls_min'] * 100:.0f} % of the two-point "
        f"steps at both speeds, and at {slow:g} mm/s mu_eff within "
        f"{r['mu_eff_rel_tol'] * 100:.0f} % of mu and "
        f"the late peak within {r['oracle_rel_tol'] * 100:.0f} % of the oracle in >= "
        f"{r['oracle_frac_min'] * 100:.0f} % of the worlds, the deepest contact under "
        f"{r['penetration_bound_um']:g} um (fixed {r['fixed']}).",
    ]
    return "\n".join(lines)


def _pull_speed_mechanism(m: dict) -> list[str]:
    """One world, one rate-dependent term changed (``pull_speed --mechanism``)."""
    lines = [
        f"One world (K_theta 3 N m/rad, beta0 -0.2 deg, L_C = top, the first repeat), one "
        f"rate-dependent term changed at a time; {m['engine']}; {m['device']}, "
        f"{m['date'][:10]}:",
        "",
        "| variant | late peak F_z N | oracle N | both walls loaded | effective mu |",
        "|---|---|---|---|---|",
    ]
    for r in m["rows"]:
        both = r["both_walls_frac_in_two_point"]
        lines.append(
            f"| {r['variant']} | {_num(r['peak_fz_late_N'], '.3f')} | "
            f"{r['oracle_peak_fz_late_N']:.3f} | {'-' if both is None else f'{both:.2f}'} | "
            f"{r['mu_eff']:.3f} |"
        )
    return lines


def _pull_speed_mjx(m: dict) -> list[str]:
    """The MJX spot checks beside the MuJoCo C replica on the same worlds (``--mjx``)."""
    from benchmarks.pull_speed import MU, PLANS, _check_key, _plan
    from peghole_mjx.experiments.sweep import reduction_pct

    lines = [
        f"The experiment itself (MJX-JAX), the first two repeats at one L_C; {m['device']}, "
        f"{m['date'][:10]}:",
        "",
        "| preset | K_theta N m/rad | beta0 deg | L_C mm | pull mm/s | MJX precision, step | MJX "
        "late peak F_z N (per world) | MuJoCo C float64, same worlds | oracle N | MJX both "
        "walls loaded |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def name(r: dict) -> str:
        tilt = r.get("theta0_deg", 0.0)
        mu = PLANS[_plan(r)].mu
        return (
            r["preset"]
            + (f", theta0 {tilt:g} deg" if tilt else "")
            + (f", mu {mu:g}" if mu != MU else "")
        )

    for r in m["rows"]:
        pk, orc, both = _per_world(r)
        twin = " / ".join(_num(v, ".3f") for v in r.get("c_float64_peak_fz_late_N", []))
        lines.append(
            f"| {name(r)} | {r['k_rot_Nm_rad']:g} | {r['beta0_deg']:+g} | {r['L_C_mm']:g} "
            f"| {r['speed_mm_s']:g} "
            f"| {r['precision']}, {r['timestep_ms']:g} ms | {pk} | {twin or '-'} | {orc} | {both} |"
        )
    # where a check ran at every L_C: the reductions of those two worlds per L_C (paired draws)
    by_check: dict[tuple, dict[float, dict]] = {}
    for r in m["rows"]:
        key = (name(r), *_check_key(r)[1:-1])  # the check less its L_C
        by_check.setdefault(key, {})[r["L_C_mm"]] = r
    for key, rows in by_check.items():
        if len(rows) < 3:
            continue
        tip, centre, top = (rows[lc] for lc in sorted(rows))
        red = {
            col: f"{reduction_pct(tip[col], top[col]):.1f} % / "
            f"{reduction_pct(tip[col], centre[col]):.1f} %"
            for col in ("peak_fz_late_N", "c_float64_peak_fz_late_N", "oracle_peak_fz_late_N")
        }
        lines += [
            "",
            f"{key[0]}, K_theta {key[1]:g} N m/rad, beta0 {key[2]:+g} deg, {key[3]:g} mm/s, "
            f"those two worlds at every L_C, tip vs top / tip vs centre (mean peaks): MJX "
            f"{red['peak_fz_late_N']}, MuJoCo C replica {red['c_float64_peak_fz_late_N']}, "
            f"oracle {red['oracle_peak_fz_late_N']}.",
        ]
    return lines


def _cell_name(c: dict) -> str:
    return (
        f"{c['preset']}, K_theta {c['k_rot_Nm_rad']:g} N m/rad, K_lat {c['k_lat_N_m']:g} N/m, "
        f"beta0 {c['beta0_deg']:+g} deg, theta0 {c['theta0_deg']:g} deg, mu {c['mu']:g}"
    )


def _ci(x: dict) -> str:
    return f"{x['value']:.1f} % [{x['ci95'][0]:.1f}, {x['ci95'][1]:.1f}]"


def _ordered(v: list[float]) -> bool:
    return v[0] < v[1] < v[2]


def _qs_top(c: dict) -> float:
    return c["quasi_static"]["reduction_tip_vs_top_pct"]


def _big_cells_agreeing(cells: list[dict]) -> tuple[list[dict], list[dict]]:
    """The cells where the oracle predicts >= 50 % tip vs top, and those of them where the
    simulation agrees within 10 points (issue 19's rect-2 criterion)."""
    cells = [c for c in cells if c["reduction_tip_vs_top_pct"]["value"] is not None]
    big = [c for c in cells if _qs_top(c) >= 50]
    agree = [c for c in big if abs(c["reduction_tip_vs_top_pct"]["value"] - _qs_top(c)) <= 10]
    return big, agree


def compliance_findings() -> str:
    """R1 / R2 against the sweep: best match, the defaults' cells, the largest reduction,
    agreement with the oracle, peak magnitudes against the thesis's 12 N."""
    lines = []
    rect = RESULTS / "compliance_sweep_rect.json"
    if rect.exists():
        d = json.loads(rect.read_text())
        cells = [c for c in d["cells"] if c["reduction_tip_vs_top_pct"]["value"] is not None]
        b = d["best_match_R1"]
        best = next(c for c in cells if all(c[k] == v for k, v in b["cell"].items()))
        lines.append(
            f"- **R1 (rect, thesis 77.1 % tip vs top, 55.6 % tip vs centre)**: closest cell "
            f"{_cell_name(best)}: {_ci(b['reduction_tip_vs_top_pct'])} and "
            f"{_ci(b['reduction_tip_vs_centre_pct'])}; the oracle predicts "
            f"{b['quasi_static']['reduction_tip_vs_top_pct']:.1f} % and "
            f"{b['quasi_static']['reduction_tip_vs_centre_pct']:.1f} %. 77.1 % is "
            f"{'inside' if b['r1_in_ci95_tip_vs_top'] else 'outside'} that cell's interval."
        )
        top = max(cells, key=lambda c: c["reduction_tip_vs_top_pct"]["value"])
        lines.append(
            f"- Largest simulated tip-vs-top reduction: {_ci(top['reduction_tip_vs_top_pct'])} "
            f"({_cell_name(top)})."
        )
        for c in cells:
            if c["k_rot_Nm_rad"] == 300.0 and c["k_lat_N_m"] == 300.0 and c["theta0_deg"] == 0:
                lines.append(
                    f"- The project's default stiffnesses ({_cell_name(c)}): "
                    f"{_ci(c['reduction_tip_vs_top_pct'])} tip vs top (oracle "
                    f"{c['quasi_static']['reduction_tip_vs_top_pct']:.1f} %)."
                )
        big, agree = _big_cells_agreeing(cells)
        lines.append(
            f"- Cells where the oracle predicts >= 50 % tip vs top: {len(big)}; the simulation "
            f"agrees within 10 points in {len(agree)} of them."
        )
        held = [
            f"K_theta {c['k_rot_Nm_rad']:g} N m/rad with beta0 {c['beta0_deg']:+g} deg"
            for c in cells
            if _ordered(list(c["peak_fz_N"].values()))
        ]
        lines.append(
            "- The thesis's ordering (mean peak tip < centre < top) holds in the simulated cells "
            + ("; ".join(held) if held else "none")
            + f" ({len(held)} of {len(cells)} cells)."
        )
        peak = max(max(c["peak_fz_N"].values()) for c in cells)
        lines.append(
            f"- Peak F_z magnitudes: at most {peak:.2f} N in the swept cells, against the "
            'thesis\'s "over 12 N" for the Ch 2-3 method on the real robot (E13: a plausibility '
            "check, not a target)."
        )
    slow_rect = RESULTS / "quasi_static" / "compliance_sweep_rect.json"
    if slow_rect.exists():
        d = json.loads(slow_rect.read_text())
        x = d["settings"]
        big, agree = _big_cells_agreeing(d["cells"])
        each = "; ".join(
            f"K_theta {c['k_rot_Nm_rad']:g} N m/rad, beta0 {c['beta0_deg']:+g} deg: "
            f"{_ci(c['reduction_tip_vs_top_pct'])} against {_qs_top(c):.1f} %"
            for c in big
        )
        pen = [c.get("max_penetration_two_point_um") for c in d["cells"]]
        lines.append(
            f"- **At the slow pull** (the experiment itself, MJX {x.get('precision', 'float32')}, "
            f"{x['experiment']['speed_m_s'] * 1e3:g} mm/s, `quasi_static/`): cells where the "
            f"oracle predicts >= 50 % tip vs top: {len(big)}; the simulation agrees within 10 "
            f"points in {len(agree)} of them ({each}); deepest contact inside the two-point "
            f"windows {max((v for v in pen if v is not None), default=float('nan')):.1f} um "
            f"(limit {d['cells'][0]['penetration_limit_um']:.1f} um)."
        )
    dual = RESULTS / "compliance_sweep_dual.json"
    if dual.exists():
        d = json.loads(dual.read_text())
        for c in d["cells"]:
            q, r = c["quasi_static"], c["reduction_tip_vs_top_pct"]
            if r["value"] is None:
                continue
            pk = c["peak_fz_N"]
            order = list(pk.values())
            lines.append(
                f"- **R2 (dual)**, {_cell_name(c)}: oracle tip vs top "
                f"{q['reduction_tip_vs_top_pct']:.1f} %, simulated {_ci(r)}; simulated peaks "
                f"tip / centre / top {' / '.join(f'{v:.3f}' for v in order)} N "
                f"({'ordered as R2' if order[0] < order[1] < order[2] else 'not ordered as R2'})."
            )
    slow = RESULTS / "pull_speed_dual.json"
    if slow.exists():
        d = json.loads(slow.read_text())
        v = min(c["speed_mm_s"] for c in d["cells"])
        for c in (c for c in d["cells"] if c["speed_mm_s"] == v):
            pk, orc = list(c["peak_fz_N"].values()), list(c["oracle_peak_fz_N"].values())
            top, cen = c["reduction_tip_vs_top_pct"], c["reduction_tip_vs_centre_pct"]
            # the oracle's ordering with a 1 % margin: its tip and centre peaks can tie
            orc_ordered = orc[0] < 0.99 * orc[1] and orc[1] < 0.99 * orc[2]
            lines.append(
                f"- **R2 (dual) pulled at {v:g} mm/s** ({d['engine'].split(';')[0]}), "
                f"{d['preset']}, K_theta {c['k_rot_Nm_rad']:g} N m/rad, beta0 "
                f"{c['beta0_deg']:+g} deg: mean peaks tip / centre / top "
                f"{' / '.join(f'{x:.3f}' for x in pk)} N "
                f"({'ordered as R2' if _ordered(pk) else 'not ordered as R2'}); oracle "
                f"{' / '.join(f'{x:.3f}' for x in orc)} N "
                f"({'ordered' if orc_ordered else 'not ordered, 1 % margin'}); tip vs top "
                f"{_ci(top)} (oracle {top['oracle']:.1f} %), tip vs centre {_ci(cen)} (oracle "
                f"{cen['oracle']:.1f} %)."
            )
    return "\n".join(lines)


POLICIES = ROOT / "peghole_mjx" / "policies"


def _eval_row(label: str, r: dict, thesis: str) -> str:
    return (
        f"| {label} | {r['success_rate']:.3f} | {_num(r['mean_time_s'], '.2f')} | "
        f"{r['mean_fz_N']:#.3g} | {r['peak_fz_N']:#.3g} | {r['mean_fxy_N']:#.3g} | {thesis} |"
    )  # 3 significant digits: the dual forces are hundredths of a newton


def _batch_flag(ev: dict) -> str:
    """``--batch N`` when the evaluation ran in slices (older files record no batch)."""
    batch = ev.get("batch", ev["episodes"])
    return f" --batch {batch}" if batch < ev["episodes"] else ""


def pretrained() -> str:
    """The committed pretrained policies' evaluations (``evaluation.json`` beside each)."""
    lines = []
    for name, sub in (
        ("rect", "rect_extract"),
        ("rect_hard", "rect_extract_hard"),
        ("dual", "dual_extract"),
        ("dual_hard", "dual_extract_hard"),
    ):
        path = POLICIES / sub / "evaluation.json"
        if not path.exists():
            lines += [f"`{name}`: pending (no committed policy yet).", ""]
            continue
        ev = json.loads(path.read_text())
        pol = json.loads((POLICIES / sub / "policy.json").read_text())
        th = ev["thesis"]
        prov = pol.get("provenance", {})
        rect = name.startswith("rect")
        none = "no thesis result (R6: the dual RL study was not possible in PyBullet)"
        lines += [
            f"`{name}` ({ev['env']}, {ev['preset']}, compliance strategy "
            f"{'on' if ev['compliance_strategy'] else 'off'}; trained for {pol['env_steps']} "
            f"env steps on {prov.get('device', '?')}; evaluated as trained on {ev['episodes']} "
            f"randomised episodes, seed {ev['seed']}, from "
            f"[`{path.relative_to(ROOT)}`]({path.relative_to(ROOT)}); "
            f"`peghole evaluate {name} --episodes {ev['episodes']}{_batch_flag(ev)} --json` "
            "reproduces it):",
            "",
            "| policy | success | mean time s | mean F_z N | peak F_z N | mean F_xy N | thesis |",
            "|---|---|---|---|---|---|---|",
            _eval_row(
                "SAC (ours)",
                ev["policy"],
                f"R4: {th['success_rate']} success, {th['mean_time_s']} s; "
                f"R5: peak F_z <= {th['peak_fz_N_policy']} N"
                if rect
                else none,
            ),
            _eval_row(
                "scripted baseline (Ch 2-3 method)",
                ev["baseline"],
                f"R5: peak F_z > {th['peak_fz_N_baseline']} N" if rect else none,
            ),
            "",
            f"Mean extraction force of the policy vs the baseline: "
            f"**{-ev['force_reduction_pct']:+.1f} %** "
            f"({'lower' if ev['force_reduction_pct'] > 0 else 'higher'}; thesis R3, rect: "
            f"{-th['force_reduction_pct']:+.1f} %; target: at least 29.6 % lower).",
            "",
        ]
        lines += _both_succeed(name)
    return "\n".join(lines).rstrip()


def _both_succeed(name: str) -> list[str]:
    """The paired reductions over all episodes and over the episodes both succeed in, where a
    paired analysis is committed (``benchmarks/results/<name>_cpu-2core/paired*.json``)."""
    lines = []
    for path in sorted(RESULTS.glob(f"{name}_cpu-2core/paired*.json")):
        paired = json.loads(path.read_text())
        both = paired.get("both_succeed")
        if both:
            lo_all, hi_all = paired["bootstrap"]["reduction_pct_95"]
            lo, hi = both["bootstrap"]["reduction_pct_95"]
            lines += [
                f"Paired bootstrap 95 % intervals ([`{path.relative_to(ROOT)}`]"
                f"({path.relative_to(ROOT)})): over all {paired['episodes']} episodes "
                f"{-paired['reduction_pct']:+.1f} % [{-hi_all:+.1f}, {-lo_all:+.1f}]; over the "
                f"{both['episodes']} episodes both succeed in "
                f"{-both['reduction_pct']:+.1f} % [{-hi:+.1f}, {-lo:+.1f}].",
                "",
            ]
    return lines


def force_sources() -> str:
    """The scripted baseline with one setting changed (``benchmarks/force_sources.py``)."""
    paths = sorted(RESULTS.glob("force_sources_*.json"), key=lambda p: "dual" in p.name)
    if not paths:
        return "Pending: run `python -m benchmarks.force_sources`."
    lines = []
    for path in paths:
        d = json.loads(path.read_text())
        lines += [
            f"{d['env']}, {d['episodes']} episodes (seed {d['seed']}) per variant; {d['device']}; "
            f"{d['date']}; from [`{path.relative_to(ROOT)}`]({path.relative_to(ROOT)}).",
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


def rl_vs_rlcs() -> str:
    """RL vs RL + CS learning runs (``benchmarks/rl_vs_rlcs.py``, thesis Fig 4.5, C4.1)."""
    paths = sorted(RESULTS.glob("rl_vs_rlcs_*.json"))
    if not paths:
        return "Pending: run `python -m benchmarks.rl_vs_rlcs`."
    lines = []
    for path in paths:
        d = json.loads(path.read_text())
        a, b = d["rl_cs"], d["rl"]
        if "per_seed" in a:
            lines += _rl_vs_rlcs_seeds(d, path)
            continue
        lines += [
            f"{d['env']} on {d['device']} ({d['date'][:10]}), profile `{a['profile']}`, seed "
            f"{a['seed']}; from [`{path.relative_to(ROOT)}`]({path.relative_to(ROOT)}) and "
            f"its `.png`. {d['note']}".rstrip(),
            "",
            "| run | env steps | training episodes: mean F_z N (std over the run's windows) "
            "| evaluations: mean success | evaluations: mean F_z N | last eval: success, F_z N |",
            "|---|---|---|---|---|---|",
        ]
        for label, r in (("RL + CS", a), ("RL", b)):
            last = r["evaluations"][-1]
            lines.append(
                f"| {label} | {r['env_steps']} | {r['train_mean_fz_N']:.2f} "
                f"({r['train_std_fz_N']:.2f}, {r['train_windows']} windows) | "
                f"{r['eval_mean_success']:.3f} | "
                f"{r['eval_mean_fz_N']:.2f} | {last['success_rate']:.3f}, {last['mean_fz_N']:.2f} |"
            )
        c = d["c4_1"]
        lines += [
            "",
            f"C4.1 ({c['claim']}): lower {'yes' if c['lower'] else 'no'}, steadier "
            f"{'yes' if c['steadier'] else 'no'}: **{c['verdict']}**; training-episode force "
            f"{d['force_reduction_train_pct']:.1f} % lower with the CS.",
            "",
        ]
    return "\n".join(lines).rstrip()


def _mean_ci(v: dict, fmt: str = ".2f") -> str:
    ci = v.get("ci95_t")
    return f"{v['mean']:{fmt}}" + (f" [{ci[0]:{fmt}}, {ci[1]:{fmt}}]" if ci else "")


def _rl_vs_rlcs_seeds(d: dict, path: Path) -> list[str]:
    """The multi-seed comparison: means over seeds with 95 % t-intervals, and the verdicts."""
    a = d["rl_cs"]
    lines = [
        f"{d['env']} on {d['device']} ({d['date'][:10]}), profile `{a['profile']}`, seeds "
        f"{a['seeds']} per arm, {a['env_steps']} env steps each; from "
        f"[`{path.relative_to(ROOT)}`]({path.relative_to(ROOT)}) and its `.png` (bands: 95 % "
        f"over seeds). {d['note']}".rstrip(),
        "",
        "| arm | training: mean F_z N | training: std of F_z N | training: mean F_xy N "
        "| training: F_xy first - last chunk N | final eval success | final eval F_z N |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, r in (("RL + CS", d["rl_cs"]), ("RL", d["rl"])):
        o = r["over_seeds"]
        lines.append(
            f"| {label} | {_mean_ci(o['train_mean_fz_N'])} | {_mean_ci(o['train_std_fz_N'])} "
            f"| {_mean_ci(o['train_mean_fxy_N'])} "
            f"| {_mean_ci(o['train_fxy_first_minus_last_N'])} "
            f"| {_mean_ci(o['final_success_rate'], '.3f')} | {_mean_ci(o['final_mean_fz_N'])} |"
        )
    c1, c2 = d["c4_1"], d["c4_2"]

    def ci(v):
        return "n/a" if v is None else f"[{v[0]:.2f}, {v[1]:.2f}]"

    lines += [
        "",
        f"C4.1 ({c1['claim']}): RL minus RL + CS, mean F_z "
        f"{ci(c1['rl_minus_cs_train_mean_fz_N_ci95'])} N, its std "
        f"{ci(c1['rl_minus_cs_train_std_fz_N_ci95'])} N (95 % Welch): **{c1['verdict']}**. "
        f"C4.2 ({c2['claim']}): RL + CS **{c2['verdict']['rl_cs']}**, RL "
        f"**{c2['verdict']['rl']}**.",
        "",
    ]
    fin = d.get("final_eval_rl_minus_cs_ci95")
    if fin:  # results written before 2026-11-30 lack it
        lines += [
            "Final policies, RL minus RL + CS (95 % Welch over seeds; not a thesis claim): "
            f"success {ci(fin['success_rate'])}, mean F_z {ci(fin['mean_fz_N'])} N, "
            f"mean time {ci(fin['mean_time_s'])} s.",
            "",
        ]
    return lines


def _cost_variant(e: dict) -> str:
    """How a cost entry departs from its scene's defaults: "" or e.g. " (cap 28)"."""
    out = ""
    if e.get("contact_cap", "default") != "default":
        out += f" (cap {e['contact_cap']})"
    if e.get("geometry"):
        out += f" (geometry {e['geometry']})"
    return out


def cost() -> str:
    """Per-world cost by collision representation (benchmarks/cost.py)."""
    path = RESULTS / "cost_cpu-2core.json"
    data = json.loads(path.read_text())
    lines = [
        f"From [`benchmarks/results/{path.name}`](benchmarks/results/{path.name}) "
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
        rep = e["representation"] + _cost_variant(e)

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
                f"{e['scene']} {e['representation']}{_cost_variant(e)} measured "
                f"{e.get('measured', '?')}"
                for e in added
            )
            + ".",
        ]
    speed = data.get("speed") or []
    if speed:
        lines += [
            "",
            "Side by side in one run (`python -m benchmarks.cost --speed`, each row a fresh "
            "process, the throughput sweep's chunked scan of the env step):",
            "",
            "| scene | representation | worlds | physics steps/s | env steps/s | compile s |",
            "|---|---|---|---|---|---|",
        ]
        for r in speed:
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


def cost_brief() -> str:
    """README summary of the per-world cost: each env's representation, its XLA traffic and
    the roofline estimates beside the (unmeasured) GPU rows (benchmarks/cost.py)."""
    from peghole_mjx.geometry.parts import (
        DUAL_DEFAULT_REPRESENTATION,
        RECT_DEFAULT_REPRESENTATION,
    )

    path = RESULTS / "cost_cpu-2core.json"
    data = json.loads(path.read_text())
    used = {
        ("rect", RECT_DEFAULT_REPRESENTATION): "RectExtract, RectExtractHard",
        ("dual", DUAL_DEFAULT_REPRESENTATION): "DualExtract, DualExtractHard",
    }
    other = "option (env config `representation`)"
    gpus = list(data["gpus"])
    lines = [
        f"Per-world cost from [`benchmarks/results/{path.name}`](benchmarks/results/{path.name}) "
        f"({data['device']}; XLA's byte count of one env step, un-optimised HLO; the roofline "
        "estimate is bandwidth / bytes, an estimate, not a measurement):",
        "",
        f"| scene | representation | used by | XLA MB per world-step | {gpus[0]} estimate, "
        f"physics steps/s | {gpus[1]} estimate | GPU measured |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in data["entries"] + data.get("extra_entries", []):
        if _cost_variant(e):
            continue  # the trade-off rows: docs/benchmarks.md
        key = (e["scene"], e["representation"])
        est = [f"{e['roofline'][g]['xla_traffic_estimate_physics_steps_per_s']:.3g}" for g in gpus]
        lines.append(
            f"| {e['scene']} | {e['representation']} | {used.get(key, other)} | "
            f"{e['xla']['env_step']['bytes_per_world'] / 1e6:.2f} | {est[0]} | {est[1]} | "
            "unmeasured (no GPU run yet) |"
        )
    return "\n".join(lines)


def generalisation() -> str:
    """The generalisation matrices (``benchmarks/generalisation.py``), one per policy file."""
    files = sorted(RESULTS.glob("generalisation_*.json"))
    if not files:
        return "Not run yet (`python -m benchmarks.generalisation --policy rect`)."
    lines = []
    for path in files:
        d = json.loads(path.read_text())
        rel = path.relative_to(ROOT)
        lines += [
            f"`{d['policy']}` ({d['env']}, trained on {d['trained_preset']}): "
            f"{d['episodes_per_cell']} randomised episodes per cell, seed {d['seed']}, the same "
            f"episodes for policy and baseline; {d['device']}, {d['date'][:10]}; from "
            f"[`{rel}`]({rel}) (`{d['command']}`)."
            + (
                ""
                if d.get("complete", True)
                else f" **Incomplete**: {len(d['cells'])} of {len(d['cells_planned'])} cells."
            ),
            "",
            "| geometry | method | success | mean time s | mean F_z N | peak F_z N "
            "| F_z vs baseline |",
            "|---|---|---|---|---|---|---|",
        ]
        for c in d["cells"]:
            name = c["cell"] if c["cell"] != "custom" else "held-out (not a preset)"
            if c["trained_on"]:
                name += " (trained)"
            red = c["force_reduction_pct"]
            for who, label in (("policy", "SAC"), ("baseline", "scripted")):
                r = c[who]
                geo = f"{name}: {c['describe']}" if who == "policy" else ""
                vs = (f"{-red:+.1f} %" if red is not None else "-") if who == "policy" else ""
                lines.append(
                    f"| {geo} | {label} | {r['success_rate']:.3f} | "
                    f"{_num(r['mean_time_s'], '.2f')} | {r['mean_fz_N']:#.3g} | "
                    f"{r['peak_fz_N']:#.3g} | {vs} |"
                )
        lines.append("")
    return "\n".join(lines).rstrip()


def _engine_rows(path: Path) -> dict[tuple[str, str, int], dict]:
    return {(r["engine"], r["scene"], int(r["worlds"])): r for r in read_csv(path)}


ENGINE_LABELS = {
    "mjx-jax": "MJX-JAX (engine mjx)",
    "mujoco-1t": "engine mujoco, 1 thread",
    "mujoco": "engine mujoco, all threads",
    "batch-ceiling": "Batch.step, no law (ceiling)",
    "pybullet": "PyBullet, one process",
}


def engines_throughput() -> str:
    """The env's two engines side by side (``--sweep engines``): env steps/s per row."""
    path = RESULTS / "throughput_engines_cpu-2core.csv"
    if not path.exists():
        return "Not measured yet: `python -m benchmarks.throughput --sweep engines`."
    rows = _engine_rows(path)
    meta = json.loads(path.with_suffix(".json").read_text())
    worlds = sorted({w for (_, _, w) in rows})
    out = [
        f"Env steps/s (one env step = 10 physics steps), {meta['device']}, {meta['date'][:10]}, "
        f"one run (`python -m benchmarks.throughput --sweep engines`; "
        f"[{path.name}](benchmarks/results/{path.name})):",
        "",
        "| scene | engine | " + " | ".join(f"{w} worlds" for w in worlds) + " |",
        "|---|---|" + "---:|" * len(worlds),
    ]
    for scene in ("rect", "dual"):
        for eng, label in ENGINE_LABELS.items():
            cells = [rows.get((eng, scene, w)) for w in worlds]
            if not any(cells):
                continue
            vals = [_num(float(c["env_steps_per_s"]), ".0f") if c else "-" for c in cells]
            out.append(f"| {scene} | {label} | " + " | ".join(vals) + " |")
    return "\n".join(out)


def engines_ratio() -> str:
    """The README's engine ratios at 64 worlds, from the same run."""
    path = RESULTS / "throughput_engines_cpu-2core.csv"
    if not path.exists():
        return "Not measured yet: `python -m benchmarks.throughput --sweep engines`."
    rows = _engine_rows(path)

    def r(eng, scene, w=64):
        row = rows.get((eng, scene, w))
        return float(row["env_steps_per_s"]) if row else float("nan")

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


def cross_engine() -> str:
    """The scripted baseline on both engines (benchmarks/cross_engine.py)."""
    path = RESULTS / "cross_engine_cpu-2core.json"
    if not path.exists():
        return "Not measured yet: `python -m benchmarks.cross_engine`."
    d = json.loads(path.read_text())
    out = [
        f"Scripted baseline, {d['episodes']} episodes of seed {d['seed']} on each engine, "
        f"{d['device']}, {d['date'][:10]} ([{path.name}](benchmarks/results/{path.name})):",
        "",
        "| env | engine | success [95 %] | mean F_z N | peak F_z N | time s | mujoco - mjx "
        "mean F_z N [95 %] | source |",
        "|---|---|---|---:|---:|---:|---|---|",
    ]
    for name, e in d["envs"].items():
        comp = e["comparison"]
        diff = comp.get("mean_fz_N_mujoco_minus_mjx")
        dtext = (
            f"{diff['mean']:+.3f} [{diff['ci95'][0]:+.3f}, {diff['ci95'][1]:+.3f}]"
            if diff
            else f"{comp['mean_fz_relative_pct']:+.1f} % (unpaired)"
        )
        for eng in ("mjx", "mujoco"):
            s = e[eng]
            lo, hi = s["success_ci95"]
            t = "-" if s.get("mean_time_s") is None else f"{s['mean_time_s']:.2f}"
            out.append(
                f"| {name} | {eng} | {s['success_rate']:.3f} [{lo:.3f}, {hi:.3f}] | "
                f"{s['mean_fz_N']:.3f} | {s['peak_fz_N']:.2f} | {t} | "
                f"{dtext if eng == 'mujoco' else ''} | {s.get('source', 'this run')} |"
            )
    return "\n".join(out)


def cross_engine_policies() -> str:
    """Each published policy (trained on MJX) on both engines."""
    path = RESULTS / "cross_engine_cpu-2core.json"
    pol = json.loads(path.read_text()).get("policies", {}) if path.exists() else {}
    if not pol:
        return "Not measured yet: `python -m benchmarks.cross_engine --envs '' --policies ...`."
    out = [
        "| policy | engine | episodes | success [95 %] | mean F_z N | time s | baseline success "
        "| reduction vs baseline % | source |",
        "|---|---|---:|---|---:|---:|---:|---:|---|",
    ]
    for name, e in pol.items():
        for eng in ("mjx", "mujoco"):
            p_, b = e[eng]["policy"], e[eng]["baseline"]
            lo, hi = p_["success_ci95"]
            src = e[eng].get("source", "this run (cross evaluation)")
            out.append(
                f"| {name} | {eng} | {p_['episodes']} | {p_['success_rate']:.3f} [{lo:.3f}, "
                f"{hi:.3f}] | {p_['mean_fz_N']:.3f} | {p_['mean_time_s']:.2f} | "
                f"{b['success_rate']:.3f} | {e[eng]['force_reduction_pct']:.1f} | {src} |"
            )
    return "\n".join(out)


TABLES = {
    "cross_engine_policies": cross_engine_policies,
    "engines_throughput": engines_throughput,
    "engines_ratio": engines_ratio,
    "cross_engine": cross_engine,
    "models_check": models_check,
    "env_rollouts": env_rollouts,
    "contact_check": contact_check,
    "compliance_sweep": compliance_sweep,
    "compliance_findings": compliance_findings,
    "compliance_sweep_envs_law": compliance_sweep_envs_law,
    "compliance_sweep_quasi_static": compliance_sweep_quasi_static,
    "low_stiffness_check": low_stiffness_check,
    "pull_speed": pull_speed,
    "r2_map": r2_map,
    "friction_frontier": friction_frontier,
    "throughput": throughput,
    "roofline": roofline,
    "cost": cost,
    "cost_brief": cost_brief,
    "time_to_success": time_to_success,
    "time_to_success_hard": time_to_success_hard,
    "time_to_success_ratio": time_to_success_hard,
    "seed_stack_dual_hull": seed_stack_dual_hull,
    "pretrained": pretrained,
    "force_sources": force_sources,
    "rl_vs_rlcs": rl_vs_rlcs,
    "generalisation": generalisation,
}


#: the Markdown file (relative to the repository root) that holds each table
TABLE_FILES = {
    "cross_engine_policies": "docs/engines.md",
    "engines_throughput": "docs/engines.md",
    "engines_ratio": "README.md",
    "cross_engine": "docs/engines.md",
    "models_check": "docs/models.md",
    "contact_check": "docs/compliance.md",
    "compliance_sweep": "docs/compliance.md",
    "compliance_findings": "docs/compliance.md",
    "compliance_sweep_envs_law": "docs/compliance.md",
    "compliance_sweep_quasi_static": "docs/compliance.md",
    "low_stiffness_check": "docs/compliance.md",
    "pull_speed": "docs/compliance.md",
    "r2_map": "docs/compliance.md",
    "friction_frontier": "docs/contact.md",
    "env_rollouts": "docs/envs.md",
    "pretrained": "docs/results.md",
    "force_sources": "docs/results.md",
    "rl_vs_rlcs": "docs/results.md",
    "generalisation": "docs/results.md",
    "throughput": "docs/benchmarks.md",
    "roofline": "docs/benchmarks.md",
    "cost": "docs/benchmarks.md",
    "cost_brief": "README.md",
    "time_to_success": "docs/benchmarks.md",
    "time_to_success_hard": "docs/benchmarks.md",
    "time_to_success_ratio": "README.md",
    "seed_stack_dual_hull": "docs/benchmarks.md",
}
assert set(TABLE_FILES) == set(TABLES)

_LINK = re.compile(r"\]\(([^)\s]+)\)")


def relink(table: str, rel_file: str) -> str:
    """Rewrite the repository-root-relative link targets of ``table`` relative to the
    directory of ``rel_file`` (absolute URLs and anchors unchanged)."""
    up = "../" * rel_file.count("/")
    if not up:
        return table

    def fix(m: re.Match) -> str:
        target = m.group(1)
        if re.match(r"[a-z]+:|#|/|\.\./", target):
            return m.group(0)
        return f"]({up}{target})"

    return _LINK.sub(fix, table)


def render(text: str, rel_file: str = "README.md", names=None) -> str:
    """``text`` with the tables ``names`` (default: those of ``rel_file``) regenerated."""
    if names is None:
        names = [n for n, f in TABLE_FILES.items() if f == rel_file]
    for name in names:
        fn = TABLES[name]
        pattern = re.compile(rf"(<!-- table:{name} -->\n).*?(<!-- /table:{name} -->)", re.S)
        if not pattern.search(text):
            raise SystemExit(f"{rel_file} has no markers for table {name!r}")
        text = pattern.sub(
            lambda m, fn=fn: m.group(1) + relink(fn(), rel_file) + "\n" + m.group(2), text
        )
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--check", action="store_true", help="exit 1 if a file is out of date")
    args = ap.parse_args()
    stale = []
    for rel_file in sorted(set(TABLE_FILES.values())):
        path = ROOT / rel_file
        old = path.read_text()
        new = render(old, rel_file)
        if new == old:
            continue
        if args.check:
            stale.append(rel_file)
        else:
            path.write_text(new)
    if stale:
        print(f"tables out of date in {', '.join(stale)}: run python -m benchmarks.readme_tables")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
