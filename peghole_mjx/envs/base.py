"""The peg-hole scene in MJX: config checks, compiled model, ids by name, sensor readings.

:class:`PegHoleBase` builds the scene of a config once (MJCF -> ``mj_model`` -> ``mjx_model``),
resolves every name it needs to an id (:mod:`peghole_mjx.envs.iiwa_constants`) and reads the
poses and the F/T sensor. The task (reset, step, reward) is
:class:`peghole_mjx.envs.extraction.PegHoleEnv`.

Frames. The hole frame has its origin at the hole mouth, +z up = the extraction direction.
Depth ``h`` is how far the peg tip is below the mouth (h > 0 inside the hole).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from ml_collections import config_dict

from peghole_mjx.control import ControlLimits, ImpedanceController
from peghole_mjx.control.kinematics import rotvec_from_mat
from peghole_mjx.core._mjx import WARP_AVAILABLE, mjx
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs import iiwa_constants as names
from peghole_mjx.envs import stuck
from peghole_mjx.envs.config import apply_overrides, base_config, env_spec, sim_options
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT, build_scene
from peghole_mjx.geometry.parts import resolve_representation
from peghole_mjx.geometry.specs import MM, PegHoleSpec
from peghole_mjx.sim.engine_mujoco import MujocoEngine
from peghole_mjx.sim.engines import (
    ENGINES,
    FTReading,
    MjxEngine,
    Readout,
    SceneIds,
    resolve_engine,
)
from peghole_mjx.sim.engines import contact_overflow as contact_overflow

__all__ = ["PegHoleBase", "State", "base_config", "contact_overflow"]


@struct.dataclass
class State:
    """Environment state (MuJoCo Playground layout)."""

    data: Any  # the engine's physics state: mjx.Data (mjx), engine_mujoco.CData (mujoco)
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    metrics: dict[str, jax.Array]
    info: dict[str, Any]


class PegHoleBase:
    """The scene of an env config: compiled models, impedance controller, ids, readings.

    Everything here is fixed when the env is built; what it derives from the config
    (substeps, peg length, the controller's wrench caps) is read from the config only.
    """

    def __init__(self, config: config_dict.ConfigDict, config_overrides: dict | None = None):
        config = resolve_engine(apply_overrides(config, config_overrides))
        self._config = config
        #: the registry name (``envs.load`` sets it: RectExtractHard is a RectExtract class)
        self.env_name = type(self).__name__
        if config.engine not in ENGINES:
            raise UserInputError(
                f"unknown engine {config.engine!r}; choose one of {list(ENGINES)} "
                "(mjx-warp on the command line: engine mjx with impl warp)"
            )
        if config.impl not in ("jax", "warp"):
            raise UserInputError(f"impl must be 'jax' or 'warp', got {config.impl!r}")
        if config.engine == "mujoco" and config.impl != "jax":
            raise UserInputError(
                "impl selects MJX's implementation: engine 'mujoco' needs impl jax"
            )
        if config.impl == "warp" and not WARP_AVAILABLE:
            raise UserInputError(
                "impl='warp' needs warp-lang (MuJoCo Warp; a CUDA GPU for speed, a CPU runs "
                "it slowly): pip install 'peghole_mjx[warp]'"
            )
        n_sub = config.ctrl_dt / config.sim_dt
        if abs(n_sub - round(n_sub)) > 1e-6 or n_sub < 1:
            raise UserInputError("ctrl_dt must be a whole multiple of sim_dt")
        self._n_substeps = round(n_sub)
        self.spec: PegHoleSpec = env_spec(config)
        #: the peg length (m), the scale of the flange height and L_C
        self.peg_length_m = self.spec.length_mm * MM
        self.representation = resolve_representation(
            self.spec,
            config.representation,
            impl="c" if config.engine == "mujoco" else config.impl,
        )
        scene = build_scene(
            self.spec,
            sim=sim_options(config),
            representation=self.representation,
            contact_cap=config.contact_cap,
        )
        if stuck.enabled(config):  # the breakaway weld (envs/stuck.py); else the scene as is
            stuck.add_weld(scene, config.stuck)
        self._mj_model = scene.compile()
        m = self._mj_model
        #: the stuck joint's weld (equality id), None without one
        self._weld = None
        if stuck.enabled(config):
            stuck.pose_weld(m)
            self._weld = m.equality(stuck.WELD_NAME).id
        if config.impl == "warp":
            # MuJoCo Warp collides box-box (rect) and capsule-box with its primitive routines
            # only with nativeccd off; the cylinder representation's cylinder-box pairs go
            # through GJK/EPA either way
            m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_NATIVECCD
        # the MJX model, on the MJX engines only: the mujoco engine never reads it (its reset's
        # IK and its steps run in MuJoCo C), so a scene MJX cannot load runs there
        self._mjx_model = self._put_mjx_model() if config.engine == "mjx" else None
        limits = ControlLimits(
            max_force_N=tuple(config.limits.max_force_N),
            max_torque_Nm=tuple(config.limits.max_torque_Nm),
        )
        self._ctrl = ImpedanceController.from_model(
            m, limits=limits, peg_body=names.PEG_BODY, tip_site=names.PEG_TIP_SITE
        )
        # ids, looked up by name
        self._peg_body = m.body(names.PEG_BODY).id
        self._hole_body = m.body(names.HOLE_BODY).id
        self._hole_mocap = int(m.body_mocapid[self._hole_body])
        self._tip_site = m.site(names.PEG_TIP_SITE).id
        self._mouth_site = m.site(names.HOLE_MOUTH_SITE).id
        self._flange_site = m.site(names.FLANGE_SITE).id
        self._ft_site = m.site(names.FT_SITE).id
        self._force_adr = int(m.sensor_adr[m.sensor(names.FT_FORCE_SENSOR).id])
        self._torque_adr = int(m.sensor_adr[m.sensor(names.FT_TORQUE_SENSOR).id])
        self._qadr = self._ctrl.qadr
        # start pose: the "inserted" keyframe (nominal hole pose)
        key = m.key(names.START_KEYFRAME)
        self._q_inserted = np.array(key.qpos)
        d = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d, key.id)
        mujoco.mj_forward(m, d)
        self._hole_pos0 = d.xpos[self._hole_body].copy()
        self._tip_local = self._ctrl.tip_local
        self._peg_mass = float(m.body_subtreemass[self._peg_body])
        self._gravity = np.array(m.opt.gravity)
        self._flange_z0 = float(d.site_xpos[self._flange_site][2] - self._hole_pos0[2])
        self._pair_friction0 = np.array(m.pair_friction)
        self._depth0_mm = float(self._hole_pos0[2] - d.site_xpos[self._tip_site][2]) / MM
        self._init_q = jnp.asarray(self._q_inserted)
        ids = SceneIds(
            peg_body=self._peg_body,
            flange_site=self._flange_site,
            ft_site=self._ft_site,
            force_adr=self._force_adr,
            torque_adr=self._torque_adr,
            hole_mocap=self._hole_mocap,
            qadr=np.asarray(self._qadr),
        )
        #: the physics engine (config ``engine``): the substep loop and the state's readings
        self.engine = (
            MujocoEngine(m, self._ctrl, ids, self._n_substeps, threads=config.mujoco_threads)
            if config.engine == "mujoco"
            else MjxEngine(
                lambda: self._mjx_model,  # the env's current model: Playground swaps it per world
                self._ctrl,
                ids,
                config.impl,
                config.naconmax,
                config.njmax,
                mj_model=m,
            )
        )

    # ------------------------------------------------------------------ properties
    @property
    def config(self) -> config_dict.ConfigDict:
        return self._config

    @property
    def mj_model(self) -> mujoco.MjModel:
        return self._mj_model

    @property
    def mjx_model(self) -> mjx.Model:
        """The ``mjx.Model`` of the scene (put on the device on first use on the ``mujoco``
        engine, whose physics never reads it)."""
        if self._mjx_model is None:
            self._mjx_model = self._put_mjx_model()
        return self._mjx_model

    def _put_mjx_model(self) -> mjx.Model:
        # on this process's first device: MJX's default, jax.devices()[0], belongs to process
        # 0 when several processes train together (training/distributed.py)
        return mjx.put_model(self._mj_model, impl=self._config.impl, device=jax.local_devices()[0])

    @property
    def dt(self) -> float:
        return self._config.ctrl_dt

    @property
    def n_substeps(self) -> int:
        return self._n_substeps

    @property
    def unwrapped(self):
        return self

    # ------------------------------------------------------------------ data and readings
    def _tip_world(self, r: Readout):
        return r.peg_pos + r.peg_mat @ jnp.asarray(self._tip_local)

    def _depth_mm(self, r: Readout, hole_pos, hole_mat):
        rel = hole_mat.T @ (self._tip_world(r) - hole_pos)
        return -rel[2] / MM

    def contact_wrench(self, reading: FTReading, hole_mat, peg_mass_kg=None):
        """F/T sensor force and torque in the hole frame with the peg's weight removed (N, N m).

        The sensor reads the wrench that the flange side applies to the tool side; the static
        part of it is the peg's weight. The remainder is (minus) the contact load on the peg.
        ``peg_mass_kg``: the peg's mass of this world (a payload draw; None: the preset's).
        """
        R_s = reading.site_mat
        f_world = R_s @ reading.force
        t_world = R_s @ reading.torque
        mass = self._peg_mass if peg_mass_kg is None else peg_mass_kg
        f_world = f_world + mass * jnp.asarray(self._gravity)  # remove holding force
        return hole_mat.T @ f_world, hole_mat.T @ t_world

    def _flange_pose(self, r: Readout, info):
        """Flange position (m) and tilt (rotation vector vs straight down, rad), hole frame."""
        rel = info["hole_mat"].T @ (r.flange_pos - info["hole_pos"])
        R = info["hole_mat"].T @ r.flange_mat @ jnp.asarray(TOOL_DOWN_MAT).T
        return rel, rotvec_from_mat(R)
