"""The BOP layout on disk (millimetres), per-image annotation shards and their merge.

::

    <out>/camera.json, models/obj_XXXXXX.ply (mm), models/models_info.json
    <out>/<split>/<scene>/rgb|depth|mask|mask_visib/..., scene_gt.json, scene_camera.json,
        scene_gt_info.json, scene_gt_coco.json [, crop_rgb/, crop_mask/, crops.json]
    <out>/test_targets_bop19.json (split ``test`` only: instances with visib_fract >= 0.1)
    <out>/.paz6d-generate/config.json and shards/<split>/<scene>/<im>.json (one per finished image)

A shard is written last for each image, so its presence means the image is complete; the scene
JSON files are rebuilt from the shards (atomically) at the end of every run. The BOP files and
entries themselves (millimetres) come from :mod:`paz6d.datasets.bop.writer`, which takes metres.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np

from data_gen.assets import Assets
from data_gen.coco import encode_rle
from data_gen.config import CONTENTS_KEY, STATE_FOLDER, GenerationConfig
from paz6d.backend.files import json_bytes, load_json, write_json_atomically
from paz6d.datasets.bop.targets import TARGETS_FILE, targets_from_gt, write_targets
from paz6d.datasets.bop.writer import gt_entry, scene_camera_entry, write_camera, write_models



def image_location(index: int, images_per_scene: int) -> tuple[int, int]:
    """``(scene_id, im_id)`` of the ``index``-th image."""
    return index // images_per_scene, index % images_per_scene


def scene_folder(config: GenerationConfig, scene_id: int) -> Path:
    return config.out / config.split / f"{scene_id:06d}"


def shard_path(config: GenerationConfig, index: int) -> Path:
    scene_id, im_id = image_location(index, config.images_per_scene)
    return config.out / STATE_FOLDER / "shards" / config.split / f"{scene_id:06d}" / f"{im_id:06d}.json"


def shard_relative_path(config: GenerationConfig, index: int) -> str:
    return str(shard_path(config, index).relative_to(config.out))


def image_relative_paths(config: GenerationConfig, index: int, instance_count: int) -> dict[str, str]:
    """Relative paths (from the output folder) of an image's files, keyed by kind."""
    scene_id, im_id = image_location(index, config.images_per_scene)
    scene = f"{config.split}/{scene_id:06d}"
    paths = {"rgb": f"{scene}/rgb/{im_id:06d}.{config.rgb_format}", "depth": f"{scene}/depth/{im_id:06d}.png"}
    for instance in range(instance_count):
        paths[f"mask/{instance}"] = f"{scene}/mask/{im_id:06d}_{instance:06d}.png"
        paths[f"mask_visib/{instance}"] = f"{scene}/mask_visib/{im_id:06d}_{instance:06d}.png"
        paths[f"crop_rgb/{instance}"] = f"{scene}/crop_rgb/{im_id:06d}_{instance:06d}.png"
        paths[f"crop_mask/{instance}"] = f"{scene}/crop_mask/{im_id:06d}_{instance:06d}.png"
    return paths


def write_state(config: GenerationConfig) -> None:
    """Records the run's fingerprint; raises ``ValueError`` if the folder holds a different run."""
    path = config.out / STATE_FOLDER / "config.json"
    fingerprint = config.fingerprint()
    if os.path.lexists(path):
        try:
            previous = load_json(path)
        except ValueError as error:
            raise ValueError(f"out: the state file of a previous run is unreadable ({error}); delete {path} "
                             "only if the folder holds nothing else you need, or use another --out") from error
        if not isinstance(previous, dict):
            raise ValueError(f"out: {path}: the state file of a previous run is not a JSON object; "
                             "use another --out")
        # A state written before input digests were recorded is compared as it was, by paths.
        before, now = _comparable(previous), _comparable(
            fingerprint if CONTENTS_KEY in previous else {k: v for k, v in fingerprint.items() if k != CONTENTS_KEY})
        if before != now:
            changed = sorted(key for key in set(before) | set(now) if before.get(key) != now.get(key))
            raise ValueError(f"out: {config.out} holds a data set generated with other settings "
                             f"({', '.join(changed)} differ); use another --out or the same settings to resume")
        if previous == fingerprint:
            return
    write_json_atomically(path, fingerprint)  # new, or the same inputs at new paths (a moved folder)


def _comparable(fingerprint: dict) -> dict:
    """What must match for a run to resume: with input digests (data sets made since they were
    recorded) the inputs' contents, not their paths."""
    if CONTENTS_KEY not in fingerprint:
        return fingerprint
    return {key: value for key, value in fingerprint.items() if key not in ("meshes", "backgrounds", "symmetries")}


def _shard_record(config: GenerationConfig, index: int) -> dict | None:
    """The shard of image ``index`` when it is a readable record of this run, else ``None``."""
    try:
        shard = load_json(shard_path(config, index))
    except ValueError:
        return None
    keys = ("im_id", "scene_gt", "scene_camera", "scene_gt_info", "coco_annotations", "crops")
    if not isinstance(shard, dict) or any(key not in shard for key in keys) or \
            shard["im_id"] != image_location(index, config.images_per_scene)[1] or \
            not isinstance(shard["scene_gt"], list) or not isinstance(shard["crops"], list):
        return None
    return shard


def image_complete(config: GenerationConfig, index: int) -> bool:
    """True when image ``index`` needs no rendering: its shard is a readable record and every file
    it implies (RGB, depth, both masks of each instance, the crops it lists) exists and is not
    empty. Anything less (a deleted or zero-byte file, a corrupt shard) means the image is made again."""
    shard = _shard_record(config, index)
    if shard is None:
        return False
    paths = image_relative_paths(config, index, len(shard["scene_gt"]))
    needed = ["rgb", "depth"] + [f"{kind}/{instance}" for instance in range(len(shard["scene_gt"]))
                                 for kind in ("mask", "mask_visib")]
    needed += [f"{kind}/{crop.get('inst_id')}" for crop in shard["crops"] if isinstance(crop, dict)
               for kind in ("crop_rgb", "crop_mask")]
    for key in needed:
        if key not in paths:
            return False
        try:
            info = os.lstat(config.out / paths[key])
        except OSError:
            return False
        if not stat.S_ISREG(info.st_mode) or info.st_size == 0:
            return False
    return True


def write_static_files(config: GenerationConfig, assets: Assets) -> list[Path]:
    """``camera.json``, ``models/obj_XXXXXX.ply`` (mm, vertex colours) and ``models_info.json``."""
    camera = write_camera(config.out / "camera.json", config.K, config.width, config.height, config.depth_scale)
    return [camera] + write_models(config.out / "models", assets.meshes, assets.object_ids, assets.diameters,
                                   assets.symmetries, units="m")


def image_shard(config: GenerationConfig, index: int, K: np.ndarray, object_ids: list[int], poses: np.ndarray,
                infos: list[dict], visible_masks: np.ndarray, crops: list[dict]) -> bytes:
    """The JSON shard of one image (everything the scene files need)."""
    _, im_id = image_location(index, config.images_per_scene)
    ground_truth = [gt_entry(object_id, pose, units="m") for object_id, pose in zip(object_ids, poses)]
    annotations = [{"image_id": im_id, "category_id": object_id, "iscrowd": 0, "area": info["px_count_visib"],
                    "bbox": info["bbox_visib"], "segmentation": encode_rle(mask), "ignore": False}
                   for object_id, info, mask in zip(object_ids, infos, visible_masks) if info["px_count_visib"] > 0]
    return json_bytes({"im_id": im_id, "scene_gt": ground_truth,
                       "scene_camera": scene_camera_entry(K, config.depth_scale),
                       "scene_gt_info": infos, "coco_annotations": annotations, "crops": crops})


def merge_scenes(config: GenerationConfig, object_ids: list[int]) -> list[Path]:
    """Rebuilds every scene's JSON files from the shards of images ``0..num_images-1``; for the
    ``test`` split also the data set's ``test_targets_bop19.json`` (what ``paz6d evaluate bop`` reads)."""
    written, targets = [], []
    scene_count = (config.num_images + config.images_per_scene - 1) // config.images_per_scene
    categories = [{"id": object_id, "name": f"obj_{object_id:06d}", "supercategory": "object"}
                  for object_id in sorted(object_ids)]
    for scene_id in range(scene_count):
        first = scene_id * config.images_per_scene
        indices = range(first, min(first + config.images_per_scene, config.num_images))
        scene_gt, scene_camera, scene_gt_info, crops = {}, {}, {}, {}
        coco = {"info": {"description": f"paz6d generate, split {config.split}, scene {scene_id}"},
                "licenses": [], "categories": categories, "images": [], "annotations": []}
        for index in indices:
            shard = _shard_record(config, index)
            if shard is None:
                raise ValueError(f"out: {shard_path(config, index)}: missing or unreadable record of image {index}; "
                                 "run the same command again to make it anew")
            key = str(shard["im_id"])
            scene_gt[key], scene_camera[key] = shard["scene_gt"], shard["scene_camera"]
            scene_gt_info[key] = shard["scene_gt_info"]
            targets += targets_from_gt(scene_id, shard["im_id"], [gt["obj_id"] for gt in shard["scene_gt"]],
                                       [info["visib_fract"] for info in shard["scene_gt_info"]])
            coco["images"].append({"id": shard["im_id"], "file_name": f"rgb/{shard['im_id']:06d}.{config.rgb_format}",
                                   "width": config.width, "height": config.height})
            for annotation in shard["coco_annotations"]:
                coco["annotations"].append({"id": len(coco["annotations"]) + 1, **annotation})
            if config.crop_size:
                crops[key] = shard["crops"]
        folder = scene_folder(config, scene_id)
        outputs = {"scene_gt.json": scene_gt, "scene_camera.json": scene_camera,
                   "scene_gt_info.json": scene_gt_info, "scene_gt_coco.json": coco}
        if config.crop_size:
            outputs["crops.json"] = crops
        for name, data in outputs.items():
            write_json_atomically(folder / name, data)
            written.append(folder / name)
    if config.split == "test":
        written.append(write_targets(config.out / TARGETS_FILE, targets))
    return written
