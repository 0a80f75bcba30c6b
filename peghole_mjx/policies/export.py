"""Export a trained policy to ONNX for a robot, and close the loop through the export.

``peghole export POLICY --out DIR`` (:func:`export_policy`) writes into ``DIR``:

* ``policy.onnx``: the observation normaliser and the policy network up to the deterministic
  action in [-1, 1], the function the JAX evaluation runs (Brax SAC, brax 0.14.2:
  ``(obs - mean) / std``, then ``Dense -> ReLU`` per hidden layer (``make_sac_networks``'
  default activation), then the ``loc`` half of the last ``Dense`` and ``tanh``, the mode of
  ``NormalTanhDistribution``; the scale half is dropped, the mode does not use it), clipped
  to [-1, 1] (a float32 tanh may round one ulp past 1; the env clips actions there). Input
  ``obs`` (batch, observation size) float32, output ``action`` (batch, action size);
* ``action.json``: format version, package version, the observation layout (name, source,
  unit and scaling per entry), the action decoding (ranges, units, frames, how the env turns
  the action into the impedance command: :func:`peghole_mjx.envs.extraction.decode_action`),
  the tool geometry and the control period. :class:`peghole_mjx.deploy.DeployedPolicy` reads
  it; docs/guide/deploy.md explains it for a KUKA iiwa;
* ``policy.json``: a copy of the policy's own.

The graph is built with the ``onnx`` package's helper API (``onnx.helper.make_node`` etc.,
onnx 1.23.2) from the network parameters, opset 17 and IR version 8 (read by ONNX Runtime
1.13 and later), and checked with ``onnx.checker.check_model(full_check=True)``. Decided
2026-12-02: not jax2onnx, which converts JAX functions generically but pins
``orbax<0.11.37`` (jax2onnx 0.17.1), while this project needs ``orbax>=0.12``; a 2-layer MLP
needs no converter. Every export is checked before it is written: the ONNX Runtime actions
equal the JAX policy's within :data:`EXPORT_TOLERANCE` on observations around the
normaliser's mean.

:func:`run_deployed` drives an env with :class:`~peghole_mjx.deploy.DeployedPolicy` (one per
world, fed the env's sensor readings: the contact wrench and the flange pose) on the episodes
of an evaluation (:func:`peghole_mjx.envs.rollout.episode_keys`), and
:func:`compare_with_evaluation` compares it with the JAX policy's evaluation rollout
(:func:`peghole_mjx.envs.rollout.rollout`) on the same episodes (``peghole export --verify N``).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import math
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from peghole_mjx import __version__, envs
from peghole_mjx.control.kinematics import rotvec_from_mat
from peghole_mjx.core._optional import optional_import
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.core.treenames import named_leaves
from peghole_mjx.deploy import (
    ACTION_FILE,
    EXPORT_FORMAT_VERSION,
    FORMAT_NAME,
    ONNX_FILE,
    POLICY_FILE,
    DeployedPolicy,
    read_spec,
)
from peghole_mjx.envs import iiwa_constants as names
from peghole_mjx.envs.extraction import residual_affine
from peghole_mjx.envs.metrics import EPISODE_METRICS, EPISODE_RECORD, summarize
from peghole_mjx.envs.rollout import episode_keys, make_runner, rollout
from peghole_mjx.files import fileio
from peghole_mjx.files.lock import OutputLock
from peghole_mjx.geometry.mjcf import TOOL_DOWN_MAT
from peghole_mjx.geometry.specs import MM
from peghole_mjx.policies import (
    PolicyBundle,
    check_meta,
    load_policy,
    make_policy_fn,
    resolve_policy_path,
)
from peghole_mjx.sim.engines import engine_overrides

#: the ONNX opset and IR version of ``policy.onnx`` (ONNX Runtime >= 1.13 reads them)
ONNX_OPSET = 17
ONNX_IR_VERSION = 8
#: largest |ONNX Runtime action - JAX action| an export may show on its check observations
EXPORT_TOLERANCE = 1e-5
#: closed-loop agreement asked of ``--verify``: identical success per episode, and the mean
#: extraction force within this fraction of the JAX evaluation's
VERIFY_FZ_RTOL = 0.01


# ---------------------------------------------------------------------- the ONNX graph
def onnx_model(network: dict[str, Any], params: Any):
    """The ONNX model of a policy: normaliser + MLP + tanh of the mean head.

    ``network``: ``policy.json``'s network description; ``params``: the bundle's
    ``(normaliser state, policy params)`` (Brax SAC layout, named as in ``params.npz``).
    """
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    arrays = named_leaves(params)
    n_obs, n_act = int(network["observation_size"]), int(network["action_size"])
    widths = [int(w) for w in network["hidden_layer_sizes"]]
    inits, nodes = [], []

    def const(name: str, value: np.ndarray) -> str:
        inits.append(numpy_helper.from_array(np.array(value, np.float32, order="C"), name))
        return name

    x = "obs"
    if network["normalize_observations"]:
        nodes.append(helper.make_node("Sub", [x, const("obs_mean", arrays["0/mean"])], ["centred"]))
        nodes.append(
            helper.make_node("Div", ["centred", const("obs_std", arrays["0/std"])], ["normed"])
        )
        x = "normed"
    for i in range(len(widths) + 1):
        kernel = arrays[f"1/params/hidden_{i}/kernel"]
        bias = arrays[f"1/params/hidden_{i}/bias"]
        last = i == len(widths)
        if last:  # the mean (loc) half of the distribution's parameters
            kernel, bias = kernel[:, :n_act], bias[:n_act]
        out = "loc" if last else f"h{i}"
        w, b = const(f"hidden_{i}_kernel", kernel), const(f"hidden_{i}_bias", bias)
        nodes.append(helper.make_node("Gemm", [x, w, b], [out + "_pre" if not last else out]))
        if not last:
            nodes.append(helper.make_node("Relu", [out + "_pre"], [out]))
        x = out
    # ONNX Runtime's float32 tanh may return 1 + 1 ulp (seen, onnxruntime 1.32): the clip
    # keeps the documented range [-1, 1] (the env clips its actions the same way)
    nodes.append(helper.make_node("Tanh", [x], ["tanh"]))
    lo, hi = const("action_min", np.float32(-1.0)), const("action_max", np.float32(1.0))
    nodes.append(helper.make_node("Clip", ["tanh", lo, hi], ["action"]))
    graph = helper.make_graph(
        nodes,
        "peghole_policy",
        [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", n_obs])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", n_act])],
        initializer=inits,
    )
    model = helper.make_model(
        graph,
        producer_name="peghole_mjx",
        producer_version=__version__,
        opset_imports=[helper.make_opsetid("", ONNX_OPSET)],
        doc_string="clip(tanh(MLP((obs - mean) / std))[:action_size], -1, 1): the deterministic "
        "SAC action",
    )
    model.ir_version = ONNX_IR_VERSION
    onnx.checker.check_model(model, full_check=True)
    return model


def _onnx():
    return optional_import("onnx", "peghole export")


# ---------------------------------------------------------------------- action.json
def _tool_geometry(env) -> dict[str, Any]:
    """The peg's geometry on the flange, from the scene at its inserted keyframe (the peg is
    welded to the flange, so the tip's offset in the flange frame is constant)."""
    m = env.mj_model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(names.START_KEYFRAME).id)
    mujoco.mj_forward(m, d)
    peg, flange = m.body(names.PEG_BODY).id, m.site(names.FLANGE_SITE).id
    tip = d.xpos[peg] + d.xmat[peg].reshape(3, 3) @ np.asarray(env._tip_local)
    R_f = d.site_xmat[flange].reshape(3, 3)
    return {
        "peg_length_m": float(env.peg_length_m),
        "flange_height_at_start_m": float(env._flange_z0),
        "tip_in_flange_m": (R_f.T @ (tip - d.site_xpos[flange])).tolist(),
        "tool_down_rotation": np.asarray(TOOL_DOWN_MAT).tolist(),
        "peg_mass_kg": float(env._peg_mass),
        "gravity_m_s2": np.asarray(env._gravity).tolist(),
    }


def observation_entries(env) -> list[dict[str, Any]]:
    """The observation layout of ``env`` (:func:`peghole_mjx.envs.extraction.observation`):
    entry ``i`` is ``(source[component] - offset) * scale`` of a named reading or state."""
    o, L = env.config.obs, float(env.peg_length_m)
    out: list[dict[str, Any]] = []

    def add(name, source, comp, scale, unit, quantity, offset=0.0):
        out.append(
            {
                "index": len(out),
                "name": name,
                "source": source,
                "component": comp,
                "offset": float(offset),
                "scale": float(scale),
                "unit": unit,
                "quantity": quantity,
            }
        )

    add("flange_x", "flange_pos_m", 0, 1 / MM, "mm", "flange offset from the hole axis, x")
    add("flange_y", "flange_pos_m", 1, 1 / MM, "mm", "flange offset from the hole axis, y")
    add(
        "flange_height",
        "flange_pos_m",
        2,
        1 / L,
        f"peg lengths ({L:g} m)",
        "flange height above its start height (0 inserted, 1 out)",
        offset=float(env._flange_z0),
    )
    fs = float(o.force_scale_N)
    for i, ax in enumerate("xyz"):
        add(
            f"force_{ax}",
            "force_N",
            i,
            1 / fs,
            f"{fs:g} N",
            f"contact force F_{ax} (F/T sensor, peg weight removed, mean over the period)",
        )
    for i, ax in enumerate(("theta", "phi", "psi")):
        add(f"tilt_{ax}", "flange_tilt_rad", i, 180 / math.pi, "deg", f"flange tilt {ax}")
    if o.torques:
        ts = float(o.torque_scale_Nm)
        for i, ax in enumerate("xyz"):
            add(f"torque_{ax}", "torque_Nm", i, 1 / ts, f"{ts:g} N m", f"F/T torque M_{ax}")
    if o.stiffness:
        add("k_xy", "k_xy_N_m", 0, 1 / o.k_xy_scale_N_m, f"{o.k_xy_scale_N_m:g} N/m", "k_xy")
        ks = float(o.k_rot_scale_Nm_rad)
        add("k_rot", "k_rot_Nm_rad", 0, 1 / ks, f"{ks:g} N m/rad", "K_theta")
        add("L_C", "L_C_m", 0, 1 / L, f"peg lengths ({L:g} m)", "compliance centre above tip")
    if o.prev_action:
        for i in range(env.action_size):
            add(f"prev_action_{i}", "prev_action", i, 1.0, "1", "the previous action")
    if o.commands:
        for i, ax in enumerate("xyz"):
            add(
                f"force_ff_{ax}",
                "force_ff_N",
                i,
                1 / fs,
                f"{fs:g} N",
                f"accumulated feed-forward force F_ff,{ax}",
            )
        for i, ax in enumerate("xyz"):
            add(
                f"command_offset_{ax}",
                "command_offset_m",
                i,
                1 / MM,
                "mm",
                f"commanded tip minus tip, {ax}",
            )
    if o.time_left:
        n = int(env.config.episode_length)
        add(
            "time_left",
            "step",
            0,
            -1.0 / n,
            f"time limits ({n} steps)",
            "share of the time limit left (1 at reset, 0 at the limit)",
            offset=n,
        )
    return out


def _residual_spec(env) -> dict[str, Any] | None:
    """``decode.residual`` of a residual policy (env ``action.residual``): the affine map
    ``clip(offset + gain * a, -1, 1)`` applied before the entries' mappings; else None."""
    affine = residual_affine(env.config, env.compliance_actions)
    if affine is None:
        return None
    offset, gain = affine
    return {"offset": [float(v) for v in offset], "gain": [float(v) for v in gain]}


def action_spec(bundle: PolicyBundle, env, onnx_sha256: str) -> dict[str, Any]:
    """The content of ``action.json`` for ``bundle`` in its training env ``env``."""
    c = env.config
    s = c.stiffness
    fx, fy, fz = (float(v) for v in c.limits.max_force_N)
    ff_xy = float(c.action.max_ff_xy_N)
    step_xy = float(c.action.max_step_offset_mm) * MM
    step_z = float(c.action.max_speed_m_s) * float(c.ctrl_dt)
    gains = env.compliance_actions
    units = {"k_xy": "N/m", "k_rot": "N m/rad", "L_C": "m"}
    fixed = env.fixed_compliance
    entries = [
        {"index": 0, "name": "dx", "maps_to": f"tip_target x += a * {step_xy:g} m"},
        {"index": 1, "name": "dy", "maps_to": f"tip_target y += a * {step_xy:g} m"},
        {"index": 2, "name": "dz", "maps_to": f"tip_target z += a * {step_z:g} m (+ = out)"},
    ]
    for i, ax in enumerate("xyz"):
        entries.append(
            {
                "index": 3 + i,
                "name": f"dF{ax}",
                "maps_to": f"F_ff,{ax} += a * {float(c.action.max_force_step_N):g} N, "
                "within force_ff_cap_N",
            }
        )
    for name, (i, lo, hi) in gains.items():
        entries.append(
            {
                "index": i,
                "name": name,
                "maps_to": f"{name} = {lo:g} + (a + 1) / 2 * ({hi:g} - {lo:g}) {units[name]}",
            }
        )
    net = bundle.meta["network"]
    obs_entries = observation_entries(env)
    if len(obs_entries) != int(net["observation_size"]):
        raise RuntimeError(  # a bug: the layout above does not follow the env's observation
            f"{len(obs_entries)} observation entries, the network takes {net['observation_size']}"
        )
    return {
        "format": FORMAT_NAME,
        "format_version": EXPORT_FORMAT_VERSION,
        "peghole_mjx_version": __version__,
        "policy": {
            "env": bundle.env_name,
            "preset": c.preset,
            "source": str(bundle.path),
            "env_overrides": bundle.env_overrides,
            "params_sha256": _params_sha256(bundle.params),
        },
        "onnx": {
            "file": ONNX_FILE,
            "sha256": onnx_sha256,
            "input": "obs",
            "output": "action",
            "dtype": "float32",
            "shape": "(batch, size): any batch size",
            "opset": ONNX_OPSET,
            "ir_version": ONNX_IR_VERSION,
            "computes": "clip(tanh(loc(MLP((obs - mean) / std))), -1, 1), hidden layers "
            f"{net['hidden_layer_sizes']} with ReLU: the deterministic SAC action",
        },
        "frames": {
            "hole": "origin at the hole mouth, +z out of the hole (the extraction direction), "
            "x and y the hole's own axes; every position, force and command is in this frame",
            "tool": "the commanded tool frame: z along the peg axis towards the tip (straight "
            "down = tool_down_rotation in the hole frame); stiffness and feed-forward act in "
            "it, moved to the compliance centre",
            "flange_tilt": "rotation vector (rad) of the flange orientation relative to "
            "straight down, hole frame",
        },
        "control": {
            "period_s": float(c.ctrl_dt),
            "rate_hz": 1.0 / float(c.ctrl_dt),
            "impedance_law_dt_s": float(c.sim_dt),
            "target_motion": "the compliance-centre target moves linearly from the previous "
            "command to the new one over the period, with velocity (tip_target - previous) / "
            "period",
            "wrench_average": "the wrench input is the mean F/T reading over the last period",
        },
        "tool": _tool_geometry(env),
        "observation": {
            "size": int(net["observation_size"]),
            "rule": "obs[i] = (source[component] - offset) * scale, float32",
            "entries": obs_entries,
        },
        "action": {
            "size": int(net["action_size"]),
            "range": [-1.0, 1.0],
            "clean": "NaN -> 0, then clipped to [-1, 1]; with decode.residual: clip(offset "
            "+ gain * a, -1, 1) before the entries' mappings",
            "entries": entries,
        },
        "decode": {
            "tip_step_m": [step_xy, step_xy, step_z],
            "force_ff_step_N": float(c.action.max_force_step_N),
            # a residual policy (env action.residual): the affine map before the decoding
            "residual": _residual_spec(env),
            "force_ff_cap_N": [min(fx, ff_xy), min(fy, ff_xy), fz],
            "learned_gains": {
                name: {"index": i, "lo": float(lo), "hi": float(hi), "unit": units[name]}
                for name, (i, lo, hi) in gains.items()
            },
            "fixed_gains": {
                "k_xy_N_m": float(fixed["k_xy"]),
                "k_rot_Nm_rad": float(fixed["k_rot"]),
                "L_C_m": float(fixed["L_C"]),
            },
            "k_z_N_m": float(s.k_z_N_m),
            "damping_ratio": float(s.damping_ratio),
            "null_space": {
                "stiffness_Nm_rad": float(s.null_stiffness_Nm_rad),
                "damping_Nms_rad": float(s.null_damping_Nms_rad),
            },
            "wrench_caps": {
                "force_N": [fx, fy, fz],
                "torque_Nm": [float(v) for v in c.limits.max_torque_Nm],
            },
        },
        "episode": {
            "success_margin_m": float(c.success_margin_mm) * MM,
            "jam_force_N": float(c.jam_force_N),
            "jam_time_s": float(c.jam_time_s),
            "max_steps": int(c.episode_length),
        },
    }


def _params_sha256(params) -> str:
    return hashlib.sha256(
        b"".join(np.asarray(x).tobytes() for x in jax.tree.leaves(params))
    ).hexdigest()


# ---------------------------------------------------------------------- export
#: the files an export writes (an export written before 2026-12-04 has no ownership manifest:
#: these names are what ``--force`` may replace in it)
EXPORT_FILES = (ONNX_FILE, ACTION_FILE, POLICY_FILE, "verification.json")


def check_out(out: Path, force: bool) -> None:
    """Refuse (one line) an ``--out`` that cannot take the export: an existing file, a
    non-empty folder without ``force``, with ``force`` a non-empty folder that is not an
    earlier export or that holds files the program did not write (named; ``--force``
    replaces only the program's own files, :func:`peghole_mjx.files.fileio.foreign_files`), an
    unwritable parent, a symbolic link loop, a name too long for the temporary names beside
    it."""
    fileio.check_no_link_loop(out, "--out")
    fileio.check_name_length(out, "--out")
    if out.exists() and not out.is_dir():
        raise UserInputError(f"--out {out} is an existing file, not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise UserInputError(
                f"--out {out} exists and is not empty: choose another folder, or pass --force "
                "to replace an earlier export"
            )
        if not (out / ACTION_FILE).is_file():
            raise UserInputError(
                f"--out {out} holds files that are not an export (no {ACTION_FILE}): --force "
                "replaces only an earlier export"
            )
        foreign = fileio.foreign_files(out, EXPORT_FILES)
        if foreign:
            raise UserInputError(
                f"--out {out} holds files peghole_mjx did not write "
                f"({fileio.describe_files(foreign)}): --force replaces only an earlier export's "
                "own files; move them away or choose another folder"
            )
    fileio.check_out_dir(out.resolve().parent, "--out", beside=False)


def export_policy(
    policy: str | Path, out: str | Path, force: bool = False, verify: int = 0, seed: int = 0
) -> dict[str, Any]:
    """Export ``policy`` (a pretrained name or a policy folder) into ``out`` (all files or
    none: written into a uniquely named folder beside it and moved,
    :func:`peghole_mjx.files.fileio.replace_dir`). ``verify``: also run that many episodes of the
    closed loop through the export and compare them with the JAX evaluation
    (:func:`compare_with_evaluation`, ``engine`` mujoco); a mismatch writes nothing and raises.
    Returns ``{"out", "max_abs_diff", "verification"}``."""
    resolve_policy_path(policy)  # an unknown name or folder: one line, before anything else
    out = Path(out)
    check_out(out, force)
    # one writer per output (2026-12-04): a second export into the same folder is refused
    with OutputLock(out, "peghole export"):
        check_out(out, force)  # again: an export that held the lock may have written it
        return _export_locked(policy, out, verify, seed)


def _export_locked(policy: str | Path, out: Path, verify: int, seed: int) -> dict[str, Any]:
    _onnx()
    bundle = load_policy(policy)
    env = bundle.make_env()
    model = onnx_model(bundle.meta["network"], bundle.params)
    data = model.SerializeToString()
    spec = action_spec(bundle, env, hashlib.sha256(data).hexdigest())
    target = out.resolve()  # "." or "a/.." name no folder to put a temporary one beside
    tmp = fileio.temp_dir_beside(target)  # a unique name: never a folder of the user's
    try:
        fileio.write_bytes_with(tmp / ONNX_FILE, lambda f: f.write(data))
        fileio.write_text(tmp / ACTION_FILE, json.dumps(spec, indent=2) + "\n")
        fileio.write_text(tmp / POLICY_FILE, (bundle.path / POLICY_FILE).read_text())
        diff = check_export(tmp, bundle)
        verification = None
        if verify:
            verification = compare_with_evaluation(bundle, tmp, verify, seed=seed)
            fileio.write_text(tmp / "verification.json", json.dumps(verification, indent=2) + "\n")
            if not verification["agrees"]:
                raise VerificationError(
                    f"the closed loop through the export differs from the JAX evaluation on "
                    f"{verify} episodes: {verification['summary_line']}; nothing was written"
                )
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    fileio.replace_dir(tmp, target, known=EXPORT_FILES)
    return {"out": str(out), "max_abs_diff": diff, "verification": verification}


class VerificationError(RuntimeError):
    """``--verify``: the closed loop through the export did not reproduce the evaluation."""


def check_export(folder: Path, bundle: PolicyBundle, n: int = 256, seed: int = 0) -> float:
    """Max |ONNX Runtime action - JAX action| on ``n`` observations drawn around the
    normaliser's mean (+- 3 standard deviations); raises if above :data:`EXPORT_TOLERANCE`
    (a bug of the exporter, never a user error)."""
    norm = named_leaves(bundle.params)
    size = int(bundle.meta["network"]["observation_size"])
    mean = np.asarray(norm.get("0/mean", np.zeros(size)), np.float32)
    std = np.asarray(norm.get("0/std", np.ones(size)), np.float32)
    rng = np.random.default_rng(seed)
    obs = (mean + std * rng.uniform(-3, 3, (n, size))).astype(np.float32)
    diff = float(np.max(np.abs(DeployedPolicy(folder).act_obs(obs) - jax_actions(bundle, obs))))
    if not diff <= EXPORT_TOLERANCE:
        raise RuntimeError(f"export check failed: ONNX and JAX actions differ by {diff:.3g}")
    return diff


def jax_actions(bundle: PolicyBundle, obs: np.ndarray) -> np.ndarray:
    """The JAX policy's deterministic actions of a batch of observations (the evaluation's
    function, :meth:`PolicyBundle.policy_fn`)."""
    fn = jax.jit(bundle.policy_fn())
    return np.asarray(fn(bundle.params, jnp.asarray(obs, jnp.float32), jax.random.PRNGKey(0)))


# ---------------------------------------------------------------------- closed loop
@dataclass
class DeployedRollout:
    """Episodes of an env driven by :class:`DeployedPolicy` (:func:`run_deployed`)."""

    per_episode: dict[str, np.ndarray]
    #: largest |deployed observation - env observation| over the steps
    max_obs_diff: float
    #: largest |deployed command - the env's decoded command| (tip m, force N, gains)
    max_command_diff: dict[str, float]
    steps: int
    #: the env's observations of the running worlds, in step order (with ``record``)
    observations: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict[str, Any]:
        return summarize(self.per_episode)


@functools.lru_cache(maxsize=8)
def _loop_functions(env):
    """``(probe, step)`` of ``env``, jitted over a batch of worlds (cached per env: the
    mujoco engine's graphs hold host callbacks, which JAX 0.10 does not store in its
    persistent compilation cache, so each new jit object compiles again).

    ``probe(states)``: what the robot measures (contact wrench, flange pose; hole frame), the
    env's observation, its decoded command (hole frame), done, reward and episode metrics."""
    H_keys = ("cmd_tip", "wrench_ff", "k_xy", "k_rot", "L_C")

    def one(s):
        r = env.engine.readout(s.data)
        pos, tilt = env._flange_pose(r, s.info)
        H, hp = s.info["hole_mat"], s.info["hole_pos"]
        cmd = {k: s.info[k] for k in H_keys}
        cmd["cmd_tip"] = H.T @ (cmd["cmd_tip"] - hp)
        cmd_tilt = rotvec_from_mat(H.T @ s.info["cmd_mat"] @ jnp.asarray(TOOL_DOWN_MAT).T)
        metrics = {k: s.metrics[k] for k in EPISODE_METRICS}
        return s.info["wrench"], pos, tilt, s.obs, cmd, cmd_tilt, s.done, s.reward, metrics

    return jax.jit(jax.vmap(one)), jax.jit(jax.vmap(env.step))


def run_deployed(
    folder: str | Path,
    episodes: int,
    seed: int = 0,
    env=None,
    engine: str = "mujoco",
    record: bool = False,
    max_steps: int | None = None,
    gamma: float = 0.99,
) -> DeployedRollout:
    """Run ``episodes`` episodes (those of an evaluation with ``seed``) of the exported
    policy's env, each world driven by its own :class:`DeployedPolicy` that sees only what a
    robot measures: the env's contact wrench and flange pose each step. Its raw action goes to
    the env's step; its command is compared with the env's decoded command, its observation
    with the env's (``max_command_diff``, ``max_obs_diff``). ``env``: an already built env of
    the export's config (``engine`` is ignored then); ``max_steps``: stop early (recording)."""
    folder = Path(folder)
    spec = read_spec(folder)
    meta = check_meta(json.loads((folder / POLICY_FILE).read_text()), str(folder / POLICY_FILE))
    if env is None:
        env = envs.load(
            meta["env"], config_overrides={**meta["env_overrides"], **engine_overrides(engine)}
        )
    elif env.env_name != spec["policy"]["env"] or env.action_size != spec["action"]["size"]:
        raise UserInputError(f"{folder} is an export for {spec['policy']['env']}, not this env")
    _, keys = episode_keys(seed, episodes)
    # the start states of the policy's evaluation rollout: its runner's reset (the same
    # compiled function when that rollout ran on this env object)
    reset, _ = make_runner(env, make_policy_fn(meta["network"]), 25, True, gamma)
    states = reset(keys)[0]
    probe, step = _loop_functions(env)
    wrench, pos, tilt, obs, cmd, cmd_tilt, *_ = jax.device_get(probe(states))
    pols = []
    for i in range(episodes):
        p = DeployedPolicy(folder)
        p.reset(
            cmd["cmd_tip"][i],
            cmd_tilt[i],
            k_xy_N_m=cmd["k_xy"][i],
            k_rot_Nm_rad=cmd["k_rot"][i],
            L_C_m=cmd["L_C"][i],
        )
        pols.append(p)
    record_ = {k: np.zeros(episodes, np.float32) for k in EPISODE_RECORD}
    ret, disc, gamma_t = np.zeros(episodes), np.zeros(episodes), np.ones(episodes)
    finished = np.zeros(episodes, bool)
    obs_diff, cmd_diff = 0.0, dict.fromkeys(("tip_m", "force_ff_N", "gains"), 0.0)
    seen, t = [], 0
    limit = int(env.config.episode_length) if max_steps is None else int(max_steps)
    while t < limit and not finished.all():
        actions = np.zeros((episodes, env.action_size), np.float32)
        sent = {}
        for i in np.flatnonzero(~finished):
            o = pols[i].observation(wrench[i], pos[i], tilt[i])
            obs_diff = max(obs_diff, float(np.max(np.abs(o - obs[i]))))
            sent[i] = pols[i].decode(pols[i].act_obs(o))
            actions[i] = sent[i].action
        if record:
            seen.append(obs[~finished])
        states = step(states, jnp.asarray(actions))
        t += 1
        wrench, pos, tilt, obs, cmd, _, done, reward, metrics = jax.device_get(probe(states))
        for i, c in sent.items():
            d = cmd_diff
            d["tip_m"] = max(d["tip_m"], float(np.max(np.abs(c.tip_target_m - cmd["cmd_tip"][i]))))
            d["force_ff_N"] = max(
                d["force_ff_N"], float(np.max(np.abs(c.force_ff_hole_N - cmd["wrench_ff"][i])))
            )
            g = (c.k_xy_N_m - cmd["k_xy"][i], c.k_rot_Nm_rad - cmd["k_rot"][i])
            g += (c.compliance_centre_m - cmd["L_C"][i],)
            d["gains"] = max(d["gains"], float(np.max(np.abs(g))))
        r = np.where(finished, 0.0, reward)
        ret, disc, gamma_t = ret + r, disc + gamma_t * r, gamma_t * gamma
        now = (done > 0) & ~finished
        ended = {**metrics, "return": ret, "discounted_return": disc}
        for k in EPISODE_RECORD:
            record_[k] = np.where(now, ended[k], record_[k]).astype(np.float32)
        finished |= now
    return DeployedRollout(
        per_episode=record_,
        max_obs_diff=obs_diff,
        max_command_diff=cmd_diff,
        steps=t,
        observations=np.concatenate(seen) if record else None,
    )


def compare_with_evaluation(
    policy: str | Path | PolicyBundle,
    folder: str | Path,
    episodes: int,
    seed: int = 0,
    engine: str = "mujoco",
    env=None,
) -> dict[str, Any]:
    """The JAX policy's evaluation rollout and the closed loop through the export
    (:func:`run_deployed`) on the same ``episodes`` (``seed``) of the ``engine`` env:
    ``agrees`` when success is identical episode by episode and the mean F_z is within
    :data:`VERIFY_FZ_RTOL`. ``env``: an already built env of the policy in ``engine``."""
    bundle = policy if isinstance(policy, PolicyBundle) else load_policy(policy)
    if env is None:
        env = bundle.make_env(engine_overrides(engine))
    bundle.check_env(env)
    ref = rollout(
        env, bundle.policy_fn(), episodes, seed=seed, progress=False, params=bundle.params
    )
    dep = run_deployed(folder, episodes, seed=seed, env=env)
    a, b = ref.summary().as_dict(), dep.summary()
    same = bool(np.array_equal(ref.per_episode["success"] > 0, dep.per_episode["success"] > 0))
    rel = abs(b["mean_fz_N"] - a["mean_fz_N"]) / max(abs(a["mean_fz_N"]), 1e-12)
    line = (
        f"success {a['success_rate']:.3f} (JAX) vs {b['success_rate']:.3f} (ONNX), "
        f"{'identical' if same else 'different'} per episode; mean F_z {a['mean_fz_N']:.4f} "
        f"vs {b['mean_fz_N']:.4f} N ({100 * rel:.3f} %)"
    )
    return {
        "episodes": episodes,
        "seed": seed,
        "engine": env.config.engine,
        "jax": a,
        "deployed": b,
        "success_identical": same,
        "mean_fz_rel_diff": rel,
        "max_obs_diff": dep.max_obs_diff,
        "max_command_diff": dep.max_command_diff,
        "agrees": same and rel <= VERIFY_FZ_RTOL,
        "summary_line": line,
    }


def cmd_export(args: argparse.Namespace) -> int:
    """``peghole export`` (parser: :mod:`peghole_mjx.cli.export`)."""
    try:
        res = export_policy(
            args.policy, args.out, force=args.force, verify=args.verify, seed=args.seed
        )
    except VerificationError as exc:
        print(f"peghole export: verification failed: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(
        f"exported {args.policy} to {args.out} (policy.onnx, action.json, policy.json); ONNX "
        f"Runtime vs JAX actions differ by at most {res['max_abs_diff']:.2g}"
    )
    if res["verification"] is not None:
        print(f"verified on {args.verify} episodes: {res['verification']['summary_line']}")
    return 0


__all__ = [
    "EXPORT_TOLERANCE",
    "DeployedRollout",
    "VerificationError",
    "action_spec",
    "check_export",
    "cmd_export",
    "compare_with_evaluation",
    "export_policy",
    "jax_actions",
    "observation_entries",
    "onnx_model",
    "run_deployed",
]
