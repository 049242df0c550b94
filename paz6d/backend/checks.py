"""Input validators shared by every backend: one place for shape/finiteness/unit-norm checks.

Each validator returns the input as a float64 numpy array and raises ``ValueError`` with a
message naming the argument and the expected shape when the input is bad.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

UNIT_NORM_TOLERANCE = 1e-6


#: Rows per block when validating large batches: keeps the temporaries in the CPU cache.
BLOCK_ROWS = 8192


def short_repr(value, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, for values quoted in error messages (an
    input file may hold megabytes in one value; long strings, lists and dicts are described by
    their length)."""
    if isinstance(value, (str, bytes, list, tuple, dict)) and len(value) > limit:
        return f"a {type(value).__name__} of length {len(value)}"
    try:
        text = repr(value)
    except ValueError:  # an int with more digits than Python converts to text
        return f"a {type(value).__name__} too long to print"
    return text if len(text) <= limit else text[:limit] + "..."


def _as_shaped_array(value, name: str, trailing_shape: tuple[int, ...], min_leading: int = 0) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as error:
        raise ValueError(f"{name}: expected a numeric array of shape (..., "
                         f"{', '.join(map(str, trailing_shape))}), got {type(value).__name__}") from error
    expected = "(..., " + ", ".join(map(str, trailing_shape)) + ")"
    count = len(trailing_shape)
    if array.ndim < count + min_leading or array.shape[array.ndim - count:] != tuple(trailing_shape):
        raise ValueError(f"{name}: expected shape {expected}, got {array.shape}")
    return array


def _require_finite(array: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite values")


def as_array(value, name: str, trailing_shape: tuple[int, ...], min_leading: int = 0) -> np.ndarray:
    """Converts ``value`` to float64 with shape ``(..., *trailing_shape)`` and finite entries.

    Args:
        value: array-like input.
        name: argument name used in error messages.
        trailing_shape: required trailing dimensions, e.g. ``(4,)`` for quaternions.
        min_leading: minimum number of leading (batch) dimensions.
    """
    array = _as_shaped_array(value, name, trailing_shape, min_leading)
    _require_finite(array, name)
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
    quaternion = _as_shaped_array(value, name, (4,))
    squared_norms = np.einsum("...i,...i->...", quaternion, quaternion)
    low, high = (1.0 - UNIT_NORM_TOLERANCE) ** 2, (1.0 + UNIT_NORM_TOLERANCE) ** 2
    # NaN fails both comparisons, so finiteness is only examined on the error path.
    if not np.all((squared_norms >= low) & (squared_norms <= high)):
        _require_finite(quaternion, name)
        norms = np.sqrt(squared_norms)
        worst = norms.flat[np.argmax(np.abs(norms - 1.0))]
        raise ValueError(f"{name}: expected unit quaternions (x, y, z, w), found norm {worst:.6g}; "
                         "normalize with paz6d.backend.quaternion.normalize first")
    return quaternion


def _rotation_defects(flat: np.ndarray) -> tuple[float, float]:
    """Largest ``|R^T R - I|`` entry and smallest determinant of ``(N, 3, 3)`` matrices (NaN-propagating)."""
    worst, smallest = 0.0, np.inf
    for start in range(0, len(flat), BLOCK_ROWS):
        m = np.ascontiguousarray(flat[start:start + BLOCK_ROWS].reshape(-1, 9).T)
        columns = ((m[0], m[3], m[6]), (m[1], m[4], m[7]), (m[2], m[5], m[8]))
        errors = []
        for i in range(3):
            for j in range(i, 3):
                dot = columns[i][0] * columns[j][0] + columns[i][1] * columns[j][1] + columns[i][2] * columns[j][2]
                errors.append(np.abs(dot - 1.0) if i == j else np.abs(dot))
        (a, b, c), (d, e, f), (g, h, k) = (m[0], m[1], m[2]), (m[3], m[4], m[5]), (m[6], m[7], m[8])
        determinant = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
        block_worst = np.max(np.maximum.reduce(errors))
        worst = block_worst if np.isnan(block_worst) else max(worst, float(block_worst))
        smallest = min(smallest, float(np.min(determinant)))
        if np.isnan(worst):
            break
    return worst, smallest


def as_rotation_matrix(value, name: str = "rotation_matrix", tolerance: float = 1e-5) -> np.ndarray:
    """Returns a ``(..., 3, 3)`` array after checking it is orthonormal with determinant +1."""
    matrix = _as_shaped_array(value, name, (3, 3))
    identity_error, determinant = _rotation_defects(matrix.reshape(-1, 3, 3))
    if not identity_error <= tolerance or not determinant > 0:
        _require_finite(matrix, name)
        raise ValueError(f"{name}: expected orthonormal rotation matrices with det +1 "
                         f"(max |R^T R - I| = {identity_error:.3g}, min det = {determinant:.3g})")
    return matrix


def as_camera_matrix(value, name: str = "K") -> np.ndarray:
    """Returns a 3x3 pinhole intrinsics matrix with positive focal lengths."""
    matrix = as_array(value, name, (3, 3))
    if matrix.ndim != 2:
        raise ValueError(f"{name}: expected shape (3, 3), got {matrix.shape}")
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0 or not np.allclose(matrix[2], [0, 0, 1]):
        raise ValueError(f"{name}: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got "
                         f"{matrix.tolist()}")
    return matrix


# ------------------------------------------------------------------ fields of parsed JSON files

def required_field(entry, name: str, where: str, size: int | None = None):
    """``entry[name]``; with ``size``, as a flat float64 array of ``size`` finite numbers.

    Raises:
        ValueError: ``"<where>: missing field 'name'"`` or a wrong count / non-numeric value.
    """
    if not isinstance(entry, dict) or name not in entry:
        raise ValueError(f"{where}: missing field {name!r}")
    value = entry[name]
    if size is not None:
        try:
            array = np.asarray(value, dtype=np.float64).ravel()
        except (TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"{where}: field {name!r} is not numeric, got {short_repr(value)}") from error
        if array.size != size or not np.all(np.isfinite(array)):
            found = f"{array.size} numbers" if array.size != size else "NaN or infinite values"
            raise ValueError(f"{where}: field {name!r} must hold {size} finite numbers, got {found}")
        return array
    return value


def unknown_fields(dataclass_type, data: dict) -> list[str]:
    """The keys of ``data``, sorted, that are not fields of ``dataclass_type`` (a dataclass)."""
    return sorted(set(data) - {item.name for item in dataclasses.fields(dataclass_type)})


def is_whole_number(value) -> bool:
    """Whether ``value`` is a number with an integer value (``3``, ``3.0``, ``np.int64(3)``), not ``True``,
    ``2.5``, ``"3"``, ``None`` or NaN."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return False
    return math.isfinite(value) and int(value) == value


def integer_field(entry, name: str, where: str, minimum: int = 0) -> int:
    """``entry[name]`` as an ``int`` ``>= minimum`` (a JSON integer, not ``1.5``, ``"1"`` or ``true``).

    Raises:
        ValueError: ``"<where>: missing field 'name'"`` or naming the field and the value found.
    """
    value = required_field(entry, name, where)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{where}: field {name!r} must be an integer >= {minimum}, got {short_repr(value)}")
    return value


def number_field(entry, name: str, where: str, minimum: float | None = None, maximum: float | None = None,
                 positive: bool = False) -> float:
    """``entry[name]`` as a finite ``float`` (within ``[minimum, maximum]``; ``> 0`` with ``positive``).

    Raises:
        ValueError: naming ``where``, the field and the value found.
    """
    value = required_field(entry, name, where)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or \
            (minimum is not None and value < minimum) or (maximum is not None and value > maximum) or \
            (positive and value <= 0):
        expected = "a positive number" if positive else "a finite number"
        if minimum is not None or maximum is not None:
            expected += f" in [{'-inf' if minimum is None else minimum}, {'inf' if maximum is None else maximum}]"
        raise ValueError(f"{where}: field {name!r} must be {expected}, got {short_repr(value)}")
    return float(value)


def check_depth(depth, name: str = "depth", shape: tuple[int, int] | None = None) -> np.ndarray:
    """A depth image as float32 ``(H, W)`` metres (0 = no data), checked.

    Args:
        name: the argument or file named in errors.
        shape: the required ``(H, W)`` (the image's), or ``None``.
    Raises:
        ValueError: not 2D, another size than ``shape``, NaN/infinite or negative values.
    """
    try:
        array = np.asarray(depth, dtype=np.float32)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected a numeric (H, W) depth image in metres, got {type(depth).__name__}") \
            from error
    if array.ndim != 2:
        raise ValueError(f"{name}: expected a depth image of shape (H, W) in metres, got shape {array.shape}")
    if shape is not None and array.shape != tuple(shape):
        raise ValueError(f"{name}: depth image is {array.shape[1]}x{array.shape[0]} pixels, expected "
                         f"{shape[1]}x{shape[0]} (the RGB image's size)")
    bad = int(np.count_nonzero(~np.isfinite(array)))
    if bad:
        raise ValueError(f"{name}: {bad} NaN or infinite depth values; expected finite metres (0 = no data)")
    if np.any(array < 0):
        raise ValueError(f"{name}: negative depth values; expected metres >= 0 (0 = no data)")
    return array
