"""Pose error functions: properties (hypothesis), brute-force references and VSD on rendered depth."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from evaluation import pose_errors

POINT_CLOUDS = st.integers(min_value=0, max_value=2**32 - 1)


def random_points(seed: int, count: int = 60) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-50.0, 50.0, (count, 3))


def random_poses(seed: int, count: int, spread_deg: float = 180.0, spread_mm: float = 40.0) -> np.ndarray:
    generator = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (count, 1, 1))
    rotation_vectors = generator.normal(size=(count, 3))
    rotation_vectors *= np.radians(generator.uniform(0, spread_deg, (count, 1))) / np.linalg.norm(
        rotation_vectors, axis=1, keepdims=True)
    T[:, :3, :3] = Rotation.from_rotvec(rotation_vectors).as_matrix()
    T[:, :3, 3] = generator.normal(0.0, spread_mm, (count, 3)) + [0.0, 0.0, 800.0]
    return T


@settings(max_examples=30, deadline=None)
@given(POINT_CLOUDS)
def test_add_and_adi_are_zero_for_identical_poses(seed):
    points = random_points(seed)
    T = random_poses(seed + 1, 5)
    assert np.all(pose_errors.add_error(T, T, points) < 1e-9)
    assert np.all(pose_errors.adi_error(T, T, points) < 1e-9)
    assert np.all(pose_errors.mssd_error(T, T, points, np.eye(4)[None]) < 1e-9)


@settings(max_examples=30, deadline=None)
@given(POINT_CLOUDS)
def test_adi_is_at_most_add(seed):
    points = random_points(seed)
    T_est = random_poses(seed + 1, 8)
    T_gt = random_poses(seed + 2, 8)
    assert np.all(pose_errors.adi_error(T_est, T_gt, points) <= pose_errors.add_error(T_est, T_gt, points) + 1e-12)


@settings(max_examples=20, deadline=None)
@given(POINT_CLOUDS)
def test_errors_do_not_depend_on_the_order_of_estimates(seed):
    points = random_points(seed)
    T_est = random_poses(seed + 1, 12)
    T_gt = random_poses(seed + 2, 12)
    K = np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
    order = np.random.default_rng(seed).permutation(12)
    symmetries = pose_errors.symmetry_transformations(continuous=[([0.0, 0.0, 1.0], [1.0, 2.0, 0.0])], max_step=0.2)
    for function in (lambda a, b: pose_errors.add_error(a, b, points),
                     lambda a, b: pose_errors.adi_error(a, b, points),
                     lambda a, b: pose_errors.mssd_error(a, b, points, symmetries),
                     lambda a, b: pose_errors.mspd_error(a, b, points, K, symmetries),
                     lambda a, b: pose_errors.projection_error(a, b, points, K)):
        np.testing.assert_array_equal(function(T_est, T_gt)[order], function(T_est[order], T_gt[order]))


def test_adi_of_a_non_orthonormal_estimate_uses_its_own_posed_points():
    points = random_points(8, 300)
    T_est, T_gt = random_poses(9, 3), random_poses(10, 3)
    T_est[1, :3, :3] *= 1.01  # a rounded/scaled rotation: the model-frame shortcut would be off by 1 %
    expected = [cKDTree(points @ A[:3, :3].T + A[:3, 3]).query(points @ B[:3, :3].T + B[:3, 3])[0].mean()
                for A, B in zip(T_est, T_gt)]
    np.testing.assert_allclose(pose_errors.adi_error(T_est, T_gt, points), expected, rtol=1e-12)


def test_batched_errors_equal_one_estimate_at_a_time():
    points = random_points(3, 500)
    T_est, T_gt = random_poses(4, 9), random_poses(5, 9)
    K = np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
    symmetries = pose_errors.symmetry_transformations(discrete=[np.diag([-1.0, -1.0, 1.0, 1.0])])

    def errors(T_a, T_b):
        return [pose_errors.add_error(T_a, T_b, points), pose_errors.adi_error(T_a, T_b, points),
                pose_errors.mssd_error(T_a, T_b, points, symmetries),
                pose_errors.mspd_error(T_a, T_b, points, K, symmetries),
                pose_errors.projection_error(T_a, T_b, points, K)]

    whole = errors(T_est, T_gt)
    single = [np.concatenate(values) for values in zip(*(errors(T_est[i], T_gt[i]) for i in range(len(T_est))))]
    for a, b in zip(whole, single):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def cylinder_points(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of a cylinder around the z axis through (5, -3, 0) mm, with its exact symmetry set."""
    angles = np.linspace(0.0, 2 * np.pi, 36, endpoint=False)
    heights = np.linspace(-30.0, 30.0, 5)
    a, h = np.meshgrid(angles, heights)
    points = np.stack([20 * np.cos(a.ravel()) + 5, 20 * np.sin(a.ravel()) - 3, h.ravel()], axis=1)
    return points, np.array([5.0, -3.0, 0.0])


@settings(max_examples=25, deadline=None)
@given(POINT_CLOUDS, st.integers(min_value=0, max_value=35))
def test_mssd_and_mspd_are_invariant_under_a_symmetry_of_the_object(seed, step):
    points, offset = cylinder_points(seed)
    # 36 samples per turn: the sampled rotations map this 36-fold cylinder onto itself exactly.
    symmetries = pose_errors.symmetry_transformations(continuous=[([0.0, 0.0, 2.0], offset)], max_step=np.pi / 36)
    assert len(symmetries) == 36
    T_est, T_gt = random_poses(seed, 4, 30.0, 10.0), random_poses(seed + 7, 4, 30.0, 10.0)
    K = np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
    T_gt_moved = T_gt @ symmetries[step]
    np.testing.assert_allclose(pose_errors.mssd_error(T_est, T_gt_moved, points, symmetries),
                               pose_errors.mssd_error(T_est, T_gt, points, symmetries), atol=1e-9)
    np.testing.assert_allclose(pose_errors.mspd_error(T_est, T_gt_moved, points, K, symmetries),
                               pose_errors.mspd_error(T_est, T_gt, points, K, symmetries), atol=1e-9)
    # The symmetric pose of the ground truth itself has zero error.
    assert np.all(pose_errors.mssd_error(T_gt_moved, T_gt, points, symmetries) < 1e-9)


def test_symmetry_transformations_match_bop_sampling():
    discrete = np.diag([-1.0, -1.0, 1.0, 1.0])
    discrete[:3, 3] = [4.0, 0.0, 0.0]
    axis, offset = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 2.0])
    result = pose_errors.symmetry_transformations([discrete], [(axis, offset)])
    steps = int(np.ceil(np.pi / 0.01))
    assert steps == 315 and result.shape == (2 * steps, 4, 4)
    expected = []
    for T_discrete in (np.eye(4), discrete):  # BOP's order: discrete outer, continuous inner
        for index in range(steps):
            angle = index * 2 * np.pi / steps
            c, s = np.cos(angle), np.sin(angle)
            R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
            T_continuous = np.eye(4)
            T_continuous[:3, :3] = R
            T_continuous[:3, 3] = -R @ offset + offset
            expected.append(T_continuous @ T_discrete)
    np.testing.assert_allclose(result, np.array(expected), atol=1e-12)


def test_rotation_error_matches_the_angle_of_the_relative_rotation():
    generator = np.random.default_rng(0)
    angles = np.concatenate([[0.0, 1e-3, 0.1, 90.0, 179.9, 180.0], generator.uniform(0, 180, 50)])
    axes = generator.normal(size=(len(angles), 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    R_gt = Rotation.random(len(angles), random_state=1).as_matrix()
    R_est = Rotation.from_rotvec(np.radians(angles)[:, None] * axes).as_matrix() @ R_gt
    # acos resolves about sqrt(2 * 1.1e-16) rad = 8.5e-7 deg near 0 and 180 degrees.
    np.testing.assert_allclose(pose_errors.rotation_error_deg(R_est, R_gt), angles, atol=1e-6)


def test_translation_and_projection_errors_against_loops():
    points = random_points(11, 40)
    T_est, T_gt = random_poses(12, 6), random_poses(13, 6)
    K = np.array([[580.0, 0.0, 330.0], [0.0, 575.0, 250.0], [0.0, 0.0, 1.0]])
    expected = []
    for A, B in zip(T_est, T_gt):
        distances = []
        for x in points:
            a = K @ (A[:3, :3] @ x + A[:3, 3])
            b = K @ (B[:3, :3] @ x + B[:3, 3])
            distances.append(np.hypot(*(a[:2] / a[2] - b[:2] / b[2])))
        expected.append(np.mean(distances))
    np.testing.assert_allclose(pose_errors.projection_error(T_est, T_gt, points, K), expected, rtol=1e-12)
    np.testing.assert_allclose(pose_errors.translation_error(T_est[:, :3, 3], T_gt[:, :3, 3]),
                               [np.sqrt(np.sum((a - b) ** 2)) for a, b in zip(T_est[:, :3, 3], T_gt[:, :3, 3])])


def test_accuracy_auc_integrates_the_accuracy_threshold_curve():
    errors = np.array([0.0, 12.5, 40.0, 99.0, 100.0, 250.0, np.inf])
    thresholds = np.linspace(0.0, 100.0, 200001)
    curve = (errors[None, :] <= thresholds[:, None]).mean(axis=1)
    numeric = np.trapezoid(curve, thresholds) / 100.0
    assert pose_errors.accuracy_auc(errors, 100.0) == pytest.approx(numeric, abs=1e-5)
    assert pose_errors.accuracy_auc([0.0, 0.0], 100.0) == 1.0
    assert pose_errors.accuracy_auc([np.inf], 100.0) == 0.0
    with pytest.raises(ValueError, match="errors"):
        pose_errors.accuracy_auc([np.nan], 100.0)


def test_bad_inputs_name_the_argument():
    points = random_points(1)
    with pytest.raises(ValueError, match="T_est"):
        pose_errors.add_error(np.full((4, 4), np.nan), np.eye(4), points)
    with pytest.raises(ValueError, match="T_gt"):
        pose_errors.add_error(np.eye(4), 2 * np.eye(4), points)
    with pytest.raises(ValueError, match="T_est/T_gt"):
        pose_errors.add_error(random_poses(1, 3), random_poses(2, 2), points)
    with pytest.raises(ValueError, match="points"):
        pose_errors.adi_error(np.eye(4), np.eye(4), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="K"):
        pose_errors.mspd_error(np.eye(4), np.eye(4), points, np.eye(3)[None].repeat(2, 0), np.eye(4)[None])
    with pytest.raises(ValueError, match="diameter"):
        pose_errors.ObjectModel(points, diameter=0.0)


# --- VSD ---------------------------------------------------------------------------------------

K_VSD = np.array([[180.0, 0.0, 79.6], [0.0, 182.0, 60.3], [0.0, 0.0, 1.0]])


def vsd_reference(depth_test, depth_est, depth_gt, K, delta, taus, diameter):
    """Per-pixel loop over the BOP'19 VSD definition (distance images, bop19 visibility)."""
    height, width = depth_test.shape
    union = inter = 0
    misaligned = []
    for row in range(height):
        for col in range(width):
            scale = np.sqrt(((col - K[0, 2]) / K[0, 0]) ** 2 + ((row - K[1, 2]) / K[1, 1]) ** 2 + 1.0)
            test, est, gt = depth_test[row, col] * scale, depth_est[row, col] * scale, depth_gt[row, col] * scale
            visible_gt = gt > 0 and (test == 0 or gt - test <= delta)
            visible_est = est > 0 and (test == 0 or est - test <= delta or visible_gt)
            if visible_gt or visible_est:
                union += 1
            if visible_gt and visible_est:
                inter += 1
                misaligned.append(abs(gt - est) / diameter)
    misaligned = np.array(misaligned)
    return np.array([(np.sum(misaligned >= tau) + union - inter) / union for tau in taus])


@pytest.fixture(scope="module")
def depth_renderer():
    renderers = pytest.importorskip("renderers")
    try:
        renderer = renderers.Renderer(160, 120, antialias="none")
    except renderers.PlatformUnavailableError as error:
        pytest.skip(f"no offscreen OpenGL: {error}")
    with renderer:
        yield renderer


def pose_mm(rotation_vector, translation_mm) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotation_vector).as_matrix()
    T[:3, 3] = translation_mm
    return T


def render_mm(renderer, meshes_and_poses) -> np.ndarray:
    objects = []
    for mesh, T_mm in meshes_and_poses:
        T = T_mm.copy()
        T[:3, 3] /= 1000.0
        objects.append((mesh, T))
    return renderer.render(K_VSD, objects, rgb=False, masks=False).depth.astype(np.float64) * 1000.0


def test_vsd_is_zero_for_the_ground_truth_and_matches_a_per_pixel_reference(depth_renderer):
    mesh = trimesh.creation.box((0.08, 0.05, 0.06))
    occluder = trimesh.creation.box((0.03, 0.2, 0.01))
    diameter = 1000.0 * np.sqrt(0.08**2 + 0.05**2 + 0.06**2)
    T_gt = pose_mm([0.3, -0.4, 0.2], [5.0, -3.0, 600.0])
    depth_gt = render_mm(depth_renderer, [(mesh, T_gt)])
    depth_test = render_mm(depth_renderer, [(mesh, T_gt), (occluder, pose_mm([0, 0, 0.1], [-10.0, 0.0, 520.0]))])
    depth_test[50:54, 70:90] = 0.0  # missing sensor depth: counted as visible (bop19 mode)
    assert np.count_nonzero(depth_test != depth_gt) > 100, "the occluder must hide part of the object"
    taus = np.arange(0.05, 0.51, 0.05)
    np.testing.assert_array_equal(
        pose_errors.vsd_error(depth_test, depth_gt, depth_gt, K_VSD, 15.0, taus, diameter), np.zeros(len(taus)))
    for rotation, translation in (([0.31, -0.39, 0.21], [6.0, -2.0, 602.0]), ([0.3, -0.4, 0.9], [30.0, 10.0, 640.0])):
        depth_est = render_mm(depth_renderer, [(mesh, pose_mm(rotation, translation))])
        ours = pose_errors.vsd_error(depth_test, depth_est, depth_gt, K_VSD, 15.0, taus, diameter)
        reference = vsd_reference(depth_test, depth_est, depth_gt, K_VSD, 15.0, taus, diameter)
        np.testing.assert_allclose(ours, reference, atol=1e-12)
        assert np.all(np.diff(ours) <= 0) and 0 < ours[-1] < 1
    empty = np.zeros_like(depth_gt)
    np.testing.assert_array_equal(pose_errors.vsd_error(depth_test, empty, empty, K_VSD, 15.0, taus), np.ones(10))
