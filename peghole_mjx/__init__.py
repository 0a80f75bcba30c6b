"""peghole_mjx: GPU-parallel simulation and learning for robotic peg-hole disassembly.

Subpackages, one concept each:

* :mod:`peghole_mjx.geometry` - peg-hole specs and presets, convex parts, MJCF scenes, checks
* :mod:`peghole_mjx.analysis` - quasi-static mechanics of extraction (thesis Ch 2-3)
* :mod:`peghole_mjx.control` - Cartesian impedance law with a compliance centre
* :mod:`peghole_mjx.envs` - batched MJX extraction environments
* :mod:`peghole_mjx.training` - Brax SAC training, evaluation, learning curves
* :mod:`peghole_mjx.policies` - saved and pretrained policies
"""

import os as _os

# XLA's CPU fusion emitters (the default in jaxlib 0.10) make MJX's small, deep kinematic
# trees 20-50x slower on the CPU: 19 ms vs 0.4 ms per mjx.kinematics of the iiwa (measured
# here, 2-core CPU, jax 0.10.2). The flag only touches the CPU backend; it must be set before
# JAX starts its backends, so it lives at the top of the package.
_FLAG = "--xla_cpu_use_fusion_emitters=false"
if _FLAG.split("=")[0] not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " " + _FLAG).strip()

# Rendering (rollout GIFs) must work headless: without a display, MuJoCo's default GLFW
# backend cannot open a context, so choose EGL unless the user chose a backend. Like the flag
# above, this must happen before mujoco is imported.
if "MUJOCO_GL" not in _os.environ and not _os.environ.get("DISPLAY"):
    _os.environ["MUJOCO_GL"] = "egl"

# A persistent XLA compilation cache, on by default, so that a second run of any command loads
# its compiled graphs (minutes on a 2-core CPU) from disk: PEGHOLE_JAX_CACHE unset -> the
# user's cache folder ($XDG_CACHE_HOME or ~/.cache)/peghole_mjx/jax; a path -> that folder;
# 0 / off -> no cache. JAX's own JAX_COMPILATION_CACHE_DIR, when set, wins. Results are the
# same with or without it (it stores compiled code, keyed by the graph, flags and versions);
# jax 0.10.2 does not store graphs with host callbacks (measured 2026-12-02: "Not writing
# persistent cache entry for 'jit_reset' because it uses host callbacks"), so the mujoco
# engine's step and the host half of its reset compile again in each process (rollouts compile
# the pure-JAX half, PegHoleEnv.reset_start, apart). Set before JAX is imported, like the
# flag above (docs/guide/getting_started.md, "Compilation cache").
_CACHE = _os.environ.get("PEGHOLE_JAX_CACHE", "").strip()
if _CACHE.lower() not in ("0", "off", "false", "no") and not _os.environ.get(
    "JAX_COMPILATION_CACHE_DIR"
):
    _base = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    _os.environ["JAX_COMPILATION_CACHE_DIR"] = _CACHE or _os.path.join(_base, "peghole_mjx", "jax")
    _os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1")
    import sys as _sys

    if "jax" in _sys.modules:  # imported before us: its config has read the environment
        _jax = _sys.modules["jax"]
        _jax.config.update("jax_compilation_cache_dir", _os.environ["JAX_COMPILATION_CACHE_DIR"])
        _jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

__version__ = "0.1.0"
