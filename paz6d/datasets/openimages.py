"""Open Images V6/V7 bounding boxes: the box CSVs, the class-description CSV and the split folders.

Files, as Open Images publishes them (looked up in ``root`` and ``root/annotations``):

* boxes: ``<split>-annotations-bbox.csv`` or ``oidv6-<split>-annotations-bbox.csv`` (or
  ``<root>/<split>/labels/detections.csv``, the downloader layout), header
  ``ImageID,Source,LabelName,Confidence,XMin,XMax,YMin,YMax,IsOccluded,IsTruncated,IsGroupOf,IsDepiction,IsInside``
  (the flags may be ``-1``: unknown);
* classes: ``oidv7-class-descriptions-boxable.csv``, ``oidv6-class-descriptions-boxable.csv``,
  ``class-descriptions-boxable.csv``, ``oidv7-class-descriptions.csv`` or
  ``<root>/<split>/metadata/classes.csv``: ``LabelName,DisplayName`` rows (``/m/011k07,Tortoise``),
  with or without that header line (the boxable lists of V6 have none, V7's have one);
* images: ``<root>/<split>/<ImageID>.jpg`` (or ``<root>/<split>/data/<ImageID>.jpg``).

Splits are ``train``, ``validation`` (``val`` is accepted) and ``test``.

Conversion: coordinates are fractions of the image size, so the box in pixels is
``(XMin * W, YMin * H, XMax * W, YMax * H)`` with ``W, H`` read from the image file's header when
the sample is read (PNG ``IHDR`` or JPEG ``SOF`` marker, without decoding pixels; other formats are
decoded). No EXIF rotation is applied. ``class_names`` are the display names in the description
file's order; ``extras`` keep per box ``label_names`` (the ``/m/...`` ids), ``confidence``, ``source``
and ``is_occluded``, ``is_truncated``, ``is_group_of``, ``is_depiction``, ``is_inside`` (``int8``,
``-1`` unknown), and per image ``image_id`` and ``image_size`` ``(width, height)``.

Example:
    >>> samples = load("open-images-v7", "validation")  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
from array import array
from pathlib import Path

import numpy as np

from paz6d.backend.files import input_file_errors, read_input_text
from paz6d.backend.image import image_size_from_header
from paz6d.backend.paths import path_inside
from paz6d.datasets.sample import Sample, SampleSequence

BOX_COLUMNS = ("ImageID", "Source", "LabelName", "Confidence", "XMin", "XMax", "YMin", "YMax", "IsOccluded",
               "IsTruncated", "IsGroupOf", "IsDepiction", "IsInside")
FLAG_COLUMNS = ("IsOccluded", "IsTruncated", "IsGroupOf", "IsDepiction", "IsInside")
FLAG_EXTRAS = {"IsOccluded": "is_occluded", "IsTruncated": "is_truncated", "IsGroupOf": "is_group_of",
               "IsDepiction": "is_depiction", "IsInside": "is_inside"}
CLASS_FILES = ("oidv7-class-descriptions-boxable.csv", "oidv6-class-descriptions-boxable.csv",
               "class-descriptions-boxable.csv", "oidv7-class-descriptions.csv", "class-descriptions.csv")
SPLITS = {"train": "train", "validation": "validation", "val": "validation", "test": "test"}
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
def _first_existing(candidates: list[Path]) -> Path | None:
    return next((path for path in candidates if path.is_file()), None)


def find_files(root: str | Path, split: str) -> dict[str, Path | None]:
    """The box CSV, class-description CSV and image folder of ``split`` under ``root`` (``None``
    where nothing is found)."""
    root = Path(root)
    split = SPLITS.get(split, split)
    folders = [root, root / "annotations"]
    boxes = _first_existing([folder / name for folder in folders
                             for name in (f"{split}-annotations-bbox.csv", f"oidv6-{split}-annotations-bbox.csv",
                                          f"oidv7-{split}-annotations-bbox.csv")]
                            + [root / split / "labels" / "detections.csv"])
    classes = _first_existing([folder / name for folder in folders for name in CLASS_FILES]
                              + [root / split / "metadata" / "classes.csv"])
    images = root / split / "data" if (root / split / "data").is_dir() else root / split
    return {"boxes": boxes, "classes": classes, "images": images}


def is_openimages_root(root: str | Path) -> bool:
    """Whether ``root`` holds an Open Images box CSV of some split."""
    root = Path(root)
    return root.is_dir() and any(find_files(root, split)["boxes"] is not None for split in ("train", "validation",
                                                                                            "test"))


def _rows(path: Path, what: str) -> list[list[str]]:
    try:
        return [row for row in csv.reader(io.StringIO(read_input_text(path, what), newline="")) if row]
    except csv.Error as error:
        raise ValueError(f"{path}: malformed CSV ({error})") from None


def read_class_descriptions(path: str | Path) -> tuple[list[str], list[str]]:
    """``(label_names, display_names)`` of a ``LabelName,DisplayName`` CSV, with or without header."""
    path = Path(path)
    rows = _rows(path, "Open Images class-description CSV")
    if rows and [cell.strip() for cell in rows[0][:2]] == ["LabelName", "DisplayName"]:
        rows, first_line = rows[1:], 2
    else:
        first_line = 1
    if not rows:
        raise ValueError(f"{path}: expected LabelName,DisplayName rows, found none")
    labels, names = [], []
    for line, row in enumerate(rows, start=first_line):
        if len(row) < 2 or not row[0].strip():
            raise ValueError(f"{path}, line {line}: expected 'LabelName,DisplayName', got {','.join(row)!r}")
        labels.append(row[0].strip())
        names.append(row[1].strip())
    duplicates = (sorted({label for label in labels if labels.count(label) > 1}) if len(set(labels)) < len(labels)
                  else [])
    if duplicates:
        raise ValueError(f"{path}: field LabelName: {duplicates[:5]} listed more than once")
    return labels, names


def _checked(path: Path, values: list[str], lines: list[int], name: str, dtype, check, expected: str) -> np.ndarray:
    """``values`` (the text of one column) as an array; ``ValueError`` naming the line and field of
    the first value that does not parse or fails ``check``."""
    try:
        array = np.array(values, dtype=dtype)
        bad = ~check(array)
    except (ValueError, OverflowError):  # text, or a whole number beyond the column's integer type
        array, bad = None, None
    if bad is None or bad.any():
        for line, value in zip(lines, values):
            try:
                if check(np.array([value], dtype=dtype))[0]:
                    continue
            except (ValueError, OverflowError):
                pass
            raise ValueError(f"{path}, line {line}, field {name}: expected {expected}, got {value!r}")
    return array


def _fraction(values: np.ndarray) -> np.ndarray:
    return np.isfinite(values) & (values >= 0) & (values <= 1)


def _flag(values: np.ndarray) -> np.ndarray:
    return np.isin(values, (-1, 0, 1))


#: numeric columns: (dtype, check, what is expected)
_NUMBERS = {**{name: (np.float64, _fraction, "a fraction of the image size in [0, 1]")
               for name in ("XMin", "XMax", "YMin", "YMax")},
            "Confidence": (np.float64, _fraction, "a number in [0, 1]"),
            **{name: (np.int64, _flag, "0, 1 or -1 (unknown)") for name in FLAG_COLUMNS}}
_ROWS_PER_CHUNK = 500_000  # rows whose numbers are converted together (the train split has 14.6 million)


def read_boxes(path: str | Path, label_index: dict[str, int]) -> dict:
    """Columns of an Open Images box CSV, checked, read as a stream (the train split's 14.6 million
    rows are never all held as text).

    Returns:
        dict with ``image_codes (R,) int64`` indexing ``image_ids`` (unique, in order of first
        appearance), ``class_ids (R,)``, ``source_codes (R,)`` indexing ``sources``, ``confidence (R,)``,
        ``normalized (R, 4)`` ``XMin, YMin, XMax, YMax`` and each flag column ``(R,) int8`` (``-1``
        where the file has no such column).
    Raises:
        ValueError: naming the file, the line and the field.
    """
    path = Path(path)
    with input_file_errors(path, "Open Images box CSV"):
        handle = path.open(newline="", encoding="utf-8-sig")
    image_codes, source_codes, image_ids, sources = {}, {}, [], []
    rows_image, rows_class, rows_source = array("q"), array("q"), array("q")  # 8 bytes a row, not a Python int
    parts: dict[str, list[np.ndarray]] = {}
    with handle:
        reader = csv.reader(handle)
        try:
            header = [cell.strip() for cell in next(reader, [])]
            missing = [column for column in BOX_COLUMNS if column not in header and column not in FLAG_COLUMNS]
            if not header or missing:
                raise ValueError(f"{path}: header lacks {missing or list(BOX_COLUMNS)}; expected "
                                 f"{','.join(BOX_COLUMNS)}")
            at = {name: header.index(name) for name in header}
            numbers = [name for name in _NUMBERS if name in at]
            parts = {name: [] for name in numbers}
            text: dict[str, list[str]] = {name: [] for name in numbers}
            lines: list[int] = []

            def flush() -> None:
                for name in numbers:
                    dtype, check, expected = _NUMBERS[name]
                    parts[name].append(_checked(path, text[name], lines, name, dtype, check, expected))
                    text[name].clear()
                box = [parts[name][-1] for name in ("XMin", "YMin", "XMax", "YMax")]
                inverted = np.flatnonzero((box[2] < box[0]) | (box[3] < box[1]))
                if len(inverted):
                    raise ValueError(f"{path}, line {lines[inverted[0]]}, field XMax/YMax: XMax < XMin or YMax < YMin")
                lines.clear()

            width, at_image, at_label, at_source = len(header), at["ImageID"], at["LabelName"], at["Source"]
            for row in reader:
                if not row:
                    continue
                if len(row) != width:
                    raise ValueError(f"{path}, line {reader.line_num}: expected {width} fields, got {len(row)}")
                class_id = label_index.get(row[at_label])
                if class_id is None:
                    raise ValueError(f"{path}, line {reader.line_num}, field LabelName: unknown class "
                                     f"{row[at_label]!r} (not in the class-description file)")
                image = image_codes.setdefault(row[at_image], len(image_codes))
                if image == len(image_ids):
                    image_ids.append(row[at_image])
                source = source_codes.setdefault(row[at_source], len(source_codes))
                if source == len(sources):
                    sources.append(row[at_source])
                rows_image.append(image)
                rows_class.append(class_id)
                rows_source.append(source)
                lines.append(reader.line_num)
                for name in numbers:
                    text[name].append(row[at[name]])
                if len(lines) == _ROWS_PER_CHUNK:
                    flush()
            flush()
        except csv.Error as error:
            raise ValueError(f"{path}, line {reader.line_num}: malformed CSV ({error})") from None
        except UnicodeDecodeError as error:
            raise ValueError(f"{path}: not UTF-8 text ({error.reason})") from None
    columns = {name: np.concatenate(chunks) for name, chunks in parts.items()}
    count = len(rows_image)
    result = {"image_ids": image_ids, "sources": sources,
              "image_codes": np.frombuffer(rows_image, dtype=np.int64),
              "class_ids": np.frombuffer(rows_class, dtype=np.int64),
              "source_codes": np.frombuffer(rows_source, dtype=np.int64), "confidence": columns["Confidence"],
              "normalized": np.stack([columns[name] for name in ("XMin", "YMin", "XMax", "YMax")], axis=1).reshape(-1,
                                                                                                                   4)}
    for name in FLAG_COLUMNS:
        result[name] = columns[name].astype(np.int8) if name in columns else np.full(count, -1, dtype=np.int8)
    return result


def _find_image(folder: Path, image_id: str, where: str) -> Path:
    """The image file of ``image_id`` in ``folder`` (``.jpg`` when none exists); ``ValueError`` naming
    ``where`` for an id that would lead outside ``folder``."""
    path_inside(folder, image_id + IMAGE_SUFFIXES[0], where)
    for suffix in IMAGE_SUFFIXES:
        if (folder / f"{image_id}{suffix}").is_file():
            return folder / f"{image_id}{suffix}"
    return folder / f"{image_id}.jpg"


def load(root: str | Path, split: str = "train", boxes_csv: str | Path | None = None,
         classes_csv: str | Path | None = None, images: str | Path | None = None,
         include_group_of: bool = True) -> SampleSequence:
    """An Open Images split as a lazy :class:`SampleSequence`, one sample per image of the box CSV
    (in order of first appearance); image sizes are read from file headers when a sample is read.

    Args:
        root: the Open Images folder (see the module doc for the layout).
        split: ``train``, ``validation`` (or ``val``) or ``test``.
        boxes_csv, classes_csv, images: explicit paths overriding the layout's.
        include_group_of: keep ``IsGroupOf`` boxes (boxes around a group of objects).
    Raises:
        ValueError: a missing file; a malformed CSV row (file, line and field), an unknown class.
    """
    root = Path(root)
    found = find_files(root, split)
    boxes_path = Path(boxes_csv) if boxes_csv is not None else found["boxes"]
    classes_path = Path(classes_csv) if classes_csv is not None else found["classes"]
    if boxes_path is None:
        raise ValueError(f"root: no Open Images box CSV for split {split!r} in {root} (expected "
                         f"{SPLITS.get(split, split)}-annotations-bbox.csv or "
                         f"oidv6-{SPLITS.get(split, split)}-annotations-bbox.csv)")
    if classes_path is None:
        raise ValueError(f"root: no Open Images class-description CSV in {root} (expected one of {list(CLASS_FILES)})")
    image_folder = Path(images) if images is not None else found["images"]
    label_names, display_names = read_class_descriptions(classes_path)
    table = read_boxes(boxes_path, {label: position for position, label in enumerate(label_names)})
    keep = np.ones(len(table["class_ids"]), dtype=bool) if include_group_of else table["IsGroupOf"] != 1
    rows_by_image = np.argsort(table["image_codes"], kind="stable")
    starts = np.searchsorted(table["image_codes"][rows_by_image], np.arange(len(table["image_ids"]) + 1))
    order = table["image_ids"]

    def read(position: int) -> Sample:
        image_id = order[position]
        rows = rows_by_image[starts[position]:starts[position + 1]]
        rows = rows[keep[rows]]
        path = _find_image(image_folder, image_id, f"{boxes_path}: ImageID {image_id!r:.60}")
        width, height = image_size_from_header(path)
        boxes = table["normalized"][rows] * np.array([width, height, width, height], dtype=np.float64)
        class_ids = table["class_ids"][rows]
        extras = {"image_id": image_id, "image_size": (width, height),
                  "label_names": [label_names[i] for i in class_ids],
                  "source": [table["sources"][i] for i in table["source_codes"][rows]],
                  "confidence": table["confidence"][rows]}
        extras.update({key: table[name][rows] for name, key in FLAG_EXTRAS.items()})
        return Sample(image=path, boxes=boxes.reshape(-1, 4), class_ids=class_ids,
                      class_names=[display_names[i] for i in class_ids], extras=extras,
                      source=f"{boxes_path}: ImageID {image_id}")

    return SampleSequence(len(order), read, display_names)
