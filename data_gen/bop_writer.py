"""The BOP layout on disk (millimetres), per-image annotation shards and their merge.

::

    <out>/camera.json, models/obj_XXXXXX.ply (mm), models/models_info.json
    <out>/<split>/<scene>/rgb|depth|mask|mask_visib/..., scene_gt.json, scene_camera.json,
        scene_gt_info.json, scene_gt_coco.json [, crop_rgb/, crop_mask/, crops.json]
    <out>/test_targets_bop19.json (split ``test`` only: instances with visib_fract >= 0.1)
    <out>/.paz6d-generate/config.json and shards/<split>/<scene>/<im>.json (one per finished image)

A shard is written last for each image, so its presence means the image is complete; the scene
JSON files are rebuilt from the shards (atomically) at the end of every run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from data_gen.assets import Assets
from data_gen.coco import bbox_xywh, encode_rle
from data_gen.config import GenerationConfig
from paz6d.backend.files import json_bytes, write_bytes_atomically, write_json_atomically
from paz6d.backend.mesh import bounding_box

STATE_FOLDER = ".paz6d-generate"


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
    if path.exists():
        previous = json.loads(path.read_text())
        if previous != fingerprint:
            keys = set(previous) | set(fingerprint)
            changed = sorted(key for key in keys if previous.get(key) != fingerprint.get(key))
            raise ValueError(f"out: {config.out} holds a data set generated with other settings "
                             f"({', '.join(changed)} differ); use another --out or the same settings to resume")
        return
    write_json_atomically(path, fingerprint)


def write_static_files(config: GenerationConfig, assets: Assets) -> list[Path]:
    """``camera.json``, ``models/obj_XXXXXX.ply`` (mm, vertex colours) and ``models_info.json``."""
    K = np.asarray(config.K)
    written = [config.out / "camera.json"]
    write_json_atomically(written[0], {"cx": K[0, 2], "cy": K[1, 2], "depth_scale": config.depth_scale,
                                       "fx": K[0, 0], "fy": K[1, 1], "height": config.height,
                                       "width": config.width})
    models_info = {}
    for mesh, object_id, mesh_diameter in zip(assets.meshes, assets.object_ids, assets.diameters):
        millimetres = mesh.copy()
        if millimetres.visual.kind == "texture":
            millimetres.visual = millimetres.visual.to_color()
        millimetres.apply_scale(1000.0)
        path = config.out / "models" / f"obj_{object_id:06d}.ply"
        write_bytes_atomically(path, millimetres.export(file_type="ply", encoding="binary"))
        written.append(path)
        low, high = bounding_box(millimetres.vertices)
        info = {"diameter": float(mesh_diameter * 1000.0), "min_x": float(low[0]), "min_y": float(low[1]),
                "min_z": float(low[2]), "size_x": float(high[0] - low[0]), "size_y": float(high[1] - low[1]),
                "size_z": float(high[2] - low[2])}
        info.update(assets.symmetries.get(object_id, {}))
        models_info[str(object_id)] = info
    written.append(config.out / "models" / "models_info.json")
    write_json_atomically(written[-1], models_info)
    return written


def instance_annotations(visible: np.ndarray, full: np.ndarray, depth_valid: np.ndarray) -> dict:
    """BOP ``scene_gt_info`` entry of one instance from its ``(H, W)`` bool masks."""
    px_count_all = int(full.sum())
    px_count_visib = int(visible.sum())
    return {"bbox_obj": bbox_xywh(full), "bbox_visib": bbox_xywh(visible), "px_count_all": px_count_all,
            "px_count_valid": int((full & depth_valid).sum()), "px_count_visib": px_count_visib,
            "visib_fract": px_count_visib / px_count_all if px_count_all else 0.0}


def image_shard(config: GenerationConfig, index: int, K: np.ndarray, object_ids: list[int], poses: np.ndarray,
                infos: list[dict], visible_masks: np.ndarray, crops: list[dict]) -> bytes:
    """The JSON shard of one image (everything the scene files need)."""
    _, im_id = image_location(index, config.images_per_scene)
    ground_truth = [{"cam_R_m2c": pose[:3, :3].ravel().tolist(), "cam_t_m2c": (pose[:3, 3] * 1000.0).tolist(),
                     "obj_id": object_id} for object_id, pose in zip(object_ids, poses)]
    annotations = [{"image_id": im_id, "category_id": object_id, "iscrowd": 0, "area": info["px_count_visib"],
                    "bbox": info["bbox_visib"], "segmentation": encode_rle(mask), "ignore": False}
                   for object_id, info, mask in zip(object_ids, infos, visible_masks) if info["px_count_visib"] > 0]
    return json_bytes({"im_id": im_id, "scene_gt": ground_truth,
                       "scene_camera": {"cam_K": K.ravel().tolist(), "depth_scale": config.depth_scale},
                       "scene_gt_info": infos, "coco_annotations": annotations, "crops": crops})


#: BOP'19 estimation targets are the instances at least this visible.
TARGET_MIN_VISIBLE_FRACTION = 0.1


def _targets(scene_id: int, im_id: int, gt: list[dict], infos: list[dict]) -> list[dict]:
    """BOP'19 targets of one image: per object, the count of instances with visib_fract >= 0.1."""
    counts: dict[int, int] = {}
    for instance, info in zip(gt, infos):
        if info["visib_fract"] >= TARGET_MIN_VISIBLE_FRACTION:
            counts[instance["obj_id"]] = counts.get(instance["obj_id"], 0) + 1
    return [{"scene_id": scene_id, "im_id": im_id, "obj_id": obj_id, "inst_count": count}
            for obj_id, count in sorted(counts.items())]


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
            shard = json.loads(shard_path(config, index).read_text())
            key = str(shard["im_id"])
            scene_gt[key], scene_camera[key] = shard["scene_gt"], shard["scene_camera"]
            scene_gt_info[key] = shard["scene_gt_info"]
            targets += _targets(scene_id, shard["im_id"], shard["scene_gt"], shard["scene_gt_info"])
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
        write_json_atomically(config.out / "test_targets_bop19.json", targets)
        written.append(config.out / "test_targets_bop19.json")
    return written
