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

from paz6d.backend.checks import BLOCK_ROWS, as_array, as_rotation_matrix, as_unit_quaternion

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
    x, y, z, w = np.moveaxis(q, -1, 0)
    return q * _canonical_signs(x, y, z, w)[..., None]


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of shape ``(*shape, 4)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def _row_blocks(count: int):
    """Slices of at most ``BLOCK_ROWS`` rows: the elementwise formulas below run block by block
    so that their temporaries stay in the CPU cache (faster on large batches: ``benchmarks/backend.py``)."""
    return (slice(start, start + BLOCK_ROWS) for start in range(0, count, BLOCK_ROWS))


def _canonical_signs(x: np.ndarray, y: np.ndarray, z: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``±1`` per quaternion making ``w > 0``, or for ``w == 0`` the first non-zero of x, y, z."""
    signs = np.copysign(1.0, w)
    ties = w == 0
    if np.any(ties):
        leading = np.where(x[ties] != 0, x[ties], np.where(y[ties] != 0, y[ties], z[ties]))
        signs[ties] = np.where(leading < 0, -1.0, 1.0)
    return signs


def to_rotation_matrix(q) -> np.ndarray:
    """``(..., 4)`` unit quaternions to ``(..., 3, 3)`` rotation matrices."""
    q = as_unit_quaternion(q, "q")
    flat = q.reshape(-1, 4)
    matrix = np.empty((len(flat), 3, 3))
    for block in _row_blocks(len(flat)):
        x, y, z, w = flat[block].T
        out = matrix[block]
        x2, y2, z2 = 2.0 * x, 2.0 * y, 2.0 * z
        xx, yy, zz = x * x2, y * y2, z * z2
        xy, xz, yz = x * y2, x * z2, y * z2
        wx, wy, wz = w * x2, w * y2, w * z2
        np.subtract(1.0, yy + zz, out=out[:, 0, 0])
        np.subtract(xy, wz, out=out[:, 0, 1])
        np.add(xz, wy, out=out[:, 0, 2])
        np.add(xy, wz, out=out[:, 1, 0])
        np.subtract(1.0, xx + zz, out=out[:, 1, 1])
        np.subtract(yz, wx, out=out[:, 1, 2])
        np.subtract(xz, wy, out=out[:, 2, 0])
        np.add(yz, wx, out=out[:, 2, 1])
        np.subtract(1.0, xx + yy, out=out[:, 2, 2])
    return matrix.reshape(q.shape[:-1] + (3, 3))


def from_rotation_matrix(matrix) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices to canonical unit quaternions ``(..., 4)`` (see :func:`canonical`).

    Per matrix, the formula is built around a component whose square is at least 1/4, chosen
    with three comparisons (M. Day, "Converting a rotation matrix to a quaternion", 2015), so
    it is accurate for every angle; the result is normalized.
    """
    matrix = as_rotation_matrix(matrix, "matrix")
    flat = matrix.reshape(-1, 9)
    q = np.empty((len(flat), 4))
    for block in _row_blocks(len(flat)):
        m00, m01, m02, m10, m11, m12, m20, m21, m22 = flat[block].T
        # 4 w^2, 4 x^2, 4 y^2, 4 z^2 and the products 4 w x, 4 w y, 4 w z, 4 x y, 4 x z, 4 y z.
        ww, xx = 1.0 + m00 + m11 + m22, 1.0 + m00 - m11 - m22
        yy, zz = 1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22
        wx, wy, wz = m21 - m12, m02 - m20, m10 - m01
        xy, xz, yz = m01 + m10, m02 + m20, m12 + m21
        # Branches x, y (z^2 < 1/4 side) and z, w; each candidate is 4 * q_k * (x, y, z, w).
        xy_side, x_branch, z_branch = m22 < 0, m00 > m11, m00 < -m11
        x = np.where(xy_side, np.where(x_branch, xx, xy), np.where(z_branch, xz, wx))
        y = np.where(xy_side, np.where(x_branch, xy, yy), np.where(z_branch, yz, wy))
        z = np.where(xy_side, np.where(x_branch, xz, yz), np.where(z_branch, zz, wz))
        w = np.where(xy_side, np.where(x_branch, wx, wy), np.where(z_branch, wz, ww))
        scale = _canonical_signs(x, y, z, w) / np.sqrt(x * x + y * y + z * z + w * w)
        out = q[block]
        np.multiply(x, scale, out=out[:, 0])
        np.multiply(y, scale, out=out[:, 1])
        np.multiply(z, scale, out=out[:, 2])
        np.multiply(w, scale, out=out[:, 3])
    return q.reshape(matrix.shape[:-2] + (4,))


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
    # hypot instead of norm: |v|^2 overflows for |v| > 1e154 rad, hypot does not.
    angle = np.hypot(np.hypot(vector[..., 0], vector[..., 1]), vector[..., 2])
    small = angle < 1e-8
    # The quaternion has period 4*pi in the angle; reducing first keeps sin/cos exact for huge angles.
    half = np.mod(angle, 4.0 * np.pi) / 2.0
    # sin(angle/2)/angle -> 1/2 - angle^2/48 as angle -> 0.
    small_angle = np.where(small, angle, 0.0)  # keeps the series term finite for huge angles
    scale = np.where(small, 0.5 - small_angle ** 2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([vector * scale[..., None], np.cos(half)[..., None]], axis=-1)


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

    Uses ``p' = p + w t + v × t`` with ``t = 2 v × p``, which avoids building matrices.
    """
    q = as_unit_quaternion(q, "q")
    points = as_array(points, "points", (3,))
    shape = np.broadcast_shapes(q.shape[:-1], points.shape[:-1])
    if q.ndim == 1:  # one rotation for every point: a single matrix product
        return points @ to_rotation_matrix(q).T
    flat_q = np.broadcast_to(q, shape + (4,)).reshape(-1, 4)
    flat_points = np.broadcast_to(points, shape + (3,)).reshape(-1, 3)
    rotated = np.empty((len(flat_points), 3))
    for block in _row_blocks(len(flat_points)):
        x, y, z, w = flat_q[block].T
        px, py, pz = flat_points[block].T
        tx, ty, tz = 2.0 * (y * pz - z * py), 2.0 * (z * px - x * pz), 2.0 * (x * py - y * px)
        out = rotated[block]
        np.add(px + w * tx, y * tz - z * ty, out=out[:, 0])
        np.add(py + w * ty, z * tx - x * tz, out=out[:, 1])
        np.add(pz + w * tz, x * ty - y * tx, out=out[:, 2])
    return rotated.reshape(shape + (3,))


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc; ``t`` in [0, 1] broadcasts.

    Returns ``(..., 4)`` unit quaternions; ``t=0`` gives ``q0`` and ``t=1`` gives ``±q1``.
    """
    q0 = as_unit_quaternion(q0, "q0")
    q1 = as_unit_quaternion(q1, "q1")
    t = np.asarray(t, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError("t: expected finite interpolation parameters (0 gives q0, 1 gives q1), got NaN or inf")
    t = t[..., None]
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
