"""Checked access to the fields of BOP JSON files; every error names the file, entry and field."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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
        except (TypeError, ValueError) as error:
            raise ValueError(f"{where}: field {name!r} is not numeric") from error
        if array.size != size or not np.all(np.isfinite(array)):
            raise ValueError(f"{where}: field {name!r} must hold {size} finite numbers, got {array.size}")
        return array
    return value


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
