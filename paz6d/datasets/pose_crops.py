"""One adapter from the sample-based 6D-pose loaders (YCB-Video, FAT) to what the pose trainers consume:
per annotated instance of one object, the image, its box, visible mask, intrinsics and ``T_model2cam``.

``paz6d train aae --dataset`` cuts its input crops from these records (:func:`paz6d.aae.dataset.dataset_crops`)
and ``paz6d train keypointnet --dataset`` its views (:func:`paz6d.keypointnet.dataset.sample_object_views`);
BOP data sets keep their own reader (:mod:`paz6d.datasets.bop`). :func:`pose_dataset` resolves the data set,
the object class and its mesh: YCB-Video's ``models/<class>/textured.obj`` (metres) or ``--dataset-mesh``
(FAT ships no meshes; its poses are those of the original YCB ``google_16k`` models, see
:mod:`paz6d.datasets.fat`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from paz6d.backend.image import load_image
from paz6d.datasets import fat, ycb_video
from paz6d.datasets.pose_format import DEFAULT_SPLITS, check_pose_split
from paz6d.datasets.sample import SampleSequence


@dataclass(frozen=True)
class ObjectInstance:
    """One annotated instance of an object.

    Attributes:
        image: ``(H, W, 3)`` uint8 RGB of its frame.
        box: ``(4,)`` ``x_min, y_min, x_max, y_max`` pixels (the data set's box).
        mask: ``(H, W)`` bool visible mask, or None when the data set has none.
        T_model2cam: ``(4, 4)`` pose, metres.
        K: ``(3, 3)`` intrinsics of ``image``.
        visible_fraction: the data set's visibility (FAT), or None.
        frame: the frame's name in the data set.
    """

    image: np.ndarray
    box: np.ndarray
    mask: np.ndarray | None
    T_model2cam: np.ndarray
    K: np.ndarray
    visible_fraction: float | None
    frame: str


@dataclass(frozen=True)
class PoseDataset:
    """A data set resolved for one object: its samples, the object's class name, mesh and mesh scale."""

    samples: SampleSequence
    class_name: str
    mesh_path: Path
    mesh_scale: float
    split: str


def load_samples(root: str | Path, dataset_format: str, split: str | None = None, masks: bool = True) -> SampleSequence:
    """The :class:`SampleSequence` of a YCB-Video or FAT data set (``split`` default: ``train`` / ``mixed``)."""
    split = check_pose_split(DEFAULT_SPLITS[dataset_format] if split is None else split, dataset_format)
    if dataset_format == "ycb_video":
        return ycb_video.load(root, split, masks=masks)
    if dataset_format == "fat":
        return fat.load(root, split, masks=masks)
    raise ValueError(f"format: expected ycb_video or fat for the sample loaders, got {dataset_format!r}")


def resolve_class(class_names: list[str], object_class: str | None, object_id: int | None, where: str) -> str:
    """The data set's name of the chosen object: ``object_class`` (FAT's ``_16k`` suffix optional),
    ``object_id`` (1-based class index, as YCB-Video's label images and BOP YCB-V ids) or the only class.

    Raises:
        ValueError: ``"object_class: ..."`` / ``"object_id: ..."`` naming the classes of ``where``.
    """
    if object_class is not None and object_id is not None:
        raise ValueError("object_class: give --object-class or --object-id, not both")
    if object_class is not None:
        for name in (object_class, f"{object_class}_16k"):
            if name in class_names:
                return name
        raise ValueError(f"object_class: no class {object_class!r} in {where} (classes: {class_names})")
    if object_id is not None:
        if not 1 <= object_id <= len(class_names):
            raise ValueError(f"object_id: expected a class index in 1..{len(class_names)} of {where}, got {object_id}")
        return class_names[object_id - 1]
    if len(class_names) != 1:
        raise ValueError(f"object_class: {where} has {len(class_names)} classes; choose one with --object-class "
                         f"(classes: {class_names})")
    return class_names[0]


def pose_dataset(root: str | Path, dataset_format: str, split: str | None = None, object_class: str | None = None,
                 object_id: int | None = None, mesh: str | Path | None = None,
                 mesh_scale: float | None = None) -> PoseDataset:
    """Resolves a YCB-Video or FAT data set for training on one object.

    Args:
        root: data set folder.
        dataset_format: ``"ycb_video"`` or ``"fat"``.
        split: see :func:`load_samples`.
        object_class / object_id: the object (see :func:`resolve_class`).
        mesh: the object's mesh (``--dataset-mesh``); default YCB-Video's ``models/<class>/textured.obj``
            (FAT: required).
        mesh_scale: mesh units to metres (default 1: YCB meshes are metres).
    Raises:
        ValueError: naming the setting (``dataset_mesh:``, ``object_class:``, ``split:``) or the file.
    """
    root = Path(root)
    samples = load_samples(root, dataset_format, split)
    class_name = resolve_class(samples.class_names, object_class, object_id, f"{root} ({dataset_format})")
    if mesh is None:
        if dataset_format == "fat":
            raise ValueError(f"dataset_mesh: FAT data sets ship no meshes; pass the YCB mesh of {class_name} with "
                             "--dataset-mesh (e.g. <ycb models>/<class>/google_16k/textured.obj, metres)")
        mesh = ycb_video.model_mesh_path(root, class_name)
    mesh = Path(mesh)
    if not mesh.is_file():
        raise ValueError(f"dataset_mesh: {mesh}: mesh file not found")
    return PoseDataset(samples, class_name, mesh, 1.0 if mesh_scale is None else float(mesh_scale),
                       DEFAULT_SPLITS[dataset_format] if split is None else split)


def object_instances(samples: SampleSequence, class_name: str, min_visible_fraction: float = 0.0,
                     progress: bool = True) -> Iterator[ObjectInstance]:
    """Every instance of ``class_name`` with a non-empty box (and visible mask, where the data set has
    masks) whose visibility (where known) is at least ``min_visible_fraction``, frame by frame.

    Images are read only for frames that hold the object.
    """
    for sample in tqdm(samples, total=len(samples), desc="read data set", unit="img", disable=not progress,
                       dynamic_ncols=True):
        wanted = [index for index, name in enumerate(sample.class_names) if name == class_name]
        if not wanted:
            continue
        image = load_image(sample.image) if not isinstance(sample.image, np.ndarray) else sample.image
        visibility = sample.extras.get("visibility")
        for index in wanted:
            box = sample.boxes[index]
            mask = None if sample.masks is None else sample.masks[index]
            fraction = None if visibility is None or not np.isfinite(visibility[index]) else float(visibility[index])
            if box[2] <= box[0] or box[3] <= box[1] or (mask is not None and not mask.any()):
                continue
            if fraction is not None and fraction < min_visible_fraction:
                continue
            yield ObjectInstance(image, np.asarray(box, dtype=np.float64), mask, sample.poses[index],
                                 sample.camera_matrix, fraction, str(sample.extras.get("frame", "")))
