"""KeypointNet training views cut from a data set: BOP (e.g. the output of ``paz6d generate``), YCB-Video or FAT.

Every annotated instance of the chosen object that is visible enough becomes one
:class:`~paz6d.keypointnet.views.ViewSet` entry: the square crop around its visible box
(``margin`` × the longer side) resized to ``input_size``, its visible mask, the crop intrinsics
and the ground-truth pose. The image's own background is kept (``alpha`` = 255 everywhere), so
batch-time background replacement leaves it untouched.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend.image import mask_box
from paz6d.backend.square_crop import crop_intrinsics, crop_square, square_window
from paz6d.datasets.bop import BOPDataset, load_models_info, model_path
from paz6d.datasets.bop.units import MM_PER_M
from paz6d.datasets.pose_crops import object_instances, pose_dataset
from paz6d.keypointnet.views import ViewSet


def _default_split(root: Path) -> str:
    for split in ("train_pbr", "train"):
        if (root / split).is_dir():
            return split
    raise ValueError(f"{root}: no train_pbr/ or train/ split folder; pass --split")


def bop_object_views(root: str | Path, object_id: int | None = None, split: str | None = None,
                     input_size: int = 128, mesh_scale: float = 1.0 / MM_PER_M, margin: float = 1.25,
                     min_visible_fraction: float = 0.6, max_views: int | None = None) -> tuple[ViewSet, Path, float]:
    """Crops of one object from a BOP data set.

    Args:
        root: data set folder (``models/``, ``<split>/<scene>/``).
        object_id: BOP object id (default: the first one in ``models/models_info.json``).
        split: split folder (default ``train_pbr``, else ``train``).
        mesh_scale: factor from the model file's units to metres (BOP: millimetres, 0.001).
        min_visible_fraction: instances less visible than this (``visib_fract`` or mask ratio) are skipped.
        max_views: stop after this many views.
    Returns:
        ``(views, mesh_path, mesh_scale)``.
    Raises:
        ValueError: missing folders/files, or no usable view of the object (e.g. all masks empty).
    """
    root = Path(root)
    models_info = load_models_info(root / "models" / "models_info.json")
    if object_id is None:
        object_id = next(iter(models_info))
    if object_id not in models_info:
        raise ValueError(f"{root / 'models' / 'models_info.json'}: no object id {object_id} "
                         f"(have {sorted(models_info)})")
    mesh_path = model_path(root / "models", object_id)
    if not mesh_path.is_file():
        raise ValueError(f"{mesh_path}: model file of object {object_id} not found")
    dataset = BOPDataset(root, split or _default_split(root))
    views: list = []
    for sample in dataset:
        if sample.image is None:
            continue
        for instance in sample.objects:
            if instance.obj_id != object_id or instance.mask_visib is None or not instance.mask_visib.any():
                continue
            visible = instance.mask_visib
            fraction = (instance.info or {}).get("visib_fract")
            if fraction is None and instance.mask is not None and instance.mask.any():
                fraction = visible.sum() / instance.mask.sum()
            if fraction is not None and fraction < min_visible_fraction:
                continue
            _add_view(views, sample.image, visible, sample.K, instance.T_model2cam, margin, input_size)
            if max_views is not None and len(views) >= max_views:
                break
        if max_views is not None and len(views) >= max_views:
            break
    return _view_set(views, input_size, f"{root}: found {len(views)} usable views of object {object_id}",
                     min_visible_fraction), mesh_path, mesh_scale


def _add_view(views: list, image: np.ndarray, visible: np.ndarray, K: np.ndarray, T_model2cam: np.ndarray,
              margin: float, input_size: int) -> None:
    """Appends ``(rgb, mask, K, pose)`` of the square crop around the ``visible`` mask's box."""
    window = square_window(mask_box(visible), margin)
    views.append((crop_square(image, window, input_size),
                  crop_square(visible.astype(np.uint8) * 255, window, input_size) > 127,
                  crop_intrinsics(K, window, input_size), T_model2cam))


def _view_set(views: list, input_size: int, found: str, min_visible_fraction: float) -> ViewSet:
    if len(views) < 2:
        raise ValueError(f"{found} (non-empty visible mask, visible fraction >= {min_visible_fraction}); "
                         "KeypointNet needs at least 2")
    rgb, masks, intrinsics, poses = (np.stack(column) for column in zip(*views))
    return ViewSet(rgb, np.full((len(rgb), input_size, input_size), 255, np.uint8), masks, intrinsics, poses)


def sample_object_views(root: str | Path, dataset_format: str, split: str | None = None,
                        object_class: str | None = None, object_id: int | None = None, mesh: str | Path | None = None,
                        mesh_scale: float | None = None, input_size: int = 128, margin: float = 1.25,
                        min_visible_fraction: float = 0.6, max_views: int | None = None,
                        progress: bool = True) -> tuple[ViewSet, Path, float]:
    """:func:`bop_object_views` for a YCB-Video or FAT data set (through :mod:`paz6d.datasets.pose_crops`):
    crops around the visible masks of one class.

    Args:
        root, dataset_format, split, object_class, object_id, mesh, mesh_scale: see
            :func:`paz6d.datasets.pose_crops.pose_dataset` (default mesh: YCB-Video's ``textured.obj``).
        min_visible_fraction: FAT instances less visible than this are skipped (YCB-Video has no visibility).
    Returns:
        ``(views, mesh_path, mesh_scale)``.
    Raises:
        ValueError: a bad setting or file, or fewer than 2 usable views.
    """
    source = pose_dataset(root, dataset_format, split, object_class, object_id, mesh, mesh_scale)
    views: list = []
    for instance in object_instances(source.samples, source.class_name, min_visible_fraction, progress):
        if instance.mask is None:
            raise ValueError(f"{root}: frame {instance.frame} has no masks; KeypointNet views need them")
        _add_view(views, instance.image, instance.mask, instance.K, instance.T_model2cam, margin, input_size)
        if max_views is not None and len(views) >= max_views:
            break
    found = f"{root} ({dataset_format}, split {source.split}): found {len(views)} usable views of {source.class_name}"
    return _view_set(views, input_size, found, min_visible_fraction), source.mesh_path, source.mesh_scale
