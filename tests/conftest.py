"""Shared test setup: quiet mjx import, CPU-only JAX unless a GPU test asks otherwise."""

import peghole_mjx._mjx  # noqa: F401
