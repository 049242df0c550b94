"""Detection training data: a ``paz6d generate`` output or a VOC, COCO or Open Images folder, turned
into SSD batches.

``paz6d generate`` writes ``<dataset>/<split>/<scene>/scene_gt_coco.json`` (visible boxes, categories
named ``obj_XXXXXX``) next to ``rgb/``. VOC devkit (or bare XML) folders, COCO folders (or one
instances JSON file) and Open Images folders are read through :mod:`paz6d.datasets` (difficult VOC
boxes, COCO crowd boxes and Open Images group boxes are left out of training). :func:`load_detection_set`
reads a split of any of them (:func:`detect_format` tells them apart); :func:`training_batch` makes one
augmented batch as a pure function of ``(seed, step)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.abstract.processor import reseed
from paz6d.backend import boxes as boxes_backend
from paz6d.backend.files import load_json_object
from paz6d.backend.paths import path_inside
from paz6d.backend.image import load_image, resize
from paz6d.datasets import coco, openimages, voc
from paz6d.datasets.sample import Sample, SampleSequence, check_sample
from paz6d.ssd.config import DATASET_FORMATS
from paz6d.ssd.encoding import encode_targets
from paz6d.synthesis.box_augment import AnnotatedImage

COCO_FILE = "scene_gt_coco.json"
#: Values of ``--format`` (``auto``: :func:`detect_format`).
FORMATS = DATASET_FORMATS


@dataclass(frozen=True)
class DetectionSample:
    """One annotated image: ``path``, ``boxes (N, 4)`` ``xyxy`` pixels and ``class_ids (N,)`` (1-based,
    indices into the set's ``class_names`` + 1)."""

    path: Path
    boxes: np.ndarray
    class_ids: np.ndarray


@dataclass(frozen=True)
class DetectionSet:
    """A split's samples and its class names (class id ``i`` is ``class_names[i - 1]``; sorted for a
    generated set, the data set's own order for VOC, COCO and Open Images)."""

    class_names: tuple[str, ...]
    samples: tuple[DetectionSample, ...]

    def __len__(self) -> int:
        return len(self.samples)


def default_split(dataset: Path) -> str:
    """``train`` when ``dataset/train`` exists, else the only split folder holding COCO annotations."""
    if (dataset / "train").is_dir():
        return "train"
    splits = sorted(path.parent.parent.name for path in dataset.glob(f"*/*/{COCO_FILE}"))
    if len(set(splits)) != 1:
        raise ValueError(f"dataset: {dataset} has no 'train' split and {len(set(splits))} splits with "
                         f"{COCO_FILE} files ({sorted(set(splits))}); name one with --split")
    return splits[0]


def _load_generated(dataset: str | Path, split: str | None = None,
                       class_names: tuple[str, ...] | None = None) -> DetectionSet:
    """Reads every ``<dataset>/<split>/*/scene_gt_coco.json`` (a ``paz6d generate`` output).

    Args:
        dataset: data set folder (BOP layout, as ``paz6d generate`` writes).
        split: split folder (default: :func:`default_split`).
        class_names: the classes to use (e.g. a trained model's); default: every category, sorted.
    Raises:
        ValueError: no annotation file or no annotated image (empty data set), a category outside
            ``class_names``, malformed annotations; messages name the file.
    """
    dataset = Path(dataset)
    if not dataset.is_dir():
        raise ValueError(f"dataset: {dataset} is not a directory")
    split = default_split(dataset) if split is None else split
    files = sorted((dataset / split).glob(f"*/{COCO_FILE}"))
    if not files:
        raise ValueError(f"dataset: no {COCO_FILE} in {dataset / split}/<scene>/ (is it a `paz6d generate` output?)")
    contents = [(path, load_json_object(path)) for path in files]
    try:
        names = sorted({str(category["name"]) for _, document in contents
                        for category in document.get("categories", [])})
    except (KeyError, TypeError) as error:
        raise ValueError(f"dataset: {dataset / split}: a {COCO_FILE} holds a malformed 'categories' list "
                         f"({type(error).__name__}: {error})") from error
    if class_names is None:
        class_names = tuple(names)
    index = {name: position + 1 for position, name in enumerate(class_names)}
    samples = []
    for path, document in contents:
        try:
            category_names = {category["id"]: category["name"] for category in document["categories"]}
            annotations: dict[int, list] = {}
            for annotation in document["annotations"]:
                annotations.setdefault(annotation["image_id"], []).append(annotation)
            for image in document["images"]:
                rows = [a for a in annotations.get(image["id"], []) if not a.get("iscrowd", 0) and not a.get("ignore")]
                unknown = sorted({category_names[a["category_id"]] for a in rows} - set(index))
                if unknown:
                    raise ValueError(f"{path}: unknown class(es) {unknown}; the classes are {list(class_names)}")
                where = f"{path}: image id {image['id']!r:.40}"
                try:
                    boxes = np.asarray([a["bbox"] for a in rows], dtype=np.float64).reshape(-1, 4)
                except ValueError as error:
                    raise ValueError(f"{where}, field 'bbox': expected [x, y, w, h] numbers ({error})") from None
                with np.errstate(over="ignore", invalid="ignore"):
                    boxes = boxes_backend.convert(boxes, "xywh", "xyxy")
                ids = np.asarray([index[category_names[a["category_id"]]] for a in rows], dtype=np.int64)
                file = path_inside(path.parent, image["file_name"], f"{where}, field 'file_name'")
                size = (image["width"], image["height"]) if "width" in image and "height" in image else None
                check_sample(Sample(file, boxes, ids, [category_names[a["category_id"]] for a in rows],
                                    extras={"image_size": size}, source=where))
                keep = np.all(boxes[:, 2:] > boxes[:, :2], axis=1)
                if np.any(keep):
                    samples.append(DetectionSample(file, boxes[keep], ids[keep]))
        except (KeyError, TypeError, AttributeError) as error:
            raise ValueError(f"{path}: malformed COCO annotations ({type(error).__name__}: {error})") from error
    if not samples:
        raise ValueError(f"dataset: {dataset / split} holds no annotated image (empty data set)")
    if not class_names:
        raise ValueError(f"dataset: {dataset / split} has no categories")
    return DetectionSet(tuple(class_names), tuple(samples))


def detect_format(dataset: str | Path) -> str:
    """The format of a data set folder: ``generated`` (``<split>/<scene>/scene_gt_coco.json``), ``voc``
    (``Annotations/`` or ``*.xml``), ``coco`` (``annotations/instances_*.json``, or a JSON file) or
    ``openimages`` (``*-annotations-bbox.csv``).

    Raises:
        ValueError: none of them, naming the folder and what each format needs.
    """
    dataset = Path(dataset)
    if dataset.is_dir() and any(dataset.glob(f"*/*/{COCO_FILE}")):
        return "generated"
    if coco.is_coco_root(dataset):
        return "coco"
    if dataset.is_dir() and voc.is_voc_root(dataset):
        return "voc"
    if openimages.is_openimages_root(dataset):
        return "openimages"
    raise ValueError(f"dataset: cannot tell the format of {dataset}: expected a `paz6d generate` output "
                     f"(<split>/<scene>/{COCO_FILE}), a VOC folder (Annotations/*.xml or *.xml), a COCO folder "
                     "(annotations/instances_<split>.json) or an Open Images folder (<split>-annotations-bbox.csv); "
                     "or name it with --format")


def _default_split(dataset: Path, dataset_format: str) -> str | None:
    """``train``-like split of a VOC, COCO or Open Images folder (``None``: the format has no splits)."""
    if dataset_format == "voc":
        if not voc.is_devkit_folder(dataset):
            return None
        for split in ("trainval", "train"):
            if (dataset / voc.IMAGE_SETS / f"{split}.txt").is_file():
                return split
        return None
    if dataset_format == "coco":
        if dataset.is_file():
            return None
        splits = sorted(p.stem.removeprefix("instances_") for p in (dataset / "annotations").glob("instances_*.json"))
        if not splits:
            raise ValueError(f"dataset: {dataset} has no COCO annotations/instances_<split>.json")
        training = [split for split in splits if split.startswith("train")]
        if len(training) == 1 or len(splits) == 1:
            return (training or splits)[0]
        raise ValueError(f"dataset: {dataset} has the COCO splits {splits}; name one with --split")
    for split in ("train", "validation", "test"):
        if openimages.find_files(dataset, split)["boxes"] is not None:
            return split
    return "train"


def samples_to_detection_set(samples: SampleSequence, source: str,
                             class_names: tuple[str, ...] | None = None) -> DetectionSet:
    """A :class:`DetectionSet` of a loader's samples: images with at least one box of positive size,
    class ids shifted past the background (1-based).

    Args:
        samples: from :mod:`paz6d.datasets` (``Sample.image`` a path).
        source: what the samples come from (for messages).
        class_names: the classes to use (e.g. a trained model's); default the data set's.
    """
    names = tuple(samples.class_names) if class_names is None else tuple(class_names)
    index = {name: position + 1 for position, name in enumerate(names)}
    kept = []
    for sample in samples:
        unknown = sorted(set(sample.class_names) - set(index))
        if unknown:
            raise ValueError(f"{source}: image {sample.image}: unknown class(es) {unknown}; the classes are "
                             f"{list(names)}")
        boxes = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 4)
        ids = np.array([index[name] for name in sample.class_names], dtype=np.int64)
        keep = np.all(boxes[:, 2:] > boxes[:, :2], axis=1)
        if np.any(keep):
            kept.append(DetectionSample(Path(sample.image), boxes[keep], ids[keep]))
    if not kept:
        raise ValueError(f"dataset: {source} holds no annotated image (empty data set)")
    if not names:
        raise ValueError(f"dataset: {source} has no classes")
    return DetectionSet(names, tuple(kept))


def load_detection_set(dataset: str | Path, split: str | None = None, class_names: tuple[str, ...] | None = None,
                       dataset_format: str = "auto") -> DetectionSet:
    """Reads a detection data set of any supported format.

    Args:
        dataset: a ``paz6d generate`` output, a VOC devkit year folder (or folder of XML files), a COCO
            folder (or instances JSON file) or an Open Images folder.
        split: split (generated: ``train`` or the only one; VOC: ``trainval``/``train``; COCO: the
            ``train*`` instances file; Open Images: ``train``, else ``validation``).
        class_names: the classes to use (e.g. a trained model's); default: the data set's.
        dataset_format: one of :data:`FORMATS`.
    Raises:
        ValueError: an unknown format, no annotated image (empty data set), a class outside
            ``class_names``, malformed annotations; messages name the file.
    """
    if dataset_format not in FORMATS:
        raise ValueError(f"format: expected one of {FORMATS}, got {dataset_format!r}")
    dataset = Path(dataset)
    if not dataset.exists():
        raise ValueError(f"dataset: {dataset} does not exist")
    if dataset_format == "auto":
        dataset_format = detect_format(dataset)
    if dataset_format == "generated":
        return _load_generated(dataset, split, class_names)
    split = _default_split(dataset, dataset_format) if split is None else split
    if dataset_format == "voc":
        samples = voc.load(dataset, split, drop_difficult=True)
    elif dataset_format == "coco":
        samples = coco.load(dataset, split, masks=False, include_crowd=False)
    else:
        samples = openimages.load(dataset, split or "train", include_group_of=False)
    where = f"{dataset_format} data set {dataset}" + (f", split {split}" if split else "")
    return samples_to_detection_set(samples, where, class_names)


def prepare_sample(sample: AnnotatedImage, input_size: int, priors: np.ndarray, num_classes: int,
                   iou_threshold: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Resizes an (augmented) sample to ``input_size`` and encodes its boxes: ``(image (S, S, 3) uint8,
    target (P, 4 + C) float32)``."""
    height, width = sample.image.shape[:2]
    image = resize(sample.image, (input_size, input_size))
    boxes = boxes_backend.normalize(sample.boxes, (width, height)) if len(sample.boxes) else sample.boxes
    return image, encode_targets(boxes, sample.class_ids, priors, num_classes, iou_threshold)


def training_batch(data: DetectionSet, augmentation: Callable[[], Callable] | None, seed: int, step: int,
                   batch_size: int, input_size: int,
                   priors: np.ndarray, iou_threshold: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Batch ``step``: ``images (B, S, S, 3)`` uint8 and ``targets (B, P, 4 + C)`` float32.

    Sample ``b`` is image ``rng.integers(len(data))`` of ``rng = default_rng([seed, step, b])``, augmented
    by a processor over :class:`AnnotatedImage` that ``augmentation()`` makes (one per batch, so batches
    can be made in several threads), reseeded per sample: a batch depends only on ``(seed, step)``.
    """
    chain = augmentation() if augmentation is not None else None
    images, targets = [], []
    for slot in range(batch_size):
        generator = np.random.default_rng([seed, step, slot])
        sample = data.samples[int(generator.integers(len(data)))]
        annotated = AnnotatedImage(load_image(sample.path), sample.boxes, sample.class_ids)
        if chain is not None:
            reseed(chain, [seed, step, slot, 1])
            annotated = chain(annotated)
        image, target = prepare_sample(annotated, input_size, priors, len(data.class_names) + 1, iou_threshold)
        images.append(image)
        targets.append(target)
    return np.stack(images), np.stack(targets)
