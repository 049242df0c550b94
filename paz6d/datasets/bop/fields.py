"""Checked access to the fields of BOP JSON files; every error names the file, entry and field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from paz6d.backend.checks import short_repr
from paz6d.backend.files import load_json


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


def entries_by_id(path: Path, kind: str = "image") -> dict[int, object]:
    """A JSON object keyed by numeric ids (``"3": ...``) as ``{3: ...}``, sorted by id; ``kind``
    (``"image"`` or ``"object"``) names the ids in error messages."""
    data = load_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected an object keyed by {kind} id")
    entries = {}
    for key, value in data.items():
        if not str(key).isdigit():
            raise ValueError(f"{path}: key {key!r} is not an {kind} id")
        entries[int(key)] = value
    return dict(sorted(entries.items()))
