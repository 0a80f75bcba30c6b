"""peghole_mjx: GPU-parallel simulation and learning for robotic peg-hole disassembly.

Subpackages, one concept each, top to bottom (a layer imports only the layers below it;
``.importlinter`` checks it):

* :mod:`peghole_mjx.cli` - the ``peghole`` command (with :mod:`peghole_mjx.demo`, the demo)
* :mod:`peghole_mjx.training` - Brax SAC training, evaluation, learning curves (and
  :mod:`peghole_mjx.gym`, the Gymnasium adapters)
* :mod:`peghole_mjx.policies` - saved and pretrained policies, their export
* :mod:`peghole_mjx.envs` - the batched extraction environments;
  :mod:`peghole_mjx.experiments` - the compliance-centre experiments
* :mod:`peghole_mjx.sim` - the physics engines under the envs (MJX-JAX, MuJoCo Warp, MuJoCo C)
* :mod:`peghole_mjx.control` - Cartesian impedance law with a compliance centre;
  :mod:`peghole_mjx.analysis` - quasi-static mechanics of extraction (thesis Ch 2-3)
* :mod:`peghole_mjx.geometry` - peg-hole specs and presets, convex parts, MJCF scenes, checks
* :mod:`peghole_mjx.files` - durable writes, locks, provenance (and :mod:`peghole_mjx.deploy`,
  the robot-side runner)
* :mod:`peghole_mjx.core` - errors, input checks, progress, optional imports: every layer's base

Importing the package changes no process-wide setting: :func:`peghole_mjx.core.runtime.configure`
sets the XLA flags, the headless GL backend and the compilation cache that the ``peghole``
commands use (docs/guide/getting_started.md, "Process-wide settings").
"""

__version__ = "0.1.0"
