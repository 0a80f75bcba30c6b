"""Provenance stamped on every committed result: device, library versions, date."""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import os
import platform

_PACKAGES = (
    "peghole_mjx",
    "mujoco",
    "mujoco-mjx",
    "jax",
    "jaxlib",
    "brax",
    "numpy",
    "coacd",
    "trimesh",
)


def versions() -> dict[str, str]:
    """Installed versions of the stack (missing packages are left out)."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


def device() -> str:
    """The JAX default device and the host CPU, e.g. ``cpu (2 cores, x86_64)``."""
    cores = os.cpu_count()
    host = f"{cores} cores, {platform.machine()}"
    try:
        import jax

        dev = jax.devices()[0]
        kind = getattr(dev, "device_kind", dev.platform)
        if dev.platform == "cpu":
            return f"cpu ({host})"
        return f"{dev.platform}: {kind} x{jax.device_count()} (host {host})"
    except Exception:  # jax missing or broken: still say what the host is
        return f"cpu ({host})"


def provenance() -> dict[str, object]:
    """``{"device", "versions", "date"}`` for a result file."""
    return {
        "device": device(),
        "versions": versions(),
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
