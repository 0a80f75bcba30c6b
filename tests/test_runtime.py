"""Importing the package sets nothing process-wide; :func:`peghole_mjx.core.runtime.configure` does.

Each check runs in a fresh interpreter (the test process's own environment was configured by
conftest.py), with the variables ``configure`` sets removed from its environment first.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

#: the environment variables configure() may set
SET_BY_CONFIGURE = (
    "XLA_FLAGS",
    "MUJOCO_GL",
    "JAX_COMPILATION_CACHE_DIR",
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
    "PEGHOLE_JAX_CACHE",
)

PROBE = """
import json, os, sys
import jax
try:  # gymnasium sets PYGAME_HIDE_SUPPORT_PROMPT on its own import: a dependency's, not ours
    import gymnasium
except ImportError:
    pass
before = dict(os.environ)
cfg = lambda: {k: getattr(jax.config, k) for k in (
    "jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
    "jax_enable_x64", "jax_platforms")}
cfg0 = cfg()
import peghole_mjx, peghole_mjx.geometry, peghole_mjx.analysis, peghole_mjx.control
import peghole_mjx.envs, peghole_mjx.experiments, peghole_mjx.policies, peghole_mjx.training
import peghole_mjx.gym
changed = {k: os.environ.get(k) for k in set(before) | set(os.environ)
           if before.get(k) != os.environ.get(k)}
out = {"env": changed, "config_before": cfg0, "config_after": cfg()}
if sys.argv[1:] == ["configure"]:
    from peghole_mjx.core import runtime
    runtime.configure()
    out["configured"] = {k: os.environ.get(k) for k in ("XLA_FLAGS", "MUJOCO_GL",
                         "JAX_COMPILATION_CACHE_DIR")}
    out["cache_dir"] = jax.config.jax_compilation_cache_dir
print("PROBE" + json.dumps(out))
"""


def _probe(tmp_path, *args: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in SET_BY_CONFIGURE and k != "DISPLAY"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    res = subprocess.run(
        [sys.executable, "-c", PROBE, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("PROBE")][-1]
    return json.loads(line[len("PROBE") :])


def test_importing_the_package_changes_no_environment_variable_or_jax_config(tmp_path):
    out = _probe(tmp_path)
    assert out["env"] == {}
    assert out["config_after"] == out["config_before"]


def test_configure_sets_the_flags_and_the_cache(tmp_path):
    out = _probe(tmp_path, "configure")
    c = out["configured"]
    assert "--xla_cpu_use_fusion_emitters=false" in c["XLA_FLAGS"]
    assert c["MUJOCO_GL"] == "egl"
    expected = os.path.join(str(tmp_path), "peghole_mjx", "jax")
    assert c["JAX_COMPILATION_CACHE_DIR"] == expected
    assert out["cache_dir"] == expected  # jax was imported first: its config was updated
