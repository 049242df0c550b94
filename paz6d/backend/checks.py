"""Input validators shared by every backend: one place for shape/finiteness/unit-norm checks.

Each validator returns the input as a float64 numpy array and raises ``ValueError`` with a
message naming the argument and the expected shape when the input is bad.
"""

from __future__ import annotations

import numpy as np

UNIT_NORM_TOLERANCE = 1e-6


def as_array(value, name: str, trailing_shape: tuple[int, ...], min_leading: int = 0) -> np.ndarray:
    """Converts ``value`` to float64 with shape ``(..., *trailing_shape)`` and finite entries.

    Args:
        value: array-like input.
        name: argument name used in error messages.
        trailing_shape: required trailing dimensions, e.g. ``(4,)`` for quaternions.
        min_leading: minimum number of leading (batch) dimensions.
    """
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected a numeric array of shape (..., "
                         f"{', '.join(map(str, trailing_shape))}), got {type(value).__name__}") from error
    expected = "(..., " + ", ".join(map(str, trailing_shape)) + ")"
    count = len(trailing_shape)
    if array.ndim < count + min_leading or array.shape[array.ndim - count:] != tuple(trailing_shape):
        raise ValueError(f"{name}: expected shape {expected}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return array


def as_points(value, name: str, dimension: int = 3, min_count: int = 1) -> np.ndarray:
    """Returns an ``(N, dimension)`` float64 array with ``N >= min_count`` finite rows."""
    array = as_array(value, name, (dimension,))
    if array.ndim != 2:
        raise ValueError(f"{name}: expected shape (N, {dimension}), got {array.shape}")
    if len(array) < min_count:
        raise ValueError(f"{name}: expected at least {min_count} points of shape (N, {dimension}), "
                         f"got {len(array)}")
    return array


def as_unit_quaternion(value, name: str = "quaternion") -> np.ndarray:
    """Returns a ``(..., 4)`` scalar-last quaternion array after checking unit norm."""
    quaternion = as_array(value, name, (4,))
    norms = np.linalg.norm(quaternion, axis=-1)
    if np.any(np.abs(norms - 1.0) > UNIT_NORM_TOLERANCE):
        worst = norms.flat[np.argmax(np.abs(norms - 1.0))]
        raise ValueError(f"{name}: expected unit quaternions (x, y, z, w), found norm {worst:.6g}; "
                         "normalize with paz6d.backend.quaternion.normalize first")
    return quaternion


def as_rotation_matrix(value, name: str = "rotation_matrix", tolerance: float = 1e-5) -> np.ndarray:
    """Returns a ``(..., 3, 3)`` array after checking it is orthonormal with determinant +1."""
    matrix = as_array(value, name, (3, 3))
    identity_error = np.abs(np.swapaxes(matrix, -1, -2) @ matrix - np.eye(3)).max(axis=(-1, -2))
    determinant = np.linalg.det(matrix)
    if np.any(identity_error > tolerance) or np.any(determinant <= 0):
        raise ValueError(f"{name}: expected orthonormal rotation matrices with det +1 "
                         f"(max |R^T R - I| = {np.max(identity_error):.3g}, min det = {np.min(determinant):.3g})")
    return matrix


def as_camera_matrix(value, name: str = "K") -> np.ndarray:
    """Returns a 3x3 pinhole intrinsics matrix with positive focal lengths."""
    matrix = as_array(value, name, (3, 3))
    if matrix.ndim != 2:
        raise ValueError(f"{name}: expected shape (3, 3), got {matrix.shape}")
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0 or not np.allclose(matrix[2], [0, 0, 1]):
        raise ValueError(f"{name}: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {matrix.tolist()}")
    return matrix
