"""The poses of a JSON-lines stream as a BOP'19 results CSV, so that ``paz6d evaluate bop`` scores a video run.

Each entry with a :class:`~paz6d.abstract.Pose6D` of class ``obj_XXXXXX`` becomes one row: object id
``XXXXXX``, image id the frame's file name when it is a number (``000012.png`` -> 12, a BOP ``rgb``
folder's frames), else the frame index; score the entry's box score (its pose's without a box); time the
frame's latency in seconds. Other classes (faces, non-BOP names) are left out.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, Pose6D
from paz6d.datasets.bop import write_pose_results
from paz6d.video.records import FrameRecord

_BOP_CLASS = re.compile(r"^obj_(\d+)$")


def image_id(record: FrameRecord) -> int:
    """The BOP image id of a record: its file name's number (``000012.png`` -> 12), else its frame index."""
    stem = Path(record.file).stem if record.file else ""
    return int(stem) if stem.isdigit() else record.frame


def write_bop_results(records, path: str | Path, scene_id: int) -> int:
    """Writes the BOP-object poses of ``records`` (:class:`~paz6d.video.records.FrameRecord` s) as a BOP'19
    results CSV of scene ``scene_id``; returns the number of rows.

    Raises:
        ValueError: a negative ``scene_id``, or two frames with the same image id.
    """
    if scene_id < 0:
        raise ValueError(f"scene_id: expected a BOP scene id >= 0, got {scene_id}")
    rows: dict[str, list] = {"im_ids": [], "obj_ids": [], "scores": [], "rotations": [], "translations": [],
                             "times": []}
    seen: dict[int, int] = {}
    for record in records:
        im_id = image_id(record)
        if im_id in seen:
            raise ValueError(f"frames {seen[im_id]} and {record.frame} have the same image id {im_id}")
        seen[im_id] = record.frame
        for entry in record.results:
            pose, box = entry.get("pose"), entry.get("box")
            match = _BOP_CLASS.match(pose.class_name or "") if isinstance(pose, Pose6D) else None
            if match is None:
                continue
            rows["im_ids"].append(im_id)
            rows["obj_ids"].append(int(match.group(1)))
            rows["scores"].append(box.score if isinstance(box, Box2D) else pose.score)
            rows["rotations"].append(pose.rotation_matrix)
            rows["translations"].append(pose.translation)
            rows["times"].append(record.latency_ms / 1000.0)
    count = len(rows["im_ids"])
    write_pose_results(path, np.full(count, scene_id), rows["im_ids"], rows["obj_ids"], rows["scores"],
                       np.reshape(rows["rotations"], (-1, 3, 3)), np.reshape(rows["translations"], (-1, 3)),
                       rows["times"])
    return count
