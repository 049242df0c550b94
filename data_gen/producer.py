"""Makes one image and all its files, from nothing but the run's config and the image index."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_gen import bop_writer
from data_gen.assets import ZNEAR, Assets, load_assets
from data_gen.config import GenerationConfig
from data_gen.files import image_bytes
from paz6d.backend.files import write_bytes_atomically
from data_gen.randomization import (background_image, composite, degrade, random_colors, random_lighting,
                                    random_tints)
from data_gen.scene import sample_scene
from paz6d.backend.square_crop import crop_intrinsics, crop_square, square_window

CROP_MARGIN = 1.2


def image_generator(seed: int, index: int) -> np.random.Generator:
    """The random generator of image ``index``: independent of how images are split among workers."""
    return np.random.default_rng(np.random.SeedSequence([seed, index]))


@dataclass
class RenderedImage:
    """Arrays of one finished image, before encoding."""

    index: int
    rgb: np.ndarray
    depth_png: np.ndarray
    masks: np.ndarray
    visible_masks: np.ndarray
    object_ids: list[int]
    poses: np.ndarray


class ImageProducer:
    """Owns the assets (loaded here unless given) and one :class:`renderers.Renderer` (one GL
    context) of a worker."""

    def __init__(self, config: GenerationConfig, assets: Assets | None = None):
        from renderers import Renderer  # GL is loaded only where images are made

        self.config = config
        self.assets = assets if assets is not None else load_assets(config)
        self.K = np.asarray(config.K)
        zfar = 2.0 * (self.assets.distance[1] + float(self.assets.radii.max()))
        self.renderer = Renderer(config.width, config.height, platform=config.platform, znear=ZNEAR, zfar=zfar,
                                 antialias=config.antialias)

    def close(self) -> None:
        self.renderer.close()

    def render(self, index: int) -> RenderedImage:
        """Samples, renders, composites and degrades image ``index`` (all draws from its own seed)."""
        config, assets = self.config, self.assets
        generator = image_generator(config.seed, index)
        scene = sample_scene(generator, assets, config)
        lighting = random_lighting(generator, config, float(np.mean(assets.distance)))
        tints = np.concatenate([random_tints(generator, len(scene.object_indices), config.color_jitter),
                                random_colors(generator, len(scene.clutter_indices))])
        objects = [(assets.meshes[i], pose) for i, pose in zip(scene.object_indices, scene.poses)]
        objects += [(assets.distractors[i], pose) for i, pose in zip(scene.clutter_indices, scene.clutter_poses)]
        out = self.renderer.render(self.K, objects, lighting=lighting, tints=tints,
                                   masked_objects=len(scene.object_indices))
        background = background_image(generator, assets.backgrounds, config.width, config.height)
        rgb = degrade(generator, composite(out.rgb, out.alpha, background), config)
        depth_png = np.round(out.depth * (1000.0 / config.depth_scale))
        return RenderedImage(index, rgb, np.minimum(depth_png, 65535).astype(np.uint16), out.masks,
                             out.visible_masks, [assets.object_ids[i] for i in scene.object_indices], scene.poses)

    def encode(self, image: RenderedImage) -> dict[str, bytes]:
        """Every file of the image as ``{path relative to the output folder: bytes}``; the shard,
        which marks the image as complete, comes last."""
        config = self.config
        paths = bop_writer.image_relative_paths(config, image.index, len(image.object_ids))
        files = {paths["rgb"]: image_bytes(image.rgb, config.rgb_format),
                 paths["depth"]: image_bytes(image.depth_png)}
        depth_valid = image.depth_png > 0
        infos, crops = [], []
        for instance, (full, visible) in enumerate(zip(image.masks, image.visible_masks)):
            files[paths[f"mask/{instance}"]] = image_bytes(full)
            files[paths[f"mask_visib/{instance}"]] = image_bytes(visible)
            info = bop_writer.instance_annotations(visible, full, depth_valid)
            infos.append(info)
            if config.crop_size and info["px_count_visib"] > 0:
                x, y, w, h = info["bbox_obj"]
                window = square_window((x, y, x + w, y + h), margin=CROP_MARGIN)
                files[paths[f"crop_rgb/{instance}"]] = image_bytes(crop_square(image.rgb, window, config.crop_size))
                files[paths[f"crop_mask/{instance}"]] = image_bytes(
                    crop_square(full.astype(np.uint8) * 255, window, config.crop_size) > 127)
                pose = image.poses[instance]
                crops.append({"inst_id": instance, "obj_id": image.object_ids[instance], "window": list(window),
                              "cam_K": crop_intrinsics(self.K, window, config.crop_size).ravel().tolist(),
                              "cam_R_m2c": pose[:3, :3].ravel().tolist(),
                              "cam_t_m2c": (pose[:3, 3] * 1000.0).tolist(), "visib_fract": info["visib_fract"]})
        files[bop_writer.shard_relative_path(config, image.index)] = bop_writer.image_shard(
            config, image.index, self.K, image.object_ids, image.poses, infos, image.visible_masks, crops)
        return files


def write_files(output: Path, files: dict[str, bytes]) -> int:
    """Writes ``files`` (in order, each atomically) under ``output``; returns how many."""
    for relative, data in files.items():
        write_bytes_atomically(output / relative, data)
    return len(files)
