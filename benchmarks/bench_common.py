"""Shared pieces of the benchmarks: the impedance law ported to NumPy, CSV rows, provenance.

The NumPy port (:func:`impedance_torque`) is line for line the JAX law of
:class:`peghole_mjx.control.impedance.ImpedanceController` (same clip, same 1e-9 regulariser
of the operational-space inertia, same null-space projector), so the MuJoCo C and PyBullet
baselines run the same controller as the MJX environments at every physics step. The test
suite checks it against the JAX law on one state (``tests/test_benchmarks.py``).
"""

from __future__ import annotations

import csv
import datetime as _dt
import importlib.metadata
import os
import platform
import resource
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"

#: the throughput CSV's columns, in order
COLUMNS = (
    "engine",
    "device",
    "scene",
    "worlds",
    "physics_steps_per_s",
    "env_steps_per_s",
    "compile_s",
    "peak_mem_mb",
    "versions",
    "date",
)
ENGINES = ("mjx-jax", "mjx-warp", "mujoco-c", "mujoco-c-rollout", "pybullet")
SCENES = {
    "rect": "RectExtract",
    "dual": "DualExtract",  # the env's default collision representation: capsule
    "dual-mesh": "DualExtract",
    "dual-cylinder": "DualExtract",
}
#: env config overrides of the scene variants (collision representations)
SCENE_OVERRIDES: dict[str, dict] = {
    "dual-mesh": {"representation": "mesh"},
    "dual-cylinder": {"representation": "cylinder"},  # MuJoCo Warp (and C) only
}

#: packages named in the compact ``versions`` string (short name, distribution name)
_VERSION_PACKAGES = (
    ("mujoco", "mujoco"),
    ("mjx", "mujoco-mjx"),
    ("jax", "jax"),
    ("warp", "warp-lang"),
    ("pybullet", "pybullet"),
    ("sb3", "stable-baselines3"),
    ("torch", "torch"),
    ("numpy", "numpy"),
)


def versions_dict(names: Iterable[str] | None = None) -> dict[str, str]:
    """Installed versions (python first); packages that are missing are left out."""
    out = {"python": platform.python_version()}
    for short, dist in _VERSION_PACKAGES:
        if names is not None and short not in names:
            continue
        try:
            out[short] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


def versions_str(names: Iterable[str] | None = None) -> str:
    """Compact ``name=version`` list separated by ``;`` (no commas: it is a CSV field)."""
    return ";".join(f"{k}={v}" for k, v in versions_dict(names).items())


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def cpu_label() -> str:
    """``cpu-2core``: the file-name label of this host's CPU."""
    return f"cpu-{os.cpu_count()}core"


def device_label(kind: str | None) -> str:
    """File label: ``cpu-2core`` or e.g. ``gpu-h100`` (one results file per device)."""
    if kind is None:
        return cpu_label()
    for short in ("h200", "h100", "a100", "l40s", "l4", "a10g", "v100", "t4"):
        if short in kind.lower().replace(" ", ""):
            return f"gpu-{short}"
    return "gpu-" + "".join(ch for ch in kind.lower() if ch.isalnum())[:16]


def cpu_device() -> str:
    """``cpu (2 cores, x86_64)``, as :func:`peghole_mjx.provenance.device` names a CPU."""
    return f"cpu ({os.cpu_count()} cores, {platform.machine()})"


def max_rss_mb() -> float:
    """Peak resident set size of this process image, MiB.

    Linux's ``VmHWM`` (``/proc/self/status``): ``getrusage``'s ``ru_maxrss`` is not used
    because it keeps the parent's peak across fork + exec, so a worker started by a large
    driver would report the driver's memory.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # not Linux


def load_average() -> tuple[float, float, float] | None:
    try:
        return os.getloadavg()
    except OSError:
        return None


def write_csv(path: Path | str, rows: Sequence[dict]) -> Path:
    """Write throughput rows with exactly :data:`COLUMNS` (extra keys are an error)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="raise", lineterminator="\n")
        w.writeheader()
        for r in rows:
            missing, extra = set(COLUMNS) - set(r), set(r) - set(COLUMNS)
            if missing or extra:
                raise ValueError(
                    f"row misses columns {sorted(missing)} / has extra {sorted(extra)}: {r}"
                )
            w.writerow(r)
    return path


def read_csv(path: Path | str) -> list[dict]:
    """Rows of a throughput CSV, numbers parsed (empty fields become None)."""
    out = []
    with Path(path).open(newline="") as f:
        for r in csv.DictReader(f):
            row: dict = dict(r)
            row["worlds"] = int(r["worlds"])
            for k in ("physics_steps_per_s", "env_steps_per_s", "compile_s", "peak_mem_mb"):
                row[k] = float(r[k]) if r[k] not in ("", None) else None
            out.append(row)
    return out


# ----------------------------------------------------------------------------- the law in NumPy
def rotvec_from_mat(R: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (NumPy twin of the JAX one; smooth at zero)."""
    s = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    sin = np.linalg.norm(s)
    cos = 0.5 * (np.trace(R) - 1.0)
    angle = np.arctan2(sin, cos)
    return s * (angle / sin if sin > 1e-9 else 1.0)


def rot_from_rotvec(v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula."""
    th = float(np.linalg.norm(v))
    if th < 1e-12:
        return np.eye(3)
    k = np.asarray(v) / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def rotz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def impedance_torque(
    J: np.ndarray,
    M: np.ndarray,
    bias: np.ndarray,
    q: np.ndarray,
    qvel: np.ndarray,
    x_C: np.ndarray,
    R: np.ndarray,
    target_pos: np.ndarray,
    target_mat: np.ndarray,
    target_vel: np.ndarray,
    stiffness: np.ndarray,
    damping_ratio: float,
    wrench_ff: np.ndarray,
    q_null: np.ndarray,
    null_gains: Sequence[float],
    max_wrench: Sequence[float],
    ctrl_lo: np.ndarray,
    ctrl_hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint torques and the clipped wrench of the Cartesian impedance law (NumPy).

    ``J`` (6, n): world translational and rotational Jacobian of the compliance centre ``x_C``
    on the peg body, ``M`` (n, n) joint-space inertia, ``bias`` (n,) gravity + Coriolis
    torques, ``R`` the peg body's rotation. The rest as in
    :class:`peghole_mjx.control.impedance.ImpedanceController` (its module docstring has the
    equations).
    """
    Rc = target_mat
    n = J.shape[1]
    J_loc = np.vstack([Rc.T @ J[:3], Rc.T @ J[3:]])
    e_p = Rc.T @ (target_pos - x_C)
    e_r = Rc.T @ rotvec_from_mat(Rc @ R.T)
    err = np.concatenate([e_p, e_r])
    v_loc = J_loc @ qvel
    v_des = np.concatenate([Rc.T @ target_vel, np.zeros(3)])
    Minv = np.linalg.inv(M)
    Lam = np.linalg.inv(J_loc @ Minv @ J_loc.T + 1e-9 * np.eye(6))
    K = np.asarray(stiffness, float)
    D = 2.0 * damping_ratio * np.sqrt(K * np.clip(np.diag(Lam), 0.0, None))
    w_raw = K * err + D * (v_des - v_loc) + wrench_ff
    cap = np.asarray(max_wrench, float)
    w = np.clip(w_raw, -cap, cap)
    Jbar = Minv @ J_loc.T @ Lam
    NT = np.eye(n) - J_loc.T @ Jbar.T
    tau0 = null_gains[0] * (q_null - q) - null_gains[1] * qvel
    tau = J_loc.T @ w + bias + NT @ tau0
    return np.clip(tau, ctrl_lo, ctrl_hi), w
