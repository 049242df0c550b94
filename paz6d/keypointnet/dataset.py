"""KeypointNet training views cut from a BOP data set (e.g. the output of ``paz6d generate``).

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
    rgb, masks, intrinsics, poses = [], [], [], []
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
            window = square_window(mask_box(visible), margin)
            rgb.append(crop_square(sample.image, window, input_size))
            masks.append(crop_square(visible.astype(np.uint8) * 255, window, input_size) > 127)
            intrinsics.append(crop_intrinsics(sample.K, window, input_size))
            poses.append(instance.T_model2cam)
            if max_views is not None and len(rgb) >= max_views:
                break
        if max_views is not None and len(rgb) >= max_views:
            break
    if len(rgb) < 2:
        raise ValueError(f"{root}: found {len(rgb)} usable views of object {object_id} (non-empty visible mask, "
                         f"visible fraction >= {min_visible_fraction}); KeypointNet needs at least 2")
    views = ViewSet(np.stack(rgb), np.full((len(rgb), input_size, input_size), 255, np.uint8), np.stack(masks),
                    np.stack(intrinsics), np.stack(poses))
    return views, mesh_path, mesh_scale
