"""Process-wide settings of the ``peghole`` commands, applied by one explicit call.

Importing :mod:`peghole_mjx` changes nothing in the process. :func:`configure` sets what the
commands want (the ``peghole`` entry point calls it first thing, the test suite's conftest
too); a user of the Python API calls it once, before the first JAX computation, to get the
same flags:

* ``XLA_FLAGS`` gains ``--xla_cpu_use_fusion_emitters=false``: XLA's CPU fusion emitters (the
  default in jaxlib 0.10) make MJX's small, deep kinematic trees 20-50x slower on the CPU
  (19 ms vs 0.4 ms per ``mjx.kinematics`` of the iiwa, 2-core CPU, jax 0.10.2). XLA reads
  the variable when JAX starts its backends, so it has no effect once a JAX computation has
  run (then :func:`configure` warns and leaves the flags alone).
* ``MUJOCO_GL=egl`` when no display is set and the user chose no backend: rendering (rollout
  GIFs) must work headless, where MuJoCo's default GLFW cannot open a context. MuJoCo reads it
  when its GL context module is first imported (at the first render).
* a persistent XLA compilation cache, so that a second run of any command loads its compiled
  graphs (minutes on a 2-core CPU) from disk: ``PEGHOLE_JAX_CACHE`` unset -> the user's cache
  folder (``$XDG_CACHE_HOME`` or ``~/.cache``)/peghole_mjx/jax; a path -> that folder;
  ``0`` / ``off`` -> no cache. JAX's own ``JAX_COMPILATION_CACHE_DIR``, when set, wins.
  Results are the same with or without it; jax 0.10.2 does not store graphs with host
  callbacks (the ``mujoco`` engine's step compiles again in each process).
"""

from __future__ import annotations

import os
import warnings

import jax  # importing JAX starts no backend: the flags below still apply until one starts
from jax._src import xla_bridge  # private (jax 0.10.2): whether a backend has started

__all__ = ["CPU_FLAG", "configure"]

#: the XLA flag :func:`configure` adds (see the module docstring)
CPU_FLAG = "--xla_cpu_use_fusion_emitters=false"

_OFF = ("0", "off", "false", "no")


def _backends_started() -> bool:
    return bool(xla_bridge.backends_are_initialized())


def configure() -> None:
    """Set ``XLA_FLAGS``, ``MUJOCO_GL`` and the compilation cache (module docstring).

    Idempotent; call it before the first JAX computation. Values the user set are kept."""
    flag_name = CPU_FLAG.split("=")[0]
    if flag_name not in os.environ.get("XLA_FLAGS", ""):
        if _backends_started():
            warnings.warn(
                f"peghole_mjx.core.runtime.configure(): JAX's backends already started, {CPU_FLAG} "
                "not applied (call configure() before the first JAX computation)",
                stacklevel=2,
            )
        else:
            os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + CPU_FLAG).strip()

    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"

    cache = os.environ.get("PEGHOLE_JAX_CACHE", "").strip()
    if cache.lower() in _OFF or os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = cache or os.path.join(base, "peghole_mjx", "jax")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")
    # JAX read the environment when it was imported (above): its config is set directly
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
    )
