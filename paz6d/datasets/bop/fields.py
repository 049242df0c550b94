"""Checked access to the fields of BOP JSON files; every error names the file, entry and field.

The field checks themselves (:func:`required_field`, :func:`integer_field`, :func:`number_field`)
are generic and live in :mod:`paz6d.backend.checks`; they are re-exported here for the BOP readers.
"""

from __future__ import annotations

from pathlib import Path

from paz6d.backend.checks import integer_field, number_field, required_field
from paz6d.backend.files import load_json

__all__ = ["BOX_FIELDS", "box_field", "entries_by_id", "integer_field", "number_field", "required_field"]

#: The ground-truth boxes of ``scene_gt_info.json`` by short name: the whole projected object, its visible part.
BOX_FIELDS = {"obj": "bbox_obj", "visib": "bbox_visib"}


def box_field(box: str, name: str = "box") -> str:
    """The ``scene_gt_info.json`` field of ``box`` (a key of :data:`BOX_FIELDS`); ``name`` names the
    argument in the ValueError for any other value."""
    if box not in BOX_FIELDS:
        raise ValueError(f"{name}: expected one of {sorted(BOX_FIELDS)}, got {box!r}")
    return BOX_FIELDS[box]


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
