"""MeshExtract: pull any peg out of its hole, the parts read from a task folder.

The same task as RectExtract and DualExtract (:class:`~peghole_mjx.envs.extraction.PegHoleEnv`:
action, impedance law, observation, reward, randomisation, termination; the scripted Ch 2-3
baseline of :mod:`peghole_mjx.envs.rollout`), on the peg-hole of the folder named by the
config entry ``task`` (``--set env.task=DIR``): its convex pieces, frames, start pose,
friction, mass and measured contact cap (:mod:`peghole_mjx.geometry.task`). The folder is made
by ``peghole task make PEG HOLE`` (a user's meshes) or ``peghole task builtin NAME`` (the
built-in irregular parts, :mod:`peghole_mjx.geometry.shapes`).

Engines: ``mujoco`` (MuJoCo C) collides any convex pieces; ``mjx`` (MJX-JAX) only pieces whose
planar faces have at most 20 vertices (``geometry/task.py``, ``MJX_MAX_FACE_VERTICES``; the
built-in parts all do) and compiles one collision function per mesh pair, minutes for tens of
pairs on a CPU.
"""

from __future__ import annotations

from pathlib import Path

from ml_collections import config_dict

from peghole_mjx.core.errors import UserInputError
from peghole_mjx.envs.config import apply_overrides, base_config, env_spec
from peghole_mjx.envs.extraction import PegHoleEnv
from peghole_mjx.geometry.task import MJX_MAX_FACE_VERTICES


def default_config() -> config_dict.ConfigDict:
    """No preset: the parts come from ``task`` (a task folder; "" = none, refused when the env
    is built). 8 s episodes at 50 Hz, as DualExtract: a 40-50 mm pull at the scripted
    20 mm/s takes 2-3 s (raise ``episode_length`` for a deeper part)."""
    config = base_config("")
    config.task = ""
    config.episode_length = 400
    return config


class MeshExtract(PegHoleEnv):
    """The extraction task on a task folder's parts. Tables: see PegHoleEnv."""

    def __init__(
        self, config: config_dict.ConfigDict | None = None, config_overrides: dict | None = None
    ):
        config = apply_overrides(config or default_config(), config_overrides)
        spec = env_spec(config)
        if config.engine == "auto" and not spec.mjx_ok:  # MuJoCo C takes any convex face
            config = config.copy_and_resolve_references()
            config.engine, config.impl = "mujoco", "jax"
        if config.engine == "mjx" and not spec.mjx_ok:
            raise UserInputError(
                f"task {spec.folder}: a convex piece has a face of {spec.max_face_vertices} "
                f"vertices, more than MJX-JAX's {MJX_MAX_FACE_VERTICES}: use --engine mujoco"
            )
        super().__init__(config, None)


def absolute_task(overrides: dict, key: str = "task") -> dict:
    """``overrides`` with the task folder entry ``key`` (``task``; ``env.task`` for training's
    flat keys) made absolute: a run or policy records the folder it was trained on, which then
    resolves from any working directory, and two spellings of one folder are one setting."""
    value = overrides.get(key)
    if isinstance(value, str) and value:
        return {**overrides, key: str(Path(value).expanduser().resolve())}
    return overrides
