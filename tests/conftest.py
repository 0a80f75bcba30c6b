"""Shared test setup: quiet mjx import, CPU-only JAX, one compilation cache for the session.

The persistent XLA compilation cache is shared by the test process and every ``peghole``
subprocess a test starts (they inherit the environment), so a graph compiled once (an env
step takes about a minute on a 2-core CPU) is loaded from disk afterwards. It only saves
time: results are the same with or without it.
"""

import os
import tempfile

if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = os.path.join(
        tempfile.gettempdir(), "peghole_mjx_test_jax_cache"
    )
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")

import peghole_mjx._mjx  # noqa: F401
