"""peghole_mjx: GPU-parallel simulation and learning for robotic peg-hole disassembly.

Subpackages, one concept each:

* :mod:`peghole_mjx.geometry` - peg-hole specs and presets, convex parts, MJCF scenes, checks
* :mod:`peghole_mjx.analysis` - quasi-static mechanics of extraction (thesis Ch 2-3)
"""

__version__ = "0.1.0"
