"""Rigid transforms in SE(3) as ``(..., 4, 4)`` homogeneous matrices.

Naming follows the frames: ``T_a2b`` maps coordinates in frame ``a`` to frame ``b``
(``x_b = R @ x_a + t``); ``compose(T_b2c, T_a2b) == T_a2c``.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend import quaternion
from paz6d.backend.checks import as_array, as_rotation_matrix


def from_rotation_translation(rotation_matrix, translation) -> np.ndarray:
    """Builds ``(..., 4, 4)`` poses from ``(..., 3, 3)`` rotations and ``(..., 3)`` translations."""
    rotation_matrix = as_rotation_matrix(rotation_matrix, "rotation_matrix")
    translation = as_array(translation, "translation", (3,))
    shape = np.broadcast_shapes(rotation_matrix.shape[:-2], translation.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = rotation_matrix
    T[..., :3, 3] = translation
    T[..., 3, 3] = 1.0
    return T


def as_pose_matrix(T, name: str = "T") -> np.ndarray:
    """Validates ``(..., 4, 4)`` rigid transforms (orthonormal rotation, last row ``[0, 0, 0, 1]``)."""
    T = as_array(T, name, (4, 4))
    if not np.allclose(T[..., 3, :], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"{name}: expected last row [0, 0, 0, 1] of a rigid transform")
    as_rotation_matrix(T[..., :3, :3], f"{name}[..., :3, :3]")
    return T


def to_rotation_translation(T) -> tuple[np.ndarray, np.ndarray]:
    """Splits ``(..., 4, 4)`` poses into rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    T = as_pose_matrix(T)
    return T[..., :3, :3].copy(), T[..., :3, 3].copy()


def compose(T_b2c, T_a2b) -> np.ndarray:
    """Chains two transforms: returns ``T_a2c = T_b2c @ T_a2b`` (apply ``T_a2b`` first)."""
    return as_pose_matrix(T_b2c, "T_b2c") @ as_pose_matrix(T_a2b, "T_a2b")


def invert(T) -> np.ndarray:
    """Inverse rigid transform using ``R^T`` (no general matrix inversion)."""
    rotation, translation = to_rotation_translation(T)
    rotation_inverse = np.swapaxes(rotation, -1, -2)
    translation_inverse = -np.einsum("...ij,...j->...i", rotation_inverse, translation)
    return from_rotation_translation(rotation_inverse, translation_inverse)


def apply(T, points) -> np.ndarray:
    """Applies ``T`` ``(4, 4)`` (or ``(..., 4, 4)`` broadcast) to points ``(..., N, 3)``."""
    T = as_pose_matrix(T)
    points = as_array(points, "points", (3,))
    rotation = T[..., :3, :3]
    translation = T[..., None, :3, 3]
    return np.einsum("...ij,...nj->...ni", rotation, points) + translation if T.ndim > 2 \
        else points @ rotation.T + T[:3, 3]


def interpolate(T0, T1, t) -> np.ndarray:
    """Interpolates poses: slerp on rotation, linear on translation; ``t`` in [0, 1] broadcasts."""
    rotation0, translation0 = to_rotation_translation(T0)
    rotation1, translation1 = to_rotation_translation(T1)
    t = np.asarray(t, dtype=np.float64)
    q = quaternion.slerp(quaternion.from_rotation_matrix(rotation0),
                         quaternion.from_rotation_matrix(rotation1), t)
    translation = (1.0 - t[..., None]) * translation0 + t[..., None] * translation1
    return from_rotation_translation(quaternion.to_rotation_matrix(q), translation)
