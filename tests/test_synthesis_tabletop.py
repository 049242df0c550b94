"""Tabletop scenes: a camera above a table, objects upright and resting on it, inside the image."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from scipy.ndimage import uniform_filter

from data_gen.config import GenerationConfig
from paz6d.backend.camera import project_points
from paz6d.backend.transform import apply, invert
from paz6d.synthesis.occluders import distractor_library
from paz6d.synthesis.photo_backgrounds import sample_photographs
from paz6d.synthesis.sampling import hull_points
from paz6d.synthesis.tabletop import look_at, sample_tabletop_scene, table_mesh


@dataclass
class _Settings:
    K = [[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]]
    width: int = 640
    height: int = 480
    objects_per_image: tuple[int, int] = (3, 5)
    rotation: str = "so3"
    elevation_degrees: tuple[float, float] = (30.0, 80.0)
    inplane_degrees: float = 10.0
    distractors: int = 3
    occluder_probability: float = 0.0
    occluders: int = 1


@dataclass
class _Assets:
    meshes: list
    centres: np.ndarray
    radii: np.ndarray
    outlines: list
    distractors: list
    distractor_radii: np.ndarray
    distractor_outlines: list
    distance: tuple[float, float] = (0.8, 1.2)


def _assets() -> _Assets:
    meshes = [trimesh.creation.box((0.06, 0.04, 0.1)), trimesh.creation.cylinder(0.03, 0.08)]
    meshes[1].apply_translation((0.0, 0.0, 0.05))  # an origin away from the base, as scanned models have
    distractors = distractor_library(0.08)
    centres = np.array([0.5 * (m.vertices.min(0) + m.vertices.max(0)) for m in meshes])
    return _Assets(meshes, centres,
                   np.array([np.linalg.norm(m.vertices - c, axis=1).max() for m, c in zip(meshes, centres)]),
                   [hull_points(np.asarray(m.vertices)) for m in meshes], distractors,
                   np.array([np.linalg.norm(d.vertices, axis=1).max() for d in distractors]),
                   [hull_points(np.asarray(d.vertices)) for d in distractors])


def test_look_at_puts_the_eye_at_the_origin_and_the_target_ahead():
    T = look_at(np.array([0.0, -1.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(apply(T, np.array([[0.0, -1.0, 1.0]])), [[0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(apply(T, np.zeros((1, 3))), [[0, 0, np.sqrt(2)]], atol=1e-12)
    # the table's "up" points up in the image (negative y)
    assert (T[:3, :3] @ np.array([0.0, 0.0, 1.0]))[1] < 0
    with pytest.raises(ValueError, match="up"):
        look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))


def test_objects_stand_upright_on_the_table_inside_the_image():
    assets, settings = _assets(), _Settings()
    photographs = sample_photographs()[:3]
    for seed in range(5):
        scene = sample_tabletop_scene(np.random.default_rng(seed), assets, settings, photographs)
        table, T_table2cam = scene.support
        assert isinstance(table, trimesh.Trimesh) and np.ptp(table.vertices[:, 2]) == 0
        eye = invert(T_table2cam)[:3, 3]  # looking at a point within 0.1 m of the table origin
        elevation = np.degrees(np.arcsin(eye[2] / np.linalg.norm(eye)))
        assert len(scene.object_indices) >= 1
        for index, T in zip(scene.object_indices, scene.T_model2cam):
            T_model2table = invert(T_table2cam) @ T
            np.testing.assert_allclose(T_model2table[:3, 2], [0, 0, 1], atol=1e-9)  # upright
            lowest = apply(T_model2table, assets.outlines[index])[:, 2].min()
            assert abs(lowest) < 1e-9  # resting on the plane
            pixels = project_points(apply(T, assets.outlines[index]), np.asarray(settings.K))
            assert pixels.min() >= -0.5 and pixels[:, 0].max() <= 639.5 and pixels[:, 1].max() <= 479.5
        assert 30 - 8 <= elevation <= 80 + 8 and 0.8 - 0.15 <= np.linalg.norm(eye) <= 1.2 + 0.15


def test_table_mesh_carries_a_photographic_texture():
    mesh = table_mesh(np.random.default_rng(0), sample_photographs()[:2], side=1.0, texture_pixels=64)
    np.testing.assert_allclose(np.ptp(mesh.vertices, axis=0), [1.0, 1.0, 0.0])
    np.testing.assert_allclose(mesh.face_normals[:, 2], 1.0)  # facing up, towards the camera
    texture = np.asarray(mesh.visual.material.baseColorTexture)
    assert texture.shape == (64, 64, 3) and texture.std() > 0


def test_the_table_renders_as_sharp_as_its_texture():
    """Seen from above at one texel per pixel, the rendered table is its texture: pixel-level detail
    survives (a vertex-coloured plane would blur it)."""
    from renderers import Renderer
    from renderers.lights import Lighting

    mesh = table_mesh(np.random.default_rng(1), sample_photographs(), side=1.0, texture_pixels=256)
    texture = np.asarray(mesh.visual.material.baseColorTexture).astype(np.float64)
    T_table2cam = look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    K = np.array([[256.0, 0.0, 63.5], [0.0, 256.0, 63.5], [0.0, 0.0, 1.0]])  # 1 texel (1/256 m) per pixel at 1 m
    with Renderer(128, 128, antialias="none") as renderer:
        rgb = renderer.render(K, [(mesh, T_table2cam)], lighting=Lighting(ambient=(1.0, 1.0, 1.0), lights=()),
                              masks=False).rgb.astype(np.float64)
    centre = texture[64:192, 64:192]  # image "up" along the table's +y: the texture appears upright
    assert np.corrcoef(rgb.ravel(), centre.ravel())[0, 1] > 0.99
    blurred = uniform_filter(centre, size=(7, 7, 1), mode="nearest")  # a 7-px box blur
    assert np.corrcoef(rgb.ravel(), blurred.ravel())[0, 1] < 0.97  # pixel-level detail, not a blur of it


def test_generation_config_checks_the_scene_style(tmp_path):
    mesh = tmp_path / "box.ply"
    trimesh.creation.box((0.1, 0.1, 0.1)).export(mesh)
    floating = GenerationConfig(meshes=(mesh,), out=tmp_path / "out", num_images=1)
    assert "scene" not in floating.fingerprint()  # data sets made before scene styles still resume
    tabletop = GenerationConfig(meshes=(mesh,), out=tmp_path / "out", num_images=1, scene="tabletop")
    assert tabletop.fingerprint()["scene"] == "tabletop"
    assert tabletop.fingerprint()["table"] == "texture-map"  # sets with the old vertex-coloured table do not resume
    with pytest.raises(ValueError, match="scene: expected one of"):
        GenerationConfig(meshes=(mesh,), out=tmp_path / "out", num_images=1, scene="ocean")
    with pytest.raises(ValueError, match="elevation_degrees: a tabletop camera"):
        GenerationConfig(meshes=(mesh,), out=tmp_path / "out", num_images=1, scene="tabletop",
                         elevation_degrees=(-80.0, -20.0))


def test_paz6d_generate_writes_tabletop_scenes(shared_data, tmp_path):
    from data_gen.generator import generate
    from paz6d.datasets.bop import BOPDataset

    models = shared_data / "bop_lmo" / "models"
    config = GenerationConfig(meshes=(models / "obj_000005.ply", models / "obj_000009.ply"), out=tmp_path / "out",
                              num_images=2, width=160, height=120, mesh_scale=0.001, scene="tabletop",
                              objects_per_image=(2, 2), distance=(0.5, 0.6), elevation_degrees=(40.0, 70.0), seed=1)
    generate(config, workers=1, show_progress=False)
    samples = list(BOPDataset(tmp_path / "out", split="train"))
    assert len(samples) == 2
    normals = [obj.T_model2cam[:3, 2] for sample in samples[:1] for obj in sample.objects]
    np.testing.assert_allclose(normals[0], normals[1], atol=1e-3)  # upright on the same table
    assert all(obj.info["visib_fract"] > 0 for sample in samples for obj in sample.objects)
    # the table fills part of the depth image around the objects
    assert (samples[0].depth > 0).mean() > 0.3
