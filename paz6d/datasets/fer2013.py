"""FER-2013 facial expressions: the Kaggle CSV and image-folder layouts, as grey ``uint8`` faces.

* CSV (Kaggle ``fer2013.csv``): header ``emotion,pixels,Usage``; ``emotion`` is 0-6 in
  :data:`FER2013_CLASSES` order, ``pixels`` holds 48x48 space-separated grey levels and ``Usage``
  is ``Training``, ``PublicTest`` or ``PrivateTest``.
* Image folder: ``root/<class>/<image>`` (any image format OpenCV reads), optionally split as
  ``root/train/<class>/...`` and ``root/test/<class>/...``.

Reading the CSV is vectorised: a file in the Kaggle layout (header ``emotion,pixels,Usage``, no
quotes) is parsed with numpy over the whole pixel column (the 35,887-row file in about a second);
anything else, or a file with an error, goes through the row-by-row reader, whose messages name the
line.

:func:`load` gives the common interface: a :class:`~paz6d.datasets.sample.SampleSequence` of inline
``(48, 48) uint8`` faces, ``Usage`` ``Training``/``PublicTest``/``PrivateTest`` mapped to the splits
``train``/``val``/``test`` (:data:`SPLITS`).

Example:
    >>> faces, labels, class_names = load_image_folder("faces/fer2013_sample")  # doctest: +SKIP
    >>> train = load("fer2013/fer2013.csv", "train")  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.files import read_input_bytes, read_input_text
from paz6d.backend.image import load_image
from paz6d.datasets.sample import Sample, SampleSequence

FER2013_CLASSES = ("angry", "disgust", "fear", "happy", "sad", "surprise", "neutral")
FER2013_SIZE = 48
CSV_COLUMNS = ("emotion", "pixels", "Usage")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp")
#: paz6d split name -> FER-2013 ``Usage`` value.
SPLITS = {"train": "Training", "val": "PublicTest", "test": "PrivateTest"}
CSV_FILE = "fer2013.csv"
_ROWS_PER_CHUNK = 2048  # rows parsed together by the vectorised reader (bounds its memory to ~0.3 GB)


def _parse_pixel_fields(data: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """Grey levels of the pixel fields ``data[starts[i]:ends[i]]`` (bytes of integers separated by
    single spaces) as ``(N, 48, 48) uint8``, or ``None`` when any field is not exactly 2304 integers
    in 0..255 of at most 3 digits (the caller then reads row by row to name the bad line).

    Works on the spaces only: a valid field has 2303 of them, the tokens lie between consecutive
    separators, and their 1-3 digits are gathered from their ends.
    """
    size = FER2013_SIZE ** 2
    faces = np.empty((len(starts), size), dtype=np.uint8)
    for first in range(0, len(starts), _ROWS_PER_CHUNK):
        field_starts, field_ends = starts[first:first + _ROWS_PER_CHUNK], ends[first:first + _ROWS_PER_CHUNK]
        low = int(field_starts[0])
        chunk = data[low:int(field_ends[-1])]
        spaces = np.flatnonzero(chunk == 32).astype(np.int32)
        rows = len(field_starts)
        if len(spaces) != (size - 1) * rows:
            return None
        separators = np.empty((rows, size + 1), dtype=np.int32)
        separators[:, 0] = field_starts - low - 1
        separators[:, 1:-1] = spaces.reshape(rows, size - 1)
        separators[:, -1] = field_ends - low
        lengths = np.diff(separators, axis=1) - 1
        if lengths.min() < 1 or lengths.max() > 3:
            return None  # also catches spaces outside their row's field, which shift the separators
        token_ends = separators[:, 1:]
        lengths = lengths.astype(np.int16)
        values = np.zeros((rows, size), dtype=np.int16)
        invalid = np.zeros((rows, size), dtype=bool)
        for position, scale in ((1, 1), (2, 10), (3, 100)):  # digits gathered from each token's end
            digits = chunk.take(np.maximum(token_ends - position, 0)) - np.uint8(48)  # non-digits wrap to >= 10
            present = lengths >= position
            invalid |= present & (digits >= 10)
            values += digits.astype(np.int16) * (present * np.int16(scale))
        if invalid.any() or values.max() > 255:
            return None
        faces[first:first + rows] = values
    return faces.reshape(-1, FER2013_SIZE, FER2013_SIZE)


def _read_kaggle_layout(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The vectorised reader of :func:`load_fer2013_csv`; ``None`` when the file is not exactly in the
    Kaggle layout or holds a bad row (left to the row-by-row reader and its messages)."""
    raw = read_input_bytes(path, "FER-2013 CSV file")
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n")
    if b'"' in raw or b"\r" in raw:
        return None
    data = np.frombuffer(raw, dtype=np.uint8)
    line_ends = np.flatnonzero(data == 10)
    if len(data) == 0 or data[-1] != 10:
        line_ends = np.append(line_ends, len(data))
    line_starts = np.concatenate([[0], line_ends[:-1] + 1])
    if bytes(data[:line_ends[0]]).strip() != b",".join(column.encode() for column in CSV_COLUMNS):
        return None
    line_starts, line_ends = line_starts[1:], line_ends[1:]
    nonempty = line_ends > line_starts
    line_starts, line_ends = line_starts[nonempty], line_ends[nonempty]
    if len(line_starts) == 0:
        return None
    commas = np.flatnonzero(data == 44)
    first_comma = np.searchsorted(commas, line_starts)
    if np.any(np.searchsorted(commas, line_ends) - first_comma != 2):
        return None
    label_ends, usage_starts = commas[first_comma], commas[first_comma + 1] + 1
    try:
        labels = np.array([int(raw[start:end]) for start, end in zip(line_starts, label_ends)], dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if labels.size and (labels.min() < 0 or labels.max() >= len(FER2013_CLASSES)):
        return None
    faces = _parse_pixel_fields(data, label_ends + 1, usage_starts - 1)
    if faces is None:
        return None
    usage = np.array([raw[start:end].decode("utf-8", "replace").strip() for start, end in zip(usage_starts, line_ends)])
    return faces, labels, usage


def load_fer2013_csv(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reads a FER-2013 CSV file.

    Returns:
        ``faces (N, 48, 48) uint8``, ``labels (N,) int64`` indexing :data:`FER2013_CLASSES` and
        ``usage (N,) str``.
    Raises:
        ValueError: missing file or columns, or a row with a bad label or pixel count
            (the message names the line).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"data: FER-2013 CSV file {path} does not exist")
    fast = _read_kaggle_layout(path)
    if fast is not None:
        return _checked_usage(path, *fast)
    faces, labels, usage = [], [], []
    reader = csv.DictReader(io.StringIO(read_input_text(path, "FER-2013 CSV file"), newline=""))
    try:
        missing = [column for column in CSV_COLUMNS if column not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path}: expected the FER-2013 header {','.join(CSV_COLUMNS)}, missing {missing}")
        for line, row in enumerate(reader, start=2):
            try:
                label = int(row["emotion"])
                pixels = np.array(row["pixels"].split(), dtype=np.int64)
            except (TypeError, ValueError, AttributeError, OverflowError):
                raise ValueError(f"{path}, line {line}: cannot parse emotion/pixels (expected an integer label "
                                 "and space-separated grey levels)") from None
            if not 0 <= label < len(FER2013_CLASSES):
                raise ValueError(f"{path}, line {line}: emotion {label} outside 0..{len(FER2013_CLASSES) - 1}")
            if pixels.size != FER2013_SIZE ** 2 or pixels.min() < 0 or pixels.max() > 255:
                raise ValueError(f"{path}, line {line}: expected {FER2013_SIZE ** 2} grey levels in 0..255, "
                                 f"got {pixels.size} values")
            faces.append(pixels.astype(np.uint8).reshape(FER2013_SIZE, FER2013_SIZE))
            labels.append(label)
            usage.append(row["Usage"])
    except csv.Error as error:  # a NUL byte, an unterminated quote, a field beyond the csv field size limit
        raise ValueError(f"{path}, line {reader.line_num}: malformed CSV ({error})") from None
    if not faces:
        raise ValueError(f"{path}: no data rows")
    return _checked_usage(path, np.stack(faces), np.array(labels, dtype=np.int64), np.array(usage))


def _checked_usage(path: Path, faces: np.ndarray, labels: np.ndarray,
                   usage: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arguments, when every row's ``Usage`` is one of :data:`SPLITS`' values (a misspelt or
    garbled one would drop the row from every split without a word); else ``ValueError`` naming the row."""
    unknown = np.flatnonzero(~np.isin(usage, list(SPLITS.values())))
    if len(unknown):
        row = int(unknown[0])
        raise ValueError(f"{path}, data row {row + 1}, field Usage: {str(usage[row])!r:.60}; expected one of "
                         f"{list(SPLITS.values())} ({len(unknown)} row(s) with another value)")
    return faces, labels, usage


def class_folders(root: Path) -> list[Path]:
    """Sub-folders of ``root`` that hold at least one image, sorted by name."""
    return sorted(folder for folder in root.iterdir() if folder.is_dir()
                  and any(path.suffix.lower() in IMAGE_SUFFIXES for path in folder.iterdir()))


def load_image_folder(root, class_names: tuple[str, ...] | None = None,
                      size: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Reads ``root/<class>/<image>`` as grey faces.

    Args:
        root: folder with one sub-folder per class.
        class_names: label order; by default :data:`FER2013_CLASSES` when the folders are exactly
            those names, else the sorted folder names.
        size: ``(width, height)`` to resize every image to; required when sizes differ.
    Returns:
        ``faces (N, H, W) uint8``, ``labels (N,) int64`` indexing ``class_names``, ``class_names``.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"data: image folder {root} does not exist")
    folders = class_folders(root)
    if not folders:
        raise ValueError(f"{root}: expected one sub-folder of images per class (root/<class>/<image>), found none")
    names = [folder.name for folder in folders]
    if class_names is None:
        class_names = FER2013_CLASSES if set(names) == set(FER2013_CLASSES) else tuple(names)
    unknown = sorted(set(names) - set(class_names))
    if unknown:
        raise ValueError(f"{root}: class folders {unknown} are not in class_names {list(class_names)}")
    faces, labels = [], []
    for folder in folders:
        for path in sorted(folder.iterdir()):
            if path.suffix.lower() not in IMAGE_SUFFIXES:
                continue
            face = load_image(path, grayscale=True)
            if size is not None:
                face = cv2.resize(face, tuple(int(value) for value in size), interpolation=cv2.INTER_AREA)
            elif faces and face.shape != faces[0].shape:
                raise ValueError(f"{path}: size {face.shape[::-1]} differs from {faces[0].shape[::-1]}; pass size=")
            faces.append(face)
            labels.append(class_names.index(folder.name))
    return np.stack(faces), np.array(labels, dtype=np.int64), tuple(class_names)


def csv_path(root_or_csv: str | Path) -> Path:
    """The FER-2013 CSV: ``root_or_csv`` itself, or ``fer2013.csv`` inside that folder."""
    path = Path(root_or_csv)
    return path / CSV_FILE if path.is_dir() else path


def usage_of_split(split: str | None) -> str | None:
    """FER-2013 ``Usage`` of a split (``train``, ``val``, ``test`` or a ``Usage`` value; ``None``: all)."""
    if split is None or split in SPLITS.values():
        return split
    if split not in SPLITS:
        raise ValueError(f"split: expected one of {list(SPLITS)} (or {list(SPLITS.values())}), got {split!r}")
    return SPLITS[split]


def load(root_or_csv: str | Path, split: str | None = None) -> SampleSequence:
    """FER-2013 faces of one split as a :class:`SampleSequence` of inline images.

    Args:
        root_or_csv: ``fer2013.csv`` or the folder holding it.
        split: ``train`` (Usage ``Training``), ``val`` (``PublicTest``), ``test`` (``PrivateTest``), or
            ``None`` for every row.
    Returns:
        Samples with ``image (48, 48) uint8``, ``class_ids (1,)`` indexing :data:`FER2013_CLASSES`,
        one class name, no boxes (``(0, 4)``) and ``extras`` ``usage`` and ``row`` (0-based data row).
    Raises:
        ValueError: a missing or malformed file (the message names the line), an unknown split.
    """
    usage_value = usage_of_split(split)
    faces, labels, usage = load_fer2013_csv(csv_path(root_or_csv))
    rows = np.arange(len(labels)) if usage_value is None else np.flatnonzero(usage == usage_value)

    def read(position: int) -> Sample:
        row = int(rows[position])
        return Sample(image=faces[row], boxes=np.zeros((0, 4)), class_ids=labels[row:row + 1].copy(),
                      class_names=[FER2013_CLASSES[labels[row]]], extras={"usage": str(usage[row]), "row": row})

    return SampleSequence(len(rows), read, FER2013_CLASSES)
