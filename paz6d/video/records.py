"""The JSON-lines stream of a video run: one line per frame, each message as its ``to_dict()``.

A line is a JSON object::

    {"frame": 12, "timestamp_s": 0.4, "latency_ms": 31.5, "file": "000012.png",
     "results": [{"box": {"type": "Box2D", "x_min": 210.4, ..., "class_name": "obj_000005"},
                  "pose": {"type": "Pose6D", "quaternion": [x, y, z, w], "translation": [tx, ty, tz], ...}}]}

``file`` is the image's file name for a folder's frames (absent for a video or a device). ``results`` holds
one object per thing the pipeline found. Its values are messages
(:class:`~paz6d.abstract.Box2D`, :class:`~paz6d.abstract.Pose6D`, :class:`~paz6d.abstract.Keypoints2D`,
:class:`~paz6d.abstract.Keypoints3D`), written as ``{"type": <class name>, **message.to_dict()}``, or plain
values (a label, a list of class scores, a re-projection error). :func:`result_entries` turns what a
pipeline returns into these objects, naming each value by its type (``box``, ``pose``, ``keypoints2d``,
``keypoints3d``, ``label``, ``scores``, ``value``) or by its field name (a dataclass such as
:class:`~paz6d.faces.head_pose.HeadDetection`). :meth:`FrameRecord.from_dict` reads a line back
into messages (``from_dict`` of each), so another process gets the same objects.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from paz6d.abstract import Box2D, Keypoints2D, Keypoints3D, Pose6D
from paz6d.backend.files import read_input_text

#: Message classes by the ``type`` written in the stream.
MESSAGE_TYPES = {cls.__name__: cls for cls in (Box2D, Pose6D, Keypoints2D, Keypoints3D)}
#: Entry names of values found in a tuple, by type.
ENTRY_NAMES = {Box2D: "box", Pose6D: "pose", Keypoints2D: "keypoints2d", Keypoints3D: "keypoints3d"}


def _name_of(value: Any) -> str:
    for cls, name in ENTRY_NAMES.items():
        if isinstance(value, cls):
            return name
    if isinstance(value, str):
        return "label"
    if isinstance(value, (np.ndarray, list, tuple)):
        return "scores"
    return "value"


def entry_of(item: Any) -> dict[str, Any]:
    """One thing a pipeline found as ``{name: value}``: a dict as is, a dataclass by its fields, a message
    or a tuple by the types of its values (a repeated name gets ``_1``, ``_2``...)."""
    if isinstance(item, dict):
        return dict(item)
    if dataclasses.is_dataclass(item) and not isinstance(item, tuple(MESSAGE_TYPES.values())):
        return {field.name: getattr(item, field.name) for field in dataclasses.fields(item)}
    values = item if isinstance(item, tuple) else (item,)
    entry: dict[str, Any] = {}
    for value in values:
        name = base = _name_of(value)
        count = 1
        while name in entry:
            name, count = f"{base}_{count}", count + 1
        entry[name] = value
    return entry


def result_entries(output: Any) -> list[dict[str, Any]]:
    """A pipeline's output as a list of entries (:func:`entry_of`): a list or tuple of things found, one
    message, a dict of named values (one entry) or ``None`` (nothing found)."""
    if output is None:
        return []
    if isinstance(output, list):
        return [entry_of(item) for item in output]
    return [entry_of(output)]


def encode(value: Any) -> Any:
    """A JSON-safe form of ``value``: messages tagged with their ``type``, arrays as lists, NaN/inf as ``None``.

    Raises:
        ValueError: a value of a type the stream cannot hold.
    """
    for name, cls in MESSAGE_TYPES.items():
        if isinstance(value, cls):
            return {"type": name, **encode(value.to_dict())}
    if isinstance(value, dict):
        return {str(key): encode(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode(item) for item in value]
    if isinstance(value, np.ndarray):
        return encode(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (str, int, bool)):
        return value
    raise ValueError(f"results: cannot write a {type(value).__name__} to the JSON-lines stream (expected messages, "
                     "numbers, strings, lists or dicts)")


def decode(value: Any) -> Any:
    """Inverse of :func:`encode`: ``{"type": "Pose6D", ...}`` becomes a :class:`~paz6d.abstract.Pose6D`
    (its ``from_dict``); arrays stay lists."""
    if isinstance(value, dict):
        kind = value.get("type")
        if kind in MESSAGE_TYPES:
            return MESSAGE_TYPES[kind].from_dict({key: item for key, item in value.items() if key != "type"})
        return {key: decode(item) for key, item in value.items()}
    if isinstance(value, list):
        return [decode(item) for item in value]
    return value


@dataclass(frozen=True)
class FrameRecord:
    """One line of the stream: the ``frame`` index, its ``timestamp_s``, the pipeline's ``latency_ms``,
    its ``results`` (entries of messages and values) and, for a folder's frames, the image ``file`` name
    (written only then)."""

    frame: int
    timestamp_s: float
    latency_ms: float
    results: list[dict[str, Any]] = field(default_factory=list)
    file: str | None = None

    def to_dict(self) -> dict[str, Any]:
        data = {"frame": self.frame, "timestamp_s": self.timestamp_s, "latency_ms": self.latency_ms}
        if self.file is not None:
            data["file"] = self.file
        return {**data, "results": encode(self.results)}

    @classmethod
    def from_dict(cls, data: dict) -> "FrameRecord":
        if not isinstance(data, dict):
            raise ValueError(f"FrameRecord.from_dict: expected a dict, got {type(data).__name__}")
        missing = [key for key in ("frame", "timestamp_s", "latency_ms", "results") if key not in data]
        if missing:
            raise ValueError(f"FrameRecord.from_dict: missing field(s) {missing}")
        if not isinstance(data["results"], list):
            raise ValueError("FrameRecord.from_dict: field 'results' must be a list of entries")
        file = data.get("file")
        if file is not None and not isinstance(file, str):
            raise ValueError(f"FrameRecord.from_dict: field 'file' must be a file name, got {type(file).__name__}")
        return cls(int(data["frame"]), float(data["timestamp_s"]), float(data["latency_ms"]),
                   [decode(entry) for entry in data["results"]], file)


def record_line(record: FrameRecord) -> str:
    """One JSON line (no line break) of ``record``."""
    return json.dumps(record.to_dict(), allow_nan=False)


def read_records(path: str | Path) -> Iterator[FrameRecord]:
    """The records of a JSON-lines file, in order.

    Raises:
        ValueError: a line that is not JSON or not a record (naming the file and line number).
    """
    path = Path(path)
    for number, line in enumerate(read_input_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            yield FrameRecord.from_dict(json.loads(line))
        except (ValueError, TypeError) as error:
            raise ValueError(f"{path}: line {number}: not a frame record ({error})") from error
