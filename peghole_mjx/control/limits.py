"""The thesis's robot limits and the impedance layer's default gains: one source of truth.

Everything that the impedance law, the experiments and the RL environments clip or default to
lives here (SI units). Joint torque limits are NOT repeated here: they are read from the MJCF
actuator ``ctrlrange`` (:func:`peghole_mjx.control.impedance.ImpedanceController.from_model`).

Thesis sources (Ch 4, Sec 4.3.1 and Table 4.2, real KUKA LBR iiwa settings):

* contact-force threshold 20 N in x and y. Erratum E11: Sec 4.3.1 says 20 N, Table 4.2 says
  10 N; we take 20 N (the text, and the value the RL reward and termination were tuned with).
  The thesis gives no threshold along the extraction axis z; we cap it at 60 N (a safety
  bound well above every measured extraction force, so extraction is never force-limited);
* max Cartesian torque [3, 3, 1] N m (about the tool x, y, z axes);
* Cartesian speed <= 0.1 m/s; per-step translation offset <= 0.1 mm in x, y; per-step
  rotation offset <= 5 deg.

Default gains: the Ch 2-3 experiments use a lateral stiffness of 0.3 N/mm = 300 N/m and the
analyses a rotational stiffness K_theta = 30e4 N mm/rad = 300 N m/rad (erratum E8: units
differ between chapters; Table 4.2's 50 N/m is the RL's stiffness). Erratum E10: Sec 3.4.2
calls K_x, K_y = 0.3 N/mm the stiffness "along the extraction direction"; since x, y are the
lateral axes in every analysis of the thesis (the planar models have K_x lateral), we apply
0.3 N/mm laterally and use a stiffer 2000 N/m along the extraction axis z, so that the commanded
constant pulling speed is tracked (a 300 N/m extraction spring would need 33 mm of lag to
transmit 10 N and would turn extraction into stick-slip).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ControlLimits:
    """Cartesian limits of the impedance layer (SI), expressed in the compliance frame."""

    #: per-axis cap of the commanded Cartesian force (x, y lateral; z along the peg), N (E11)
    max_force_N: tuple[float, float, float] = (20.0, 20.0, 60.0)
    #: per-axis cap of the commanded Cartesian moment about the tool x, y, z axes, N m
    max_torque_Nm: tuple[float, float, float] = (3.0, 3.0, 1.0)
    #: speed limit of the commanded compliance-centre motion, m/s
    max_speed_m_s: float = 0.1
    #: per-control-step offset limits of the RL action (Sec 4.3.1)
    max_step_offset_m: float = 0.1e-3
    max_step_rotation_rad: float = math.radians(5.0)

    @property
    def max_wrench(self) -> tuple[float, ...]:
        """The six wrench caps (force, then torque) as one tuple."""
        return (*self.max_force_N, *self.max_torque_Nm)


@dataclass(frozen=True)
class ImpedanceGains:
    """Default gains of the Cartesian impedance law (SI)."""

    #: lateral stiffness (thesis Ch 2-3 experiments, 0.3 N/mm), N/m
    lateral_stiffness_N_m: float = 300.0
    #: stiffness along the extraction (peg) axis, N/m (E10 decision, see module docstring)
    axial_stiffness_N_m: float = 2000.0
    #: rotational stiffness (thesis analyses, K_theta = 30e4 N mm/rad), N m/rad
    rotational_stiffness_Nm_rad: float = 300.0
    #: damping ratio of the Cartesian law (1 = critical)
    damping_ratio: float = 1.0
    #: null-space posture stiffness and damping, N m/rad and N m s/rad
    null_stiffness_Nm_rad: float = 10.0
    null_damping_Nms_rad: float = 2.0
    #: the RL's translational stiffness gains (Table 4.2), N/m
    rl_stiffness_N_m: tuple[float, float, float] = (50.0, 50.0, 50.0)

    @property
    def stiffness(self) -> tuple[float, ...]:
        """6-D stiffness (x, y, z, rx, ry, rz) in the compliance frame."""
        k, r = self.lateral_stiffness_N_m, self.rotational_stiffness_Nm_rad
        return (k, k, self.axial_stiffness_N_m, r, r, r)


LIMITS = ControlLimits()
GAINS = ImpedanceGains()
