"""The physics layer under the envs: the engines that step MuJoCo for a task (:mod:`.engines`:
the seam and MJX, JAX or Warp; :mod:`.engine_mujoco`: MuJoCo C through ``mujoco.batch``) and
the opt-in fix of MJX-JAX's elliptic-cone Hessian (:mod:`.mjx_fixes`)."""
