"""PASCAL VOC detection annotations: a devkit year folder, or a bare folder of VOC XML files.

Layouts:

* devkit year folder (``VOCdevkit/VOC2007``): ``Annotations/<id>.xml``, ``ImageSets/Main/<split>.txt``
  (one image id per line; per-class lists ``<id> <flag>`` are read by their first column) and
  ``JPEGImages/<filename>``;
* bare folder: ``<root>/*.xml`` (every file, sorted by name); images are looked up in ``images``
  (default: ``root``) under the XML's ``<filename>``.

Box convention: VOC stores 1-based, inclusive pixel indices (``xmin = 1`` is the first pixel column,
and the object covers columns ``xmin..xmax``). paz6d boxes are continuous coordinates where pixel
``i`` (0-based) covers ``[i, i + 1)``, so the loader returns
``(xmin - 1, ymin - 1, xmax, ymax)``: the same pixels, and the width ``xmax - xmin + 1`` that VOC's
"+1 pixel" area uses (``evaluation.voc`` keeps the raw XML numbers and adds that pixel in its IoU
instead). ``voc_coordinates=True`` returns the raw XML numbers unchanged.

Each sample's ``extras`` hold ``difficult`` and ``truncated`` (``(N,) bool`` per box), ``image_id``
(the XML file stem), ``filename`` and ``image_size`` (``(width, height)`` from ``<size>``, or
``None`` when absent).

Example:
    >>> samples = load("VOCdevkit/VOC2007", "trainval", drop_difficult=True)  # doctest: +SKIP
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.backend.files import read_input_bytes, read_input_text
from paz6d.backend.paths import path_inside
from paz6d.datasets.sample import Sample, SampleSequence

#: The 20 PASCAL VOC classes, in the devkit's order (class id ``i`` is ``VOC_CLASSES[i]``).
VOC_CLASSES = ("aeroplane", "bicycle", "bird", "boat", "bottle", "bus", "car", "cat", "chair", "cow",
               "diningtable", "dog", "horse", "motorbike", "person", "pottedplant", "sheep", "sofa", "train",
               "tvmonitor")
ANNOTATIONS, IMAGE_SETS, IMAGES = "Annotations", Path("ImageSets") / "Main", "JPEGImages"
_FLAGS = {"0": False, "1": True}


def is_devkit_folder(root: str | Path) -> bool:
    """Whether ``root`` is a VOC devkit year folder (it holds ``Annotations/``)."""
    return (Path(root) / ANNOTATIONS).is_dir()


def is_voc_root(root: str | Path) -> bool:
    """Whether ``root`` is a devkit year folder or a folder holding VOC ``*.xml`` files."""
    root = Path(root)
    return root.is_dir() and (is_devkit_folder(root) or any(root.glob("*.xml")))


def split_ids(root: str | Path, split: str) -> list[str]:
    """Image ids of ``ImageSets/Main/<split>.txt`` (first column of each non-empty line)."""
    path = Path(root) / IMAGE_SETS / f"{split}.txt"
    if not path.is_file():
        available = sorted(p.stem for p in (Path(root) / IMAGE_SETS).glob("*.txt"))
        raise ValueError(f"split: {path} not found; the image sets of {root} are {available}")
    ids = [line.split()[0] for line in read_input_text(path, "VOC image-set file").splitlines() if line.strip()]
    seen: dict[str, int] = {}
    for number, image_id in enumerate(ids, start=1):
        path_inside(Path(root) / ANNOTATIONS, f"{image_id}.xml", f"{path}: image id #{number}")
        if image_id in seen:
            raise ValueError(f"{path}: image id #{number} {image_id!r:.60} is listed twice (also #{seen[image_id]})")
        seen[image_id] = number
    if not ids:
        raise ValueError(f"{path}: expected one image id per line, found none")
    return ids


def _flag(element: ElementTree.Element, tag: str, where: str) -> bool:
    text = (element.findtext(tag) or "0").strip()
    if text not in _FLAGS:
        raise ValueError(f"{where}, field <{tag}>: expected 0 or 1, got {text!r}")
    return _FLAGS[text]


def _number(element: ElementTree.Element, tag: str, where: str) -> float:
    text = element.findtext(tag)
    if text is None:
        raise ValueError(f"{where}, field <bndbox>/<{tag}>: missing; expected a number")
    try:
        value = float(text.strip())
    except ValueError:
        raise ValueError(f"{where}, field <bndbox>/<{tag}>: expected a number, got {text.strip()!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}, field <bndbox>/<{tag}>: expected a finite number, got {text.strip()!r}")
    return value


def read_annotation(path: str | Path, class_names: Sequence[str] | None = VOC_CLASSES,
                    voc_coordinates: bool = False) -> dict:
    """Parses one VOC XML annotation (the one VOC XML reader: data sets and ``evaluation.voc``).

    Args:
        path: the ``.xml`` file.
        class_names: known classes; an object of another class is an error (``None``: any name).
        voc_coordinates: keep the XML's 1-based inclusive numbers instead of paz6d pixel boxes.
    Returns:
        dict with ``filename``, ``image_size`` (``(width, height)`` or ``None``), ``names`` (N),
        ``boxes (N, 4) float64`` ``x_min, y_min, x_max, y_max`` pixels, ``difficult`` and
        ``truncated`` ``(N,) bool``.
    Raises:
        ValueError: malformed XML, a missing or non-numeric field, an unknown class, a box with
            ``xmax < xmin``; the message names the file, the ``<object>`` and the field.
    """
    path = Path(path)
    try:
        root = ElementTree.fromstring(read_input_bytes(path, "VOC XML annotation"))
    except ElementTree.ParseError as error:
        raise ValueError(f"{path}: malformed XML ({error}); expected a VOC <annotation> file") from None
    except RecursionError:
        raise ValueError(f"{path}: XML nested too deeply; expected a VOC <annotation> file") from None
    if root.tag != "annotation":
        raise ValueError(f"{path}: root element <{root.tag}>; expected a VOC <annotation>")
    size = root.find("size")
    image_size = None
    if size is not None and size.findtext("width") is not None:
        where = f"{path}, <size>"
        try:
            image_size = (int(size.findtext("width").strip()), int(size.findtext("height", "").strip()))
        except ValueError:
            raise ValueError(f"{where}, field <width>/<height>: expected integers, got "
                             f"{size.findtext('width')!r}, {size.findtext('height')!r}") from None
    known = None if class_names is None else set(class_names)
    names, boxes, difficult, truncated = [], [], [], []
    for number, element in enumerate(root.findall("object"), start=1):
        where = f"{path}, <object> #{number}"
        name = (element.findtext("name") or "").strip()
        if not name:
            raise ValueError(f"{where}, field <name>: missing; expected a class name")
        if known is not None and name not in known:
            raise ValueError(f"{where}, field <name>: unknown class {name!r}; expected one of {list(class_names)}")
        box_element = element.find("bndbox")
        if box_element is None:
            raise ValueError(f"{where} ({name}), field <bndbox>: missing")
        box = [_number(box_element, tag, where) for tag in ("xmin", "ymin", "xmax", "ymax")]
        if box[2] < box[0] or box[3] < box[1]:
            raise ValueError(f"{where}, field <bndbox>: xmax < xmin or ymax < ymin in {box}")
        if not voc_coordinates:
            box = [box[0] - 1.0, box[1] - 1.0, box[2], box[3]]
        names.append(name)
        boxes.append(box)
        difficult.append(_flag(element, "difficult", where))
        truncated.append(_flag(element, "truncated", where))
    return {"filename": (root.findtext("filename") or "").strip() or f"{path.stem}.jpg", "image_size": image_size,
            "names": names, "boxes": np.array(boxes, dtype=np.float64).reshape(-1, 4),
            "difficult": np.array(difficult, dtype=bool), "truncated": np.array(truncated, dtype=bool)}


def load(root: str | Path, split: str | None = None, drop_difficult: bool = False,
         class_names: Sequence[str] = VOC_CLASSES, images: str | Path | None = None,
         voc_coordinates: bool = False) -> SampleSequence:
    """A VOC data set as a lazy :class:`SampleSequence` (each XML is parsed when its sample is read).

    Args:
        root: a devkit year folder (``VOCdevkit/VOC2012``) or a folder of ``*.xml`` files.
        split: devkit image set (``train``, ``val``, ``trainval``, ``test``, or a per-class list);
            ``None`` takes every file of ``Annotations/``. A bare XML folder has no splits.
        drop_difficult: leave out boxes marked ``<difficult>1``.
        class_names: the classes (default :data:`VOC_CLASSES`); ``Sample.class_ids`` index them.
        images: image folder (default ``root/JPEGImages`` for a devkit folder, else ``root``).
        voc_coordinates: boxes as written in the XML (1-based, inclusive) instead of paz6d pixels.
    Raises:
        ValueError: a missing folder or image set, or (when a sample is read) a malformed XML file.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"root: VOC folder {root} does not exist")
    if is_devkit_folder(root):
        annotations = root / ANNOTATIONS
        ids = split_ids(root, split) if split is not None else sorted(p.stem for p in annotations.glob("*.xml"))
        paths = [annotations / f"{image_id}.xml" for image_id in ids]
        image_folder = Path(images) if images is not None else root / IMAGES
    else:
        if split is not None:
            raise ValueError(f"split: {root} is a bare folder of XML files (no ImageSets/); pass split=None")
        paths = sorted(root.glob("*.xml"))
        image_folder = Path(images) if images is not None else root
    if not paths:
        raise ValueError(f"root: {root} holds no VOC XML annotation (expected Annotations/*.xml or *.xml)")
    class_names = list(class_names)
    index = {name: position for position, name in enumerate(class_names)}

    def read(position: int) -> Sample:
        parsed = read_annotation(paths[position], class_names, voc_coordinates)
        keep = ~parsed["difficult"] if drop_difficult else np.ones(len(parsed["names"]), dtype=bool)
        names = [name for name, kept in zip(parsed["names"], keep) if kept]
        image = path_inside(image_folder, parsed["filename"], f"{paths[position]}, field <filename>")
        return Sample(image=image, boxes=parsed["boxes"][keep],
                      class_ids=np.array([index[name] for name in names], dtype=np.int64).reshape(-1),
                      class_names=names,
                      extras={"difficult": parsed["difficult"][keep], "truncated": parsed["truncated"][keep],
                              "image_id": paths[position].stem, "filename": parsed["filename"],
                              "image_size": parsed["image_size"]}, source=str(paths[position]))

    return SampleSequence(len(paths), read, class_names)
