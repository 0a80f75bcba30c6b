"""The thesis's simulator rebuilt as a baseline: RectExtract in PyBullet (seed stack).

Same task as the registered env it is built for (``RectExtract``, default, or
``RectExtractHard``), with every number taken from the project (one source of truth): the
env's default config (``peghole_mjx.envs.get_default_config(env)``: its preset, rect-2 or
rect-3, through :func:`peghole_mjx.geometry.specs.get_preset`),
its convex pieces (:func:`peghole_mjx.geometry.parts.hole_parts` / ``peg_parts``: four wall
boxes and a floor box, the peg one box), the env config (action scales, stiffness, jamming,
success margin, episode length, randomisation, e.g. RectExtractHard's +-4 deg commanded tilt
error), the
limits and gains (:mod:`peghole_mjx.control.limits`), the reward terms and weights
(:func:`peghole_mjx.envs.reward.reward_terms`, Table 4.1).

Robot: PyBullet's bundled ``kuka_iiwa/model.urdf`` (LBR iiwa 14 R820) with three links added
by fixed joints, as on the MJCF robot: the F/T sensor (0.35 kg, 37.5 mm, on the media flange
0.045 m along link 7's z) and the peg (box, 0.4 kg) below it. The joint torque limits are the
MJCF actuators' (the data-sheet torques), not the URDF's 300 N m.

Impedance: the same Cartesian impedance law with a compliance centre as the MJX envs, run in
joint-torque control at every 2 ms physics step
(:func:`peghole_mjx.control.reference.impedance_torque`, the NumPy twin of
:class:`peghole_mjx.control.ImpedanceController`): the Jacobian of the compliance centre from
``calculateJacobian``, the joint-space inertia from ``calculateMassMatrix``, gravity and Coriolis
torques from ``calculateInverseDynamics``; PyBullet's velocity motors are switched off. Gains: k_xy
300 N/m, k_z 2000 N/m, k_rot 300 N m/rad, critical damping, compliance centre at the tip (the env
defaults).

Observation (9): flange x, y offset (mm), flange height / peg length, F/T force / 20 N (the
fixed-joint reaction of the peg, peg weight and the sensor's own offset removed by zeroing at
reset, averaged over the 10 substeps), flange tilt (deg). Action (6) in [-1, 1]: dx, dy x 0.1 mm,
dz x 0.1 m/s x 20 ms, dF x 2 N (total clipped to 20/20/60 N).

Differences from the MJX env (documented, not hidden): PyBullet's kinematics and inertias are
the URDF's (the MJCF iiwa has its own inertial values and a 0.1 kg m^2 armature per joint that
PyBullet cannot model), contact is Bullet's (soft-constraint LCP, 50 solver iterations,
contact margins; MuJoCo's soft-contact parameters have no PyBullet equivalent), and the
friction coefficient is set on the hole with 1.0 on the peg (Bullet multiplies the two).

Every entry of the env config is accounted for (:func:`check_config`): read by the sim
(:data:`HONOURED`), a MuJoCo model setting with no Bullet counterpart (:data:`ENGINE_ONLY`:
Bullet's own contact and solver stand in), inert with the compliance strategy off
(:data:`INACTIVE`), or honoured at one value only (:data:`REQUIRED`); any other value or entry
is refused with one line rather than ignored.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from peghole_mjx.control.reference import (
    impedance_torque,
    rot_from_rotvec,
    rotvec_from_mat,
)
from peghole_mjx.control.reference import rot_z as rotz
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs import get_default_config
from peghole_mjx.envs.reward import OUTCOME_WEIGHTS, REWARD_WEIGHTS, reward_terms
from peghole_mjx.envs.rollout import SCRIPTED_SPEED_M_S
from peghole_mjx.geometry.mjcf import ACTUATORS, ROBOT_XML, TOOL_DOWN_MAT
from peghole_mjx.geometry.parts import hole_parts, peg_parts
from peghole_mjx.geometry.specs import MM, RectSpec, get_preset

FLANGE_Z_M = 0.045  # media flange along link 7's z (MJCF body "flange")
FT_HEIGHT_M = 0.0375  # F/T sensor height (MJCF body "tool" above the flange)
FT_MASS_KG = 0.35
HOLE_XY_M = (0.6, 0.0)  # as the MJCF scene
N_ARM = 7
FT_LINK, PEG_LINK = 7, 8  # link indices of the added fixed links

#: the registered envs this sim rebuilds (the rectangular peg-hole, compliance strategy off)
PYBULLET_ENVS = ("RectExtract", "RectExtractHard")

#: env config entries the sim reads (dotted names of the flattened config)
HONOURED = frozenset(
    {
        "preset",
        "ctrl_dt",
        "sim_dt",
        "episode_length",
        "jam_force_N",
        "jam_time_s",
        "success_margin_mm",
        "action.max_step_offset_mm",
        "action.max_speed_m_s",
        "action.max_force_step_N",
        "action.max_ff_xy_N",
        "limits.max_force_N",
        "limits.max_torque_Nm",
        "obs.force_scale_N",
        "randomization.hole_xy_mm",
        "randomization.hole_yaw_deg",
        "randomization.lateral_error_mm",
        "randomization.angular_error_deg",
        "randomization.friction_scale",
        "stiffness.k_xy_N_m",
        "stiffness.k_z_N_m",
        "stiffness.k_rot_Nm_rad",
        "stiffness.damping_ratio",
        "stiffness.compliance_centre_mm",
        "stiffness.null_stiffness_Nm_rad",
        "stiffness.null_damping_Nms_rad",
    }
    | {f"reward_config.{k}" for k in (*REWARD_WEIGHTS, "force_scale_N", "stiffness_scale_N_m")}
    | {
        f"reward_config.{k}"
        for k in ("w_stf_rot", "rot_stiffness_scale_Nm_rad", "w_fz", "fz_scale_N")
    }
)
#: MuJoCo/MJX model settings with no Bullet counterpart (Bullet's contact and solver instead)
ENGINE_ONLY = frozenset(
    {
        "engine",
        "mujoco_threads",
        "impl",
        "naconmax",
        "njmax",
        "contact_cap",
        "representation",
        "contact.timeconst_s",
        "contact.friction_timeconst_s",
    }
)
#: entries that act only with the compliance strategy on (refused: see REQUIRED) or with an
#: observation extra on
INACTIVE = frozenset(
    {
        "compliance_rotation",
        "stiffness.k_xy_min_N_m",
        "stiffness.k_xy_max_N_m",
        "stiffness.k_rot_min_Nm_rad",
        "stiffness.k_rot_max_Nm_rad",
        "obs.k_xy_scale_N_m",
        "obs.k_rot_scale_Nm_rad",
        "obs.torque_scale_Nm",
        # the stuck joint's figures act only with stuck.enabled (REQUIRED off)
        "stuck.breakaway_N",
        "stuck.timeconst_s",
        # the residual's scale acts only with action.residual (REQUIRED off)
        "action.residual_scale",
        # the outcome reward's settings act only with reward_config.kind outcome (REQUIRED:
        # the seed stack pays the thesis's eq 4.4)
        *(f"reward_config.{k}" for k in OUTCOME_WEIGHTS),
        "reward_config.time_limit",
    }
)
#: entries the sim honours at one value only: the 9-D observation, the 6-D action with the
#: fixed stiffness (compliance strategy off), the preset's own geometry
REQUIRED = {
    "reward_config.kind": "thesis",
    "action.residual": False,
    "compliance_strategy": False,
    "learn_compliance_centre": False,
    "obs.prev_action": False,
    "obs.commands": False,
    "obs.time_left": False,
    "obs.stiffness": False,
    "obs.torques": False,
    "geometry": "",
    "randomization.stiffness_N_m": (0.0, 0.0),
    # the transfer shifts (docs/research/transfer.md) and the stuck joint: off only
    "randomization.ft_noise_force_N": 0.0,
    "randomization.ft_noise_torque_Nm": 0.0,
    "randomization.ft_bias_force_N": 0.0,
    "randomization.ft_bias_torque_Nm": 0.0,
    "randomization.ft_drift_force_N_sqrt_s": 0.0,
    "randomization.ft_drift_torque_Nm_sqrt_s": 0.0,
    "randomization.obs_latency_steps": 0,
    "randomization.action_latency_steps": 0,
    "randomization.tool_axial_mm": (0.0, 0.0),
    "randomization.tool_lateral_mm": (0.0, 0.0),
    "randomization.tool_tilt_deg": (0.0, 0.0),
    "randomization.payload_mass_scale": (1.0, 1.0),
    "stuck.enabled": False,
}


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def check_config(config) -> None:
    """Refuse (one line, :class:`UserInputError`) an env config entry the sim cannot honour.

    Every entry must be read by the sim, be a MuJoCo-only setting, be inert with the
    compliance strategy off, or hold the one value the sim models.
    """
    for key, value in sorted(_flatten(config.to_dict()).items()):
        want = REQUIRED.get(key)
        norm = tuple(value) if isinstance(value, list | tuple) else value
        if key in REQUIRED and norm != want:
            raise UserInputError(
                f"the PyBullet seed stack cannot honour env config {key}={value!r} "
                f"(it models {key}={want!r} only)"
            )
        if key not in HONOURED | ENGINE_ONLY | INACTIVE | set(REQUIRED):
            raise UserInputError(
                f"the PyBullet seed stack does not know env config entry {key!r} "
                "(benchmarks/baselines/pybullet_peghole.py: HONOURED, ENGINE_ONLY, INACTIVE or "
                "REQUIRED)"
            )


def env_config(env: str):
    """The registered env's default config, checked for the PyBullet sim (one line if not)."""
    if env not in PYBULLET_ENVS:
        raise UserInputError(
            f"the PyBullet seed stack rebuilds {list(PYBULLET_ENVS)} only, not {env!r}"
        )
    config = get_default_config(env)
    check_config(config)
    return config


def _ctrl_range() -> tuple[np.ndarray, np.ndarray]:
    """The iiwa's joint torque limits from the MJCF actuators (one source of truth)."""
    m = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    rng = np.array([m.actuator(a).ctrlrange for a in ACTUATORS])
    return rng[:, 0].copy(), rng[:, 1].copy()


def make_urdf(spec: RectSpec, out_dir: Path) -> Path:
    """PyBullet's kuka_iiwa URDF with the F/T sensor and the peg added (absolute mesh paths)."""
    import pybullet_data

    src = Path(pybullet_data.getDataPath()) / "kuka_iiwa" / "model.urdf"
    text = src.read_text()
    text = text.replace('filename="meshes/', f'filename="{src.parent}/meshes/')
    (peg,) = peg_parts(spec)
    hx, hy, hz = (float(v) for v in peg.half_size)
    m = spec.peg_mass_kg
    ixx, iyy, izz = (
        m / 3 * (hy**2 + hz**2),
        m / 3 * (hx**2 + hz**2),
        m / 3 * (hx**2 + hy**2),
    )
    extra = f"""
  <joint name="ft_mount" type="fixed">
    <parent link="lbr_iiwa_link_7"/><child link="ft_sensor"/>
    <origin xyz="0 0 {FLANGE_Z_M}" rpy="0 0 0"/>
  </joint>
  <link name="ft_sensor">
    <inertial><origin xyz="0 0 {FT_HEIGHT_M / 2}"/><mass value="{FT_MASS_KG}"/>
      <inertia ixx="2e-4" ixy="0" ixz="0" iyy="2e-4" iyz="0" izz="2e-4"/></inertial>
  </link>
  <joint name="peg_mount" type="fixed">
    <parent link="ft_sensor"/><child link="peg"/>
    <origin xyz="0 0 {FT_HEIGHT_M}" rpy="0 0 0"/>
  </joint>
  <link name="peg">
    <inertial><origin xyz="0 0 {hz}"/><mass value="{m}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>
    <visual><origin xyz="0 0 {hz}"/><geometry><box size="{2 * hx} {2 * hy} {2 * hz}"/></geometry>
    </visual>
    <collision><origin xyz="0 0 {hz}"/>
      <geometry><box size="{2 * hx} {2 * hy} {2 * hz}"/></geometry></collision>
  </link>
</robot>"""
    text = text.replace("</robot>", extra)
    out = Path(out_dir) / "iiwa14_peg.urdf"
    out.write_text(text)
    return out


@dataclass
class StepResult:
    obs: np.ndarray
    reward: float
    terms: dict[str, float]
    success: bool
    failure: bool
    jammed: bool
    depth_mm: float
    fxy_N: float


class PegHoleSim:
    """One PyBullet world (its own DIRECT client): reset, step, observation, reward."""

    def __init__(self, env: str = "RectExtract", seed: int = 0, config=None):
        import pybullet as p

        self.p = p
        self.env = env
        if config is None:
            config = env_config(env)
        else:
            check_config(config)
        self.c = config
        self.rc = self.c.reward_config
        self.spec = get_preset(self.c.preset)
        if not isinstance(self.spec, RectSpec):
            raise ValueError("the PyBullet baseline models the rectangular peg-hole only")
        self.rng = np.random.default_rng(seed)
        self.cid = p.connect(p.DIRECT)
        self._tmp = tempfile.TemporaryDirectory(prefix="peghole_pb_")
        urdf = make_urdf(self.spec, Path(self._tmp.name))
        kw = {"physicsClientId": self.cid}
        p.setGravity(0, 0, -9.81, **kw)
        self.sim_dt = float(self.c.sim_dt)
        self.n_sub = round(self.c.ctrl_dt / self.c.sim_dt)
        p.setPhysicsEngineParameter(fixedTimeStep=self.sim_dt, numSubSteps=0, **kw)
        self.robot = p.loadURDF(
            str(urdf),
            useFixedBase=True,
            flags=p.URDF_USE_INERTIA_FROM_FILE,
            **kw,
        )
        for j in range(-1, p.getNumJoints(self.robot, **kw)):
            p.changeDynamics(self.robot, j, linearDamping=0.0, angularDamping=0.0, **kw)
        p.changeDynamics(self.robot, PEG_LINK, lateralFriction=1.0, **kw)
        # hole block: the project's convex pieces as boxes on one static body
        parts = hole_parts(self.spec)
        shapes = p.createCollisionShapeArray(
            shapeTypes=[p.GEOM_BOX] * len(parts),
            halfExtents=[list(map(float, h.half_size)) for h in parts],
            collisionFramePositions=[list(map(float, h.pos)) for h in parts],
            **kw,
        )
        self.top_z = (self.spec.hole_depth_mm + self.spec.floor_mm) * MM
        self.hole_pos0 = np.array([HOLE_XY_M[0], HOLE_XY_M[1], self.top_z])
        self.hole = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shapes,
            basePosition=self.hole_pos0.tolist(),
            **kw,
        )
        for j in range(-1, FT_LINK):  # arm links never touch the block (as in the MJCF)
            p.setCollisionFilterPair(self.robot, self.hole, j, -1, 0, **kw)
        p.setCollisionFilterPair(self.robot, self.hole, FT_LINK, -1, 0, **kw)
        # torque control: switch the default velocity motors off
        p.setJointMotorControlArray(
            self.robot, list(range(N_ARM)), p.VELOCITY_CONTROL, forces=[0.0] * N_ARM, **kw
        )
        p.enableJointForceTorqueSensor(self.robot, PEG_LINK, True, **kw)
        self.ctrl_lo, self.ctrl_hi = _ctrl_range()
        s = self.c.stiffness
        self.k_xy = float(s.k_xy_N_m)
        self.k_rot = float(s.k_rot_Nm_rad)
        self.stiffness = np.array(
            [s.k_xy_N_m, s.k_xy_N_m, s.k_z_N_m, s.k_rot_Nm_rad, s.k_rot_Nm_rad, s.k_rot_Nm_rad]
        )
        self.zeta = float(s.damping_ratio)
        self.L_C = float(s.compliance_centre_mm) * MM
        self.null_gains = (s.null_stiffness_Nm_rad, s.null_damping_Nms_rad)
        self.L = self.spec.length_mm * MM
        (peg,) = peg_parts(self.spec)
        self.half_len = float(peg.half_size[2])
        self.depth0_mm = self.spec.hole_depth_mm - 0.5  # tip 0.5 mm above the bottom (MJCF)
        # nominal start: solve the arm for the nominal hole, keep it as the null-space posture
        self.q = np.array([0.0, 0.5, 0.0, -1.6, 0.0, 1.0, 0.0])  # the MJCF IK seed
        self.q_null = self._solve_start(self.hole_pos0, np.eye(3), iters=60)
        self.q_start = self.q_null.copy()
        self._set_q(self.q_null, np.zeros(N_ARM))
        self.flange_z0 = self._flange()[0][2] - self.hole_pos0[2]
        self._zero_ft = np.zeros(6)
        self.info: dict = {}

    # ----------------------------------------------------------------- kinematics helpers
    def close(self) -> None:
        try:
            self.p.disconnect(self.cid)
        except Exception:
            pass
        self._tmp.cleanup()

    def _set_q(self, q, qd) -> None:
        for j in range(N_ARM):
            self.p.resetJointState(
                self.robot, j, float(q[j]), float(qd[j]), physicsClientId=self.cid
            )

    def _joints(self) -> tuple[np.ndarray, np.ndarray]:
        st = self.p.getJointStates(self.robot, list(range(N_ARM)), physicsClientId=self.cid)
        return np.array([s[0] for s in st]), np.array([s[1] for s in st])

    def _peg(self) -> tuple[np.ndarray, np.ndarray]:
        """Peg COM-frame position and rotation (the link's inertial frame)."""
        ls = self.p.getLinkState(
            self.robot, PEG_LINK, computeForwardKinematics=True, physicsClientId=self.cid
        )
        R = np.array(self.p.getMatrixFromQuaternion(ls[1])).reshape(3, 3)
        return np.array(ls[0]), R

    def _flange(self) -> tuple[np.ndarray, np.ndarray]:
        ls = self.p.getLinkState(
            self.robot, N_ARM - 1, computeForwardKinematics=True, physicsClientId=self.cid
        )
        R = np.array(self.p.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
        return np.array(ls[4]) + R @ np.array([0.0, 0.0, FLANGE_Z_M]), R

    def tip(self) -> np.ndarray:
        pos, R = self._peg()
        return pos + R @ np.array([0.0, 0.0, self.half_len])

    def _jacobian(self, q, qd, local) -> np.ndarray:
        """(6, 7) world Jacobian of a point given in the peg's COM frame.

        ``calculateJacobian`` takes the point in the URDF link frame (checked against finite
        differences): the peg's link frame is its mount, the COM frame ``half_len`` below it.
        """
        zeros = [0.0] * N_ARM
        local_link = np.asarray(local, float) + np.array([0.0, 0.0, self.half_len])
        lin, ang = self.p.calculateJacobian(
            self.robot,
            PEG_LINK,
            local_link.tolist(),
            list(map(float, q)),
            list(map(float, qd)),
            zeros,
            physicsClientId=self.cid,
        )
        return np.vstack([np.array(lin), np.array(ang)])

    def _solve_start(self, hole_pos, hole_mat, iters: int = 12) -> np.ndarray:
        """Newton steps on the 6-D tip pose error (as the MJX env's reset)."""
        tip_target = hole_pos + hole_mat @ np.array([0.0, 0.0, -self.depth0_mm * MM])
        mat_target = hole_mat @ TOOL_DOWN_MAT
        q = self.q.copy()
        for _ in range(iters):
            self._set_q(q, np.zeros(N_ARM))
            pos, R = self._peg()
            tip = pos + R @ np.array([0.0, 0.0, self.half_len])
            err = np.concatenate([tip_target - tip, rotvec_from_mat(mat_target @ R.T)])
            if np.linalg.norm(err) < 1e-10:
                break
            J = self._jacobian(q, np.zeros(N_ARM), [0.0, 0.0, self.half_len])
            q = q + np.linalg.lstsq(J, err, rcond=None)[0]
        return q

    def _ft_raw(self) -> np.ndarray:
        """Reaction wrench of the peg's fixed joint (PyBullet's joint F/T sensor)."""
        return np.array(
            self.p.getJointState(self.robot, PEG_LINK, physicsClientId=self.cid)[2], float
        )

    def contact_force(self) -> np.ndarray:
        """F/T force in the hole frame, zeroed at reset (peg weight and bias removed), N.

        PyBullet reports the fixed joint's reaction in the peg's (child) link frame; rotated to
        the world and then to the hole frame, minus the reading at reset rotated the same
        way (at reset the peg hangs free of contact: its weight).
        """
        _, R = self._peg()
        f_world = R @ self._ft_raw()[:3]
        return self.info["hole_mat"].T @ (f_world - self._ft_weight_world)

    # ----------------------------------------------------------------- env API
    def reset(self) -> np.ndarray:
        r = self.c.randomization
        rng = self.rng
        hole_xy = rng.uniform(-1.0, 1.0, 2) * r.hole_xy_mm * MM
        hole_pos = self.hole_pos0 + np.array([hole_xy[0], hole_xy[1], 0.0])
        yaw = rng.uniform(-1.0, 1.0) * math.radians(r.hole_yaw_deg)
        H = rotz(yaw)
        p, kw = self.p, {"physicsClientId": self.cid}
        p.resetBasePositionAndOrientation(
            self.hole, hole_pos.tolist(), [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)], **kw
        )
        self.q = self.q_start.copy()
        q = self._solve_start(hole_pos, H)
        self._set_q(q, np.zeros(N_ARM))
        rad = r.lateral_error_mm * MM * math.sqrt(rng.uniform())
        ang = rng.uniform(0.0, 2 * math.pi)
        lat = np.array([rad * math.cos(ang), rad * math.sin(ang), 0.0])
        tilt = rng.uniform(-1.0, 1.0, 2) * math.radians(r.angular_error_deg)
        R_tilt = rot_from_rotvec(np.array([tilt[0], tilt[1], 0.0]))
        fric = rng.uniform(*r.friction_scale)
        p.changeDynamics(self.hole, -1, lateralFriction=self.spec.friction * fric, **kw)
        tip = self.tip()
        # the sensor is zeroed at the start: one gravity-compensated step of the free peg
        # fills the joint reaction forces with its weight; then the pose is restored
        g = p.calculateInverseDynamics(
            self.robot, list(map(float, q)), [0.0] * N_ARM, [0.0] * N_ARM, **kw
        )
        p.setJointMotorControlArray(
            self.robot, list(range(N_ARM)), p.TORQUE_CONTROL, forces=list(g), **kw
        )
        p.stepSimulation(**kw)
        _, R = self._peg()
        self._ft_weight_world = R @ self._ft_raw()[:3]
        self._set_q(q, np.zeros(N_ARM))
        self.info = {
            "cmd_tip": tip + H @ lat,
            "cmd_mat": H @ R_tilt @ TOOL_DOWN_MAT,
            "hole_pos": hole_pos,
            "hole_mat": H,
            "wrench_ff": np.zeros(3),
            "friction_scale": fric,
            "depth_mm": 0.0,
            "jam_time": 0.0,
            "step": 0,
            "wrench": np.zeros(3),
        }
        self.info["depth_mm"] = self._depth_mm()
        return self.obs()

    def _depth_mm(self) -> float:
        H, hp = self.info["hole_mat"], self.info["hole_pos"]
        return float(-(H.T @ (self.tip() - hp))[2] / MM)

    def obs(self) -> np.ndarray:
        H, hp = self.info["hole_mat"], self.info["hole_pos"]
        pos, Rf = self._flange()
        rel = H.T @ (pos - hp)
        rot = rotvec_from_mat(H.T @ Rf @ TOOL_DOWN_MAT.T)
        o = np.concatenate(
            [
                rel[:2] / MM,
                [(rel[2] - self.flange_z0) / self.L],
                self.info["wrench"] / self.c.obs.force_scale_N,
                np.rad2deg(rot),
            ]
        )
        return np.where(np.isfinite(o), o, 0.0).astype(np.float32)

    def _torque(self, target_pos, target_mat, target_vel, ff) -> np.ndarray:
        q, qd = self._joints()
        pos, R = self._peg()
        local_C = np.array([0.0, 0.0, self.half_len - self.L_C])  # COM frame: tip - L_C
        x_C = pos + R @ local_C
        J = self._jacobian(q, qd, local_C)
        p, kw = self.p, {"physicsClientId": self.cid}
        M = np.array(p.calculateMassMatrix(self.robot, list(map(float, q)), **kw))
        bias = np.array(
            p.calculateInverseDynamics(
                self.robot, list(map(float, q)), list(map(float, qd)), [0.0] * N_ARM, **kw
            )
        )
        tau, _ = impedance_torque(
            J,
            M,
            bias,
            q,
            qd,
            x_C,
            R,
            target_pos,
            target_mat,
            target_vel,
            self.stiffness,
            self.zeta,
            np.concatenate([ff, np.zeros(3)]),
            self.q_null,
            self.null_gains,
            (*self.c.limits.max_force_N, *self.c.limits.max_torque_Nm),
            self.ctrl_lo,
            self.ctrl_hi,
        )
        return tau

    def step(self, action: np.ndarray) -> StepResult:
        c, info = self.c, self.info
        a = np.clip(np.asarray(action, float), -1.0, 1.0)
        H = info["hole_mat"]
        dxy = a[:2] * c.action.max_step_offset_mm * MM
        dz = a[2] * c.action.max_speed_m_s * c.ctrl_dt
        prev = info["cmd_tip"]
        cmd_tip = prev + H @ np.array([dxy[0], dxy[1], dz])
        fx, fy, fz = c.limits.max_force_N  # the env's feed-forward caps (envs/extraction.py)
        cap = np.asarray((min(fx, c.action.max_ff_xy_N), min(fy, c.action.max_ff_xy_N), fz))
        wrench_ff = np.clip(info["wrench_ff"] + a[3:6] * c.action.max_force_step_N, -cap, cap)
        cmd_mat = info["cmd_mat"]
        axis = cmd_mat[:, 2]
        vel = (cmd_tip - prev) / c.ctrl_dt
        ff = cmd_mat.T @ (H @ wrench_ff)
        p, kw = self.p, {"physicsClientId": self.cid}
        forces = np.zeros(3)
        for i in range(self.n_sub):
            tip = prev + (i + 1.0) / self.n_sub * (cmd_tip - prev)
            tau = self._torque(tip - self.L_C * axis, cmd_mat, vel, ff)
            p.setJointMotorControlArray(
                self.robot, list(range(N_ARM)), p.TORQUE_CONTROL, forces=tau.tolist(), **kw
            )
            p.stepSimulation(**kw)
            forces += self.contact_force()
        f = forces / self.n_sub
        q, qd = self._joints()
        finite = bool(np.all(np.isfinite(q)) and np.all(np.isfinite(qd)) and np.all(np.isfinite(f)))
        f = f if finite else np.zeros(3)
        fxy = float(np.linalg.norm(f[:2]))
        depth = self._depth_mm() if finite else info["depth_mm"]
        dz_mm = depth - info["depth_mm"]
        jam_time = info["jam_time"] + c.ctrl_dt if fxy > c.jam_force_N else 0.0
        jammed = jam_time >= c.jam_time_s
        success = finite and depth < -c.success_margin_mm
        step = info["step"] + 1
        timeout = step >= c.episode_length
        failure = (jammed or not finite or timeout) and not success
        terms = reward_terms(
            dz_mm,
            fxy,
            self.k_xy,
            float(success),
            float(failure),
            self.rc,
            k_rot_Nm_rad=self.k_rot,
            fz_N=float(abs(f[2])),
        )
        terms = {k: float(v) for k, v in terms.items()}
        if not finite:
            terms["progress"] = 0.0
        info.update(
            cmd_tip=cmd_tip,
            wrench_ff=wrench_ff,
            depth_mm=depth,
            jam_time=jam_time,
            step=step,
            wrench=f,
        )
        return StepResult(
            obs=self.obs(),
            reward=sum(terms.values()),
            terms=terms,
            success=success,
            failure=failure,
            jammed=bool(jammed and not success),
            depth_mm=depth,
            fxy_N=fxy,
        )


def scripted_action(config) -> np.ndarray:
    """The scripted baseline's action in this sim: the MJX envs' scripted baseline
    (:func:`peghole_mjx.envs.rollout.scripted_policy`) with the compliance strategy off, a
    straight pull at ``SCRIPTED_SPEED_M_S`` with no lateral offset and no feed-forward (the
    stiffness is the env config's fixed one)."""
    a = np.zeros(6, np.float32)
    a[2] = SCRIPTED_SPEED_M_S / config.action.max_speed_m_s
    return np.clip(a, -1.0, 1.0)


def make_gym_env(env: str = "RectExtract", seed: int = 0, config=None):
    """A gymnasium ``Env`` around :class:`PegHoleSim` (import-time optional dependency);
    ``config``: an env config of ``env`` with changes (checked by :func:`check_config`),
    default the env's own."""
    import gymnasium as gym

    class PyBulletRectExtract(gym.Env):
        """RectExtract(Hard) in PyBullet: 9-D observation, 6-D action in [-1, 1], eq 4.4 reward."""

        metadata = {"render_modes": []}  # noqa: RUF012

        def __init__(self):
            self.sim = PegHoleSim(env, seed=seed, config=config)
            self.observation_space = gym.spaces.Box(-np.inf, np.inf, (9,), np.float32)
            self.action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            if seed is not None:
                self.sim.rng = np.random.default_rng(seed)
            return self.sim.reset(), {}

        def step(self, action):
            r = self.sim.step(action)
            info = {f"reward/{k}": v for k, v in r.terms.items()}
            info.update(is_success=r.success, jammed=r.jammed, depth_mm=r.depth_mm, fxy_N=r.fxy_N)
            timeout = self.sim.info["step"] >= self.sim.c.episode_length
            terminated = r.success or (r.failure and not timeout)
            truncated = timeout and not r.success
            return r.obs, r.reward, bool(terminated), bool(truncated), info

        def close(self):
            self.sim.close()

    return PyBulletRectExtract()


__all__ = [
    "PYBULLET_ENVS",
    "REWARD_WEIGHTS",
    "PegHoleSim",
    "check_config",
    "env_config",
    "make_gym_env",
    "make_urdf",
    "scripted_action",
]
