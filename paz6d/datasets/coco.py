"""COCO instances annotations (``instances_<split>.json``): boxes, classes, crowd flags, keypoints and
masks from polygons or run-length encodings, as a lazy :class:`SampleSequence`.

Layout: ``<root>/annotations/instances_<split>.json`` with images in ``<root>/<split>/`` (COCO 2014
and 2017 both ship so: ``train2017/``, ``val2017/``), or any instances JSON file with an image folder.

Conversion rules:

* ``bbox`` ``[x, y, w, h]`` (pixels, continuous) becomes ``x_min, y_min, x_max = x + w, y_max = y + h``;
* category ids (1..90 with gaps in COCO) become contiguous class ids ``0..C-1`` in increasing id
  order; ``class_names`` are the categories' names in that order, ``extras["category_ids"]`` keeps
  the original id per box;
* ``iscrowd`` is kept per box in ``extras["iscrowd"]`` (``include_crowd=False`` drops crowd boxes);
* segmentations are decoded when a sample is read (``masks=True``) into ``(N, H, W) bool``, as
  pycocotools' ``annToMask`` does: polygons (parts united) are rasterized like ``rleFrPoly``
  (vertices on a 5x grid, column boundaries kept where the walk crosses a pixel-column centre),
  uncompressed RLE ``counts`` lists and compressed RLE strings (COCO's LEB128 variant) are
  expanded in column-major order;
* ``keypoints`` ``[x1, y1, v1, ...]`` become ``Sample.keypoints (N, K, 3)`` when present.

The records are checked here, one annotation at a time (messages name the file, record and field);
the decoding itself is :mod:`paz6d.backend.rle`, the same (numba) code that COCO scoring
(:mod:`evaluation.coco_masks`) uses.

Example:
    >>> samples = load("coco", "val2017", masks=False)  # doctest: +SKIP
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from paz6d.backend import rle
from paz6d.backend.image import MAX_IMAGE_SIDE
from paz6d.backend.files import load_json_object
from paz6d.backend.paths import path_inside
from paz6d.datasets.sample import Sample, SampleSequence

_RLE_OFFSET = 48  # compressed RLE characters are chr(48 + 6-bit group)


def annotation_file(root: str | Path, split: str) -> Path:
    """``<root>/annotations/instances_<split>.json``."""
    return Path(root) / "annotations" / f"instances_{split}.json"


def is_coco_root(root: str | Path) -> bool:
    """Whether ``root`` is an instances JSON file or a folder with ``annotations/instances_*.json``."""
    root = Path(root)
    if root.is_file():
        return root.suffix == ".json"
    return root.is_dir() and any((root / "annotations").glob("instances_*.json"))


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_ids(records: list[dict], key: str, path: Path) -> None:
    """Refuses an ``id`` that is no integer (a list, text, a boolean) or appears twice in ``key``."""
    seen: dict[int, int] = {}
    for number, record in enumerate(records):
        value = record["id"]
        if not _is_integer(value):
            raise ValueError(f"{path}: {key}[{number}], field 'id': expected an integer, got {value!r:.40}")
        if value in seen:
            raise ValueError(f"{path}: {key}[{number}], field 'id': {value} is also the id of {key}[{seen[value]}]; "
                             "ids must be unique")
        seen[value] = number


def _check_annotation(annotation, number: int, path: Path, images: dict, categories: dict) -> None:
    """Raises ``ValueError`` naming the file, the annotation and the field for a malformed record."""
    if not isinstance(annotation, dict):
        raise ValueError(f"{path}: annotations[{number}]: expected an object, got {type(annotation).__name__}")
    where = f"{path}: annotations[{number}] (id {annotation.get('id')!r})"
    for field in ("id", "image_id", "category_id", "bbox"):
        if field not in annotation:
            raise ValueError(f"{where}, field '{field}': missing")
    for field in ("image_id", "category_id"):
        if not _is_integer(annotation[field]):
            raise ValueError(f"{where}, field '{field}': expected an integer id, got {annotation[field]!r:.40}")
    if annotation["image_id"] not in images:
        raise ValueError(f"{where}, field 'image_id': {annotation['image_id']!r} is not an id of 'images'")
    if annotation["category_id"] not in categories:
        raise ValueError(f"{where}, field 'category_id': unknown category {annotation['category_id']!r}; "
                         f"expected one of the ids of 'categories'")
    box = annotation["bbox"]
    if not isinstance(box, list) or len(box) != 4 or not all(_is_number(v) for v in box) or box[2] < 0 or box[3] < 0:
        raise ValueError(f"{where}, field 'bbox': expected [x, y, width, height] (finite numbers, sizes >= 0), "
                         f"got {box!r}")
    if "area" in annotation and not _is_number(annotation["area"]):
        raise ValueError(f"{where}, field 'area': expected a finite number, got {annotation['area']!r:.40}")
    if annotation.get("iscrowd", 0) not in (0, 1):
        raise ValueError(f"{where}, field 'iscrowd': expected 0 or 1, got {annotation['iscrowd']!r}")
    keypoints = annotation.get("keypoints")
    if keypoints is not None and (not isinstance(keypoints, list) or len(keypoints) % 3
                                  or not all(_is_number(v) for v in keypoints)):
        raise ValueError(f"{where}, field 'keypoints': expected [x1, y1, v1, x2, y2, v2, ...] numbers")


def _records(data: dict, key: str, path: Path, fields: tuple[str, ...]) -> list[dict]:
    records = data.get(key)
    if not isinstance(records, list):
        raise ValueError(f"{path}: field '{key}': expected a list, got {type(records).__name__}")
    for number, record in enumerate(records):
        if not isinstance(record, dict):
            raise ValueError(f"{path}: {key}[{number}]: expected an object, got {type(record).__name__}")
        for field in fields:
            if field not in record:
                raise ValueError(f"{path}: {key}[{number}] (id {record.get('id')!r}), field '{field}': missing")
    return records


def counts_from_string(counts: str | bytes, where: str = "counts") -> np.ndarray:
    """Run lengths of a compressed COCO RLE string (``rleFrString``; decoded by
    :func:`paz6d.backend.rle.decode_counts_strings`): 5 data bits per character (offset 48),
    continuation bit 0x20, sign extension from 0x10, counts after the second stored as a difference
    to the count two places before."""
    data = counts.encode("ascii") if isinstance(counts, str) else bytes(counts)
    codes = np.frombuffer(data, dtype=np.uint8)
    bad = np.flatnonzero((codes < _RLE_OFFSET) | (codes >= _RLE_OFFSET + 64))
    if len(bad):
        raise ValueError(f"{where}: character {chr(data[bad[0]])!r} outside '0'..'o' in a compressed RLE")
    if len(codes) and (codes[-1] - _RLE_OFFSET) & 0x20:
        raise ValueError(f"{where}: compressed RLE string ends inside a value")
    try:
        return rle.decode_counts_strings([data], where)[0]
    except ValueError as error:  # a value of more than 60 bits, or negative run lengths
        raise ValueError(f"{where}: {str(error).removeprefix(f'{where}[0]: ')}") from None


def mask_from_counts(counts, height: int, width: int, where: str = "counts") -> np.ndarray:
    """``(H, W) bool`` mask of COCO run lengths (background first, column-major)."""
    counts = np.asarray(counts, dtype=np.int64).reshape(-1)
    if np.any(counts < 0) or counts.sum() != height * width:
        raise ValueError(f"{where}: RLE counts must be non-negative and sum to height * width = {height * width}, "
                         f"got sum {int(counts.sum())}")
    return rle.mask_from_intervals(rle.intervals_from_counts([counts], [height], [width], where), 0)


def mask_from_polygon(coordinates, height: int, width: int) -> np.ndarray:
    """``(H, W) bool`` mask of one polygon ``[x0, y0, x1, y1, ...]`` (pixels), pixel for pixel as
    pycocotools' ``rleFrPoly`` (:func:`paz6d.backend.rle.segmentations_to_intervals`)."""
    return _mask_from_polygons([list(coordinates)], height, width)


def _mask_from_polygons(parts: list, height: int, width: int) -> np.ndarray:
    """``(H, W) bool`` union of checked polygons (each ``[x0, y0, ...]``, >= 3 points)."""
    return rle.mask_from_intervals(rle.segmentations_to_intervals([parts], [height], [width]), 0)


def mask_from_segmentation(segmentation, height: int, width: int, where: str = "segmentation") -> np.ndarray:
    """``(H, W) bool`` mask of a COCO segmentation (polygon list, uncompressed or compressed RLE),
    as pycocotools' ``annToMask``; ``where`` names the record in errors."""
    if isinstance(segmentation, dict):
        size, counts = segmentation.get("size"), segmentation.get("counts")
        if not isinstance(size, list) or len(size) != 2 or list(size) != [height, width]:
            raise ValueError(f"{where}, field 'size': expected the image size [{height}, {width}], got {size!r}")
        if isinstance(counts, (str, bytes)):
            counts = counts_from_string(counts, f"{where}, field 'counts'")
        elif not isinstance(counts, list) or not all(isinstance(c, int) and not isinstance(c, bool) for c in counts):
            raise ValueError(f"{where}, field 'counts': expected a compressed RLE string or a list of integers")
        return mask_from_counts(counts, height, width, f"{where}, field 'counts'")
    if not isinstance(segmentation, list) or not all(isinstance(part, list) for part in segmentation):
        raise ValueError(f"{where}: expected a polygon list [[x0, y0, x1, y1, ...], ...] or an RLE dict "
                         "with 'size' and 'counts'")
    parts = segmentation
    if parts and len(parts[0]) == 4:  # pycocotools reads 4-number parts as boxes [x, y, w, h]
        parts = [[x, y, x, y + h, x + w, y + h, x + w, y] for x, y, w, h in parts]
    for part in parts:
        if len(part) < 6 or len(part) % 2 or not all(_is_number(value) for value in part):
            raise ValueError(f"{where}: a polygon needs an even number (>= 6) of finite coordinates, got "
                             f"{len(part)} values")
    if not parts:
        return np.zeros((height, width), dtype=bool)
    return _mask_from_polygons(parts, height, width)  # the parts united, as annToMask


def load(root: str | Path, split: str | None = None, images: str | Path | None = None, masks: bool = True,
         include_crowd: bool = True, skip_empty: bool = False) -> SampleSequence:
    """A COCO instances file as a lazy :class:`SampleSequence` in the file's image order.

    Args:
        root: a COCO folder (with ``annotations/instances_<split>.json``) or an instances JSON file.
        split: ``train2017``, ``val2014``, ... (required for a folder).
        images: image folder; default ``<root>/<split>``, or for a JSON file in ``annotations/`` the
            sibling folder named after the file (``instances_val2017.json`` -> ``../val2017``), else
            the JSON file's folder. ``file_name`` is relative to it.
        masks: decode segmentations into ``Sample.masks`` when a sample is read.
        include_crowd: keep ``iscrowd`` boxes (flagged in ``extras["iscrowd"]``).
        skip_empty: leave out images without (kept) annotations.
    Raises:
        ValueError: missing files; malformed records (the message names the file, the record and
            the field), an annotation of an unknown image or category.
    """
    root = Path(root)
    if root.is_dir():
        if split is None:
            found = sorted(p.stem.removeprefix("instances_") for p in (root / "annotations").glob("instances_*.json"))
            raise ValueError(f"split: {root} is a COCO folder; name a split (one of {found})")
        path = annotation_file(root, split)
        default_images = root / split
    else:
        path = root
        stem = path.stem.removeprefix("instances_")
        default_images = path.parent.parent / stem if path.parent.name == "annotations" else path.parent
    if not path.is_file():
        raise ValueError(f"root: COCO annotation file {path} not found")
    image_folder = Path(images) if images is not None else default_images
    data = load_json_object(path)
    image_records = _records(data, "images", path, ("id", "file_name", "width", "height"))
    category_records = _records(data, "categories", path, ("id", "name"))
    annotations = _records(data, "annotations", path, ())
    _check_ids(image_records, "images", path)
    _check_ids(category_records, "categories", path)
    for number, record in enumerate(image_records):
        if not all(_is_integer(record[key]) and 0 < record[key] <= MAX_IMAGE_SIDE for key in ("width", "height")):
            raise ValueError(f"{path}: images[{number}] (id {record['id']!r}), field 'width'/'height': expected "
                             f"integers in 1..{MAX_IMAGE_SIDE}, got {record['width']!r:.40}, {record['height']!r:.40}")
        path_inside(image_folder, record["file_name"], f"{path}: images[{number}] (id {record['id']!r}), field "
                                                       "'file_name'")
    categories = sorted(category_records, key=lambda record: record["id"])
    class_of = {record["id"]: position for position, record in enumerate(categories)}
    class_names = [str(record["name"]) for record in categories]
    images_by_id = {record["id"]: record for record in image_records}
    by_image: dict = {image_id: [] for image_id in images_by_id}
    for number, annotation in enumerate(annotations):
        _check_annotation(annotation, number, path, images_by_id, class_of)
        if include_crowd or not annotation.get("iscrowd", 0):
            by_image[annotation["image_id"]].append(number)
    order = [record["id"] for record in image_records if not skip_empty or by_image[record["id"]]]

    def read(position: int) -> Sample:
        image = images_by_id[order[position]]
        rows = [annotations[number] for number in by_image[image["id"]]]
        boxes = np.array([row["bbox"] for row in rows], dtype=np.float64).reshape(-1, 4)
        with np.errstate(over="ignore"):  # an overflowing box becomes inf, which check_sample refuses
            boxes[:, 2:] += boxes[:, :2]
        class_ids = np.array([class_of[row["category_id"]] for row in rows], dtype=np.int64)
        instance_masks = None
        if masks:
            instance_masks = np.zeros((len(rows), image["height"], image["width"]), dtype=bool)
            for slot, (number, row) in enumerate(zip(by_image[image["id"]], rows)):
                if "segmentation" in row:
                    instance_masks[slot] = mask_from_segmentation(
                        row["segmentation"], image["height"], image["width"],
                        f"{path}: annotations[{number}] (id {row['id']!r}), field 'segmentation'")
        keypoints = None
        with_keypoints = [row["keypoints"] for row in rows if "keypoints" in row]
        if with_keypoints:  # (x, y, visibility); a box without keypoints gets zeros (visibility 0)
            size = len(with_keypoints[0])
            if any(len(values) != size for values in with_keypoints):
                raise ValueError(f"{path}: image {image['id']!r}, field 'keypoints': annotations differ in their "
                                 f"number of keypoints")
            keypoints = np.array([row.get("keypoints", [0] * size) for row in rows],
                                 dtype=np.float64).reshape(len(rows), -1, 3)
        return Sample(image=image_folder / image["file_name"], boxes=boxes, class_ids=class_ids,
                      class_names=[class_names[i] for i in class_ids], masks=instance_masks, keypoints=keypoints,
                      extras={"iscrowd": np.array([bool(row.get("iscrowd", 0)) for row in rows], dtype=bool),
                              "category_ids": np.array([row["category_id"] for row in rows], dtype=np.int64),
                              "annotation_ids": [row["id"] for row in rows],
                              "area": np.array([row.get("area", 0.0) for row in rows], dtype=np.float64),
                              "image_id": image["id"], "image_size": (image["width"], image["height"])},
                      source=f"{path}: image id {image['id']}")

    return SampleSequence(len(order), read, class_names)
