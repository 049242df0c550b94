"""KeypointNet discovery: pair curriculum, bootstrap anchors, the discovery preset, gradients through the SVD."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.keypointnet import views as kv
from paz6d.keypointnet.config import (DISCOVERY, QUICK, KeypointTraining, anchor_start_step, anchors_due,
                                      pair_angle_at)


def test_relative_angles_hand_computed():
    identity = np.eye(3)
    rotations = np.stack([identity, Rotation.from_euler("z", 90, degrees=True).as_matrix(),
                          Rotation.from_euler("x", 180, degrees=True).as_matrix(),
                          Rotation.from_rotvec([0.0, 0.3, 0.0]).as_matrix()])
    np.testing.assert_allclose(kv.relative_angles(rotations, identity), [0.0, 90.0, 180.0, math.degrees(0.3)],
                               atol=1e-6)
    # relative to a turned view: the angle of rotations[v] @ rotation.T
    turned = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    assert kv.relative_angles(rotations[1:2], turned)[0] == pytest.approx(60.0)


def test_pair_partners_respect_the_curriculum_angle():
    rotations = Rotation.random(400, random_state=1).as_matrix()
    first = np.arange(0, 400, 7)
    rng = np.random.default_rng(0)
    for max_angle in (45.0, 90.0):
        partners = kv.pair_partners(rotations, first, rng, max_angle)
        angles = [kv.relative_angles(rotations[[b]], rotations[a])[0] for a, b in zip(first, partners)]
        assert np.all(partners != first) and max(angles) <= max_angle
    # no view within 1 degree: one of the 8 nearest views
    partners = kv.pair_partners(rotations, first, rng, 1.0)
    for a, b in zip(first, partners):
        angles = kv.relative_angles(rotations, rotations[a])
        angles[a] = np.inf
        assert b in np.argsort(angles)[:8]
    unlimited = kv.pair_partners(rotations, first, np.random.default_rng(0), None)
    angles = [kv.relative_angles(rotations[[b]], rotations[a])[0] for a, b in zip(first, unlimited)]
    assert np.all(unlimited != first) and np.median(angles) > 90.0  # uniform pairs: mostly far apart
    with pytest.raises(ValueError, match="max_angle"):
        kv.pair_partners(rotations, first, rng, 0.0)


def test_pair_angle_curriculum_hand_computed():
    settings = QUICK.replace(pair_angle=(30.0, 180.0), pair_angle_ramp=0.5, steps=100)
    assert [pair_angle_at(step, settings) for step in (0, 25, 50, 90)] == pytest.approx([30.0, 105.0, 180.0, 180.0])
    assert pair_angle_at(10, settings.replace(pair_angle_ramp=0.0)) == 180.0
    assert pair_angle_at(10, QUICK.replace(steps=100)) is None
    with pytest.raises(ValueError, match="pair_angle: expected at most 180.0"):
        settings.replace(pair_angle=(30.0, 200.0))


def test_anchors_are_due_from_the_start_then_every_period():
    settings = QUICK.replace(anchor_start=0.3, anchor_every=25, steps=100)
    assert anchor_start_step(settings) == 30 and anchor_start_step(QUICK.replace(steps=100)) is None
    assert not anchors_due(29, None, settings)
    assert anchors_due(30, None, settings)
    assert not anchors_due(54, 30, settings)
    assert anchors_due(55, 30, settings)
    assert not anchors_due(500, None, QUICK.replace(steps=1000))  # no bootstrapping without anchor_start


def test_discovery_preset_requires_discovery_mode(tmp_path):
    mesh = tmp_path / "m.ply"
    mesh.write_text("ply")
    settings = KeypointTraining(tmp_path / "run", mesh, mode="discovery", config="discovery").model_config
    assert settings == DISCOVERY and settings.pair_angle == (30.0, 180.0) and settings.anchor_start > 0
    with pytest.raises(ValueError, match="--mode discovery"):
        KeypointTraining(tmp_path / "run", mesh, config="discovery")


def test_relative_pose_gradient_through_the_svd_matches_finite_differences():
    from paz6d.keypointnet import model as kp

    tf = kp.tf
    rng = np.random.default_rng(0)
    points_a = rng.normal(size=(1, 6, 3)).astype(np.float32)
    R_true = Rotation.from_rotvec([0.3, -0.2, 0.5])
    points_b = (R_true.apply(points_a[0])[None] + 1.0).astype(np.float32)
    R_claimed = (Rotation.from_euler("z", 30, degrees=True) * R_true).as_matrix()[None].astype(np.float32)
    variable = tf.Variable(points_b)
    with tf.GradientTape() as tape:
        loss = kp.relative_pose_loss(points_a, variable, R_claimed)
    gradient = tape.gradient(loss, variable).numpy()
    step, numeric = 1e-3, np.zeros_like(points_b)
    for index in np.ndindex(points_b.shape):
        plus, minus = points_b.copy(), points_b.copy()
        plus[index] += step
        minus[index] -= step
        numeric[index] = (float(kp.relative_pose_loss(points_a, plus, R_claimed)) -
                          float(kp.relative_pose_loss(points_a, minus, R_claimed))) / (2 * step)
    assert np.abs(gradient).max() > 0.05  # the loss does pull on the keypoints
    np.testing.assert_allclose(gradient, numeric, atol=2e-3)


def test_tiny_discovery_run_bootstraps_from_anchors_after_the_start(tmp_path):
    # Not marked slow although it takes ~35 s at load average 9 (like the tiny runs of
    # test_keypointnet_training.py): it is the only test of the anchor term inside the training loss and
    # of the batches that carry the anchors.
    import csv

    from paz6d.assets.demo_object import write_demo_object
    from paz6d.backend.tensorflow_guard import import_tensorflow
    from paz6d.keypointnet.train import train_keypointnet

    import_tensorflow()  # before the renderer (workers=0)
    mesh = write_demo_object(tmp_path / "mesh")
    tiny = DISCOVERY.replace(num_keypoints=5, input_size=32, filters=8, downsample=2, dilations=(1, 2), views=24,
                             validation_views=8, lift_views=8, pairs=4, learning_rate=3e-3, checkpoint_every=20,
                             sample_every=20, anchor_views=12, anchor_every=10, anchor_start=0.3)
    job = KeypointTraining(tmp_path / "run", mesh, mesh_scale=1e-3, mode="discovery", config="discovery", workers=0,
                           steps=40, progress=False, settings=tiny)
    train_keypointnet(job)
    with (job.out / "log.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    # anchor_start 0.3 of 40 steps = step 12: the logged steps 10, 20, 30, 40 have the anchor term from 20 on
    assert [row["anchor"] == "" for row in rows] == [True, False, False, False]
    assert all(np.isfinite(float(row["anchor"])) and float(row["anchor"]) > 0 for row in rows[1:])


def test_anchor_source_lifts_when_due_and_keeps_the_anchors_in_between(tmp_path):
    from paz6d.keypointnet.model import build_keypointnet
    from paz6d.keypointnet.train import AnchorSource

    rng = np.random.default_rng(0)
    count, size = 10, 32
    rotations = Rotation.random(count, random_state=2).as_matrix()
    T = np.tile(np.eye(4), (count, 1, 1))
    T[:, :3, :3], T[:, :3, 3] = rotations, [0.0, 0.0, 0.5]
    K = np.tile(np.array([[60.0, 0, 15.5], [0, 60.0, 15.5], [0, 0, 1]]), (count, 1, 1))
    masks = np.zeros((count, size, size), bool)
    masks[:, 8:24, 8:24] = True
    views = kv.ViewSet(rng.integers(0, 256, (count, size, size, 3), dtype=np.uint8),
                       masks.astype(np.uint8) * 255, masks, K, T)
    model = build_keypointnet(4, size, 8, 2, (1,))
    settings = QUICK.replace(anchor_start=0.5, anchor_every=10, steps=20, downsample=2, anchor_views=8, input_size=size)
    source = AnchorSource(model, views, settings, seed=0, object_diameter=0.1)
    assert source(9) is None and source.lifted_at is None
    first = source(10)
    assert first.shape == (4, 3) and np.all(np.isfinite(first)) and source.lifted_at == 10
    assert source(19) is first  # not re-lifted within anchor_every steps
    model.get_layer("logits").bias.assign(np.arange(4, dtype=np.float32))  # the network changed
    again = source(20)
    assert again is not first and source.lifted_at == 20


def test_spread_modes_hand_computed():
    from paz6d.keypointnet.keypoints import spread_modes

    first = [[0, 0, 0]] * 4 + [[1, 0, 0]]  # keypoint 0: mostly at the origin
    second = [[0.05, 0, 0]] * 3 + [[0, 2, 0]] * 2  # keypoint 1: mostly next to keypoint 0, sometimes far
    per_view = np.stack([np.array(first, float), np.array(second, float)], axis=1)  # (V=5, N=2, 3)
    # keypoint 0 is the more concentrated (4 estimates together): it keeps its mode; keypoint 1 takes
    # its densest place at least delta = 0.5 from it
    np.testing.assert_allclose(spread_modes(per_view, radius=0.1, delta=0.5), [[0, 0, 0], [0, 2, 0]])
    # without the separation each keypoint gets its own densest place (the median would too)
    np.testing.assert_allclose(spread_modes(per_view, radius=0.1, delta=0.0), [[0, 0, 0], [0.05, 0, 0]])
    # no candidate delta away: the one farthest from the chosen points
    np.testing.assert_allclose(spread_modes(per_view, radius=0.1, delta=5.0), [[0, 0, 0], [0, 2, 0]])
    with pytest.raises(ValueError, match="per_view"):
        spread_modes(np.zeros((5, 3)), 0.1, 0.5)
