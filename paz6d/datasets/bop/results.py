"""BOP'19 pose results files: ``scene_id,im_id,obj_id,score,R,t,time``, one estimate per line.

``R`` holds the 9 entries of ``R_model2cam`` row-major separated by spaces, ``t`` the 3 entries
of ``t_model2cam`` in millimetres, ``time`` the run time in seconds for the whole image (-1 when
unknown). Lines are numbered from 1 (the header) in every error message. Reader and writer take
translations in the units the caller works in (``units="m"``, the default, or ``"mm"``) and
convert once, here.

Example:
    >>> results = read_pose_results("results_lmo-test.csv", object_ids={1, 5}, units="mm")  # doctest: +SKIP
    >>> results.rotations.shape                                                          # doctest: +SKIP
    (1426, 3, 3)
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.checks import short_repr
from paz6d.backend.files import read_input_text, write_csv_atomically
from paz6d.datasets.bop.units import Units, lengths_from_mm, mm_from_lengths

HEADER = ("scene_id", "im_id", "obj_id", "score", "R", "t", "time")
#: Largest accepted ``max |R^T R - I|`` of a pose rotation: loose enough for the rounded rotations
#: stored in BOP files (LM-O scene 2's ground truth reaches 0.0094), tight enough to reject scaled,
#: sheared or reflected matrices.
ROTATION_TOLERANCE = 0.05


@dataclass(frozen=True)
class PoseResults:
    """Estimates read from a results file, as parallel arrays of length ``E``.

    Attributes:
        path: the file read.
        scene_ids, im_ids, obj_ids: ``(E,)`` int64 BOP ids.
        scores: ``(E,)`` confidences (higher = more confident).
        rotations: ``(E, 3, 3)`` ``R_model2cam``.
        translations: ``(E, 3)`` ``t_model2cam`` in :attr:`units`.
        times: ``(E,)`` seconds per image (-1 = unknown).
        line_numbers: ``(E,)`` 1-based line of each estimate in the file.
        skipped: ``(line, reason)`` of the rows dropped with ``skip_invalid=True``.
        units: units of :attr:`translations` (``"m"`` or ``"mm"``).
    """

    path: Path
    scene_ids: np.ndarray
    im_ids: np.ndarray
    obj_ids: np.ndarray
    scores: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    times: np.ndarray
    line_numbers: np.ndarray
    skipped: tuple[tuple[int, str], ...] = ()
    units: Units = "m"

    def __len__(self) -> int:
        return len(self.scores)

    @property
    def T_model2cam(self) -> np.ndarray:
        """``(E, 4, 4)`` ``T_model2cam`` with translations in :attr:`units`."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        T[:, :3, :3] = self.rotations
        T[:, :3, 3] = self.translations
        return T


def _integer(text: str, name: str) -> int:
    text = text.strip()
    if not text.isdigit():
        raise ValueError(f"field {name!r}: expected a non-negative integer, got {short_repr(text)}")
    if len(text) > 18:
        raise ValueError(f"field {name!r}: id of {len(text)} digits is too large")
    return int(text)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _numbers(text: str, name: str, count: int) -> np.ndarray:
    parts = text.split()
    if len(parts) != count:
        raise ValueError(f"field {name!r}: expected {count} numbers separated by spaces, got {len(parts)}")
    try:
        values = np.array([float(part) for part in parts])
    except ValueError:
        bad = next(part for part in parts if not _is_float(part))
        raise ValueError(f"field {name!r}: not a number: {short_repr(bad)}") from None
    if not np.all(np.isfinite(values)):
        raise ValueError(f"field {name!r}: contains NaN or infinite values")
    return values


def _parse_row(row: list[str], rotation_tolerance: float) -> tuple:
    if len(row) != len(HEADER):
        raise ValueError(f"expected {len(HEADER)} comma-separated fields {','.join(HEADER)}, got {len(row)}")
    scene_id = _integer(row[0], "scene_id")
    im_id = _integer(row[1], "im_id")
    obj_id = _integer(row[2], "obj_id")
    score = _numbers(row[3], "score", 1)[0]
    R = _numbers(row[4], "R", 9).reshape(3, 3)
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    if error > rotation_tolerance or np.linalg.det(R) <= 0:
        raise ValueError(f"field 'R': not a rotation matrix (max |R^T R - I| = {error:.3g}, "
                         f"det = {np.linalg.det(R):.3g}; expected orthonormal within {rotation_tolerance:g}, det +1)")
    t = _numbers(row[5], "t", 3)
    time = _numbers(row[6], "time", 1)[0]
    return scene_id, im_id, obj_id, score, R, t, time


def read_pose_results(path: str | Path, object_ids=None, image_ids=None, skip_invalid: bool = False,
                      rotation_tolerance: float = ROTATION_TOLERANCE, units: Units = "m") -> PoseResults:
    """Reads a BOP'19 results CSV.

    Args:
        path: the CSV file (header ``scene_id,im_id,obj_id,score,R,t,time``).
        object_ids: known object ids; an estimate of another object is invalid (``None``: no check).
        image_ids: known ``(scene_id, im_id)`` pairs; an estimate of another image is invalid.
        skip_invalid: drop invalid rows and record them in :attr:`PoseResults.skipped` instead of
            raising.
        rotation_tolerance: largest accepted ``max |R^T R - I|``.
        units: units of the returned translations (``"m"``, or ``"mm"`` as stored).

    Raises:
        ValueError: naming the file and line: missing file, wrong header, wrong field count,
            non-integer ids, NaN/inf numbers, non-rotation ``R``, unknown object or image (the
            header is always checked, also with ``skip_invalid``).
    """
    path = Path(path)
    text = read_input_text(path, "results file")
    object_ids = None if object_ids is None else {int(value) for value in object_ids}
    image_ids = None if image_ids is None else {(int(scene), int(image)) for scene, image in image_ids}
    parsed, lines, skipped = [], [], []
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader, None)
        if header is None or tuple(field.strip() for field in header) != HEADER:
            found = "an empty file" if header is None else short_repr(",".join(header))
            raise ValueError(f"{path}:1: expected the header {','.join(HEADER)}, got {found}")
        for row in reader:
            if not row or all(not field.strip() for field in row):
                continue
            try:
                values = _parse_row(row, rotation_tolerance)
                if object_ids is not None and values[2] not in object_ids:
                    raise ValueError(f"unknown object id {values[2]} (known: {sorted(object_ids)})")
                if image_ids is not None and (values[0], values[1]) not in image_ids:
                    raise ValueError(f"unknown image: scene {values[0]}, image {values[1]} is not in the "
                                     "data set's ground truth")
            except ValueError as error:
                if not skip_invalid:
                    raise ValueError(f"{path}:{reader.line_num}: {error}") from None
                skipped.append((reader.line_num, str(error)))
                continue
            parsed.append(values)
            lines.append(reader.line_num)
    except csv.Error as error:  # a NUL byte, an unterminated quote, a field beyond the csv field size limit
        raise ValueError(f"{path}:{reader.line_num}: malformed CSV ({error})") from None
    count = len(parsed)
    columns = list(zip(*parsed)) if parsed else [()] * len(HEADER)
    return PoseResults(
        path=path,
        scene_ids=np.array(columns[0], dtype=np.int64),
        im_ids=np.array(columns[1], dtype=np.int64),
        obj_ids=np.array(columns[2], dtype=np.int64),
        scores=np.array(columns[3], dtype=np.float64),
        rotations=np.array(columns[4], dtype=np.float64).reshape(count, 3, 3),
        translations=lengths_from_mm(np.array(columns[5], dtype=np.float64).reshape(count, 3), units),
        times=np.array(columns[6], dtype=np.float64),
        line_numbers=np.array(lines, dtype=np.int64),
        skipped=tuple(skipped),
        units=units)


def write_pose_results(path: str | Path, scene_ids, im_ids, obj_ids, scores, rotations, translations,
                       times=None, units: Units = "m") -> Path:
    """Writes estimates as a BOP'19 results CSV (atomically: temporary file, then ``os.replace``).

    Args:
        path: output CSV.
        scene_ids, im_ids, obj_ids: ``(E,)`` ids.
        scores: ``(E,)`` confidences.
        rotations: ``(E, 3, 3)`` ``R_model2cam``.
        translations: ``(E, 3)`` ``t_model2cam`` in ``units`` (written in millimetres).
        times: ``(E,)`` seconds per image (default -1).
        units: ``"m"`` or ``"mm"``.
    """
    path = Path(path)
    rotations = np.asarray(rotations, dtype=np.float64).reshape(-1, 9)
    translations_mm = mm_from_lengths(np.asarray(translations, dtype=np.float64).reshape(-1, 3), units)
    count = len(rotations)
    times = np.full(count, -1.0) if times is None else np.asarray(times, dtype=np.float64)
    columns = [np.asarray(values).ravel() for values in (scene_ids, im_ids, obj_ids, scores)]
    if any(len(values) != count for values in columns + [translations_mm, times]):
        raise ValueError(f"write_pose_results: expected {count} values in every column")
    rows = ([int(columns[0][index]), int(columns[1][index]), int(columns[2][index]), repr(float(columns[3][index])),
             " ".join(repr(float(value)) for value in rotations[index]),
             " ".join(repr(float(value)) for value in translations_mm[index]),
             repr(float(times[index])) if math.isfinite(times[index]) else "-1"] for index in range(count))
    return write_csv_atomically(path, HEADER, rows)
