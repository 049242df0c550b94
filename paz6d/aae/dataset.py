"""AAE training pairs streamed from a data set: BOP (e.g. ``paz6d generate`` output), YCB-Video or FAT.

Each annotated instance of the object gives one pair: the input is the square crop of the image around
its ground-truth box (:func:`paz6d.aae.model.crop_object`, the crop the pipeline makes at test time)
and the target is a clean rendering of the object at the ground-truth pose seen through the crop of its
whole-object box (the crop's intrinsics, :func:`paz6d.backend.square_crop.crop_intrinsics`), rendered in
worker processes that never import TensorFlow. The input's box is the whole object's (``crop_box="obj"``,
input and target through the same window) or, for BOP data sets, the visible part's (``"visib"``, what a
detector or a ground-truth visible box gives at test time: the model learns to see the whole object's
canonical view in the crop of a partly hidden one).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from paz6d.aae.config import check_crop_box
from paz6d.aae.model import crop_object
from paz6d.aae.views import render_at_transforms
from paz6d.backend.square_crop import crop_intrinsics, square_window
from paz6d.datasets.bop import BOPDataset
from paz6d.datasets.bop.fields import box_field
from paz6d.datasets.pose_crops import load_samples, object_instances


@dataclass(frozen=True)
class CropPairs:
    """``inputs`` and ``targets``: ``(N, S, S, 3)`` uint8 crops; ``T_model2cam``: ``(N, 4, 4)`` poses."""

    inputs: np.ndarray
    targets: np.ndarray
    T_model2cam: np.ndarray

    def __len__(self) -> int:
        return len(self.inputs)


def dataset_crops(root: str | Path, obj_id: int, crop_size: int, padding: float, split: str = "train",
                  min_visible_fraction: float = 0.1, progress: bool = True,
                  crop_box: str = "obj") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crops ``(N, S, S, 3)`` around each instance's ``bbox_obj`` or ``bbox_visib`` (``crop_box``), the
    intrinsics ``(N, 3, 3)`` of the crop of its whole-object box and its pose ``(N, 4, 4)``, for every
    instance of ``obj_id`` with both boxes and visible fraction >= ``min_visible_fraction``."""
    key = box_field(crop_box, "crop_box")
    dataset = BOPDataset(root, split=split)
    crops, Ks, poses = [], [], []
    for sample in tqdm(dataset, total=len(dataset), desc="read data set", unit="img", disable=not progress,
                       dynamic_ncols=True):
        for instance in sample.objects:
            info = instance.info or {}
            if instance.obj_id != obj_id or "bbox_obj" not in info or key not in info or sample.image is None:
                continue
            if info.get("visib_fract", 1.0) < min_visible_fraction:
                continue
            whole, seen = _corners(info["bbox_obj"]), _corners(info[key])
            if whole is None or seen is None:
                continue
            crops.append(crop_object(sample.image, seen, crop_size, padding))
            Ks.append(crop_intrinsics(sample.K, square_window(whole, padding), crop_size))
            poses.append(instance.T_model2cam)
    if not crops:
        raise ValueError(f"--dataset: {root} ({split} split) has no visible annotated instance of object {obj_id}")
    return np.stack(crops), np.stack(Ks), np.stack(poses)


def _corners(xywh) -> tuple[float, float, float, float] | None:
    """``(x_min, y_min, x_max, y_max)`` of a BOP ``[x, y, width, height]`` box; None when it is empty."""
    x, y, width, height = xywh
    return None if width <= 0 or height <= 0 else (x, y, x + width, y + height)


def sample_crops(root: str | Path, dataset_format: str, class_name: str, crop_size: int, padding: float,
                 split: str | None = None, min_visible_fraction: float = 0.1,
                 progress: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`dataset_crops` for a YCB-Video or FAT data set (:mod:`paz6d.datasets.pose_crops`): the crops
    around the data set's boxes of ``class_name``, their intrinsics and poses."""
    crops, Ks, poses = [], [], []
    samples = load_samples(root, dataset_format, split, masks=True)
    for instance in object_instances(samples, class_name, min_visible_fraction, progress):
        crops.append(crop_object(instance.image, instance.box, crop_size, padding))
        Ks.append(crop_intrinsics(instance.K, square_window(instance.box, padding), crop_size))
        poses.append(instance.T_model2cam)
    if not crops:
        raise ValueError(f"--dataset: {root} ({split} split) has no visible annotated instance of {class_name}")
    return np.stack(crops), np.stack(Ks), np.stack(poses)


def dataset_pairs(root: str | Path, obj_id: int, mesh_path: str | Path, mesh_scale: float, crop_size: int,
                  padding: float, split: str = "train", workers: int = 2, platform: str | None = None,
                  progress: bool = True, dataset_format: str = "bop", object_class: str | None = None,
                  crop_box: str = "obj") -> CropPairs:
    """Input crops from the data set (BOP: object ``obj_id``, cut around ``crop_box``; YCB-Video / FAT:
    ``object_class``, whole-object boxes) and clean targets rendered through the whole-object crop windows."""
    if dataset_format == "bop":
        inputs, Ks, poses = dataset_crops(root, obj_id, crop_size, padding, split, progress=progress,
                                          crop_box=crop_box)
    else:
        if check_crop_box(crop_box) != "obj":
            raise ValueError(f"crop_box: {crop_box!r} needs a BOP data set's visible boxes; {dataset_format} "
                             "crops are cut around the whole object (crop_box='obj')")
        inputs, Ks, poses = sample_crops(root, dataset_format, object_class, crop_size, padding, split,
                                         progress=progress)
    targets, _ = render_at_transforms(mesh_path, mesh_scale, Ks, poses, crop_size, workers, platform, progress=progress,
                              description="render targets")
    return CropPairs(inputs, targets, poses)
