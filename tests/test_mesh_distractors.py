"""Photo-textured distractors (paz6d.synthesis.mesh_distractors), the occluder count and the
distractor style of `paz6d generate`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from data_gen.assets import load_assets
from data_gen.config import GenerationConfig
from data_gen.generator import generate
from data_gen.producer import image_generator
from paz6d.datasets.bop import BOPDataset
from paz6d.synthesis.mesh_distractors import (SIZE_FACTORS, TEXELS_PER_SIDE, bake_texture, primitive_shapes,
                                              textured_distractor_library)
from paz6d.synthesis.scene import sample_scene


def _halves_texture(side: int = 64) -> np.ndarray:
    """Left half red, right half blue."""
    texture = np.zeros((side, side, 3), np.uint8)
    texture[:, : side // 2] = (255, 0, 0)
    texture[:, side // 2:] = (0, 0, 255)
    return texture


def test_bake_texture_maps_the_photo_across_each_face():
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    baked = bake_texture(box, _halves_texture())
    edges = np.linalg.norm(baked.vertices[baked.edges[:, 0]] - baked.vertices[baked.edges[:, 1]], axis=1)
    assert edges.max() <= 0.1 / TEXELS_PER_SIDE + 1e-9
    colours = baked.visual.vertex_colors[:, :3].astype(int)
    # On the top face (normal +z) the texture's x runs along the model's x: red at low x, blue at high x.
    top = np.isclose(baked.vertices[:, 2], 0.05) & (np.abs(baked.vertices[:, :2]).max(axis=1) < 0.045)
    low_x, high_x = top & (baked.vertices[:, 0] < -0.01), top & (baked.vertices[:, 0] > 0.01)
    assert low_x.sum() > 20 and high_x.sum() > 20
    assert np.all(colours[low_x] == (255, 0, 0)) and np.all(colours[high_x] == (0, 0, 255))


def test_bake_texture_refuses_bad_input():
    with pytest.raises(ValueError, match="texture"):
        bake_texture(trimesh.creation.box((0.1, 0.1, 0.1)), np.zeros((8, 8), np.uint8))


def test_library_is_fixed_by_its_seed_and_spans_the_shapes():
    rng = np.random.default_rng(0)
    photographs = [rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), rng.integers(0, 100, (40, 40, 3), dtype=np.uint8)]
    library = textured_distractor_library(0.1, photographs, textures_per_shape=1, seed=3)
    assert len(library) == len(primitive_shapes(1.0)) * len(SIZE_FACTORS)
    assert np.isclose(max(mesh.extents.max() for mesh in library), 0.1, rtol=0.05)
    again = textured_distractor_library(0.1, photographs, textures_per_shape=1, seed=3)
    other = textured_distractor_library(0.1, photographs, textures_per_shape=1, seed=4)
    assert all(np.array_equal(a.visual.vertex_colors, b.visual.vertex_colors) for a, b in zip(library, again))
    assert not all(np.array_equal(a.visual.vertex_colors, b.visual.vertex_colors) for a, b in zip(library, other))
    assert all(len(np.unique(mesh.visual.vertex_colors[:, :3], axis=0)) > 10 for mesh in library)  # textured
    with pytest.raises(ValueError, match="textures_per_shape"):
        textured_distractor_library(0.1, photographs, textures_per_shape=0)


@pytest.fixture(scope="module")
def lmo_mesh(shared_data):
    return shared_data / "bop_lmo" / "models" / "obj_000001.ply"


def _config(mesh, out, **overrides) -> GenerationConfig:
    settings = dict(meshes=(mesh,), out=out, num_images=3, width=96, height=72, seed=7, mesh_scale=0.001,
                    objects_per_image=(1, 2), distractors=2)
    settings.update(overrides)
    return GenerationConfig(**settings)


def test_config_checks_the_new_fields(lmo_mesh, tmp_path):
    with pytest.raises(ValueError, match="occluders"):
        _config(lmo_mesh, tmp_path, occluders=-1)
    with pytest.raises(ValueError, match="distractor_style"):
        _config(lmo_mesh, tmp_path, distractor_style="photo")
    # Defaults leave the fingerprint of data sets made before these fields unchanged (they still resume).
    assert "occluders" not in _config(lmo_mesh, tmp_path).fingerprint()
    assert _config(lmo_mesh, tmp_path, occluders=2).fingerprint()["occluders"] == 2
    assert "neutral_distractors" not in _config(lmo_mesh, tmp_path).fingerprint()
    assert _config(lmo_mesh, tmp_path, neutral_distractors=0.3).fingerprint()["neutral_distractors"] == 0.3
    for share in (-0.1, 1.5):
        with pytest.raises(ValueError, match=r"neutral_distractors: expected a share in \[0, 1\]"):
            _config(lmo_mesh, tmp_path, neutral_distractors=share)
    assert "object_colored_distractors" not in _config(lmo_mesh, tmp_path).fingerprint()
    assert _config(lmo_mesh, tmp_path,
                   object_colored_distractors=0.5).fingerprint()["object_colored_distractors"] == 0.5
    for share in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"object_colored_distractors: expected a share in \[0, 1\]"):
            _config(lmo_mesh, tmp_path, object_colored_distractors=share)
    with pytest.raises(ValueError, match="neutral_distractors \\+ object_colored_distractors: expected shares summing"):
        _config(lmo_mesh, tmp_path, neutral_distractors=0.6, object_colored_distractors=0.6)


def test_object_coloured_distractors_take_the_meshes_colours(lmo_mesh, tmp_path):
    from data_gen.producer import ImageProducer

    config = _config(lmo_mesh, tmp_path, distractors=6, object_colored_distractors=1.0)
    producer = ImageProducer(config)
    try:
        palette = producer.palettes[0]
        assert len(producer.palettes) == 1 and len(palette) == len(producer.assets.meshes[0].vertices)
        calls = []
        render = producer.renderer.render
        producer.renderer.render = lambda *args, **kwargs: calls.append(kwargs) or render(*args, **kwargs)
        for index in range(4):
            producer.render(index)
        clutter = np.concatenate([call["tints"][call["masked_objects"]:] for call in calls])
        assert len(clutter) >= 4
        # every distractor is a vertex colour of the mesh times the objects' colour jitter (at most 1)
        low, high = palette[None] * (1 - config.color_jitter), np.minimum(palette[None] * (1 + config.color_jitter), 1)
        close = np.all((clutter[:, None] >= low - 1e-9) & (clutter[:, None] <= high + 1e-9), axis=2)
        assert close.any(axis=1).all()
        plain = ImageProducer(dataclasses.replace(config, object_colored_distractors=0.0), producer.assets)
        try:
            assert plain.palettes == []
        finally:
            plain.close()
    finally:
        producer.close()


def test_occluders_draws_one_occluder_per_draw(lmo_mesh, tmp_path):
    config = _config(lmo_mesh, tmp_path, distractors=0, occluder_probability=1.0, occluders=3,
                     distance=(0.6, 0.9))
    assets = load_assets(config)
    counts = [len(sample_scene(image_generator(0, index), assets, config).clutter_indices) for index in range(10)]
    assert max(counts) == 3 and min(counts) >= 2  # an occluder too close to the camera is skipped
    none = dataclasses.replace(config, occluders=0)
    assert all(len(sample_scene(image_generator(0, index), assets, none).clutter_indices) == 0 for index in range(5))


def test_textured_style_renders_photo_distractors(lmo_mesh, tmp_path):
    config = _config(lmo_mesh, tmp_path / "set", distractor_style="textured", distractors=6)
    assets = load_assets(config)
    assert assets.distractor_tinted.sum() == 12 and (~assets.distractor_tinted).sum() == 36
    assert len(assets.distractors) == len(assets.distractor_radii) == len(assets.distractor_outlines) == 48
    generate(config, show_progress=False)
    assert len(BOPDataset(config.out, split="train")) == 3
