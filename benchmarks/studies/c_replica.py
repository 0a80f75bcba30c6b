"""The compliance-centre experiment in MuJoCo C (float64), one world per call: the studies'
name for the experiment's ``mujoco`` engine.

The replica is not a second implementation: :func:`pull_c` is
:meth:`peghole_mjx.experiments.compliance.Extraction.trace` on the ``mujoco`` engine (the
experiment's scene, keyframe start, F/T tare, command schedule, contact rule and law, the
NumPy twin :func:`peghole_mjx.control.reference.impedance_torque`, stepped by the sim layer's
:class:`peghole_mjx.sim.engine_mujoco.MujocoEngine`). The studies' committed traces were written
by the experiment's earlier per-world loop; how closely they reproduce on the sim layer is
measured by :mod:`benchmarks.studies.sim_reproduction`. Used by
:mod:`benchmarks.studies.pull_speed`, :mod:`benchmarks.studies.friction_frontier` and
:mod:`benchmarks.studies.contact_diagnosis`."""

from __future__ import annotations

import dataclasses

import numpy as np

from peghole_mjx.experiments import compliance as cx
from peghole_mjx.geometry.specs import PRESETS

#: trace columns of :func:`pull_c`, one row per physics step
COLUMNS = cx.TRACE_COLUMNS
#: what the replica is, stored beside its results so that a result of another replica is redone
ENGINE = cx.ENGINES["mujoco"]
#: the experiment's defaults; ``EXPERIMENT.setup(kind)`` holds each geometry's L_C positions,
#: step, contact time constant and representation (``compliance.GeometrySetup``)
EXPERIMENT = cx.ExperimentConfig()


def pull_c(
    preset: str,
    mu: float,
    world: dict[str, float],
    speed_m_s: float,
    cfg: cx.ExperimentConfig | None = None,
    damping_ratio: float | None = None,
    opt: dict[str, float] | None = None,
) -> tuple[np.ndarray, int, float]:
    """One world of the compliance experiment in MuJoCo C (float64): errors ramped in over
    the settling time, then a straight pull at ``speed_m_s`` until the tip is clear
    (:meth:`~peghole_mjx.experiments.compliance.Extraction.trace`, engine ``mujoco``).

    ``world`` holds the :data:`~peghole_mjx.experiments.compliance.WORLD_KEYS` (SI, rad).
    Returns the per-step trace (:data:`COLUMNS`), the settling steps and the step.
    ``damping_ratio`` replaces ``cfg``'s (None: ``GAINS.damping_ratio``); ``opt``:
    ``mjOption`` fields set on the compiled model (e.g. ``noslip_iterations``, ``impratio``),
    for diagnoses of options the experiment does not set."""
    cfg = cfg or cx.ExperimentConfig(geometry=PRESETS[preset].kind)
    cfg = dataclasses.replace(cfg, speed_m_s=speed_m_s, damping_ratio=damping_ratio)
    return cx.Extraction(preset, cfg, mu=mu, engine="mujoco", opt=opt).trace(world)
