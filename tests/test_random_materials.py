"""Random materials (`paz6d generate --roughness/--metallic`): the renderer's per-object metallic-roughness
factors, their random draw and the generator settings."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from data_gen.config import GenerationConfig
from data_gen.producer import ImageProducer
from paz6d.synthesis.lighting import random_materials
from renderers import Renderer
from renderers.lights import Light, Lighting

K = np.array([[150.0, 0.0, 63.5], [0.0, 150.0, 63.5], [0.0, 0.0, 1.0]])


def _grey_sphere() -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    sphere.visual.vertex_colors = np.tile([128, 128, 128, 255], (len(sphere.vertices), 1))
    return sphere


def test_roughness_makes_a_highlight_metal_darkens_the_diffuse_and_none_restores_the_mesh_own():
    sphere, T = _grey_sphere(), np.eye(4)
    T[2, 3] = 0.5
    lighting = Lighting(ambient=(0.1, 0.1, 0.1),
                        lights=(Light("directional", intensity=3.0, direction=(0.3, 0.3, 1.0)),))
    with Renderer(128, 128) as renderer:
        def grey(materials):
            out = renderer.render(K, [(sphere, T)], lighting=lighting, materials=materials)
            return out.rgb, out.rgb[out.masks[0]].astype(np.float64).mean(axis=1)

        own_rgb, own = grey(None)
        _, glossy = grey([(0.1, 0.0)])
        _, matte = grey([(1.0, 0.0)])
        _, metal = grey([(0.5, 1.0)])
        again_rgb, _ = grey([None])
        assert glossy.max() >= 250 > matte.max() + 50  # a mirror-like highlight only on the glossy sphere
        assert np.median(metal) < 0.7 * np.median(matte)  # metal has (almost) no diffuse colour
        np.testing.assert_array_equal(again_rgb, own_rgb)  # None: back to the mesh's own material
        for bad, match in (([(0.5, 0.5)] * 2, r"materials: expected 1 entries"),
                           ([(1.5, 0.0)], r"materials\[0\]: expected None or \(roughness, metallic\) in \[0, 1\]"),
                           ([(0.5, 0.5, 0.5)], r"materials\[0\]")):
            with pytest.raises(ValueError, match=match):
                renderer.render(K, [(sphere, T)], materials=bad)


def test_random_materials_draw_in_their_ranges_and_nothing_without_them():
    generator = np.random.default_rng(0)
    assert random_materials(generator, 5, None, None) is None
    assert generator.random() == np.random.default_rng(0).random()  # nothing drawn
    drawn = random_materials(np.random.default_rng(1), 400, (0.2, 0.6), None)
    assert drawn.shape == (400, 2) and drawn[:, 0].min() >= 0.2 and drawn[:, 0].max() <= 0.6
    assert drawn[:, 0].std() > 0.1 and np.all(drawn[:, 1] == 0.2)  # metallic: pyrender's default


def _config(shared_data, out, **overrides) -> GenerationConfig:
    models = shared_data / "bop_lmo" / "models"
    settings = dict(meshes=(models / "obj_000005.ply", models / "obj_000009.ply"), out=out, num_images=2, width=160,
                    height=120, seed=3, mesh_scale=0.001, intrinsics=(150.0, 150.0, 79.5, 59.5),
                    objects_per_image=(2, 2), distractors=2, distance=(0.5, 0.7))
    return GenerationConfig(**{**settings, **overrides})


def test_generated_images_change_with_materials_deterministically_and_the_settings_are_checked(shared_data, tmp_path):
    def image(config):
        producer = ImageProducer(config)
        try:
            return producer.render(0).rgb
        finally:
            producer.close()

    plain = image(_config(shared_data, tmp_path))
    glossy = _config(shared_data, tmp_path, roughness=(0.1, 0.3), metallic=(0.0, 0.4))
    first = image(glossy)
    np.testing.assert_array_equal(first, image(glossy))  # the draws come from the image's own seed
    assert np.abs(first.astype(int) - plain).max() > 30
    assert "roughness" not in _config(shared_data, tmp_path).fingerprint()  # data sets made before still resume
    assert glossy.fingerprint()["roughness"] == [0.1, 0.3] and glossy.fingerprint()["metallic"] == [0.0, 0.4]
    for name, bad in (("roughness", (0.6, 0.2)), ("roughness", (-0.1, 0.5)), ("metallic", (0.0, 1.5)),
                      ("metallic", (float("nan"), 0.5))):
        with pytest.raises(ValueError, match=f"{name}: expected"):
            _config(shared_data, tmp_path, **{name: bad})
