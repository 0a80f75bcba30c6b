"""The persistent XLA compilation cache that ``peghole_mjx.core.runtime.configure()`` turns on (the
``peghole`` commands call it; importing the package changes nothing: tests/test_runtime.py):
where it goes, how to move or disable it, and that JAX's own variable wins, whether JAX or the
package was imported first."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = (
    "import {first}; import peghole_mjx.core.runtime, jax; peghole_mjx.core.runtime.configure(); "
    "print(jax.config.jax_compilation_cache_dir)"
)


def _cache_dir(tmp_path, first: str = "peghole_mjx", **env) -> str:
    base = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR",)}
    base.pop("PEGHOLE_JAX_CACHE", None)
    base.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), JAX_PLATFORMS="cpu", **env)
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(first=first)],
        env=base,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return out.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize("first", ["peghole_mjx", "jax"])
def test_cache_defaults_to_the_users_cache_folder(tmp_path, first):
    assert _cache_dir(tmp_path, first) == str(tmp_path / "xdg" / "peghole_mjx" / "jax")


def test_cache_can_be_moved_or_turned_off_and_jax_own_variable_wins(tmp_path):
    assert _cache_dir(tmp_path, PEGHOLE_JAX_CACHE=str(tmp_path / "c")) == str(tmp_path / "c")
    assert _cache_dir(tmp_path, PEGHOLE_JAX_CACHE="off") == "None"
    own = str(tmp_path / "own")
    assert _cache_dir(tmp_path, JAX_COMPILATION_CACHE_DIR=own, PEGHOLE_JAX_CACHE="off") == own
