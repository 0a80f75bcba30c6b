"""Docs tables of the results that ``peghole`` commands write into ``benchmarks/results/evals/``.

No benchmarks script writes these files; the commands that do, with the output paths used for
the committed ones:

* ``peghole models check --out benchmarks/results/evals/models_check.json`` (table
  ``models_check``: each preset's effective clearance, drop test, contacts, caps);
* ``peghole experiment contact-check --out benchmarks/results/evals/contact_check.json`` (table
  ``contact_check``: step x contact settings -> contact quality);
* ``peghole experiment sweep --out benchmarks/results/evals`` (``compliance_sweep_<geom>.json``,
  tables ``compliance_sweep`` and ``compliance_findings``), with ``--speed-mm-s ... --x64 --out
  benchmarks/results/evals/quasi_static`` (``compliance_sweep_quasi_static``) and with
  ``--no-compensate-joint-damping --no-fix-cone-hessian`` (``compliance_sweep_envs_law``: the
  ``..._envs_law`` files).

``compliance_findings`` also reads the slow dual pull of the study
``benchmarks/studies/pull_speed.py`` (``benchmarks/results/studies/pull_speed_dual.json``).
"""

from __future__ import annotations

import json

from benchmarks.common import EVALS_RESULTS, STUDIES_RESULTS, fmt_ci, per_geometry, table
from peghole_mjx.experiments.contact_check import TABLE_HEADER, table_row


@table("models_check")
def models_check() -> str:
    """Every preset's models check (``peghole models check``)."""
    data = json.loads((EVALS_RESULTS / "models_check.json").read_text())
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


@table("contact_check")
def contact_check() -> str:
    """The contact-settings table: step x settings -> contact quality (contact_check.json)."""
    d = json.loads((EVALS_RESULTS / "contact_check.json").read_text())
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
    """The sweep table of the result files ``pattern`` (with ``{geom}``) under results/evals."""
    head = [
        "| preset | K_theta N m/rad | beta0 deg | mu | K_lat L_C,top^2 / K_theta | "
        "mean peak F_z N: tip / centre / top | tip vs top % [95 % CI] (R1: 77.1) | oracle | "
        "tip vs centre % [95 % CI] (R1: 55.6) | oracle | max penetration um: two-point windows / "
        "tip in the hole (limit) | NaN worlds |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines = list(head)
    notes = []
    for d in per_geometry(EVALS_RESULTS, pattern):
        lines += _sweep_rows(d)
        x = d["settings"]
        notes.append(
            f"{d['geometry']}: {sum(c['n_worlds'] for c in d['cells'])} worlds, "
            f"{x['experiment']['speed_m_s'] * 1e3:g} mm/s, {x.get('precision', 'float32')}, "
            f"{d['device']}, {d['date'][:10]}, {d['runtime_s'] / 60:.0f} min in the invocation "
            "that wrote the file"
        )
    return "\n".join([*lines, "", "Runs: " + "; ".join(notes) + "."])


@table("compliance_sweep")
def compliance_sweep() -> str:
    """The regime sweep: simulated reductions (95 % CI) beside the quasi-static oracle's."""
    return _sweep_table("compliance_sweep_{geom}.json")


@table("compliance_sweep_quasi_static")
def compliance_sweep_quasi_static() -> str:
    """Sweep cells run at a slow pull in float64 (``--speed-mm-s ... --x64``), from
    ``benchmarks/results/evals/quasi_static/``."""
    return _sweep_table("quasi_static/compliance_sweep_{geom}.json")


@table("compliance_sweep_envs_law")
def compliance_sweep_envs_law() -> str:
    """The same sweep run with the envs' law and MJX as shipped (``--no-compensate-joint-damping
    --no-fix-cone-hessian``)."""
    return _sweep_table("compliance_sweep_{geom}_envs_law.json")


def ordered(tc_ci: list[float], ct_ci: list[float]) -> bool:
    """R2's full ordering (tip < centre < top) resolved: the lower ends of the tip-vs-centre
    and centre-vs-top intervals above 0."""
    return tc_ci[0] > 0 and ct_ci[0] > 0


def cell_name(c: dict) -> str:
    """One sweep cell's settings in words."""
    return (
        f"{c['preset']}, K_theta {c['k_rot_Nm_rad']:g} N m/rad, K_lat {c['k_lat_N_m']:g} N/m, "
        f"beta0 {c['beta0_deg']:+g} deg, theta0 {c['theta0_deg']:g} deg, mu {c['mu']:g}"
    )


def _ordered(v: list[float]) -> bool:
    return v[0] < v[1] < v[2]


def _qs_top(c: dict) -> float:
    return c["quasi_static"]["reduction_tip_vs_top_pct"]


def big_cells_agreeing(cells: list[dict]) -> tuple[list[dict], list[dict]]:
    """The cells where the oracle predicts >= 50 % tip vs top, and those of them where the
    simulation agrees within 10 points (the rect-2 criterion of the sweep's docs)."""
    cells = [c for c in cells if c["reduction_tip_vs_top_pct"]["value"] is not None]
    big = [c for c in cells if _qs_top(c) >= 50]
    agree = [c for c in big if abs(c["reduction_tip_vs_top_pct"]["value"] - _qs_top(c)) <= 10]
    return big, agree


@table("compliance_findings")
def compliance_findings() -> str:
    """R1 / R2 against the sweep: best match, the defaults' cells, the largest reduction,
    agreement with the oracle, peak magnitudes against the thesis's 12 N."""
    lines = []
    rect = EVALS_RESULTS / "compliance_sweep_rect.json"
    if rect.exists():
        d = json.loads(rect.read_text())
        cells = [c for c in d["cells"] if c["reduction_tip_vs_top_pct"]["value"] is not None]
        b = d["best_match_R1"]
        best = next(c for c in cells if all(c[k] == v for k, v in b["cell"].items()))
        lines.append(
            f"- **R1 (rect, thesis 77.1 % tip vs top, 55.6 % tip vs centre)**: closest cell "
            f"{cell_name(best)}: {fmt_ci(b['reduction_tip_vs_top_pct'])} and "
            f"{fmt_ci(b['reduction_tip_vs_centre_pct'])}; the oracle predicts "
            f"{b['quasi_static']['reduction_tip_vs_top_pct']:.1f} % and "
            f"{b['quasi_static']['reduction_tip_vs_centre_pct']:.1f} %. 77.1 % is "
            f"{'inside' if b['r1_in_ci95_tip_vs_top'] else 'outside'} that cell's interval."
        )
        top = max(cells, key=lambda c: c["reduction_tip_vs_top_pct"]["value"])
        lines.append(
            "- Largest simulated tip-vs-top reduction: "
            f"{fmt_ci(top['reduction_tip_vs_top_pct'])} ({cell_name(top)})."
        )
        for c in cells:
            if c["k_rot_Nm_rad"] == 300.0 and c["k_lat_N_m"] == 300.0 and c["theta0_deg"] == 0:
                lines.append(
                    f"- The project's default stiffnesses ({cell_name(c)}): "
                    f"{fmt_ci(c['reduction_tip_vs_top_pct'])} tip vs top (oracle "
                    f"{c['quasi_static']['reduction_tip_vs_top_pct']:.1f} %)."
                )
        big, agree = big_cells_agreeing(cells)
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
    slow_rect = EVALS_RESULTS / "quasi_static" / "compliance_sweep_rect.json"
    if slow_rect.exists():
        d = json.loads(slow_rect.read_text())
        x = d["settings"]
        big, agree = big_cells_agreeing(d["cells"])
        each = "; ".join(
            f"K_theta {c['k_rot_Nm_rad']:g} N m/rad, beta0 {c['beta0_deg']:+g} deg: "
            f"{fmt_ci(c['reduction_tip_vs_top_pct'])} against {_qs_top(c):.1f} %"
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
    dual = EVALS_RESULTS / "compliance_sweep_dual.json"
    if dual.exists():
        d = json.loads(dual.read_text())
        for c in d["cells"]:
            q, r = c["quasi_static"], c["reduction_tip_vs_top_pct"]
            if r["value"] is None:
                continue
            pk = c["peak_fz_N"]
            order = list(pk.values())
            lines.append(
                f"- **R2 (dual)**, {cell_name(c)}: oracle tip vs top "
                f"{q['reduction_tip_vs_top_pct']:.1f} %, simulated {fmt_ci(r)}; simulated peaks "
                f"tip / centre / top {' / '.join(f'{v:.3f}' for v in order)} N "
                f"({'ordered as R2' if order[0] < order[1] < order[2] else 'not ordered as R2'})."
            )
    slow = STUDIES_RESULTS / "pull_speed_dual.json"
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
                f"{fmt_ci(top)} (oracle {top['oracle']:.1f} %), tip vs centre {fmt_ci(cen)} "
                f"(oracle {cen['oracle']:.1f} %)."
            )
    return "\n".join(lines)
