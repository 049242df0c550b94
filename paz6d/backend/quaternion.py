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
_GIMBAL_LOCK_TOLERANCE = 1e-12  # rad; a larger one would cost round-trip accuracy of that size


def normalize(q) -> np.ndarray:
    """Scales ``(..., 4)`` quaternions to unit norm; raises on zero-norm input."""
    q = as_array(q, "q", (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("q: cannot normalize a zero quaternion")
    return q / norm


def canonical(q) -> np.ndarray:
    """Returns the representative of ``±q`` with ``w >= 0``; when ``w == 0`` the first non-zero
    of ``x, y, z`` is made positive."""
    q = as_unit_quaternion(q, "q")
    ordered = q[..., [3, 0, 1, 2]]
    leading = np.take_along_axis(ordered, np.argmax(ordered != 0, axis=-1)[..., None], axis=-1)
    return np.where(leading < 0, -q, q)


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

    First and third angles lie in ``[-π, π)``, the second in ``[-π/2, π/2]`` (Tait-Bryan) or
    ``[0, π]`` (proper Euler). At gimbal lock (second angle within 1e-12 rad of a singularity)
    the third angle is set to 0. Computed from the quaternion directly (Bernardes & Viollet,
    PLOS ONE 2022), which stays accurate next to the singularities where matrix-based
    formulas lose half of the digits.
    """
    order, intrinsic = _check_axes(axes)
    q = as_unit_quaternion(q, "q")
    # An intrinsic sequence equals the reversed extrinsic one with the angles reversed.
    i, j, k = (_AXIS_INDEX[axis] for axis in (order[::-1] if intrinsic else order))
    proper = i == k
    if proper:
        k = 3 - i - j
    sign = 1.0 if (j - i) % 3 == 1 else -1.0  # parity of the permutation (i, j, k)
    w = q[..., 3]
    if proper:
        a, b, c, d = w, q[..., i], q[..., j], sign * q[..., k]
    else:  # rotate the problem onto a proper sequence
        a, b, c, d = w - q[..., j], q[..., i] + sign * q[..., k], q[..., j] + w, sign * q[..., k] - q[..., i]
    second = 2.0 * np.arctan2(np.hypot(c, d), np.hypot(a, b))
    half_sum, half_difference = np.arctan2(b, a), np.arctan2(d, c)
    first, third = half_sum - half_difference, half_sum + half_difference
    near_zero = second <= _GIMBAL_LOCK_TOLERANCE
    locked = near_zero | (second >= np.pi - _GIMBAL_LOCK_TOLERANCE)
    # At lock only first + third (second = 0) or third - first (second = pi) is defined; the
    # angle that comes last in the caller's order is set to 0.
    if intrinsic:
        third = np.where(locked, np.where(near_zero, 2.0 * half_sum, 2.0 * half_difference), third)
        first = np.where(locked, 0.0, first)
    else:
        first = np.where(locked, np.where(near_zero, 2.0 * half_sum, -2.0 * half_difference), first)
        third = np.where(locked, 0.0, third)
    if not proper:
        third = sign * third
        second = second - np.pi / 2
    angles = np.stack([first, second, third], axis=-1)
    if intrinsic:
        angles = angles[..., ::-1]
    angles[..., 0::2] = np.mod(angles[..., 0::2] + np.pi, 2 * np.pi) - np.pi
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
