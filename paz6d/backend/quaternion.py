"""Unit quaternions, scalar-last ``(x, y, z, w)`` (the scipy/ROS order), vectorized over ``(..., 4)``.

All functions accept leading batch dimensions. ``q`` and ``-q`` encode the same rotation.
Example:
    >>> import numpy as np
    >>> from paz6d.backend import quaternion
    >>> q = quaternion.from_rotation_vector([0.0, 0.0, np.pi / 2])
    >>> np.round(quaternion.rotate(q, [1.0, 0.0, 0.0]), 6)
    array([0., 1., 0.])
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.checks import as_array, as_rotation_matrix, as_unit_quaternion

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def normalize(q) -> np.ndarray:
    """Scales ``(..., 4)`` quaternions to unit norm; raises on zero-norm input."""
    q = as_array(q, "q", (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("q: cannot normalize a zero quaternion")
    return q / norm


def canonical(q) -> np.ndarray:
    """Returns the representative of ``±q`` with ``w >= 0`` (ties broken on x, y, z)."""
    q = as_unit_quaternion(q, "q")
    sign = np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return q * sign


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of shape ``(*shape, 4)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def to_rotation_matrix(q) -> np.ndarray:
    """``(..., 4)`` unit quaternions to ``(..., 3, 3)`` rotation matrices."""
    q = as_unit_quaternion(q, "q")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    matrix = np.empty(q.shape[:-1] + (3, 3))
    matrix[..., 0, 0] = 1 - 2 * (yy + zz)
    matrix[..., 0, 1] = 2 * (xy - wz)
    matrix[..., 0, 2] = 2 * (xz + wy)
    matrix[..., 1, 0] = 2 * (xy + wz)
    matrix[..., 1, 1] = 1 - 2 * (xx + zz)
    matrix[..., 1, 2] = 2 * (yz - wx)
    matrix[..., 2, 0] = 2 * (xz - wy)
    matrix[..., 2, 1] = 2 * (yz + wx)
    matrix[..., 2, 2] = 1 - 2 * (xx + yy)
    return matrix


def from_rotation_matrix(matrix) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices to canonical (``w >= 0``) unit quaternions ``(..., 4)``.

    Uses the numerically stable branch choice (largest of w, x, y, z) per element.
    """
    matrix = as_rotation_matrix(matrix, "matrix")
    m = matrix
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    # 4 * (component)^2 for w, x, y, z respectively.
    candidates = np.stack([1 + trace,
                           1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                           1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
                           1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2]], axis=-1)
    choice = np.argmax(candidates, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    r = np.sqrt(np.maximum(np.take_along_axis(candidates, choice[..., None], -1)[..., 0], 1e-300))
    s = 0.5 / r
    half = 0.5 * r
    wz = (m[..., 1, 0] - m[..., 0, 1]) * s
    wy = (m[..., 0, 2] - m[..., 2, 0]) * s
    wx = (m[..., 2, 1] - m[..., 1, 2]) * s
    xy = (m[..., 0, 1] + m[..., 1, 0]) * s
    xz = (m[..., 0, 2] + m[..., 2, 0]) * s
    yz = (m[..., 1, 2] + m[..., 2, 1]) * s
    branches = [np.stack([wx, wy, wz, half], -1),
                np.stack([half, xy, xz, wx], -1),
                np.stack([xy, half, yz, wy], -1),
                np.stack([xz, yz, half, wz], -1)]
    for index, branch in enumerate(branches):
        selected = choice == index
        q[selected] = branch[selected]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def to_rotation_vector(q) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` to rotation vectors ``(..., 3)`` (axis × angle, angle in [0, π])."""
    q = canonical(q)
    vector = q[..., :3]
    sin_half = np.linalg.norm(vector, axis=-1)
    angle = 2 * np.arctan2(sin_half, q[..., 3])
    small = sin_half < 1e-8
    # angle / sin(angle/2) -> 2 as angle -> 0 (series 2 + angle^2/12).
    scale = np.where(small, 2.0 + angle ** 2 / 12.0, angle / np.where(small, 1.0, sin_half))
    return vector * scale[..., None]


def from_rotation_vector(vector) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` (axis × angle in radians) to unit quaternions ``(..., 4)``."""
    vector = as_array(vector, "vector", (3,))
    angle = np.linalg.norm(vector, axis=-1)
    small = angle < 1e-8
    # sin(angle/2)/angle -> 1/2 - angle^2/48 as angle -> 0.
    scale = np.where(small, 0.5 - angle ** 2 / 48.0, np.sin(angle / 2) / np.where(small, 1.0, angle))
    return np.concatenate([vector * scale[..., None], np.cos(angle / 2)[..., None]], axis=-1)


def _axis_quaternion(axis: str, angle: np.ndarray) -> np.ndarray:
    q = np.zeros(angle.shape + (4,))
    q[..., _AXIS_INDEX[axis]] = np.sin(angle / 2)
    q[..., 3] = np.cos(angle / 2)
    return q


def _check_axes(axes: str) -> tuple[str, bool]:
    if len(axes) != 3 or axes.lower() not in {a + b + c for a in "xyz" for b in "xyz" for c in "xyz"
                                              if a != b and b != c}:
        raise ValueError(f"axes: expected three of 'xyz' with no axis repeated consecutively, "
                         f"lower case for extrinsic or upper case for intrinsic, got {axes!r}")
    if not (axes.islower() or axes.isupper()):
        raise ValueError(f"axes: mix of intrinsic (upper) and extrinsic (lower) axes in {axes!r}")
    return axes.lower(), axes.isupper()


def from_euler(angles, axes: str = "xyz") -> np.ndarray:
    """Euler angles ``(..., 3)`` in radians to quaternions.

    ``axes`` follows scipy: lower case = extrinsic (fixed frame), upper case = intrinsic (moving
    frame), e.g. ``"xyz"`` rotates about fixed x, then y, then z.
    """
    angles = as_array(angles, "angles", (3,))
    order, intrinsic = _check_axes(axes)
    parts = [_axis_quaternion(axis, angles[..., i]) for i, axis in enumerate(order)]
    if intrinsic:
        return multiply(multiply(parts[0], parts[1]), parts[2])
    return multiply(multiply(parts[2], parts[1]), parts[0])


def to_euler(q, axes: str = "xyz") -> np.ndarray:
    """Quaternions to Euler angles ``(..., 3)`` in radians (same ``axes`` convention as ``from_euler``).

    Angles lie in ``(-π, π]`` for the first/third and ``[-π/2, π/2]`` (Tait-Bryan) or ``[0, π]``
    (proper Euler) for the second; at gimbal lock the third angle is set to 0.
    """
    order, intrinsic = _check_axes(axes)
    matrix = to_rotation_matrix(q)
    if not intrinsic:
        # extrinsic abc == intrinsic cba with reversed angle order.
        return _intrinsic_euler_from_matrix(matrix, order[::-1])[..., ::-1]
    return _intrinsic_euler_from_matrix(matrix, order)


def _intrinsic_euler_from_matrix(matrix: np.ndarray, order: str) -> np.ndarray:
    i, j, k = (_AXIS_INDEX[a] for a in order)
    proper = i == k
    if proper:
        k = 3 - i - j
    parity = 1.0 if (j - i) % 3 == 1 else -1.0
    angles = np.empty(matrix.shape[:-2] + (3,))
    if proper:
        second = np.arccos(np.clip(matrix[..., i, i], -1.0, 1.0))
        locked = np.abs(np.sin(second)) < 1e-9
        first = np.arctan2(matrix[..., j, i], -parity * matrix[..., k, i])
        third = np.arctan2(matrix[..., i, j], parity * matrix[..., i, k])
        lock_first = np.arctan2(parity * -matrix[..., j, k], matrix[..., j, j])
        first = np.where(locked, np.where(matrix[..., i, i] > 0, lock_first, -lock_first), first)
        third = np.where(locked, 0.0, third)
    else:
        second = np.arcsin(np.clip(parity * matrix[..., i, k], -1.0, 1.0))
        locked = np.abs(np.cos(second)) < 1e-9
        first = np.arctan2(-parity * matrix[..., j, k], matrix[..., k, k])
        third = np.arctan2(-parity * matrix[..., i, j], matrix[..., i, i])
        lock_first = np.arctan2(parity * matrix[..., k, j], matrix[..., j, j])
        first = np.where(locked, lock_first, first)
        third = np.where(locked, 0.0, third)
    angles[..., 0], angles[..., 1], angles[..., 2] = first, second, third
    return angles


def multiply(q1, q2) -> np.ndarray:
    """Hamilton product ``q1 ⊗ q2`` (apply ``q2`` first, then ``q1``), broadcast over batches."""
    q1 = as_array(q1, "q1", (4,))
    q2 = as_array(q2, "q2", (4,))
    x1, y1, z1, w1 = np.moveaxis(q1, -1, 0)
    x2, y2, z2, w2 = np.moveaxis(q2, -1, 0)
    return np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
                     w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2], axis=-1)


def conjugate(q) -> np.ndarray:
    """Conjugate ``(-x, -y, -z, w)``."""
    q = as_array(q, "q", (4,))
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def inverse(q) -> np.ndarray:
    """Inverse rotation of unit quaternions (their conjugate)."""
    return conjugate(as_unit_quaternion(q, "q"))


def rotate(q, points) -> np.ndarray:
    """Rotates ``points`` ``(..., 3)`` by unit quaternions ``q`` ``(..., 4)`` (broadcast).

    Uses ``p' = p + 2w (v × p) + 2 v × (v × p)``, which avoids building matrices.
    """
    q = as_unit_quaternion(q, "q")
    points = as_array(points, "points", (3,))
    vector = q[..., :3]
    w = q[..., 3:4]
    cross = 2.0 * np.cross(vector, points)
    return points + w * cross + np.cross(vector, cross)


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc; ``t`` in [0, 1] broadcasts.

    Returns ``(..., 4)`` unit quaternions; ``t=0`` gives ``q0`` and ``t=1`` gives ``±q1``.
    """
    q0 = as_unit_quaternion(q0, "q0")
    q1 = as_unit_quaternion(q1, "q1")
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.clip(np.abs(dot), -1.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    safe = np.where(near, 1.0, sin_theta)
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(near, t, np.sin(t * theta) / safe)
    result = w0 * q0 + w1 * q1
    return result / np.linalg.norm(result, axis=-1, keepdims=True)


def angle_between(q0, q1) -> np.ndarray:
    """Geodesic angle (radians, in [0, π]) of the rotation taking ``q0`` to ``q1``."""
    q0 = as_unit_quaternion(q0, "q0")
    q1 = as_unit_quaternion(q1, "q1")
    dot = np.abs(np.sum(q0 * q1, axis=-1))
    # 2*atan2(|q0 x q1 part|, |dot|) is accurate for tiny angles where arccos is not.
    relative = multiply(conjugate(q0), q1)
    return 2.0 * np.arctan2(np.linalg.norm(relative[..., :3], axis=-1), dot)


def random(n: int | None = None, seed: int | np.random.Generator | None = None) -> np.ndarray:
    """Uniformly distributed random rotations on SO(3) (Shoemake's method).

    Returns ``(n, 4)`` quaternions, or ``(4,)`` when ``n`` is None.
    """
    generator = np.random.default_rng(seed)
    count = 1 if n is None else int(n)
    if count < 0:
        raise ValueError(f"n: expected a non-negative count, got {n}")
    u1, u2, u3 = generator.random((3, count))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    q = np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                  b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)], axis=-1)
    return q[0] if n is None else q
