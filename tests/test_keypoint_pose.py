"""Keypoint-based 6D pose: crop geometry, lifting, farthest points, drawing, KeypointPose6D + PnP."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Keypoints2D, Pose6D
from paz6d.backend.camera import Camera, transform_and_project
from paz6d.backend.draw import draw_box, draw_cube, draw_keypoints, image_grid, keypoint_colors
from paz6d.backend.farthest_points import farthest_point_sampling
from paz6d.backend.pnp import PnPError
from paz6d.backend.square_crop import (crop_intrinsics, crop_square, crop_transform, projected_box, square_window,
                                      to_full_image)
from paz6d.keypointnet.keypoints import keypoint_spread, lift_keypoints
from paz6d.keypointnet.run_dir import KeypointNetRunDir, read_object, write_keypoints, write_object
from paz6d.processors.pose import DepthFromBox

K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])


def _pose(rotation_vector, translation) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotation_vector).as_matrix()
    T[:3, 3] = translation
    return T


# ----------------------------------------------------------------------------- square crops

def test_square_window_centres_and_scales_the_box():
    assert square_window((10, 20, 30, 60), margin=1.0) == (0, 20, 40)
    assert square_window((100, 100, 150, 120), margin=1.2) == (95, 80, 60)
    with pytest.raises(ValueError, match="box"):
        square_window((10, 10, 10, 20))
    with pytest.raises(ValueError, match="margin"):
        square_window((0, 0, 5, 5), margin=0)


@pytest.mark.parametrize("window, size", [((40, 30, 64), 128), ((40, 30, 80), 64), ((37, 51, 70), 64),
                                          ((-20, -10, 64), 64)])
def test_crop_square_samples_where_crop_transform_says(window, size):
    # resampling reproduces a linear image exactly: crop pixel (u', v') must hold the value of the
    # full-image coordinate to_full_image((u', v'))
    height, width = 240, 320
    v, u = np.mgrid[0:height, 0:width].astype(np.float32)
    image = (0.5 * u + 0.25 * v + 10.0).astype(np.float32)
    crop = crop_square(image, window, size)
    rows, columns = np.mgrid[0:size, 0:size]
    full = to_full_image(np.stack([columns, rows], -1).reshape(-1, 2).astype(float), window, size)
    expected = (0.5 * full[:, 0] + 0.25 * full[:, 1] + 10.0).reshape(size, size)
    scale = size / window[2]
    inside = ((full[:, 0] > 1 / scale + 1) & (full[:, 1] > 1 / scale + 1)).reshape(size, size)
    inside &= (np.stack([columns, rows], -1).min(-1) >= 1) & (np.stack([columns, rows], -1).max(-1) <= size - 2)
    # OpenCV's bilinear warp rounds sample positions to 1/32 px: slope (0.5 + 0.25) / 32 < 0.025
    np.testing.assert_allclose(crop[inside], expected[inside], atol=0.025)


def test_crop_intrinsics_equal_projection_then_crop_transform():
    rng = np.random.default_rng(0)
    points = rng.uniform([-0.2, -0.2, 0.8], [0.2, 0.2, 1.5], (20, 3))
    window = (200, 150, 180)
    pixels = points[:, :2] / points[:, 2:] @ K[:2, :2].T + K[:2, 2]
    A = crop_transform(window, 128)
    expected = pixels @ A[:2, :2].T + A[:2, 2]
    K_crop = crop_intrinsics(K, window, 128)
    got = points[:, :2] / points[:, 2:] @ K_crop[:2, :2].T + K_crop[:2, 2]
    np.testing.assert_allclose(got, expected, atol=1e-9)
    np.testing.assert_allclose(to_full_image(expected, window, 128), pixels, atol=1e-9)


@pytest.mark.parametrize("half_side", [1e5, 1e9])
def test_crop_square_of_a_huge_window_is_quick_and_shows_the_image_small(half_side):
    import time

    image = np.full((480, 640, 3), 200, np.uint8)
    window = square_window([-half_side, -half_side, half_side, half_side], margin=1.0)
    started = time.perf_counter()
    crop = crop_square(image, window, 128)
    assert time.perf_counter() - started < 1.0
    # the image covers 640 / (2 half_side) of the crop's 128 px: nothing but the padding is visible
    assert crop.shape == (128, 128, 3) and np.count_nonzero(crop) <= 3 * 4


def test_crop_square_rejects_a_window_off_the_image():
    with pytest.raises(ValueError, match="window"):
        crop_square(np.zeros((10, 10, 3), np.uint8), (50, 50, 8), 8)


# ----------------------------------------------------------------------------- lifting

def _views(points_model, count, seed=0):
    rng = np.random.default_rng(seed)
    poses = np.stack([_pose(rng.normal(size=3), [rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), 0.6])
                      for _ in range(count)])
    uv = np.stack([transform_and_project(points_model, T, K) for T in poses])
    depth = np.stack([(points_model @ T[:3, :3].T + T[:3, 3])[:, 2] for T in poses])
    return uv, depth, np.repeat(K[None], count, 0), poses


def test_lift_keypoints_recovers_points_and_ignores_outlier_views():
    points_model = np.random.default_rng(1).uniform(-0.05, 0.05, (6, 3))
    uv, depth, intrinsics, poses = _views(points_model, 9)
    lifted, spread = lift_keypoints(uv, depth, intrinsics, poses)
    np.testing.assert_allclose(lifted, points_model, atol=1e-9)
    np.testing.assert_allclose(spread, 0.0, atol=1e-9)
    uv[:3] += 40.0  # three of nine views are wrong by 40 px: the median ignores them
    lifted, spread = lift_keypoints(uv, depth, intrinsics, poses)
    np.testing.assert_allclose(lifted, points_model, atol=1e-9)
    with pytest.raises(ValueError, match="uv/depth"):
        lift_keypoints(uv, depth[:, :2], intrinsics, poses)


def test_keypoint_spread_is_the_standard_deviation():
    probabilities = np.zeros((1, 1, 3, 1))
    probabilities[0, 0, [0, 2], 0] = 0.5  # stride 2: cells at u = 0.5 and 4.5, mean 2.5 -> std 2
    assert keypoint_spread(probabilities, np.array([[[2.5, 0.5]]]), 2)[0, 0] == pytest.approx(2.0)


def test_keypoints_file_round_trip_and_errors(tmp_path):
    points = np.arange(12.0).reshape(4, 3) / 100
    write_keypoints(tmp_path, points, [True, True, False, True], "farthest-point")
    read_points, usable = KeypointNetRunDir.read_keypoints(tmp_path)
    np.testing.assert_allclose(read_points, points)
    assert usable.tolist() == [True, True, False, True]
    (tmp_path / "keypoints.json").write_text(json.dumps({"points_model": [[0, 0]], "usable": [True]}))
    with pytest.raises(ValueError, match="points_model"):
        KeypointNetRunDir.read_keypoints(tmp_path)
    with pytest.raises(ValueError, match="not found"):
        KeypointNetRunDir.read_keypoints(tmp_path / "missing")


# ----------------------------------------------------------------------------- farthest points

def test_farthest_point_sampling_matches_brute_force_greedy():
    points = np.random.default_rng(2).normal(size=(300, 3))
    chosen = farthest_point_sampling(points, 8)
    reference = [int(np.argmax(np.sum((points - points.mean(0)) ** 2, 1)))]
    for _ in range(7):
        distances = np.min(np.linalg.norm(points[:, None] - points[reference][None], axis=-1), axis=1)
        reference.append(int(np.argmax(distances)))
    assert chosen.tolist() == reference
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    filled = np.concatenate([cube, np.random.default_rng(0).uniform(0.2, 0.8, (100, 3))])
    assert sorted(farthest_point_sampling(filled, 8).tolist()) == list(range(8))  # the 8 corners
    with pytest.raises(ValueError, match="count"):
        farthest_point_sampling(points, 301)


# ----------------------------------------------------------------------------- drawing

def test_keypoint_colours_are_stable_and_distinct():
    np.testing.assert_array_equal(keypoint_colors(5), keypoint_colors(30)[:5])
    assert len({tuple(colour) for colour in keypoint_colors(30)}) == 30


def test_draw_keypoints_box_cube_and_grid():
    canvas = np.zeros((40, 60, 3), np.uint8)
    drawn = draw_keypoints(canvas, [[10, 12], [40.4, 30.6]], radius=3)
    assert canvas.sum() == 0  # input untouched
    np.testing.assert_array_equal(drawn[12, 10], keypoint_colors(2)[0])
    np.testing.assert_array_equal(drawn[31, 40], keypoint_colors(2)[1])
    boxed = draw_box(canvas, (5, 5, 20, 15), color=(255, 0, 0))
    assert boxed[5, 10, 0] > 0 and boxed[14, 10, 0] > 0 and boxed[10, 10, 0] == 0
    corners = np.array([[x, y] for x in (5, 50) for y in (5, 35) for _ in (0, 1)], float)
    assert draw_cube(canvas, corners).sum() > 0
    grid = image_grid([canvas, drawn, boxed], columns=2, padding=1)
    assert grid.shape == (2 * 40 + 3, 2 * 60 + 3, 3)
    np.testing.assert_array_equal(grid[1:41, 62:122], drawn)
    with pytest.raises(ValueError, match="colors"):
        draw_keypoints(canvas, [[1, 1]], colors=[[1, 2, 3], [4, 5, 6]])


# ----------------------------------------------------------------------------- KeypointPose6D

@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A run directory with an (untrained) tiny KeypointNet and 8 known 3D keypoints."""
    kp = pytest.importorskip("paz6d.keypointnet.model")
    folder = tmp_path_factory.mktemp("keypoint_run")
    kp.save_keypointnet(kp.build_keypointnet(8, 32, 4, 2, (1,)), folder / "model.keras")
    (folder / "config.json").write_text(json.dumps({"input_size": 32, "margin": 1.25, "downsample": 2}))
    cube = np.array([[x, y, z] for x in (-0.04, 0.04) for y in (-0.03, 0.03) for z in (-0.02, 0.02)])
    write_keypoints(folder, cube, np.ones(8, bool), "farthest-point")
    write_object(folder, float(np.linalg.norm(cube[0] - cube[-1])), cube)
    return folder


def test_pnp_lifting_recovers_a_known_pose_from_perfect_keypoints(run_dir):
    from paz6d.keypointnet.pipeline import KeypointPose6D

    T = _pose([0.4, -0.7, 0.2], [0.03, -0.02, 0.5])
    for weighted in (False, True):
        estimator = KeypointPose6D(run_dir, Camera(K, 640, 480), weighted_pnp=weighted)
        perfect = Keypoints2D(transform_and_project(estimator.points_model, T, K), np.ones(8))
        pose = estimator.pose_from_keypoints(perfect, window_side=100)
        np.testing.assert_allclose(pose.to_matrix(), T, atol=1e-7)  # Levenberg-Marquardt stops near 1e-8
        assert pose.score == 1.0
    estimator = KeypointPose6D(run_dir, Camera(K, 640, 480), weighted_pnp=False)
    corrupted = np.array(perfect.points)
    corrupted[2] += [35.0, -20.0]  # one wrong keypoint: RANSAC drops it
    pose = estimator.pose_from_keypoints(Keypoints2D(corrupted, np.ones(8)), window_side=100)
    np.testing.assert_allclose(pose.to_matrix(), T, atol=1e-6)
    assert pose.score == pytest.approx(7 / 8)
    # weighted, a wrong keypoint that says it is uncertain (score 1 / (1 + 40 px)) hardly moves the pose
    scores = np.ones(8)
    scores[2] = 1.0 / 41.0
    weighted = KeypointPose6D(run_dir, Camera(K, 640, 480)).pose_from_keypoints(Keypoints2D(corrupted, scores),
                                                                                 window_side=100)
    np.testing.assert_allclose(weighted.to_matrix(), T, atol=2e-4)


def test_weighted_pnp_beats_plain_pnp_when_the_scores_tell_the_noisy_keypoints(run_dir):
    """Keypoints with 0.3 or 3 px noise, scores ``1 / (1 + sigma)`` in crop pixels (crop = image here):
    weighting by them gives smaller translation errors than treating all alike, over seeded trials."""
    from paz6d.keypointnet.pipeline import KeypointPose6D

    camera = Camera(K, 640, 480)
    plain, weighted = (KeypointPose6D(run_dir, camera, weighted_pnp=flag) for flag in (False, True))
    rng = np.random.default_rng(3)
    errors = {"plain": [], "weighted": []}
    for trial in range(30):
        T = _pose(rng.normal(0, 0.5, 3), [0.0, 0.0, 0.5])
        sigma = np.where(np.arange(8) % 2 == 0, 0.3, 3.0)
        noisy = transform_and_project(plain.points_model, T, K) + rng.normal(0, 1, (8, 2)) * sigma[:, None]
        keypoints = Keypoints2D(noisy, 1.0 / (1.0 + sigma))
        for name, estimator in (("plain", plain), ("weighted", weighted)):
            pose = estimator.pose_from_keypoints(keypoints, window_side=estimator.input_size)
            errors[name].append(np.linalg.norm(pose.translation - T[:3, 3]))
    assert np.median(errors["weighted"]) < 0.6 * np.median(errors["plain"])


def test_fewer_than_four_usable_keypoints_is_a_clear_error(run_dir, tmp_path):
    from paz6d.keypointnet.pipeline import KeypointPose6D

    estimator = KeypointPose6D(run_dir, Camera(K, 640, 480))
    T = _pose([0.1, 0.2, 0.3], [0.0, 0.0, 0.5])
    scores = np.array([1, 1, 1, 0, 0, 0, 0, 0], float)
    keypoints = Keypoints2D(transform_and_project(estimator.points_model, T, K), scores)
    with pytest.raises(PnPError, match="only 3 of 8 keypoints are usable"):
        estimator.pose_from_keypoints(keypoints, window_side=100)
    for name in ("model.keras", "config.json"):
        (tmp_path / name).write_bytes((run_dir / name).read_bytes())
    write_keypoints(tmp_path, estimator.points_model, [True, True, True] + [False] * 5, "lifted-median")
    with pytest.raises(ValueError, match="only 3 usable keypoints"):
        KeypointPose6D(tmp_path, K)


def test_estimator_accepts_camera_or_matrix_and_box_or_tuple(run_dir):
    from paz6d.keypointnet.pipeline import KeypointPose6D

    image = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    by_camera = KeypointPose6D(run_dir, Camera(K, 160, 120))
    by_matrix = KeypointPose6D(run_dir, K)
    first = by_camera.detect(image, Box2D(40, 30, 90, 80))
    second = by_matrix.detect(image, (40, 30, 90, 80))
    np.testing.assert_allclose(first.points, second.points, atol=1e-4)
    # keypoints come back in image pixels, inside the crop window around the box
    window = square_window((40, 30, 90, 80), 1.25)
    assert np.all(first.points >= np.array(window[:2]) - 0.5)
    assert np.all(first.points <= np.array(window[:2]) + window[2] - 0.5)
    with pytest.raises(ValueError, match="160x120"):
        by_camera.detect(image[:100], (40, 30, 90, 80))
    with pytest.raises(ValueError, match="outside"):
        by_matrix.detect(image, (500, 500, 600, 600))
    with pytest.raises(ValueError, match="box2d"):
        by_matrix.detect(image, (10, 10, 5))
    result = by_matrix.estimate_batch([image, image], [(40, 30, 90, 80), (20, 20, 60, 70)])
    assert len(result) == 2 and all(pose is None or isinstance(pose, Pose6D) for pose in result)


def test_corrupt_or_incomplete_run_directory_is_a_clear_error(run_dir, tmp_path):
    from paz6d.keypointnet.pipeline import KeypointPose6D

    with pytest.raises(ValueError, match="config.json"):
        KeypointPose6D(tmp_path, K)
    for name in ("config.json", "keypoints.json"):
        (tmp_path / name).write_bytes((run_dir / name).read_bytes())
    (tmp_path / "model.keras").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ValueError, match="model.keras"):
        KeypointPose6D(tmp_path, K)


def test_local_expectation_ignores_mass_far_from_the_peak():
    from paz6d.keypointnet.keypoints import local_expectation

    probabilities = np.zeros((1, 8, 8, 2))
    probabilities[0, 2, 1, 0], probabilities[0, 2, 2, 0] = 0.3, 0.1  # a weaker mode far from the peak
    probabilities[0, 6, 6, 0], probabilities[0, 7, 7, 0] = 0.4, 0.2  # the peak and a neighbour
    probabilities[0, 5, 3, 1] = 1.0
    uv = local_expectation(probabilities, stride=4, radius=1)
    # map 0: the 3x3 window around cell (6, 6) holds 0.4 at (6, 6) and 0.2 at (7, 7): cell 6 + 1/3;
    # stride-4 cell c is centred at pixel 4 c + 1.5
    np.testing.assert_allclose(uv[0, 0], [4 * (6 + 1 / 3) + 1.5] * 2)
    np.testing.assert_allclose(uv[0, 1], [3 * 4 + 1.5, 5 * 4 + 1.5])


def test_triangulate_keypoints_recovers_points_and_drops_outlier_views():
    from paz6d.keypointnet.keypoints import triangulate_keypoints

    points_model = np.random.default_rng(4).uniform(-0.05, 0.05, (5, 3))
    uv, _, intrinsics, poses = _views(points_model, 12, seed=2)
    points, rms = triangulate_keypoints(uv, intrinsics, poses)
    np.testing.assert_allclose(points, points_model, atol=1e-9)
    np.testing.assert_allclose(rms, 0.0, atol=1e-6)
    noisy = uv + np.random.default_rng(0).normal(0.0, 0.5, uv.shape)
    noisy[[1, 5], 2] += [60.0, -45.0]  # two wild detections of keypoint 2
    points, rms = triangulate_keypoints(noisy, intrinsics, poses)
    assert np.linalg.norm(points - points_model, axis=1).max() < 1.5e-3  # 0.5 px noise at 0.6 m, f = 500
    assert rms.max() < 1.5
    with pytest.raises(ValueError, match="at least 2 views"):
        triangulate_keypoints(uv[:1], intrinsics[:1], poses[:1])


def test_depth_from_box_moves_the_object_to_fit_its_box(run_dir):
    hull = read_object(run_dir)["hull_points"]
    T = _pose([0.3, 0.5, -0.2], [0.05, -0.03, 0.6])
    box = projected_box(hull, T, K)
    too_far = T.copy()
    too_far[:3, 3] *= 1.08
    fitted = DepthFromBox(hull)(Pose6D.from_matrix(too_far), box, Camera(K, 640, 480))
    np.testing.assert_allclose(fitted.to_matrix()[:3, :3], T[:3, :3], atol=1e-9)  # rotation unchanged
    # three fixed-point steps on a perspective projection: close, not exact
    np.testing.assert_allclose(fitted.translation, T[:3, 3], rtol=2e-3)
    with pytest.raises(ValueError, match="hull_points"):
        (run_dir.parent / "bad").mkdir(exist_ok=True)
        (run_dir.parent / "bad" / "object.json").write_text(json.dumps({"diameter": 1, "hull_points": [[0, 0, 0]]}))
        read_object(run_dir.parent / "bad")


def test_estimator_with_depth_from_box_uses_the_box(run_dir):
    from paz6d.keypointnet.pipeline import KeypointPose6D

    camera = Camera(K, 640, 480)
    estimator = KeypointPose6D(run_dir, camera, depth_from_box=True)
    T = _pose([0.4, -0.7, 0.2], [0.03, -0.02, 0.5])
    keypoints = Keypoints2D(transform_and_project(estimator.points_model, T, K), np.ones(8))
    box = projected_box(estimator.hull_points, T, K)
    shrunk = Keypoints2D((keypoints.points - keypoints.points.mean(0)) * 0.95 + keypoints.points.mean(0), np.ones(8))
    plain = KeypointPose6D(run_dir, camera).estimate_from_keypoints(shrunk, box)
    fitted = estimator.estimate_from_keypoints(shrunk, box)
    assert abs(plain.translation[2] - 0.5) > 0.015  # a 5 % smaller constellation reads as 5 % farther
    assert abs(fitted.translation[2] - 0.5) < 0.003



def test_predict_and_decode_steps_work_in_batches():
    from paz6d.keypointnet.keypoints import local_expectation
    from paz6d.keypointnet.pipeline import DecodeKeypoints
    from paz6d.processors.predict import Predict

    def infer(batch):  # probability maps: the stride-4 cells' share of the first channel
        cells = batch[..., 0].reshape(len(batch), 4, 4, 4, 4).sum(axis=(2, 4))
        probabilities = (cells / cells.sum(axis=(1, 2), keepdims=True))[..., None]
        return {"probabilities": probabilities, "uv": np.zeros((len(batch), 1, 2))}

    crops = np.random.default_rng(0).uniform(0, 255, (7, 16, 16, 3))
    uv, spread = DecodeKeypoints(4)(Predict(infer, batch_size=3)(crops))
    expected = local_expectation(infer(crops)["probabilities"], 4)
    np.testing.assert_allclose(uv, expected)
    np.testing.assert_allclose(spread, keypoint_spread(infer(crops)["probabilities"], expected, 4))
    assert uv.shape == (7, 1, 2) and spread.shape == (7, 1)


def test_pipeline_steps_can_be_read_replaced_inserted_and_removed(run_dir):
    from paz6d.abstract import KeyedStep
    from paz6d.keypointnet.pipeline import KeypointPose6D

    camera = Camera(K, 640, 480)
    estimator = KeypointPose6D(run_dir, camera, depth_from_box=True)
    assert estimator.names == ["jitter", "crop", "predict", "decode", "to_image", "merge_crops", "score",
                               "to_keypoints2d", "solve_pnp", "depth_from_box", "refine_with_depth"]
    T = _pose([0.4, -0.7, 0.2], [0.03, -0.02, 0.5])
    perfect = transform_and_project(estimator.points_model, T, K)
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    box = projected_box(estimator.hull_points, T, K)
    # the untrained network's keypoints are replaced by perfect ones: the rest of the chain runs as is
    old = estimator.replace("to_image", KeyedStep(lambda uv, window: perfect, ("uv", "windows"), "points",
                                                  "to_image", per_sample=True))
    assert old.name == "to_image" and estimator["to_image"] is not old
    estimator.replace("score", KeyedStep(lambda spread, sigma: np.ones(len(spread)), ("spread", "sigma"), "scores",
                                         "score", per_sample=True))
    pose = estimator(image, box)
    np.testing.assert_allclose(pose.to_matrix(), T, atol=1e-6)
    # a step inserted after the keypoints corrupts them: the pose changes
    shift = KeyedStep(lambda keypoints: Keypoints2D(keypoints.points * 1.05, keypoints.scores), "keypoints",
                      "keypoints", "shrink", per_sample=True)
    estimator.insert("to_keypoints2d", shift, after=True)
    assert estimator.names.index("shrink") == estimator.names.index("to_keypoints2d") + 1
    assert np.abs(estimator(image, box).translation - T[:3, 3]).max() > 1e-3
    estimator.remove("shrink")
    # a constant pose in place of PnP is what comes out, then moved along its ray by depth_from_box
    fixed = Pose6D.from_matrix(_pose([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]))
    estimator.replace("solve_pnp", KeyedStep(lambda keypoints, window, camera: fixed,
                                             ("keypoints", "windows", "cameras"), "poses", "solve_pnp",
                                             per_sample=True))
    moved = estimator(image, box)
    np.testing.assert_allclose(moved.quaternion, fixed.quaternion)
    assert moved.translation[2] != 1.0
    estimator.remove("depth_from_box")
    assert estimator(image, box) == fixed
    with pytest.raises(ValueError, match=r"no step named 'missing'; steps are \['jitter', 'crop'"):
        estimator.remove("missing")


def test_jitter_boxes_moves_and_scales_each_box_and_keeps_the_plain_one_first():
    from paz6d.keypointnet.pipeline import CROP_JITTERS, JitterBoxes

    image = np.zeros((4, 4, 3))
    images, boxes = JitterBoxes(7)([image, image], [(100, 50, 200, 150), Box2D.coerce((10, 20, 30, 60))])
    assert len(images) == len(boxes) == 14 and images[7] is image
    np.testing.assert_allclose(boxes[0], [100, 50, 200, 150])
    np.testing.assert_allclose(boxes[1], [106, 50, 206, 150])  # 6 % of the width to the right
    np.testing.assert_allclose(boxes[6], [97, 47, 203, 153])   # 6 % larger
    np.testing.assert_allclose(boxes[7], [10, 20, 30, 60])
    np.testing.assert_allclose(boxes[11], [10, 17.6, 30, 57.6])  # 6 % of the height up
    for count in (0, len(CROP_JITTERS) + 1):
        with pytest.raises(ValueError, match=f"crops: expected 1 to {len(CROP_JITTERS)}"):
            JitterBoxes(count)


def test_merge_crops_averages_keypoints_and_measures_their_scatter_against_a_loop():
    from paz6d.keypointnet.pipeline import MIN_SIGMA, MergeCrops

    rng = np.random.default_rng(0)
    points = [rng.uniform(0, 100, (5, 2)) for _ in range(6)]
    spread = [rng.uniform(0.2, 4.0, 5) for _ in range(6)]
    windows = [(0, 0, side) for side in (64, 80, 64, 64, 70, 58)]
    merged, mean_spread, sigma, plain = MergeCrops(3, 32)(points, spread, windows)
    assert len(merged) == 2 and plain == [windows[0], windows[3]]
    for sample in range(2):
        crops = range(3 * sample, 3 * sample + 3)
        scale = 32 / windows[3 * sample][2]  # image pixels -> pixels of the plain crop
        for k in range(5):
            spreads = [spread[c][k] * windows[c][2] / 32 * scale for c in crops]
            weights = [1 / max(value, MIN_SIGMA) ** 2 for value in spreads]
            mean = sum(w * points[c][k] for w, c in zip(weights, crops)) / sum(weights)
            np.testing.assert_allclose(merged[sample][k], mean)
            assert mean_spread[sample][k] == pytest.approx(np.mean(spreads))
            scatter = np.sqrt(np.mean([np.sum((points[c][k] - mean) ** 2) for c in crops]) / 2) * scale
            assert sigma[sample][k] == pytest.approx(max(scatter, MIN_SIGMA))
    single = MergeCrops(1, 32)(points[:2], spread[:2], windows[:2])
    np.testing.assert_allclose(single[0][1], points[1])
    np.testing.assert_allclose(single[2][0], np.maximum(spread[0], MIN_SIGMA))


def test_several_crops_recover_the_pose_from_perfect_keypoints(run_dir):
    from paz6d.abstract import KeyedStep
    from paz6d.keypointnet.pipeline import KeypointPose6D

    T = _pose([0.4, -0.7, 0.2], [0.03, -0.02, 0.5])
    estimator = KeypointPose6D(run_dir, Camera(K, 640, 480), crops=5, max_spread=1e9)  # untrained: wide maps
    perfect = transform_and_project(estimator.points_model, T, K)
    estimator.replace("to_image", KeyedStep(lambda uv, window: perfect, ("uv", "windows"), "points", "to_image",
                                            per_sample=True))
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    box = projected_box(estimator.points_model, T, K)
    values = estimator.run_steps(estimator._values([image, image], [box, box], None), stop="merge_crops")
    assert len(values["crops"]) == 10 and len({window for window in values["windows"]}) == 5
    keypoints = estimator.detect(image, box)
    np.testing.assert_allclose(keypoints.points, perfect)
    np.testing.assert_allclose(estimator(image, box).to_matrix(), T, atol=1e-6)


def test_camera_per_call_defaults_to_the_constructor_camera(run_dir):
    from paz6d.abstract import KeyedStep
    from paz6d.keypointnet.pipeline import KeypointPose6D

    T = _pose([0.2, 0.3, -0.1], [0.01, 0.02, 0.5])
    other = Camera(K * [[1.2], [1.2], [1]], 640, 480)
    image = np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8)

    def with_perfect_keypoints(estimator):
        perfect = transform_and_project(estimator.points_model, T, K)
        estimator.replace("to_image", KeyedStep(lambda uv, window: perfect, ("uv", "windows"), "points", "to_image",
                                                per_sample=True))
        estimator.replace("score", KeyedStep(lambda spread, sigma: np.ones(len(spread)), ("spread", "sigma"),
                                             "scores", "score", per_sample=True))
        return estimator

    by_matrix = with_perfect_keypoints(KeypointPose6D(run_dir, K))
    without_camera = with_perfect_keypoints(KeypointPose6D(run_dir))
    box = (200, 150, 400, 330)
    np.testing.assert_allclose(by_matrix(image, box).to_matrix(), T, atol=1e-6)
    assert by_matrix(image, box, camera=other) == without_camera(image, box, camera=other)
    assert by_matrix(image, box, camera=other) != by_matrix(image, box)
    assert by_matrix.estimate_batch([image, image], [box, box], [None, other]) == [by_matrix(image, box),
                                                                                  by_matrix(image, box, camera=other)]
    with pytest.raises(ValueError, match="camera: none given"):
        without_camera(image, box)
    with pytest.raises(ValueError, match="does not match the camera"):
        by_matrix(image, box, camera=Camera(K, 320, 240))
