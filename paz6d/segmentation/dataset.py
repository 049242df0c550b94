"""Training and evaluation crops for the mask head, cut from a ``paz6d generate`` data set (BOP layout).

Every annotated instance with a visible box (``scene_gt_info.json`` ``bbox_visib``) and a visible mask
(``mask_visib/``) becomes one sample: the image, the box, the class and the visible mask restricted to the
box (outside ``bbox_visib`` the visible mask is empty by definition, so nothing is lost). A training crop
is the square window of ``margin`` x the longer side of a *jittered* box (as a detector's box would be),
resampled to ``S x S``; its target is the visible mask cut the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from paz6d.backend.square_crop import crop_square, square_window
from paz6d.datasets.bop.coco_ground_truth import category_name
from paz6d.datasets.bop.models import MODELS_INFO, load_models_info
from paz6d.datasets.bop.reader import BOPDataset
from paz6d.segmentation.masks import jitter_box

#: Instances less visible than this are left out of training (BOP'19's threshold for targets).
MIN_VISIBLE_FRACTION = 0.1


@dataclass
class MaskInstance:
    """One object instance: ``image`` index into :attr:`MaskSet.images`, ``box`` ``xyxy`` pixels (visible box),
    ``class_id`` index into :attr:`MaskSet.class_names`, ``mask`` ``(h, w) bool`` the visible mask inside the
    integer box ``offset = (x, y)`` (``bbox_visib``'s corner), and the BOP ids."""

    image: int
    box: np.ndarray
    class_id: int
    mask: np.ndarray
    offset: tuple[int, int]
    scene_id: int
    im_id: int
    visib_fract: float


@dataclass
class MaskSet:
    """Images ``(H, W, 3) uint8`` of a split and its instances."""

    images: list[np.ndarray]
    instances: list[MaskInstance]
    class_names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.instances)


def class_names_of(root: str | Path) -> tuple[str, ...]:
    """``obj_XXXXXX`` names of the data set's models (``models/models_info.json``), in id order."""
    path = Path(root) / "models" / MODELS_INFO
    if not path.is_file():
        raise ValueError(f"{path}: file not found (is {root} a `paz6d generate` data set?)")
    return tuple(category_name(obj_id) for obj_id in sorted(load_models_info(path)))


def load_mask_set(root: str | Path, split: str = "train", min_visible_fraction: float = MIN_VISIBLE_FRACTION,
                  progress: bool = False) -> MaskSet:
    """Reads every image and visible mask of ``root/split``.

    Raises:
        ValueError: a missing split, ``scene_gt_info.json`` or ``mask_visib`` file (named), or no instance.
    """
    dataset = BOPDataset(root, split)
    names = class_names_of(root)
    images, instances = [], []
    for sample in tqdm(dataset, total=len(dataset), desc=f"reading {split}", disable=not progress, unit="image"):
        where = f"{Path(root) / split / f'{sample.scene_id:06d}'}: image {sample.im_id}"
        if sample.image is None:
            raise ValueError(f"{where}: rgb image not found")
        index = len(images)
        images.append(sample.image)
        for number, obj in enumerate(sample.objects):
            if obj.info is None or "bbox_visib" not in obj.info:
                raise ValueError(f"{where}, instance {number}: scene_gt_info.json lacks bbox_visib")
            if obj.mask_visib is None:
                raise ValueError(f"{where}, instance {number}: "
                                 f"mask_visib/{sample.im_id:06d}_{number:06d}.png not found")
            x, y, w, h = (int(value) for value in obj.info["bbox_visib"])
            visible = float(obj.info.get("visib_fract", 1.0))
            if w < 2 or h < 2 or visible < min_visible_fraction:
                continue
            name = category_name(obj.obj_id)
            if name not in names:
                raise ValueError(f"{where}, instance {number}: object {obj.obj_id} is not in models/models_info.json")
            instances.append(MaskInstance(index, np.array([x, y, x + w, y + h], np.float64), names.index(name),
                                          np.ascontiguousarray(obj.mask_visib[y:y + h, x:x + w]), (x, y),
                                          sample.scene_id, sample.im_id, visible))
    if not instances:
        raise ValueError(f"{Path(root) / split}: no instance with a visible box "
                         f"(visib_fract >= {min_visible_fraction})")
    return MaskSet(images, instances, names)


def cut_instance(data: MaskSet, instance: MaskInstance, box, size: int, margin: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(crop (S, S, 3) uint8, target (S, S) bool)``: the window around ``box`` of the instance's image and
    visible mask."""
    window = square_window(box, margin)
    crop = crop_square(data.images[instance.image], window, size)
    x, y = instance.offset
    mask_window = (window[0] - x, window[1] - y, window[2])
    height, width = instance.mask.shape
    if (mask_window[0] + window[2] <= 0 or mask_window[1] + window[2] <= 0 or mask_window[0] >= width
            or mask_window[1] >= height):
        return crop, np.zeros((size, size), bool)
    target = crop_square(instance.mask.astype(np.uint8) * 255, mask_window, size) >= 128
    return crop, target


def crop_batch(data: MaskSet, rng: np.random.Generator, batch_size: int, size: int, margin: float,
               jitter: float) -> dict[str, np.ndarray]:
    """A training batch of random instances: ``crops (B, S, S, 3) float32`` (0..255, brightness/contrast
    jittered), ``masks (B, S, S) float32`` in {0, 1} and ``class_ids (B,) int32``."""
    picks = rng.integers(0, len(data), batch_size)
    crops = np.empty((batch_size, size, size, 3), np.float32)
    masks = np.empty((batch_size, size, size), np.float32)
    class_ids = np.empty(batch_size, np.int32)
    for slot, pick in enumerate(picks):
        instance = data.instances[pick]
        crop, target = cut_instance(data, instance, jitter_box(instance.box, rng, jitter), size, margin)
        if rng.random() < 0.5:
            crop, target = crop[:, ::-1], target[:, ::-1]
        contrast, brightness = rng.uniform(0.7, 1.3), rng.uniform(-25, 25)
        crops[slot] = np.clip((crop.astype(np.float32) - 128) * contrast + 128 + brightness, 0, 255)
        masks[slot], class_ids[slot] = target, instance.class_id
    return {"crops": crops, "masks": masks, "class_ids": class_ids}
