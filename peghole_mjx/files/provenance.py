"""Provenance stamped on every committed result: device, library versions, date (and, with
:func:`run_provenance`, the command and the commit)."""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import os
import platform
import subprocess

import jax

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


def utc_now() -> str:
    """The current UTC time, ``2026-11-29T04:30:00Z`` (the date of every result file)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def cpu_device() -> str:
    """The host CPU, ``cpu (2 cores, x86_64)``: the device of a NumPy or MuJoCo C result."""
    return f"cpu ({os.cpu_count()} cores, {platform.machine()})"


def device() -> str:
    """The JAX default device and the host CPU, e.g. ``cpu (2 cores, x86_64)``."""
    host = f"{os.cpu_count()} cores, {platform.machine()}"
    try:
        dev = jax.devices()[0]
        kind = getattr(dev, "device_kind", dev.platform)
        if dev.platform == "cpu":
            return cpu_device()
        return f"{dev.platform}: {kind} x{jax.device_count()} (host {host})"
    except Exception:  # no usable JAX backend: still say what the host is
        return cpu_device()


def provenance() -> dict[str, object]:
    """``{"device", "versions", "date"}`` for a result file."""
    return {
        "device": device(),
        "versions": versions(),
        "date": utc_now(),
    }


def commit() -> str:
    """The source tree's git commit (``+dirty`` with uncommitted changes), or ``unknown``
    outside a git checkout (an installed wheel)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(
            ["git", "-C", root, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(
            ["git", "-C", root, "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def run_provenance(command: list[str]) -> dict[str, object]:
    """:func:`provenance` plus the ``command`` that made the result and the ``commit``."""
    return {**provenance(), "command": " ".join(command), "commit": commit()}
