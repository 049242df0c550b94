"""FER-2013 facial expressions: the Kaggle CSV and image-folder layouts, as grey ``uint8`` faces.

* CSV (Kaggle ``fer2013.csv``): header ``emotion,pixels,Usage``; ``emotion`` is 0-6 in
  :data:`FER2013_CLASSES` order, ``pixels`` holds 48x48 space-separated grey levels and ``Usage``
  is ``Training``, ``PublicTest`` or ``PrivateTest``.
* Image folder: ``root/<class>/<image>`` (any image format OpenCV reads), optionally split as
  ``root/train/<class>/...`` and ``root/test/<class>/...``.

Example:
    >>> faces, labels, class_names = load_image_folder("faces/fer2013_sample")  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.files import read_input_text
from paz6d.backend.image import load_image

FER2013_CLASSES = ("angry", "disgust", "fear", "happy", "sad", "surprise", "neutral")
FER2013_SIZE = 48
CSV_COLUMNS = ("emotion", "pixels", "Usage")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp")


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
            except (TypeError, ValueError, AttributeError):
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
    return np.stack(faces), np.array(labels, dtype=np.int64), np.array(usage)


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
