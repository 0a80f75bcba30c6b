"""The physics layer under the envs, the one place of the package that steps physics: the
engines that step MuJoCo for a task (:mod:`.engines`: the seam and MJX, JAX or Warp;
:mod:`.engine_mujoco`: MuJoCo C through ``mujoco.batch``), the runs without the impedance law
(:mod:`.free`: the free peg's drop test, the replay of recorded torques) and the opt-in fix of
MJX-JAX's elliptic-cone Hessian (:mod:`.mjx_fixes`)."""
