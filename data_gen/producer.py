"""Makes one image and all its files, from nothing but the run's config and the image index."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_gen import bop_writer
from data_gen.assets import Assets, load_assets
from data_gen.config import GenerationConfig
from data_gen.files import image_bytes
from paz6d.abstract.processor import SequentialProcessor
from paz6d.backend.files import write_bytes_atomically
from paz6d.backend.image import alpha_blend
from paz6d.backend.square_crop import crop_intrinsics, crop_square, square_window
from paz6d.datasets.bop.writer import depth_png_from_lengths, gt_info_entry, pose_entry
from paz6d.synthesis.augment import RandomGaussianBlur, RandomImageNoise, share_generator
from paz6d.synthesis.backgrounds import background_image
from paz6d.synthesis.lighting import random_lighting, random_materials, random_tints
from paz6d.synthesis.occluders import mesh_palettes, random_colors
from paz6d.synthesis.photo_backgrounds import sample_photographs
from paz6d.synthesis.scene import ZNEAR, sample_scene
from paz6d.synthesis.tabletop import sample_tabletop_scene

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
    T_model2cam: np.ndarray


def degradation(config: GenerationConfig) -> SequentialProcessor:
    """The camera's degradations of a composited image: a Gaussian blur (kernel 5, sigma 0.4-1.2 px)
    with ``blur_probability``, then, for half of the images, sensor noise up to ``noise_std`` grey
    levels."""
    return SequentialProcessor([RandomGaussianBlur((5,), config.blur_probability, sigma=(0.4, 1.2)),
                                RandomImageNoise(config.noise_std, probability=0.5, quantized=True)], name="degrade")


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
        self.degrade = degradation(config)
        self.palettes = mesh_palettes(self.assets.meshes) if config.object_colored_distractors > 0 else []
        self.photographs = sample_photographs() if config.scene == "tabletop" else []  # table textures

    def close(self) -> None:
        self.renderer.close()

    def render(self, index: int) -> RenderedImage:
        """Samples, renders, composites and degrades image ``index`` (all draws from its own seed)."""
        config, assets = self.config, self.assets
        generator = image_generator(config.seed, index)
        if config.scene == "tabletop":
            scene = sample_tabletop_scene(generator, assets, config, self.photographs)
        else:
            scene = sample_scene(generator, assets, config)
        lighting = random_lighting(generator, "scene", config.light_count, float(np.mean(assets.distance)))
        object_tints = random_tints(generator, len(scene.object_indices), config.color_jitter)
        clutter_tints = random_colors(generator, len(scene.clutter_indices), config.neutral_distractors,
                                      self.palettes, config.object_colored_distractors, config.color_jitter)
        textured = ~assets.distractor_tinted[np.asarray(scene.clutter_indices, dtype=np.int64)]
        if np.any(textured):  # photo-textured distractors keep their texture's colours, jittered like objects
            clutter_tints[textured] = random_tints(generator, int(textured.sum()), config.color_jitter)
        tints = np.concatenate([object_tints, clutter_tints])
        objects = [(assets.meshes[i], pose) for i, pose in zip(scene.object_indices, scene.T_model2cam)]
        objects += [(assets.distractors[i], pose) for i, pose in zip(scene.clutter_indices, scene.clutter_T_model2cam)]
        materials = random_materials(generator, len(objects), config.roughness, config.metallic)
        if scene.support is not None:
            objects.append(scene.support)
            tints = np.concatenate([tints, np.ones((1, 3))])
            if materials is not None:
                materials = [*materials, None]  # the table keeps its own material
        out = self.renderer.render(self.K, objects, lighting=lighting, tints=tints,
                                   masked_objects=len(scene.object_indices), materials=materials)
        background = background_image(generator, assets.backgrounds, config.width, config.height)
        share_generator(self.degrade, generator)
        rgb = self.degrade(alpha_blend(out.rgb, out.alpha, background))
        return RenderedImage(index, rgb, depth_png_from_lengths(out.depth, config.depth_scale, units="m"), out.masks,
                             out.visible_masks, [assets.object_ids[i] for i in scene.object_indices], scene.T_model2cam)

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
            info = gt_info_entry(visible, full, depth_valid)
            infos.append(info)
            if config.crop_size and info["px_count_visib"] > 0:
                x, y, w, h = info["bbox_obj"]
                window = square_window((x, y, x + w, y + h), margin=CROP_MARGIN)
                files[paths[f"crop_rgb/{instance}"]] = image_bytes(crop_square(image.rgb, window, config.crop_size))
                files[paths[f"crop_mask/{instance}"]] = image_bytes(
                    crop_square(full.astype(np.uint8) * 255, window, config.crop_size) > 127)
                pose = image.T_model2cam[instance]
                crops.append({"inst_id": instance, "obj_id": image.object_ids[instance], "window": list(window),
                              "cam_K": crop_intrinsics(self.K, window, config.crop_size).ravel().tolist(),
                              **pose_entry(pose, units="m"), "visib_fract": info["visib_fract"]})
        files[bop_writer.shard_relative_path(config, image.index)] = bop_writer.image_shard(
            config, image.index, self.K, image.object_ids, image.T_model2cam, infos, image.visible_masks, crops)
        return files


def write_files(output: Path, files: dict[str, bytes]) -> int:
    """Writes ``files`` (in order, each atomically) under ``output``; returns how many."""
    for relative, data in files.items():
        write_bytes_atomically(output / relative, data)
    return len(files)
