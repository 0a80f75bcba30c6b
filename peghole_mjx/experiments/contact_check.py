"""``peghole experiment contact-check``: does a tilted peg hold two-point contact?

A standard case is pulled out of a rect preset with the thesis's compliance law: L_C at the tip,
K_lat 300 N/m, K_theta 300 N m/rad, delta0 about 2 mm and beta0 about -0.2 deg (thesis sign;
the quasi-static model puts this case in two-point contact from about 33 mm depth to the start
depth), mu 0.266, 20 mm/s. Each world's errors are scaled by a factor drawn in [0.75, 1.25].
Per world it reports, inside the 20 ms samples where both wall sides are loaded on average
(:func:`~peghole_mjx.experiments.compliance.two_point_windows`):

* ``both_frac``: the fraction of physics steps in which both sides carry force;
* ``peak_ratio_p95``: the 95th percentile over the windows of the peak per-step side force over
  its 20 ms mean (1 = steady; a contact that exists in one step of N reads N);
* ``switches_per_s``: changes of the one loaded wall side per second of simulated pull;
* ``penetration_um``: the deepest contact while the tip is below the mouth, against 25 % of
  the radial clearance (``penetration_whole_pull_um`` includes the exit);
* ``oracle_err``: the median over the windows of the relative difference between the
  time-averaged side forces and the quasi-static oracle's at the same tip depth.

A variant is a step size and a set of contact settings (:data:`VARIANTS`); the table over the
variants is the evidence for the experiment's and the environments' settings
(docs/research/contact.md).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import jax
import numpy as np

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.validation import check
from peghole_mjx.experiments import compliance as cx
from peghole_mjx.geometry.mjcf import SimOptions
from peghole_mjx.geometry.specs import MM, PRESETS

#: the standard tilted case (SI; angles in rad, thesis sign)
STANDARD_CASE = {
    "L_C": 0.0,
    "delta0": 2.0e-3,
    "beta0": math.radians(-0.2),
    "theta0": 0.0,
    "k_lat": 300.0,
    "k_rot": 300.0,
}
STANDARD_MU = 0.266
#: the bounds a variant must meet (from the contact-fidelity acceptance list)
BOUNDS = {
    "both_frac_min": 0.90,
    "peak_ratio_p95_max": 3.0,
    "penetration_fraction_of_radial_clearance_max": 0.25,
    "oracle_rel_err_max": 0.15,
    "oracle_worlds_fraction_min": 0.80,
}


@dataclass(frozen=True)
class Variant:
    """A physics step and contact settings (fields as in :class:`SimOptions`)."""

    name: str
    timestep_s: float
    friction_timeconst: float | None = 1.0
    representation: str = "edges"
    contact_timeconst: float | None = None
    note: str = ""

    def sim(self) -> SimOptions:
        return dataclasses.replace(
            SimOptions(),
            timestep=self.timestep_s,
            friction_timeconst=self.friction_timeconst,
            contact_timeconst=self.contact_timeconst,
        )


#: the variants of the settings table; "experiment" and "envs" are the settings in use
VARIANTS: dict[str, Variant] = {
    v.name: v
    for v in (
        Variant(
            "box-0.25ms-stiff-friction", 0.00025, None, "box", note="experiment until 2026-11-29"
        ),
        Variant("box-2ms-stiff-friction", 0.002, None, "box", note="envs until 2026-11-29"),
        Variant("box-1ms", 0.001, 1.0, "box"),
        Variant("edges-1ms-stiff-friction", 0.001, None, "edges"),
        Variant("edges-1ms", 0.001, 1.0, "edges"),
        Variant(
            "experiment",
            cx.ExperimentConfig().rect.timestep_s,
            1.0,
            cx.ExperimentConfig().rect.representation,
            cx.ExperimentConfig().rect.contact_timeconst_s,
            note="the experiment's settings",
        ),
        Variant("envs", SimOptions().timestep, 1.0, "edges", 0.01, note="the envs' settings"),
    )
}


def world_table(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` jittered copies of :data:`STANDARD_CASE` (errors scaled by U[0.75, 1.25])."""
    rng = np.random.default_rng([seed, 19])
    tab = {k: np.full(n, v, float) for k, v in STANDARD_CASE.items()}
    tab["delta0"] = tab["delta0"] * rng.uniform(0.75, 1.25, n)
    tab["beta0"] = tab["beta0"] * rng.uniform(0.75, 1.25, n)
    return tab


def oracle_errors(res: dict, qs: dict) -> np.ndarray:
    """Per world: the median relative difference between the simulated time-averaged side
    forces and the oracle's at the same depth, over the windows where both are two-point
    (NaN for a world without such a window)."""
    d_or = qs["depth_mm"][::-1]
    out = np.full(len(res["L_C"]), np.nan)
    for w in range(len(out)):
        fp_or = np.interp(res["depth_mm"][w], d_or, qs["f_plus"][w][::-1])
        fm_or = np.interp(res["depth_mm"][w], d_or, qs["f_minus"][w][::-1])
        sel = res["two_point"][w] & (fp_or > 0) & (fm_or > 0)
        if sel.any():
            err = np.maximum(
                np.abs(res["f_plus"][w][sel] - fp_or[sel]) / fp_or[sel],
                np.abs(res["f_minus"][w][sel] - fm_or[sel]) / fm_or[sel],
            )
            out[w] = float(np.median(err))
    return out


def check_preset(preset: str):
    """The spec of ``preset`` if it is a rect preset, else UserInputError."""
    spec = PRESETS.get(preset)
    if spec is None or spec.kind != "rect":
        raise UserInputError(
            f"contact-check runs a rect preset (rect-1, rect-2, rect-3), not {preset!r}"
        )
    return spec


def variant_config(variant: Variant, engine: str = "auto") -> cx.ExperimentConfig:
    """The experiment's config of a variant on ``engine``: the law and solver as in the envs
    (no joint-damping cancellation, MJX as shipped), so that the variants differ in contact
    settings only (at K_theta 300 N m/rad both are small effects)."""
    return cx.ExperimentConfig(
        geometry="rect",
        sim=variant.sim(),
        representation=variant.representation,
        chunk_steps=round(0.4 / variant.timestep_s),
        compensate_joint_damping=False,
        fix_cone_hessian=False,
        engine=cx.check_engine(engine, jax.config.jax_enable_x64),
    )


def run_variant(
    preset: str,
    variant: Variant,
    worlds: int = 8,
    seed: int = 0,
    progress: bool = True,
    engine: str = "auto",
) -> dict:
    """Run the standard case on ``worlds`` worlds on ``engine`` (``auto``, ``mjx`` or ``mujoco``,
    :data:`~peghole_mjx.experiments.compliance.ENGINES`); per-world metrics and the bounds'
    verdict (a variant whose every world went NaN has a ``failure`` in its summary, and fails).

    Every metric comes from the experiment's record (``Extraction.run``), which both engines
    keep alike; the one difference is which contacts count for the penetration: on ``mjx``
    those with a constraint row, on ``mujoco`` those with a positive normal force."""
    spec = check_preset(preset)
    check("worlds", worlds, "--worlds")
    cfg = variant_config(variant, engine)
    engine = cfg.engine  # auto made concrete: the result records the engine that ran
    t0 = time.perf_counter()
    ex = cx.Extraction(preset, cfg, mu=STANDARD_MU)
    tab = world_table(worlds, seed)
    t1 = time.perf_counter()
    res = ex.run(progress=progress, table=tab)
    t2 = time.perf_counter()
    qs = cx.quasi_static(preset, STANDARD_MU, tab, res["h0_mm"])
    err = oracle_errors(res, qs)
    limit_um = BOUNDS["penetration_fraction_of_radial_clearance_max"] * (
        spec.radial_clearance_mm * 1e3
    )
    pull_s = ex.n_steps * ex.dt - res["settle_s"]
    rows = []
    for w in range(worlds):
        ch = cx.chatter_stats(res, w)
        rows.append(
            {
                "delta0_mm": round(float(tab["delta0"][w]) / MM, 4),
                "beta0_deg": round(math.degrees(float(tab["beta0"][w])), 4),
                "two_point_windows": ch["windows"],
                "both_frac": ch["both_frac"],
                "peak_ratio_median": ch["peak_ratio_median"],
                "peak_ratio_p95": ch["peak_ratio_p95"],
                "switches_per_s": float(res["switches"][w].sum() / pull_s),
                "penetration_um": float(res["penetration_in_hole_mm"][w] * 1e3),
                "penetration_whole_pull_um": float(res["penetration_mm"][w] * 1e3),
                "oracle_err": None if math.isnan(err[w]) else float(err[w]),
                "nan": bool(res["nan"][w]),
            }
        )
    tp = [r for r in rows if r["two_point_windows"] > 0]
    # pooled over the worlds' two-point windows
    n_win = sum(r["two_point_windows"] for r in tp)
    both = sum(r["both_frac"] * r["two_point_windows"] for r in tp) / n_win if n_win else None
    p95 = max((r["peak_ratio_p95"] for r in tp), default=None)
    pen = max(r["penetration_um"] for r in rows)
    errs = [r["oracle_err"] for r in tp if r["oracle_err"] is not None]
    agree = sum(e <= BOUNDS["oracle_rel_err_max"] for e in errs) / len(tp) if tp else None
    summary = {
        "worlds_in_two_point": len(tp),
        "both_frac": both,
        "peak_ratio_p95_max": p95,
        "switches_per_s_mean": float(np.mean([r["switches_per_s"] for r in rows])),
        "penetration_um_max": pen,
        "penetration_limit_um": limit_um,
        "oracle_agree_fraction": agree,
        "oracle_err_median": float(np.median(errs)) if errs else None,
        "nan_worlds": sum(r["nan"] for r in rows),
        "world_steps_per_s": worlds * ex.n_steps / (t2 - t1),
        "compile_and_build_s": t1 - t0,
    }
    summary["pass"] = {
        "both_frac": both is not None and both >= BOUNDS["both_frac_min"],
        "peak_ratio": p95 is not None and p95 <= BOUNDS["peak_ratio_p95_max"],
        "penetration": pen <= limit_um,
        "oracle": agree is not None and agree >= BOUNDS["oracle_worlds_fraction_min"],
    }
    summary["pass"]["all"] = all(summary["pass"].values())
    if rows and all(r["nan"] for r in rows):
        summary["failure"] = (
            f"every one of its {worlds} worlds went NaN (the simulation diverged): no metric "
            "of this variant is a result; likely cause: its step size and contact settings, "
            "or float32 rounding (try --x64)"
        )

    x64 = engine == "mujoco" or jax.config.jax_enable_x64
    return {
        "preset": preset,
        "precision": "float64" if x64 else "float32",
        "engine": engine,
        "variant": dataclasses.asdict(variant),
        "summary": summary,
        "worlds": rows,
    }


def run_key(run: dict) -> tuple[str, str, str, str]:
    """What a run of a contact-check JSON is a run of: (preset, variant, precision, engine); a
    run from before the engine was recorded (2026-12-02) ran on ``mjx``."""
    return (
        run["preset"],
        run["variant"]["name"],
        run.get("precision", "float32"),
        run.get("engine", "mjx"),
    )


def case_dict() -> dict:
    """The standard case in readable units."""
    return {
        "L_C_mm": STANDARD_CASE["L_C"] / MM,
        "delta0_mm": STANDARD_CASE["delta0"] / MM,
        "beta0_deg": math.degrees(STANDARD_CASE["beta0"]),
        "k_lat_N_m": STANDARD_CASE["k_lat"],
        "k_rot_Nm_rad": STANDARD_CASE["k_rot"],
        "mu": STANDARD_MU,
        "speed_m_s": cx.ExperimentConfig().speed_m_s,
        "error_scale": [0.75, 1.25],
    }


TABLE_HEADER = (
    "| preset | variant | precision | step ms | contacts | contact tc ms | friction tc s | "
    "both walls | peak/mean p95 | "
    "switches/s | penetration um (limit) | oracle agree | world-steps/s | pass |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def table_row(run: dict) -> str:
    """One markdown table row of a :func:`run_variant` result."""
    v, s = run["variant"], run["summary"]

    def f(x, nd=2):
        return "-" if x is None else f"{x:.{nd}f}"

    precision = run.get("precision", "float32")
    if run.get("engine", "mjx") != "mjx":
        precision += f" ({run['engine']})"

    return (
        f"| {run['preset']} | {v['name']} | {precision} | "
        f"{v['timestep_s'] * 1e3:g} | {v['representation']} | "
        f"{(v['contact_timeconst'] or 2 * v['timestep_s']) * 1e3:g} | "
        f"{'-' if v['friction_timeconst'] is None else v['friction_timeconst']} | "
        f"{f(s['both_frac'])} | {f(s['peak_ratio_p95_max'], 1)} | "
        f"{f(s['switches_per_s_mean'], 1)} | "
        f"{f(s['penetration_um_max'])} ({s['penetration_limit_um']:.2f}) | "
        f"{f(s['oracle_agree_fraction'])} | {s['world_steps_per_s']:.0f} | "
        f"{'yes' if s['pass']['all'] else 'no'} |"
    )
