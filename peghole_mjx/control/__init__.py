"""Cartesian impedance layer with an active compliance centre (thesis Sec 2.4, 3.2, 4.3.1)."""

from peghole_mjx.control.impedance import (
    ImpedanceController,
    ImpedanceOutput,
    ImpedanceParams,
    Target,
    clip_wrench,
    force_at_point,
    make_params,
    rate_limit,
)
from peghole_mjx.control.kinematics import rot_from_rotvec, rot_y, rot_z, rotvec_from_mat
from peghole_mjx.control.limits import GAINS, LIMITS, ControlLimits, ImpedanceGains

__all__ = [
    "GAINS",
    "LIMITS",
    "ControlLimits",
    "ImpedanceController",
    "ImpedanceGains",
    "ImpedanceOutput",
    "ImpedanceParams",
    "Target",
    "clip_wrench",
    "force_at_point",
    "make_params",
    "rate_limit",
    "rot_from_rotvec",
    "rot_y",
    "rot_z",
    "rotvec_from_mat",
]
