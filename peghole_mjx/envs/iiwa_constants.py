"""Names of the iiwa peg-hole scene that the envs look up (the scene: geometry/mjcf.py).

The names, the tool-down orientation and the keyframe are defined where the scene is built
(:mod:`peghole_mjx.geometry.mjcf`) and re-exported here, so an env reads every
name it resolves from one module.
"""

from __future__ import annotations

from peghole_mjx.geometry.mjcf import (
    ACTUATORS,
    FLANGE_SITE,
    FT_FORCE_SENSOR,
    FT_SITE,
    FT_TORQUE_SENSOR,
    HOLE_BODY,
    HOLE_MOUTH_SITE,
    JOINTS,
    PEG_BODY,
    PEG_TIP_SITE,
    START_KEYFRAME,
    TOOL_DOWN_MAT,
)

#: Newton steps of the start-pose IK (from the keyframe to a hole moved by a few mm and deg;
#: a solver setting, not a task parameter)
START_IK_ITERATIONS = 4

__all__ = [
    "ACTUATORS",
    "FLANGE_SITE",
    "FT_FORCE_SENSOR",
    "FT_SITE",
    "FT_TORQUE_SENSOR",
    "HOLE_BODY",
    "HOLE_MOUTH_SITE",
    "JOINTS",
    "PEG_BODY",
    "PEG_TIP_SITE",
    "START_IK_ITERATIONS",
    "START_KEYFRAME",
    "TOOL_DOWN_MAT",
]
