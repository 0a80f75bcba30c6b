"""peghole_mjx: GPU-parallel simulation and learning for robotic peg-hole disassembly.

Subpackages, one concept each:

* :mod:`peghole_mjx.geometry` - peg-hole specs and presets, convex parts, MJCF scenes, checks
* :mod:`peghole_mjx.analysis` - quasi-static mechanics of extraction (thesis Ch 2-3)
* :mod:`peghole_mjx.control` - Cartesian impedance law with a compliance centre
* :mod:`peghole_mjx.envs` - batched MJX extraction environments
* :mod:`peghole_mjx.training` - Brax SAC training, evaluation, learning curves
* :mod:`peghole_mjx.policies` - saved and pretrained policies

Importing the package changes no process-wide setting: :func:`peghole_mjx.runtime.configure`
sets the XLA flags, the headless GL backend and the compilation cache that the ``peghole``
commands use (docs/guide/getting_started.md, "Process-wide settings").
"""

__version__ = "0.1.0"
