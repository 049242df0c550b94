"""A BOP split as COCO detection ground truth (the BOP 2D detection task's boxes), for ``paz6d evaluate coco``.

Every instance of ``scene_gt.json`` becomes an annotation whose box is its ``bbox_visib`` from
``scene_gt_info.json`` (``x, y, w, h`` pixels, the box of its visible mask). As in the BOP 2D
detection task, instances whose visible fraction is below ``min_visible_fraction`` (0.1) are not
targets: they are kept as ``iscrowd`` regions, so a detection on them is neither a hit nor a false
positive; instances with no visible pixel are left out. Categories are ``obj_XXXXXX`` (the names
``paz6d generate`` gives), with the BOP object id as category id.

Image ids are :func:`coco_image_id` ``(scene_id, im_id)``, unique over a split's scenes.

Example:
    >>> coco = bop_split_to_coco("../shared/data/bop_lmo", "test")          # doctest: +SKIP
    >>> write_json_atomically("lmo_gt.json", coco)                          # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

from paz6d.backend.paths import check_plain_name
from paz6d.backend.image import load_image
from paz6d.datasets.bop.camera import load_camera
from paz6d.datasets.bop.fields import entries_by_id, required_field
from paz6d.datasets.bop.models import MODELS_INFO
from paz6d.datasets.bop.scene import find_image, load_scene_gt_info
from paz6d.datasets.bop.targets import TARGET_MIN_VISIBLE_FRACTION

#: ``coco_image_id = scene_id * IMAGE_ID_STRIDE + im_id``.
IMAGE_ID_STRIDE = 1_000_000


def coco_image_id(scene_id: int, im_id: int) -> int:
    """The COCO image id of BOP image ``(scene_id, im_id)``."""
    if not 0 <= int(im_id) < IMAGE_ID_STRIDE or int(scene_id) < 0:
        raise ValueError(f"im_id/scene_id: expected 0 <= im_id < {IMAGE_ID_STRIDE} and scene_id >= 0, "
                         f"got {im_id}, {scene_id}")
    return int(scene_id) * IMAGE_ID_STRIDE + int(im_id)


def category_name(obj_id: int) -> str:
    """``obj_XXXXXX``, the class name of BOP object ``obj_id``."""
    return f"obj_{int(obj_id):06d}"


def bop_split_to_coco(root: str | Path, split: str = "test", min_visible_fraction: float = TARGET_MIN_VISIBLE_FRACTION,
                      scene_ids: list[int] | None = None, require_images: bool = True) -> dict:
    """COCO ground truth (``images``, ``annotations``, ``categories``) of a BOP split.

    Args:
        root: BOP data set folder (``<root>/<split>/<scene>/scene_gt.json``, ``scene_gt_info.json``).
        split: split folder.
        min_visible_fraction: instances below it become ignored (``iscrowd``) regions.
        scene_ids: scenes to convert (default: every numeric folder).
        require_images: only images whose RGB file exists (e.g. a subset of frames was downloaded).
    Raises:
        ValueError: missing split/scene files, missing fields (the message names file, image and field),
            no image at all.
    """
    root = Path(root)
    check_plain_name(split, "split")
    folder = root / split
    if not folder.is_dir():
        raise ValueError(f"{folder}: split folder not found")
    if scene_ids is None:
        scene_ids = sorted(int(path.name) for path in folder.iterdir() if path.is_dir() and path.name.isdigit())
    camera = load_camera(root / "camera.json") if (root / "camera.json").is_file() else None
    images, annotations, obj_ids = [], [], set()
    for scene_id in scene_ids:
        scene = folder / f"{scene_id:06d}"
        ground_truth = entries_by_id(scene / "scene_gt.json")
        infos = load_scene_gt_info(scene / "scene_gt_info.json")
        for im_id, entries in ground_truth.items():
            image_path = find_image(scene / "rgb", im_id)
            if image_path is None and require_images:
                continue
            if im_id not in infos or len(infos[im_id]) != len(entries):
                raise ValueError(f"{scene / 'scene_gt_info.json'}: image {im_id}: expected {len(entries)} instances "
                                 f"as in scene_gt.json, got {len(infos.get(im_id, []))}")
            image_id = coco_image_id(scene_id, im_id)
            width, height = _image_size(camera, image_path)
            name = image_path.relative_to(root).as_posix() if image_path is not None else None
            images.append({"id": image_id, "file_name": name, "width": width, "height": height,
                           "scene_id": scene_id, "im_id": im_id})
            for index, (entry, info) in enumerate(zip(entries, infos[im_id])):
                where = f"{scene / 'scene_gt.json'}: image {im_id}, instance {index}"
                obj_id = int(required_field(entry, "obj_id", where))
                obj_ids.add(obj_id)
                x, y, w, h = (float(v) for v in info["bbox_visib"])
                if w <= 0 or h <= 0:
                    continue
                ignored = float(info["visib_fract"]) < min_visible_fraction
                annotations.append({"id": len(annotations) + 1, "image_id": image_id, "category_id": obj_id,
                                    "bbox": [x, y, w, h], "area": w * h, "iscrowd": int(ignored),
                                    "visib_fract": float(info["visib_fract"])})
    if not images:
        raise ValueError(f"{folder}: no image to convert (scenes {scene_ids}; require_images={require_images})")
    obj_ids |= _model_ids(root)
    categories = [{"id": obj_id, "name": category_name(obj_id),
                   "supercategory": "object"} for obj_id in sorted(obj_ids)]
    return {"info": {"description": f"BOP {root.name} {split}: visible boxes, visib_fract >= {min_visible_fraction}"},
            "images": images, "annotations": annotations, "categories": categories}


def _image_size(camera, image_path: Path | None) -> tuple[int, int]:
    if camera is not None:
        return int(camera.width), int(camera.height)
    if image_path is None:
        raise ValueError("camera.json: needed for the image size when RGB files are absent")
    height, width = load_image(image_path).shape[:2]
    return int(width), int(height)


def _model_ids(root: Path) -> set[int]:
    """Object ids listed in ``models/models_info.json`` (none when the file is absent)."""
    path = root / "models" / MODELS_INFO
    return set(entries_by_id(path, "object")) if path.is_file() else set()

