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

__version__ = "0.1.0"
