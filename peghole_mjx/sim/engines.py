"""The physics seam of the envs: what a physics engine does for the task, and the MJX engine.

The task (:class:`peghole_mjx.envs.extraction.PegHoleEnv`: action decoding, impedance
parameters, observation, reward, termination, randomisation) is written once. What belongs to
an engine is only this:

* :meth:`solve_ik`: the arm's joint angles that put a point of the peg at a pose (the reset's
  start), by Newton steps in the engine's own kinematics (MJX on ``mjx``, MuJoCo C on
  ``mujoco``: no MJX graph in the MuJoCo C path);
* :meth:`init_data`: the physics state of an episode start (arm joints solved by the task's
  IK, the hole's mocap pose) with its derived quantities computed;
* :meth:`substeps`: the control step's physics substeps, the impedance law
  (:mod:`peghole_mjx.control`) applied before each, tracking the task's commanded targets;
  returns the new state and the F/T reading of every substep;
* per world, the friction scale at every step and, with a payload draw, the peg's mass and
  inertia scale (``mass_scale``, None without one), in both of the above;
* :meth:`readout`: the few derived quantities the task reads (:class:`Readout`), never
  engine-specific fields.
* :meth:`set_eq_active`: switch an equality constraint on or off in a state (a stuck joint's
  weld, :mod:`peghole_mjx.envs.stuck`).

Engines, chosen by the env config entry ``engine``:

* ``mjx`` (:class:`MjxEngine`, this module): MuJoCo MJX, ``impl`` ``jax`` (CPU, GPU) or
  ``warp`` (MuJoCo Warp: CUDA GPU, or slowly a CPU); the state is an ``mjx.Data``;
* ``mujoco`` (:class:`peghole_mjx.sim.engine_mujoco.MujocoEngine`): MuJoCo C through
  ``mujoco.batch`` on a thread pool, entered from the jitted env through ``jax.pure_callback``;
  the state is MuJoCo's integration state row, float64 carried bit for bit.

Both engines read the law's inputs with the same one-substep lag (the positions at the start
of the last physics step, as ``mj_step`` leaves them) and the same F/T sensor rows.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from peghole_mjx.control import ImpedanceController, ImpedanceParams, Target
from peghole_mjx.control.kinematics import newton_ik
from peghole_mjx.core._mjx import WARP_AVAILABLE, mjx, tree_path_to_attr_str, warp_types
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry import mjcf as scene

#: the physics engines an env config may name (``engine``); ``mjx-warp`` on the command line is
#: ``engine=mjx`` with ``impl=warp``
ENGINES = ("mjx", "mujoco")

#: the ``--engine`` choices of the commands: ``auto`` is :func:`default_engine` (in
#: :mod:`peghole_mjx.core._mjx`, below the envs and the experiments, which share its rule)
CLI_ENGINES = ("auto", "mjx", "mjx-warp", "mujoco")

#: the named ``vmap`` axes of a batch of worlds: callers map ``env.reset`` over the worlds with
#: ``axis_name=WORLD_AXIS`` (:func:`batch_reset`), the vmapped learner its seeds over
#: ``SEED_AXIS``. MuJoCo Warp's contact buffer is one pool shared by all worlds of a batch
#: (mujoco-mjx 3.17.0: ``naconmax`` rows in total), so a reset sizes it from these axes.
WORLD_AXIS = "worlds"
SEED_AXIS = "seeds"
BATCH_AXES = (WORLD_AXIS, SEED_AXIS)


def batch_worlds() -> int:
    """How many worlds share a batch where this is traced: the product of the sizes of the
    bound :data:`BATCH_AXES` (1 outside any of them)."""
    n = 1
    for name in BATCH_AXES:
        try:
            n *= jax.lax.axis_size(name)
        except NameError:  # the axis is not bound here
            pass
    return n


def batch_reset(env, keys: jax.Array):
    """``env.reset`` of one world per key, vmapped over :data:`WORLD_AXIS` (every batched
    reset of the package goes through here, so MuJoCo Warp's contact pool fits the batch)."""
    return jax.vmap(env.reset, axis_name=WORLD_AXIS)(keys)


def _is_warp(data) -> bool:
    return isinstance(data, mjx.Data) and data.impl == mjx.Impl.WARP


def world_where(cond: jax.Array, on_true, on_false):
    """One world's physics state: ``on_true`` where ``cond`` (a scalar, or per world under
    ``vmap``), else ``on_false``. MuJoCo Warp's fields shared by a batch's worlds (its contact
    pool) are taken from ``on_true`` (``mjx.Data.where``'s rule)."""
    if _is_warp(on_true):
        return on_true.where(~cond, on_false)
    return jax.tree.map(lambda a, b: jnp.where(cond, a, b), on_true, on_false)


def _per_world_paths(data) -> set:
    """The tree paths of ``data``'s per-world leaves: all of them, except MuJoCo Warp's fields
    shared by a batch (mujoco-mjx's own table, the one ``mjx.Data.where`` reads)."""
    table = warp_types._BATCH_DIM["Data"]
    return {
        p
        for p, _ in jax.tree_util.tree_leaves_with_path(data)
        if table.get(tree_path_to_attr_str(p), True)
    }


def select_worlds(mask: jax.Array, on_true, on_false):
    """A batch of env states (leading axis: worlds): world ``w`` from ``on_true`` where
    ``mask[w]``, else from ``on_false``. MuJoCo Warp's fields shared by the batch's worlds
    (its contact pool, recomputed at every step) are taken from ``on_false``."""
    n = mask.shape[0]

    def pick(x, y):
        return jnp.where(mask.reshape((n,) + (1,) * (x.ndim - 1)), x, y)

    data = getattr(on_false, "data", None)
    if not _is_warp(data):
        return jax.tree.map(pick, on_true, on_false)
    keep = _per_world_paths(data)
    new_data = jax.tree_util.tree_map_with_path(
        lambda p, x, y: pick(x, y) if p in keep else y, on_true.data, data
    )
    rest = jax.tree.map(pick, on_true.replace(data=None), on_false.replace(data=None))
    return rest.replace(data=new_data)


#: the env config entries that choose the engine: provenance of a run, not part of the task (a
#: policy runs on any engine), so a policy's ``env_overrides`` do not carry them
ENGINE_KEYS = ("engine", "impl", "mujoco_threads")


def task_overrides(overrides: dict) -> dict:
    """``overrides`` without the engine entries (:data:`ENGINE_KEYS`, flat or ``env.``-prefixed):
    what a policy's env is, whatever engine it ran on."""
    return {k: v for k, v in overrides.items() if k.removeprefix("env.") not in ENGINE_KEYS}


def resolve_engine(config):
    """``config`` with ``engine`` ``auto`` made concrete (:func:`auto_choice`): a copy, the
    config itself when its engine is already concrete."""
    if config.engine != "auto":
        return config
    config = config.copy_and_resolve_references()
    for key, value in engine_overrides(auto_choice(config.get("impl", "jax"))).items():
        config[key] = value
    return config


def auto_choice(impl: str = "jax") -> str:
    """The ``--engine`` name that engine ``auto`` stands for: ``mjx-warp`` when ``impl`` asks
    for MuJoCo Warp, else :func:`default_engine`."""
    return "mjx-warp" if impl == "warp" else default_engine()


def default_engine() -> str:
    """The engine ``auto`` stands for on this machine, for the envs and the experiments alike:
    ``mujoco`` (MuJoCo C) where JAX has no GPU; on a CUDA GPU ``mjx-warp`` (MuJoCo Warp) when
    warp-lang is installed, else ``mjx`` (MJX-JAX) (measured:
    benchmarks/results/perf/throughput_engines_cpu-2core.json; decided 2026-12-05:
    one default for the env, the commands, the experiments, Gym and Playground)."""
    backend = jax.default_backend()
    if backend == "cpu":
        return "mujoco"
    return "mjx-warp" if backend in ("gpu", "cuda") and WARP_AVAILABLE else "mjx"


def engine_overrides(choice: str) -> dict[str, str]:
    """The env config entries of an ``--engine`` choice (``mjx-warp``: engine mjx, impl warp)."""
    if choice not in CLI_ENGINES:
        raise UserInputError(f"unknown engine {choice!r}; choose one of {list(CLI_ENGINES)}")
    if choice == "auto":
        choice = default_engine()
    if choice == "mjx-warp":
        return {"engine": "mjx", "impl": "warp"}
    return {"engine": choice}


def engine_label(config) -> str:
    """The ``--engine`` name of an env config's engine entries (``mjx`` with ``impl`` warp is
    ``mjx-warp``): what results record as their engine."""
    impl = config.get("impl", "jax") if hasattr(config, "get") else "jax"
    if config["engine"] == "auto":
        return auto_choice(impl)
    return "mjx-warp" if config["engine"] == "mjx" and impl == "warp" else config["engine"]


#: MJX-JAX's step and forward as jitted functions of their own: JAX keeps their traces, so the
#: second and later graphs that hold them in a process (an env step, a training call, an
#: evaluation's rollout) reuse them instead of tracing MJX again (a RectExtract env step graph
#: lowered in 13 s, then in 3-5 s with these, 2-core CPU, 2026-12-05). Inside another jitted
#: function they are inlined (20 random-action steps of 3 RectExtract and 3 DualExtract worlds
#: gave the same states bit for bit, 2026-12-05; traced once: tests/test_env_config.py). MuJoCo
#: Warp keeps the plain calls (its contact pool is sized from the batch axes at trace time).
_mjx_step = jax.jit(mjx.step)
_mjx_forward = jax.jit(mjx.forward)

#: MuJoCo Warp's ``OverflowType`` bits that mean dropped contacts or constraint rows: NEFC,
#: NJMAX_NNZ, BROADPHASE, NARROWPHASE, CCD (mujoco_warp/_src/types.py). Its ``overflow``
#: bitmask is per world and sticky until the world's data is reset.
WARP_CONTACT_OVERFLOW_BITS = 0b11111


class Readout(NamedTuple):
    """What the task reads of a physics state (world frame, SI)."""

    peg_pos: jax.Array  # (3,) peg body origin
    peg_mat: jax.Array  # (3, 3) peg body rotation
    flange_pos: jax.Array  # (3,) flange site
    flange_mat: jax.Array  # (3, 3) flange site rotation
    finite: jax.Array  # () bool: the state holds no NaN/inf and the engine raised no error
    overflow: jax.Array  # () float 1.0 if the engine dropped contacts (MuJoCo Warp), else 0.0


class FTReading(NamedTuple):
    """The F/T sensor of one physics substep: its site rotation and its force/torque rows
    (sensor frame, as MuJoCo's force and torque sensors report them)."""

    site_mat: jax.Array  # (3, 3)
    force: jax.Array  # (3,)
    torque: jax.Array  # (3,)


#: ``sense(FTReading) -> (6,)``: the task's wrench of a substep's reading (peg weight removed,
#: hole frame); each engine applies it to every substep's reading
Sense = Callable[[FTReading], jax.Array]


class SceneIds(NamedTuple):
    """The ids an engine needs, resolved by name once (:meth:`from_model`)."""

    peg_body: int
    flange_site: int
    ft_site: int
    force_adr: int
    torque_adr: int
    hole_mocap: int
    qadr: np.ndarray

    @classmethod
    def from_model(cls, m: mujoco.MjModel, qadr) -> SceneIds:
        """The ids of the iiwa peg-hole scene ``m`` (the names of
        :mod:`peghole_mjx.geometry.mjcf`), ``qadr`` the arm's joint position addresses."""
        return cls(
            peg_body=m.body(scene.PEG_BODY).id,
            flange_site=m.site(scene.FLANGE_SITE).id,
            ft_site=m.site(scene.FT_SITE).id,
            force_adr=int(m.sensor_adr[m.sensor(scene.FT_FORCE_SENSOR).id]),
            torque_adr=int(m.sensor_adr[m.sensor(scene.FT_TORQUE_SENSOR).id]),
            hole_mocap=int(m.body_mocapid[m.body(scene.HOLE_BODY).id]),
            qadr=np.asarray(qadr),
        )


class ContactForces(NamedTuple):
    """A physics step's contacts, one entry each (the step's contact rows; padded entries carry
    no force): the normal force (N, 0 for a contact that carries none), the x component of the
    contact normal (geom1 to geom2), whether geom1 is on the peg, the signed distance (m), and
    whether the contact is active (a constraint row with a finite distance: MJX; a positive
    normal force: MuJoCo C)."""

    normal_force: jax.Array
    normal_x: jax.Array
    peg_is_geom1: jax.Array
    dist: jax.Array
    active: jax.Array
    #: MuJoCo C only (None on MJX): the tangential force's magnitude, N, and the world-z force
    #: of the contact on the peg, N
    tangential: np.ndarray | None = None
    peg_force_z: np.ndarray | None = None


def contact_overflow(data) -> jax.Array:
    """1.0 if MuJoCo Warp overflowed a contact or constraint buffer in this world, else 0.0.

    Warp drops what does not fit in ``naconmax`` / ``njmax`` and only prints a warning; the env
    ends such an episode as a failure and counts it (``metrics["overflow"]``). MJX-JAX sizes
    its buffers statically and never overflows: always 0.0 there.
    """
    flags = getattr(getattr(data, "_impl", None), "overflow", None)
    if flags is None:
        return jnp.zeros((), jnp.float32)
    hit = (jnp.asarray(flags).astype(jnp.int32) & WARP_CONTACT_OVERFLOW_BITS) != 0
    return jnp.any(hit).astype(jnp.float32)


class MjxEngine:
    """MuJoCo MJX (``impl`` jax or warp): the state is an ``mjx.Data``, everything is JAX."""

    name = "mjx"
    #: the step and reset are plain JAX: JAX's persistent compilation cache keeps their graphs
    host_callbacks = False

    def __init__(
        self,
        model: mjx.Model | Callable[[], mjx.Model],
        ctrl: ImpedanceController,
        ids: SceneIds,
        impl: str = "jax",
        naconmax: int = 64,
        njmax: int = 256,
        mj_model: mujoco.MjModel | None = None,
        jit_calls: bool = True,
    ):
        """``model``: the ``mjx.Model``, or a function returning the model to step with now.

        An env passes ``lambda: env._mjx_model``: the physics then reads the env's current
        model at every trace of a reset or step, so a wrapper that swaps ``_mjx_model`` for a
        per-world model under ``vmap`` (MuJoCo Playground's domain randomisation) randomises
        the physics. ``mj_model``: the compiled model, needed by MuJoCo Warp's ``make_data``
        (it refuses an ``mjx.Model``). ``jit_calls`` (MJX-JAX): step and forward through the
        module's jitted ``mjx.step`` / ``mjx.forward`` (the envs: their traces are reused);
        False: the plain calls, inlined in the caller's graph (the compliance experiment, whose
        committed records were computed so: XLA fuses the two differently, and a float32 pull
        of three rect-2 worlds then differs by up to 1.2 N in a 20 ms F_z sample, 2026-12-06)."""
        if impl == "warp" and mj_model is None:
            raise UserInputError("impl='warp' needs the compiled mujoco.MjModel (mj_model)")
        self._model = model
        self.mj_model = mj_model
        self.ctrl = ctrl
        self.ids = ids
        self.impl = impl
        self._buffers = {"naconmax": naconmax, "njmax": njmax} if impl == "warp" else {}
        jitted = impl == "jax" and jit_calls  # Warp: the plain calls (note at _mjx_step)
        self._step = _mjx_step if jitted else mjx.step
        self._forward = _mjx_forward if jitted else mjx.forward

    @property
    def model(self) -> mjx.Model:
        """The model the physics steps with: the env's current one (see ``__init__``)."""
        return self._model() if callable(self._model) else self._model

    def make_data(self, worlds: int | None = None):
        """An ``mjx.Data`` at the model's defaults (no forward pass). MuJoCo Warp's contact
        pool holds ``naconmax`` contacts per world for ``worlds`` worlds (None: every world of
        the batch being traced, :func:`batch_worlds`); ``njmax`` is per world."""
        if self.impl == "warp":  # Warp's make_data takes the MjModel, not an mjx.Model
            b = self._buffers
            n = batch_worlds() if worlds is None else worlds
            return mjx.make_data(
                self.mj_model, impl="warp", naconmax=b["naconmax"] * n, njmax=b["njmax"]
            )
        return mjx.make_data(self.model, impl=self.impl)

    def solve_ik(
        self,
        q0: jax.Array,
        pos_target: jax.Array,
        mat_target: jax.Array,
        point_local,
        iterations: int,
    ) -> jax.Array:
        """Arm joint angles that put ``point_local`` (peg body frame) at ``pos_target`` with
        the peg body's rotation ``mat_target``: ``iterations`` Newton steps from ``q0`` in MJX's
        kinematics (:func:`peghole_mjx.control.kinematics.newton_ik`)."""
        return newton_ik(
            self.model,
            self.make_data(worlds=1),  # the kinematics' start (the IK has no contacts)
            q0,
            self.ids.qadr,
            self.ctrl.dadr,
            self.ids.peg_body,
            point_local,
            pos_target=pos_target,
            mat_target=mat_target,
            iterations=iterations,
        )

    def init_data(
        self, q_arm: jax.Array, hole_pos: jax.Array, hole_quat: jax.Array, mass_scale=None
    ):
        """The state with the arm joints at ``q_arm`` and the hole mocap at its pose, forward
        (with the peg's mass and inertia times ``mass_scale`` when given)."""
        i = self.ids
        data = self.make_data()
        data = data.replace(
            qpos=data.qpos.at[i.qadr].set(q_arm),
            mocap_pos=data.mocap_pos.at[i.hole_mocap].set(hole_pos),
            mocap_quat=data.mocap_quat.at[i.hole_mocap].set(hole_quat),
        )
        return self._forward(self.scaled_mass(self.model, mass_scale), data)

    def scaled_mass(self, m, mass_scale):
        """``m`` with the peg's mass and inertia times ``mass_scale`` (None: ``m`` itself). Under
        ``vmap`` the replaced fields are per world; the constants MuJoCo derived from the
        masses when the model was compiled (``body_invweight0``, ...) stay nominal."""
        if mass_scale is None:
            return m
        b = self.ids.peg_body
        return m.replace(
            body_mass=m.body_mass.at[b].multiply(mass_scale),
            body_inertia=m.body_inertia.at[b].multiply(mass_scale),
        )

    def readout(self, data) -> Readout:
        i = self.ids
        finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
        return Readout(
            peg_pos=data.xpos[i.peg_body],
            peg_mat=data.xmat[i.peg_body],
            flange_pos=data.site_xpos[i.flange_site],
            flange_mat=data.site_xmat[i.flange_site],
            finite=finite,
            overflow=contact_overflow(data),
        )

    def ft_reading(self, data) -> FTReading:
        i = self.ids
        return FTReading(
            site_mat=data.site_xmat[i.ft_site],
            force=data.sensordata[i.force_adr : i.force_adr + 3],
            torque=data.sensordata[i.torque_adr : i.torque_adr + 3],
        )

    def substeps(
        self,
        data,
        targets: jax.Array,
        target_mat: jax.Array,
        target_vel: jax.Array,
        params: ImpedanceParams,
        friction_scale: jax.Array,
        sense: Sense,
        mass_scale: jax.Array | None = None,
    ):
        """One physics step per row of ``targets`` (n_sub, 3: the compliance centre's commanded
        position), the law before each; returns ``(data, wrenches (n_sub, 6))``.
        ``mass_scale``: the peg's mass and inertia factor of the world (None: nominal)."""
        m = self.model
        m = m.replace(pair_friction=m.pair_friction * friction_scale)
        m = self.scaled_mass(m, mass_scale)

        law_m = self.law_model(m)

        def substep(d, pos):
            target = Target(pos=pos, mat=target_mat, vel=target_vel)
            d, _ = self.law_step(d, target, params, m, law_m)
            return d, sense(self.ft_reading(d))

        return jax.lax.scan(substep, data, targets)

    def law_step(self, data, target: Target, params: ImpedanceParams, m=None, law_m=None):
        """One physics step with the impedance law applied before it, tracking ``target``:
        ``(data, the law's ImpedanceOutput)``. ``m``: the model to step with (None: the
        current :attr:`model`); ``law_m``: the model the law reads (None: :meth:`law_model`
        of ``m``). The env's substeps and the experiments' scripted pulls both step here."""
        m = self.model if m is None else m
        law_m = self.law_model(m) if law_m is None else law_m
        data, out = self.ctrl.apply(law_m, data, target, params)
        return self._step(m, data), out

    def start_data(self, m: mujoco.MjModel, d: mujoco.MjData):
        """The ``mjx.Data`` of MuJoCo state ``d`` (MJX-JAX), in the dtypes a step returns (with
        ``jax_enable_x64`` a step returns some int32 fields as int64)."""
        if self.impl != "jax":
            raise UserInputError("start_data is for MJX-JAX (impl 'jax')")
        dx0 = mjx.put_data(m, d, impl="jax")
        out = jax.eval_shape(mjx.step, self.model, dx0)
        return jax.tree.map(lambda a, o: a.astype(o.dtype), dx0, out)

    def contact_forces(self, data, peg_geom: jax.Array) -> ContactForces:
        """The contacts of the last physics step (:class:`ContactForces`); ``peg_geom``: a
        bool per geom, true on the peg's geoms."""
        con = data._impl.contact
        addr = con.efc_address
        fn = jnp.where(addr >= 0, data._impl.efc_force[jnp.maximum(addr, 0)], 0.0)
        nx = con.frame[:, 0, 0] if con.frame.ndim == 3 else con.frame[:, 0]
        active = (addr >= 0) & jnp.isfinite(con.dist)
        return ContactForces(fn, nx, peg_geom[con.geom1], con.dist, active)

    def law_model(self, m):
        """The model the impedance law reads ``m`` as. MuJoCo Warp keeps the mass matrix in
        MuJoCo's compressed rows (``M``) whatever the Jacobian type, so the law's full-inertia
        read (MJX's ``support.full_m``) must take the sparse path there: ``m`` marked sparse
        (reconstructs MuJoCo C's ``mj_fullM`` to 7e-7 on the rect scene, measured 2026-12-04).
        The physics steps with ``m`` itself. MJX-JAX: ``m`` unchanged."""
        if self.impl != "warp":
            return m
        return m.replace(opt=m.opt.replace(jacobian=mujoco.mjtJacobian.mjJAC_SPARSE))

    def set_eq_active(self, data, eq: int, active: jax.Array):
        """``data`` with equality constraint ``eq`` switched on where ``active`` (a bool of
        the world), else off: MJX's constraint rows read ``eq_active``."""
        return data.replace(
            eq_active=data.eq_active.at[eq].set(active.astype(data.eq_active.dtype))
        )

    def to_mjdata(self, data, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        """Write one world's state into a MuJoCo ``MjData`` (rendering), forward done."""
        mjx.get_data_into(d, m, data)
        mujoco.mj_forward(m, d)
