"""Rotations in NumPy (rotation vector = axis x angle, rad): the one NumPy twin of
:mod:`peghole_mjx.control.kinematics`'s JAX helpers, used by the NumPy impedance law
(:mod:`peghole_mjx.control.reference`) and the robot-side runner (:mod:`peghole_mjx.deploy`).

NumPy only, in the package's bottom layer (beside :mod:`peghole_mjx.deploy`, which may not
import :mod:`peghole_mjx.control`: that package loads JAX): the deploy side needs only NumPy
and ONNX Runtime.
"""

from __future__ import annotations

import numpy as np

from peghole_mjx.core.errors import UserInputError


def rotvec_from_mat(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, rad) of a rotation matrix; smooth at zero angle.

    ``R`` (..., 3, 3): any leading batch dimensions (one vector per matrix); float64 out."""
    R = np.asarray(R, np.float64)
    if R.shape[-2:] != (3, 3):
        raise UserInputError(f"rotvec_from_mat takes (..., 3, 3) matrices, got shape {R.shape}")
    s = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    sin = np.linalg.norm(s, axis=-1)
    cos = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    angle = np.arctan2(sin, cos)
    scale = np.where(sin > 1e-9, angle / np.maximum(sin, 1e-9), 1.0)
    return s * scale[..., None]


def rot_from_rotvec(v: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (rad), Rodrigues' formula."""
    v = np.asarray(v, np.float64)
    if v.shape != (3,):
        raise UserInputError(f"rot_from_rotvec takes one rotation vector (3,), got shape {v.shape}")
    th = float(np.linalg.norm(v))
    if th < 1e-12:
        return np.eye(3)
    k = v / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
