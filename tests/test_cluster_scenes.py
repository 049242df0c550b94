"""Clustered floating scenes (`paz6d generate --cluster`): objects placed next to each other so that they
hide each other, as in real clutter."""

from __future__ import annotations

import json

import numpy as np
import pytest

from data_gen.assets import load_assets
from data_gen.config import GenerationConfig
from data_gen.generator import generate
from data_gen.producer import image_generator
from paz6d.backend.camera import project_points
from paz6d.synthesis import sampling
from paz6d.synthesis.scene import sample_scene

K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
CUBE = np.array([[x, y, z] for x in (-0.03, 0.03) for y in (-0.03, 0.03) for z in (-0.03, 0.03)])
RADIUS = float(np.linalg.norm(CUBE[0]))


def _projected_circle(centre_cam: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    return project_points(centre_cam[None], K)[0], K[0, 0] * radius / centre_cam[2]


def test_clustered_object_lands_next_to_a_placed_one_and_apart_in_3d():
    for seed in range(20):
        generator, placed = np.random.default_rng(seed), []
        first = sampling.place_object(generator, np.eye(3), np.zeros(3), RADIUS, CUBE, K, 320, 240, (0.6, 1.2), placed)
        assert first is not None
        second = sampling.place_object(generator, np.eye(3), np.zeros(3), RADIUS, CUBE, K, 320, 240, (0.6, 1.2),
                                       placed, cluster=1.0)
        if second is None:
            continue
        (a, ra), (b, rb) = (_projected_circle(centre, radius) for centre, radius in placed)
        # image distance of the centres within the spacing range of the summed projected radii (the new
        # one's radius is taken at its depth minus its radius, as the placement margin)
        margin = K[0, 0] * RADIUS / (placed[1][0][2] - RADIUS)
        assert np.linalg.norm(a - b) <= sampling.CLUSTER_SPACING[1] * (ra + margin) + 1e-6
        assert np.linalg.norm(placed[0][0] - placed[1][0]) >= 2 * RADIUS - 1e-12


def _overlapping_pairs(config, scenes: int = 15) -> int:
    assets = load_assets(config)
    count = 0
    for index in range(scenes):
        scene = sample_scene(image_generator(config.seed, index), assets, config)
        circles = []
        for mesh_index, T in zip(scene.object_indices, scene.T_model2cam):
            centre = T[:3, :3] @ assets.centres[mesh_index] + T[:3, 3]
            circles.append(_projected_circle(centre, assets.radii[mesh_index]))
        count += sum(np.linalg.norm(p - q) < r + s for i, (p, r) in enumerate(circles) for q, s in circles[i + 1:])
    return count


def _config(shared_data, out, **overrides) -> GenerationConfig:
    models = shared_data / "bop_lmo" / "models"
    settings = dict(meshes=(models / "obj_000001.ply", models / "obj_000005.ply", models / "obj_000009.ply"),
                    out=out, num_images=8, width=320, height=240, seed=3, mesh_scale=0.001,
                    intrinsics=(300.0, 300.0, 159.5, 119.5), objects_per_image=(3, 3), distractors=0,
                    occluder_probability=0.0, distance=(0.5, 0.9))
    settings.update(overrides)
    return GenerationConfig(**settings)


def test_clustered_scenes_overlap_in_the_image_and_hide_more(shared_data, tmp_path):
    plain, clustered = _config(shared_data, tmp_path / "plain"), _config(shared_data, tmp_path / "clustered",
                                                                         cluster=1.0)
    assert _overlapping_pairs(clustered) >= 2 * max(_overlapping_pairs(plain), 5)
    visible = {}
    for name, config in (("plain", plain), ("clustered", clustered)):
        generate(config, show_progress=False)
        info = json.loads((config.out / "train" / "000000" / "scene_gt_info.json").read_text())
        visible[name] = np.array([instance["visib_fract"] for instances in info.values() for instance in instances])
    assert np.mean(visible["clustered"] < 0.95) > np.mean(visible["plain"] < 0.95) + 0.15


def test_cluster_is_checked_and_left_out_of_old_fingerprints(shared_data, tmp_path):
    for chance in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"cluster: expected a chance in \[0, 1\]"):
            _config(shared_data, tmp_path, cluster=chance)
    with pytest.raises(ValueError, match=r"cluster: only for floating scenes"):
        _config(shared_data, tmp_path, cluster=0.5, scene="tabletop")
    assert "cluster" not in _config(shared_data, tmp_path).fingerprint()  # data sets made before it still resume
    assert _config(shared_data, tmp_path, cluster=0.5).fingerprint()["cluster"] == 0.5
