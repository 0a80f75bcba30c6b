"""Run an exported policy next to a robot: NumPy and ONNX Runtime only, no JAX, no MuJoCo.

``peghole export POLICY --out DIR`` (:mod:`peghole_mjx.policies.export`) writes ``DIR`` with
``policy.onnx`` (the observation normaliser and the policy network up to the deterministic
action in [-1, 1]), ``action.json`` (the observation layout, the action decoding, the frames
and the control period) and a copy of ``policy.json``. :class:`DeployedPolicy` reads such a
folder and turns sensor readings into impedance commands, exactly as the env does::

    from peghole_mjx.deploy import DeployedPolicy

    policy = DeployedPolicy("exported/rect")
    policy.reset(commanded_tip_m=(0.0, 0.0, -0.1495))  # the tip set-point, peg inserted
    every 20 ms (``policy.period_s``):
        cmd = policy.act(wrench_N_Nm, flange_pos_m, flange_tilt_rad)
        send cmd.compliance_centre_target_m, cmd.stiffness, cmd.wrench_ff_tool, ...

Every input and output is in the *hole frame* (origin at the hole mouth, +z out of the hole,
the extraction direction), SI units; :meth:`DeployedPolicy.flange_pose` and
:meth:`DeployedPolicy.wrench_from_sensor` convert robot-base and sensor-frame readings. The
policy keeps the state the actions integrate (the commanded tip, the feed-forward force, the
previous action), as the env does; :meth:`DeployedPolicy.reset` starts an extraction.

Sensor readings that are not finite (NaN or infinity) are *refused*: :class:`SensorError`
(one line), and nothing changes, so the robot keeps the last command it was sent until a
finite reading comes (decided 2026-12-02: a command computed from a zeroed reading, what the
simulator does with a non-finite observation entry, is not a safe thing to send a robot).

What cannot be trusted is refused at load, in one line (decided 2026-12-04): a
``policy.onnx`` whose SHA-256 is not the one ``action.json`` records (an edited or swapped
file); a model that does not take one observation input and give one action output of the
recorded sizes; an ``action.json`` holding NaN, infinity, JSON nested too deeply, an action
size below 6 (the tip and feed-forward entries), or a gain, damping ratio or compliance centre
outside the robot's ranges (:data:`ROBOT_RANGES`: the KUKA iiwa's Cartesian impedance mode;
L_C on the peg, between the tip and the peg length). At run time a gain or L_C given to
:meth:`DeployedPolicy.reset` that is not finite or out of those ranges is refused, as is an
action that is not one vector of the action size, and a decoded command that is not finite or
out of range: the state does not change, and the robot keeps its last command.

This module imports neither JAX nor MuJoCo (tested: tests/test_export.py runs it with both
blocked), so it runs on a robot PC with ``pip install numpy onnxruntime`` and this one file
plus :mod:`peghole_mjx.core.errors` (the package's ``__init__`` imports neither). The mapping onto
a KUKA iiwa's Cartesian impedance mode: docs/guide/deploy.md.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import CorruptFileError, UserInputError
from peghole_mjx.core.rotations import rot_from_rotvec, rotvec_from_mat

#: the ``action.json`` format this module reads (and :mod:`peghole_mjx.policies.export` writes)
EXPORT_FORMAT_VERSION = 1
#: the files of an exported folder
ACTION_FILE = "action.json"
ONNX_FILE = "policy.onnx"
POLICY_FILE = "policy.json"
#: ``action.json``'s ``format`` entry
FORMAT_NAME = "peghole_mjx.export"
#: the readings and state an observation entry may name (``observation.entries[].source``)
SOURCES = frozenset(
    {
        "flange_pos_m",
        "force_N",
        "torque_Nm",
        "flange_tilt_rad",
        "k_xy_N_m",
        "k_rot_Nm_rad",
        "L_C_m",
        "prev_action",
        "force_ff_N",
        "command_offset_m",
        "step",
    }
)


#: the robot's ranges (KUKA LBR iiwa Cartesian impedance mode, as ``peghole_mjx.core.validation``'s
#: ``IIWA_K_TRANS``, ``IIWA_K_ROT`` and ``stiffness.damping_ratio``): inclusive (lo, hi)
ROBOT_RANGES: dict[str, tuple[float, float]] = {
    "k_xy_N_m": (0.0, 5000.0),
    "k_z_N_m": (0.0, 5000.0),
    "k_rot_Nm_rad": (0.0, 300.0),
    "damping_ratio": (0.1, 1.0),
}
#: the smallest action: tip step (3) and feed-forward step (3); gains follow
MIN_ACTION_SIZE = 6


class SensorError(UserInputError):
    """A sensor reading that cannot be used: NaN or infinity, or the wrong shape. Nothing
    changes: the robot keeps the last command it was sent."""


@dataclass(frozen=True)
class ImpedanceCommand:
    """What one action commands the impedance controller (hole frame, SI units).

    The rotation is held: the policy never commands the tool orientation, which stays at its
    value of :meth:`DeployedPolicy.reset`. ``stiffness`` and ``wrench_ff_tool`` act in the
    compliance frame: the commanded tool frame (``tool_rotation``) moved to the compliance
    centre, ``compliance_centre_m`` above the tip on the peg axis.
    """

    step: int  # control steps since reset (1 for the first command)
    action: np.ndarray  # (A,) the policy's action in [-1, 1] (what the env's step takes)
    tip_target_m: np.ndarray  # (3,) commanded peg-tip position
    tip_velocity_m_s: np.ndarray  # (3,) (tip_target - previous tip_target) / period
    tool_rotation: np.ndarray  # (3, 3) commanded tool orientation (columns: tool x, y, z)
    compliance_centre_m: float  # L_C: the compliance centre's height above the tip, m
    compliance_centre_target_m: np.ndarray  # (3,) tip_target - L_C * tool z axis
    stiffness: np.ndarray  # (6,) K_x, K_y, K_z (N/m), K_rx, K_ry, K_rz (N m/rad)
    damping_ratio: float  # of every axis (1 = critical)
    force_ff_hole_N: np.ndarray  # (3,) accumulated feed-forward force, hole frame
    wrench_ff_tool: np.ndarray  # (6,) the same force in the compliance frame, zero moment

    @property
    def k_xy_N_m(self) -> float:
        """Lateral stiffness (N/m)."""
        return float(self.stiffness[0])

    @property
    def k_rot_Nm_rad(self) -> float:
        """Rotational stiffness K_theta (N m/rad)."""
        return float(self.stiffness[3])


def _vector(value: Any, size: int, name: str) -> np.ndarray:
    """``value`` as a finite float64 vector of ``size``, else :class:`SensorError`."""
    try:
        x = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise SensorError(f"{name} must be {size} numbers, got {value!r}") from None
    if x.shape != (size,):
        raise SensorError(f"{name} must be {size} numbers, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise SensorError(
            f"{name} holds NaN or infinity ({np.array2string(x, precision=4)}): refused, "
            "the robot keeps its last command"
        )
    return x


def _rotation(value: Any, name: str) -> np.ndarray:
    """``value`` as a finite float64 (3, 3) rotation matrix, else :class:`SensorError`."""
    try:
        R = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise SensorError(f"{name} must be a 3 x 3 rotation matrix, got {value!r}") from None
    if R.shape != (3, 3):
        raise SensorError(f"{name} must be a 3 x 3 rotation matrix, got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise SensorError(
            f"{name} holds NaN or infinity: refused, the robot keeps its last command"
        )
    return R


def _not_finite(path: Path, constant: str):
    raise CorruptFileError(f"{path} holds {constant}: every number of an export is finite")


def _finite_float(path: Path, text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise CorruptFileError(f"{path} holds {text} (not finite): every number is finite")
    return x


def _in_range(value: Any, name: str, lo: float, hi: float, error=UserInputError) -> float:
    """``value`` as a float within [lo, hi], else ``error`` naming it (one line)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(x) and lo <= x <= hi):
        raise error(f"{name} = {x!r} is refused: it must be finite and within [{lo:g}, {hi:g}]")
    return x


def read_spec(folder: str | Path) -> dict[str, Any]:
    """``action.json`` of an exported folder, its format checked (one line otherwise)."""
    path = Path(folder) / ACTION_FILE
    if not path.is_file():
        raise UserInputError(
            f"{folder} is not an exported policy (no {ACTION_FILE}): write one with "
            "peghole export POLICY --out DIR"
        )
    try:
        spec = json.loads(
            path.read_text(),
            parse_constant=lambda c: _not_finite(path, c),
            parse_float=lambda t: _finite_float(path, t),
        )
    except RecursionError:
        raise CorruptFileError(f"{path} is nested too deeply to be an export") from None
    except CorruptFileError:
        raise
    except (ValueError, UnicodeDecodeError) as exc:
        raise CorruptFileError(f"{path} is not valid JSON ({exc})") from None
    if not isinstance(spec, dict) or spec.get("format") != FORMAT_NAME:
        raise CorruptFileError(
            f"{path} is not a peghole_mjx export ('format' is not {FORMAT_NAME!r})"
        )
    version = spec.get("format_version")
    if version != EXPORT_FORMAT_VERSION or type(version) is not int:
        raise UserInputError(
            f"{path}: export format {version!r}, this peghole_mjx reads format "
            f"{EXPORT_FORMAT_VERSION}: export the policy again (peghole export POLICY --out DIR)"
        )
    return spec


class DeployedPolicy:
    """An exported policy (``peghole export``) with the state its actions integrate.

    ``folder``: the export; ``threads``: ONNX Runtime's intra-op threads (1: one core, the
    network is 2 x 256 wide and takes tens of microseconds).
    """

    def __init__(self, folder: str | Path, threads: int = 1):
        self.folder = Path(folder)
        spec = read_spec(self.folder)
        self.spec = spec
        try:
            self._parse(spec)
        except CorruptFileError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise CorruptFileError(
                f"{self.folder / ACTION_FILE} is damaged: a missing or malformed entry ({exc!r})"
            ) from None

        ort = optional_import("onnxruntime", "running an exported policy")
        onnx_path = self.folder / self._onnx_file
        if not onnx_path.is_file():
            raise UserInputError(f"{self.folder}: {onnx_path.name} is missing")
        data = onnx_path.read_bytes()  # read once: the bytes loaded are the bytes hashed
        options = ort.SessionOptions()
        options.intra_op_num_threads = max(1, int(threads))
        options.inter_op_num_threads = 1
        try:
            self._session = ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own classes for a damaged file
            msg = " ".join(str(exc).split())[:200]
            raise CorruptFileError(f"{onnx_path} cannot be loaded ({msg})") from None
        # after the load: a truncated file is named as one that cannot be loaded
        digest = hashlib.sha256(data).hexdigest()
        if digest != self._onnx_sha256:
            raise CorruptFileError(
                f"{onnx_path} is not the model {ACTION_FILE} was written for (SHA-256 "
                f"{digest[:12]}..., recorded {str(self._onnx_sha256)[:12]}...): refused; "
                "export the policy again"
            )
        self._input = self._check_signature(onnx_path)
        self._started = False

    def _check_signature(self, onnx_path: Path) -> str:
        """The model's input name, once it is known to take one (batch, observation size)
        input and give one (batch, action size) output; else CorruptFileError."""
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if len(inputs) != 1 or len(outputs) != 1:
            raise CorruptFileError(
                f"{onnx_path} has {len(inputs)} inputs and {len(outputs)} outputs: an exported "
                "policy has one of each (observation -> action)"
            )
        for arg, size, what in (
            (inputs[0], self.observation_size, "observations"),
            (outputs[0], self.action_size, "actions"),
        ):
            shape = list(arg.shape or [])
            if len(shape) != 2 or shape[-1] != size:
                raise CorruptFileError(
                    f"{onnx_path} {'takes' if what == 'observations' else 'gives'} {what} of "
                    f"shape {shape}, {ACTION_FILE} says (batch, {size})"
                )
        return inputs[0].name

    def _parse(self, spec: dict[str, Any]) -> None:
        """The numbers of ``action.json`` this class uses."""
        obs, act, dec = spec["observation"], spec["action"], spec["decode"]
        self.observation_size = int(obs["size"])
        self.action_size = int(act["size"])
        #: the control period (s): one :meth:`act` per period
        self.period_s = float(spec["control"]["period_s"])
        self._entries = [
            (e["source"], int(e["component"]), float(e["offset"]), float(e["scale"]))
            for e in obs["entries"]
        ]
        self._tip_step = np.asarray(dec["tip_step_m"], np.float64)
        self._ff_step = float(dec["force_ff_step_N"])
        residual = dec.get("residual")  # files written before the entry: no residual
        self._residual = (
            None
            if residual is None
            else (
                np.asarray(residual["offset"], np.float64),
                np.asarray(residual["gain"], np.float64),
            )
        )
        self._ff_cap = np.asarray(dec["force_ff_cap_N"], np.float64)
        self._gains = {
            name: (int(g["index"]), float(g["lo"]), float(g["hi"]))
            for name, g in dec["learned_gains"].items()
        }
        self._fixed = {k: float(v) for k, v in dec["fixed_gains"].items()}
        self._k_z = float(dec["k_z_N_m"])
        self._zeta = float(dec["damping_ratio"])
        tool = spec["tool"]
        self._tool_down = np.asarray(tool["tool_down_rotation"], np.float64)
        self._tip_in_flange = np.asarray(tool["tip_in_flange_m"], np.float64)
        self._peg_mass = float(tool["peg_mass_kg"])
        self._gravity = np.asarray(tool["gravity_m_s2"], np.float64)
        self._success_m = float(spec["episode"]["success_margin_m"])
        self._onnx_file = str(spec["onnx"]["file"])
        self._onnx_sha256 = str(spec["onnx"]["sha256"])
        self._peg_length = float(tool["peg_length_m"])
        unknown = sorted({e[0] for e in self._entries} - SOURCES)
        if unknown or len(self._entries) != self.observation_size:
            raise ValueError(f"observation entries: {len(self._entries)}, unknown {unknown}")
        self._check_decoding()

    def _ranges(self) -> dict[str, tuple[float, float]]:
        """Each gain's allowed range: :data:`ROBOT_RANGES`, L_C on the peg."""
        return {**ROBOT_RANGES, "L_C_m": (0.0, self._peg_length)}

    def _check_decoding(self) -> None:
        """Refuse (CorruptFileError, one line) an action decoding that could command something
        the robot cannot take: sizes, steps and caps, gains and their ranges."""
        path = self.folder / ACTION_FILE

        def bad(msg: str):
            raise CorruptFileError(f"{path}: {msg}")

        if self.observation_size < 1:
            bad(f"observation size {self.observation_size}")
        if self.action_size < MIN_ACTION_SIZE:
            bad(
                f"action size {self.action_size}: an exported policy's action has at least "
                f"{MIN_ACTION_SIZE} entries (tip step, feed-forward step)"
            )
        if not self.period_s > 0:
            bad(f"control period {self.period_s!r} s")
        for name, v, shape in (
            ("decode.tip_step_m", self._tip_step, (3,)),
            ("decode.force_ff_cap_N", self._ff_cap, (3,)),
            ("tool.tip_in_flange_m", self._tip_in_flange, (3,)),
            ("tool.gravity_m_s2", self._gravity, (3,)),
            ("tool.tool_down_rotation", self._tool_down, (3, 3)),
        ):
            if v.shape != shape or not np.all(np.isfinite(v)):
                bad(f"{name} must be {shape} finite numbers")
        if np.any(self._tip_step < 0) or np.any(self._ff_cap < 0) or self._ff_step < 0:
            bad("a step or cap is negative")
        if self._residual is not None:
            offset, gain = self._residual
            if offset.shape != (self.action_size,) or not np.all(np.abs(offset) <= 1.0):
                bad(f"decode.residual.offset must be {self.action_size} numbers in [-1, 1]")
            if gain.shape != (self.action_size,) or not np.all((gain >= 0) & (gain <= 2)):
                bad(f"decode.residual.gain must be {self.action_size} numbers in [0, 2]")
        if not (self._peg_length > 0 and self._peg_mass > 0):
            bad("the peg's length and mass must be positive")
        ranges = self._ranges()
        for key, (lo, hi) in (
            ("k_z_N_m", ranges["k_z_N_m"]),
            ("damping_ratio", ranges["damping_ratio"]),
        ):
            value = self._k_z if key == "k_z_N_m" else self._zeta
            _in_range(value, f"decode.{key}", lo, hi, CorruptFileError)
        for key in ("k_xy_N_m", "k_rot_Nm_rad", "L_C_m"):
            if key not in self._fixed:
                bad(f"decode.fixed_gains has no {key}")
            _in_range(self._fixed[key], f"decode.fixed_gains.{key}", *ranges[key], CorruptFileError)
        units = {"k_xy": "k_xy_N_m", "k_rot": "k_rot_Nm_rad", "L_C": "L_C_m"}
        seen = set()
        for name, (i, lo, hi) in self._gains.items():
            if name not in units:
                bad(f"unknown learned gain {name!r}")
            if not MIN_ACTION_SIZE <= i < self.action_size or i in seen:
                bad(f"learned gain {name} at action index {i}")
            seen.add(i)
            rlo, rhi = ranges[units[name]]
            if not (rlo <= lo <= hi <= rhi):
                bad(
                    f"learned gain {name} on [{lo:g}, {hi:g}], outside the robot's range "
                    f"[{rlo:g}, {rhi:g}]"
                )

    # ------------------------------------------------------------------ episode state
    def reset(
        self,
        commanded_tip_m,
        commanded_tilt_rad=(0.0, 0.0, 0.0),
        *,
        k_xy_N_m: float | None = None,
        k_rot_Nm_rad: float | None = None,
        L_C_m: float | None = None,
    ) -> None:
        """Start an extraction: the commanded tip is ``commanded_tip_m`` (the impedance
        controller's set-point while the peg is inserted; hole frame, m), the commanded tool
        orientation is ``commanded_tilt_rad`` (a rotation vector from straight down, held
        throughout), the feed-forward force 0, the previous action 0, and the gains their
        fixed values (``action.json`` ``decode.fixed_gains``) unless given."""
        # every value checked before any is set: a refused reset changes nothing
        tip = _vector(commanded_tip_m, 3, "commanded_tip_m")
        tilt = _vector(commanded_tilt_rad, 3, "commanded_tilt_rad")
        ranges = self._ranges()
        given = {"k_xy_N_m": k_xy_N_m, "k_rot_Nm_rad": k_rot_Nm_rad, "L_C_m": L_C_m}
        gains = {
            k: self._fixed[k] if v is None else _in_range(v, k, *ranges[k])
            for k, v in given.items()
        }
        self._cmd_tip = tip
        self._cmd_rot = rot_from_rotvec(tilt) @ self._tool_down
        self._ff = np.zeros(3)
        self._k_xy, self._k_rot, self._L_C = (
            gains["k_xy_N_m"],
            gains["k_rot_Nm_rad"],
            gains["L_C_m"],
        )
        self._prev_action = np.zeros(self.action_size)
        self._step = 0
        self._started = True

    def _need_reset(self) -> None:
        if not self._started:
            raise UserInputError("call reset(commanded_tip_m=...) before the first act()")

    # ------------------------------------------------------------------ readings
    def flange_pose(self, flange_pos, flange_rot, hole_pos, hole_rot):
        """``(flange_pos_m, flange_tilt_rad)`` in the hole frame from poses in any common frame
        (e.g. the robot base): positions (3,) m, rotations (3, 3). The tilt is the rotation
        vector of the flange orientation relative to straight down (``tool_down_rotation``)."""
        H = _rotation(hole_rot, "hole_rot")
        pos = H.T @ (_vector(flange_pos, 3, "flange_pos") - _vector(hole_pos, 3, "hole_pos"))
        R = H.T @ _rotation(flange_rot, "flange_rot") @ self._tool_down.T
        return pos, rotvec_from_mat(R)

    def wrench_from_sensor(self, force_N, torque_Nm, sensor_rot_in_hole) -> np.ndarray:
        """The wrench input of :meth:`act` from an F/T sensor reading: the force the flange
        side exerts on the peg (sensor frame), rotated into the hole frame with the peg's
        weight removed (``tool.peg_mass_kg``), and the torque rotated (as the env does)."""
        R = _rotation(sensor_rot_in_hole, "sensor_rot_in_hole")
        f = R @ _vector(force_N, 3, "force_N") + self._peg_mass * self._gravity
        t = R @ _vector(torque_Nm, 3, "torque_Nm")
        return np.concatenate([f, t])

    def tip_position(self, flange_pos_m, flange_tilt_rad) -> np.ndarray:
        """The peg tip (hole frame, m) of a flange pose: the peg is rigid on the flange."""
        pos = _vector(flange_pos_m, 3, "flange_pos_m")
        R = rot_from_rotvec(_vector(flange_tilt_rad, 3, "flange_tilt_rad")) @ self._tool_down
        return pos + R @ self._tip_in_flange

    def extracted(self, flange_pos_m, flange_tilt_rad) -> bool:
        """True once the tip is ``episode.success_margin_m`` above the mouth (the env's
        success: the extraction is done, stop calling :meth:`act`)."""
        return bool(self.tip_position(flange_pos_m, flange_tilt_rad)[2] > self._success_m)

    def observation(self, wrench_N_Nm, flange_pos_m, flange_tilt_rad) -> np.ndarray:
        """The policy's observation (``action.json`` ``observation.entries``) of these
        readings and the current state: ``wrench_N_Nm`` (6,) the contact wrench (force N,
        torque N m; :meth:`wrench_from_sensor`), averaged over the last control period;
        ``flange_pos_m`` (3,) and ``flange_tilt_rad`` (3,) the flange pose
        (:meth:`flange_pose`); all in the hole frame. Non-finite readings: :class:`SensorError`."""
        self._need_reset()
        w = _vector(wrench_N_Nm, 6, "wrench_N_Nm")
        pos = _vector(flange_pos_m, 3, "flange_pos_m")
        tilt = _vector(flange_tilt_rad, 3, "flange_tilt_rad")
        sources = {
            "flange_pos_m": pos,
            "force_N": w[:3],
            "torque_Nm": w[3:],
            "flange_tilt_rad": tilt,
            "k_xy_N_m": np.array([self._k_xy]),
            "k_rot_Nm_rad": np.array([self._k_rot]),
            "L_C_m": np.array([self._L_C]),
            "prev_action": self._prev_action,
            "force_ff_N": self._ff,
            "step": np.array([float(self._step)]),  # control steps since reset
        }
        if any(s == "command_offset_m" for s, *_ in self._entries):
            sources["command_offset_m"] = self._cmd_tip - self.tip_position(pos, tilt)
        obs = [(sources[s][c] - off) * scale for s, c, off, scale in self._entries]
        return np.asarray(obs, np.float32)

    # ------------------------------------------------------------------ policy
    def act_obs(self, obs) -> np.ndarray:
        """The raw action(s) in [-1, 1] of observation(s) ``obs`` ((n,) or (batch, n)):
        ``policy.onnx`` alone, no state read or changed."""
        x = np.asarray(obs, np.float32)
        if x.ndim not in (1, 2) or x.shape[-1] != self.observation_size:
            raise UserInputError(
                f"observation of shape {x.shape}: this policy takes {self.observation_size} "
                f"numbers ({self.spec['policy']['env']}; see {ACTION_FILE} observation.entries)"
            )
        if not np.all(np.isfinite(x)):
            raise SensorError("the observation holds NaN or infinity: refused")
        out = self._session.run(None, {self._input: x.reshape(-1, self.observation_size)})[0]
        return out[0] if x.ndim == 1 else out

    def decode(self, action) -> ImpedanceCommand:
        """The impedance command of ``action`` (the env's ``decode_action``), advancing the
        state: the commanded tip moves by ``tip_step_m`` x action[0:3], the feed-forward force
        by ``force_ff_step_N`` x action[3:6] within ``force_ff_cap_N``; each learned gain is
        set from its action on [lo, hi]."""
        self._need_reset()
        try:
            a = np.asarray(action, np.float64)
        except (TypeError, ValueError):
            raise UserInputError(f"action must be {self.action_size} numbers") from None
        if a.shape != (self.action_size,):
            raise UserInputError(
                f"action of shape {a.shape} refused: one action is a vector of shape "
                f"({self.action_size},) (a batch or a column is not one action)"
            )
        a = np.clip(np.where(np.isnan(a), 0.0, a), -1.0, 1.0)
        applied = a
        if self._residual is not None:  # the env's residual_action
            offset, gain = self._residual
            applied = np.clip(offset + gain * a, -1.0, 1.0)
        # the new state is computed and checked first: a refused command changes nothing
        prev = self._cmd_tip
        tip = prev + applied[:3] * self._tip_step
        ff = np.clip(self._ff + applied[3:6] * self._ff_step, -self._ff_cap, self._ff_cap)
        gains = {"k_xy": self._k_xy, "k_rot": self._k_rot, "L_C": self._L_C}
        for name, (i, lo, hi) in self._gains.items():
            gains[name] = min(max(lo + 0.5 * (applied[i] + 1.0) * (hi - lo), lo), hi)
        ranges = self._ranges()
        for name, key in (("k_xy", "k_xy_N_m"), ("k_rot", "k_rot_Nm_rad"), ("L_C", "L_C_m")):
            _in_range(gains[name], f"decoded {key}", *ranges[key])
        if not (np.all(np.isfinite(tip)) and np.all(np.isfinite(ff))):
            raise UserInputError(
                f"decoded command not finite (tip {tip}, feed-forward {ff}): refused, "
                "the robot keeps its last command"
            )
        self._cmd_tip, self._ff = tip, ff
        self._k_xy, self._k_rot, self._L_C = gains["k_xy"], gains["k_rot"], gains["L_C"]
        self._prev_action = a
        self._step += 1
        axis = self._cmd_rot[:, 2]
        k_xy, k_rot = self._k_xy, self._k_rot
        return ImpedanceCommand(
            step=self._step,
            action=a.astype(np.float32),
            tip_target_m=self._cmd_tip.copy(),
            tip_velocity_m_s=(self._cmd_tip - prev) / self.period_s,
            tool_rotation=self._cmd_rot.copy(),
            compliance_centre_m=self._L_C,
            compliance_centre_target_m=self._cmd_tip - self._L_C * axis,
            stiffness=np.array([k_xy, k_xy, self._k_z, k_rot, k_rot, k_rot]),
            damping_ratio=self._zeta,
            force_ff_hole_N=self._ff.copy(),
            wrench_ff_tool=np.concatenate([self._cmd_rot.T @ self._ff, np.zeros(3)]),
        )

    def act(self, wrench_N_Nm, flange_pos_m, flange_tilt_rad) -> ImpedanceCommand:
        """One control step: the observation of these readings (:meth:`observation`), the
        policy's action (:meth:`act_obs`) and its impedance command (:meth:`decode`). A
        refused reading (:class:`SensorError`) changes nothing."""
        obs = self.observation(wrench_N_Nm, flange_pos_m, flange_tilt_rad)
        return self.decode(self.act_obs(obs))


__all__ = [
    "EXPORT_FORMAT_VERSION",
    "ROBOT_RANGES",
    "DeployedPolicy",
    "ImpedanceCommand",
    "SensorError",
    "read_spec",
    "rot_from_rotvec",
    "rotvec_from_mat",
]
