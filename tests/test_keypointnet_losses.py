"""KeypointNet losses and geometry against hand-computed values and brute-force numpy loops."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

kp = pytest.importorskip("paz6d.keypointnet.model")


def _value(tensor) -> float:
    return float(np.asarray(tensor))


def _pinhole(fx, fy, cx, cy):
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _pose(rotation: Rotation, translation) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation.as_matrix()
    T[:3, 3] = translation
    return T


def test_unproject_project_round_trip_matches_opencv_convention():
    K = _pinhole(100.0, 120.0, 50.0, 40.0)
    uv = np.array([[[50.0, 40.0], [150.0, 160.0]]])
    depth = np.array([[2.0, 4.0]])
    points = np.asarray(kp.unproject(uv, depth, K[None]))
    # by hand: (150 - 50) / 100 * 4 = 4, (160 - 40) / 120 * 4 = 4
    np.testing.assert_allclose(points[0], [[0.0, 0.0, 2.0], [4.0, 4.0, 4.0]], atol=1e-6)
    np.testing.assert_allclose(np.asarray(kp.project(points, K[None])), uv, atol=1e-4)


def test_consistency_loss_hand_computed_translation():
    # Camera B is camera A shifted: x_b = x_a + (0.1, 0, 0). A keypoint at pixel (50, 50), depth 1,
    # f = 100, c = (50, 50) is the point (0, 0, 1) in A, (0.1, 0, 1) in B, i.e. pixel (60, 50) in B.
    K = _pinhole(100.0, 100.0, 50.0, 50.0)[None]
    T_a2b = _pose(Rotation.identity(), [0.1, 0.0, 0.0])[None]
    uv_a = np.array([[[50.0, 50.0]]])
    uv_b = np.array([[[63.0, 54.0]]])  # off by (3, 4) from the exact transfer: squared error 25
    depth = np.array([[1.0]])
    # A -> B: |(60, 50) - (63, 54)|^2 = 25. B -> A: (63, 54) at depth 1 is (0.13, 0.04, 1) in B,
    # (0.03, 0.04, 1) in A, pixel (53, 54): |(53, 54) - (50, 50)|^2 = 25. Loss = (25 + 25) / 2.
    assert _value(kp.consistency_loss(uv_a, depth, uv_b, depth, K, K, T_a2b)) == pytest.approx(25.0, rel=1e-5)


def _consistency_brute_force(uv_a, z_a, uv_b, z_b, K_a, K_b, T_a2b):
    total = 0.0
    for batch in range(len(uv_a)):
        T_b2a = np.linalg.inv(T_a2b[batch])
        per_sample = 0.0
        count = uv_a.shape[1]
        for i in range(count):
            ray_a = np.linalg.inv(K_a[batch]) @ np.array([*uv_a[batch, i], 1.0])
            point_b = T_a2b[batch, :3, :3] @ (ray_a * z_a[batch, i]) + T_a2b[batch, :3, 3]
            pixel_b = (K_b[batch] @ point_b)[:2] / point_b[2]
            ray_b = np.linalg.inv(K_b[batch]) @ np.array([*uv_b[batch, i], 1.0])
            point_a = T_b2a[:3, :3] @ (ray_b * z_b[batch, i]) + T_b2a[:3, 3]
            pixel_a = (K_a[batch] @ point_a)[:2] / point_a[2]
            per_sample += np.sum((pixel_b - uv_b[batch, i]) ** 2) + np.sum((pixel_a - uv_a[batch, i]) ** 2)
        total += per_sample / (2 * count)
    return total / len(uv_a)


def test_consistency_loss_matches_brute_force_and_is_zero_for_consistent_views():
    rng = np.random.default_rng(3)
    batch, count = 3, 5
    K_a = np.stack([_pinhole(*rng.uniform([80, 80, 30, 30], [150, 150, 70, 70])) for _ in range(batch)])
    K_b = np.stack([_pinhole(*rng.uniform([80, 80, 30, 30], [150, 150, 70, 70])) for _ in range(batch)])
    T_a2b = np.stack([_pose(Rotation.random(random_state=i), rng.uniform(-0.1, 0.1, 3)) for i in range(batch)])
    points_a = rng.uniform([-0.1, -0.1, 0.8], [0.1, 0.1, 1.2], (batch, count, 3))
    uv_a = np.einsum("bij,bnj->bni", K_a, points_a)
    uv_a = uv_a[..., :2] / uv_a[..., 2:]
    points_b = np.einsum("bij,bnj->bni", T_a2b[:, :3, :3], points_a) + T_a2b[:, None, :3, 3]
    points_b[..., 2] += 1.5  # keep B in front of its camera
    T_a2b[:, 2, 3] += 1.5
    uv_b = np.einsum("bij,bnj->bni", K_b, points_b)
    uv_b = uv_b[..., :2] / uv_b[..., 2:]
    exact = kp.consistency_loss(uv_a, points_a[..., 2], uv_b, points_b[..., 2], K_a, K_b, T_a2b)
    assert _value(exact) == pytest.approx(0.0, abs=1e-6)
    noisy_uv_b = uv_b + rng.normal(0, 2.0, uv_b.shape)
    noisy_z_a = points_a[..., 2] * rng.uniform(0.9, 1.1, (batch, count))
    expected = _consistency_brute_force(uv_a, noisy_z_a, noisy_uv_b, points_b[..., 2], K_a, K_b, T_a2b)
    got = _value(kp.consistency_loss(uv_a, noisy_z_a, noisy_uv_b, points_b[..., 2], K_a, K_b, T_a2b))
    assert got == pytest.approx(expected, rel=1e-4)  # float32 arithmetic in the loss


def test_relative_pose_loss_is_the_rotation_angle_error():
    rng = np.random.default_rng(0)
    points_a = rng.normal(size=(1, 6, 3))
    R_true = Rotation.from_rotvec([0.3, -0.2, 0.5])
    points_b = R_true.apply(points_a[0])[None] + np.array([0.5, 1.0, 2.0])
    assert _value(kp.relative_pose_loss(points_a, points_b, R_true.as_matrix()[None])) == pytest.approx(0.0, abs=2e-3)
    # a claimed relative rotation 30 degrees away from the geometric one -> loss = pi / 6
    R_claimed = (Rotation.from_euler("z", 30, degrees=True) * R_true).as_matrix()[None]
    assert _value(kp.relative_pose_loss(points_a, points_b, R_claimed)) == pytest.approx(math.pi / 6, abs=1e-3)


def test_procrustes_rotation_matches_scipy_align_vectors():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(8, 3))
    b = Rotation.random(random_state=2).apply(a) + rng.normal(0, 0.05, (8, 3))
    a_centred, b_centred = a - a.mean(0), b - b.mean(0)
    reference, _ = Rotation.align_vectors(b_centred, a_centred)
    got = np.asarray(kp.procrustes_rotation(a[None].astype(np.float32), b[None].astype(np.float32)))[0]
    np.testing.assert_allclose(got, reference.as_matrix(), atol=1e-4)


def test_separation_loss_hand_computed():
    # points 0 and 1 are 0.1 apart, point 2 is far: pairs (0,1),(1,0) contribute 0.2^2 - 0.1^2 = 0.03 each
    points = np.array([[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [5.0, 0.0, 0.0]]])
    assert _value(kp.separation_loss(points, delta=0.2)) == pytest.approx(2 * 0.03 / 9, rel=1e-5)
    assert _value(kp.separation_loss(points, delta=0.05)) == pytest.approx(0.0, abs=1e-9)
    image_points = np.array([[[0.0, 0.0], [0.0, 0.3]]])  # 2D: one pair 0.3 apart, delta 0.5 -> 2 * 0.16 / 4
    assert _value(kp.separation_loss(image_points, delta=0.5)) == pytest.approx(2 * 0.16 / 4, rel=1e-5)


def test_silhouette_loss_hand_computed():
    probabilities = np.zeros((1, 2, 2, 2))
    probabilities[0, :, :, 0] = 0.25  # uniform: a quarter of the mass on the one mask cell
    probabilities[0, 0, 0, 1] = 1.0  # all mass on the mask cell
    mask = np.zeros((1, 2, 2))
    mask[0, 0, 0] = 1.0
    expected = (-math.log(0.25) - math.log(1.0)) / 2
    assert _value(kp.silhouette_loss(probabilities, mask)) == pytest.approx(expected, rel=1e-5)


def test_variance_loss_hand_computed():
    grid = kp.cell_centres(1, 3, 1)  # centres u = 0, 1, 2 on row v = 0
    probabilities = np.zeros((1, 1, 3, 1))
    probabilities[0, 0, 0, 0] = probabilities[0, 0, 2, 0] = 0.5
    uv = np.array([[[1.0, 0.0]]])
    assert _value(kp.variance_loss(probabilities, uv, grid)) == pytest.approx(1.0, rel=1e-6)
    uv_off = np.array([[[1.0, 2.0]]])  # adds 2^2 in v
    assert _value(kp.variance_loss(probabilities, uv_off, grid)) == pytest.approx(5.0, rel=1e-6)


def test_cell_centres_follow_pixel_centre_convention():
    grid = kp.cell_centres(2, 2, 4)
    # stride-4 cell 0 covers pixels 0..3 whose centres are 0..3 -> 1.5; cell 1 -> 5.5
    np.testing.assert_allclose(grid[..., 0], [[1.5, 5.5], [1.5, 5.5]])
    np.testing.assert_allclose(grid[..., 1], [[1.5, 1.5], [5.5, 5.5]])
    with pytest.raises(ValueError, match="stride"):
        kp.cell_centres(2, 2, 0)


def test_gaussian_heatmaps_peak_at_keypoint_and_sum_to_one():
    grid = kp.cell_centres(16, 16, 1)
    maps = np.asarray(kp.gaussian_heatmaps(np.array([[[3.0, 11.0], [8.0, 2.0]]]), grid, sigma=1.0))
    np.testing.assert_allclose(maps.sum(axis=(1, 2)), 1.0, rtol=1e-5)
    assert np.unravel_index(maps[0, :, :, 0].argmax(), (16, 16)) == (11, 3)
    assert np.unravel_index(maps[0, :, :, 1].argmax(), (16, 16)) == (2, 8)


def test_heatmap_and_coordinate_losses_hand_computed():
    targets = np.zeros((1, 1, 2, 1))
    targets[0, 0, 0, 0] = 1.0
    probabilities = np.zeros((1, 1, 2, 1))
    probabilities[0, 0, :, 0] = [0.5, 0.5]
    assert _value(kp.heatmap_loss(probabilities, targets)) == pytest.approx(math.log(2.0), rel=1e-5)
    uv = np.array([[[0.0, 0.0], [1.0, 1.0]]])
    target = np.array([[[3.0, 4.0], [1.0, 1.0]]])
    assert _value(kp.coordinate_loss(uv, target)) == pytest.approx(2.5, rel=1e-5)
    assert _value(kp.coordinate_loss(uv, target, weights=np.array([[1.0, 0.0]]))) == pytest.approx(5.0, rel=1e-5)


def test_depth_to_metres():
    K = _pinhole(200.0, 200.0, 64.0, 64.0)[None]
    # z = z_hat * diameter * fx / S = 1.5 * 0.2 * 200 / 128
    got = np.asarray(kp.metres_from_depth_code(np.array([[1.5]]), 0.2, K, 128))
    assert got[0, 0] == pytest.approx(1.5 * 0.2 * 200 / 128, rel=1e-6)
