"""Benchmarks, baselines, evaluations and closed studies, with their committed results.

Four kinds, each a subpackage with its results folder ``benchmarks/results/<kind>/``:

* :mod:`benchmarks.perf` - speed and cost of the engines (throughput, roofline, per-world cost);
* :mod:`benchmarks.baselines` - the thesis's PyBullet + SB3 seed stack and time to success;
* :mod:`benchmarks.evals` - evaluations of the policies and the thesis's claims;
* :mod:`benchmarks.studies` - closed investigations, each kept as a runnable record.

:mod:`benchmarks.common` is the layer below them all; :mod:`benchmarks.tables` regenerates the
docs tables that the scripts register. Run each script from the repository root as a module,
e.g. ``python -m benchmarks.perf.throughput --quick``.
"""

from peghole_mjx.core.runtime import configure

# the scripts are commands: the process-wide settings of ``peghole`` (the XLA CPU flag without
# which MJX's kinematics run 20-50x slower on a CPU, headless rendering, the compilation cache;
# peghole_mjx/core/runtime.py), applied before any of them starts JAX
configure()
