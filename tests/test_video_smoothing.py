"""paz6d.video.smoothing: pose smoothing over a sequence, measured on noisy poses of a known motion."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Keypoints2D, Pose6D
from paz6d.video.frames import Frame
from paz6d.faces.head_pose import HeadDetection
from paz6d.video.smoothing import PoseSmoother

FPS = 30.0


def true_motion(count: int = 90) -> list[Rotation | np.ndarray]:
    """An object turning at 20 degrees/s about a tilted axis while moving 0.2 m/s across, 0.6 m away."""
    times = np.arange(count) / FPS
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    rotations = Rotation.from_rotvec(np.radians(20.0) * times[:, None] * axis) * Rotation.from_euler("x", 40, True)
    translations = np.column_stack([-0.1 + 0.2 * times, 0.02 * np.sin(times), np.full(count, 0.6)])
    return rotations, translations


def noisy(rotations, translations, seed: int = 0, degrees: float = 2.0, metres: float = 0.004):
    generator = np.random.default_rng(seed)
    kicks = Rotation.from_rotvec(generator.normal(0.0, np.radians(degrees) / np.sqrt(3), (len(translations), 3)))
    return kicks * rotations, translations + generator.normal(0.0, metres, translations.shape)


def errors(rotations, translations, poses) -> tuple[float, float]:
    """Mean rotation error (degrees, scipy) and mean translation error (mm) of ``poses``."""
    estimated = Rotation.from_quat([pose.quaternion for pose in poses])
    angles = np.degrees((estimated * rotations.inv()).magnitude())
    distances = np.linalg.norm(np.array([pose.translation for pose in poses]) - translations, axis=1)
    return float(angles.mean()), float(distances.mean() * 1000)


def smooth_noisy_motion(weight: float, velocity: bool = True) -> tuple[tuple[float, float], tuple[float, float]]:
    """Mean errors (degrees, mm) of noisy poses of :func:`true_motion` and of the smoothed poses, frames 10-89."""
    rotations, translations = true_motion()
    noisy_rotations, noisy_translations = noisy(rotations, translations)
    raw = [Pose6D(q, t, "obj_000001") for q, t in zip(noisy_rotations.as_quat(), noisy_translations)]
    smoother = PoseSmoother(weight=weight, velocity=velocity)
    smoothed = [smoother([(Box2D(0, 0, 1, 1, 1.0, "obj_000001"), pose)], Frame(i, i / FPS, None))[0][1]
                for i, pose in enumerate(raw)]
    settled = slice(10, None)  # after the average has settled from its first pose
    raw_errors = errors(rotations[settled], translations[settled], raw[settled])
    smooth_errors = errors(rotations[settled], translations[settled], smoothed[settled])
    print(f"weight {weight}, velocity {velocity}: rotation {raw_errors[0]:.2f} -> {smooth_errors[0]:.2f} deg, "
          f"translation {raw_errors[1]:.2f} -> {smooth_errors[1]:.2f} mm")
    assert all(pose.class_name == "obj_000001" for pose in smoothed)
    return raw_errors, smooth_errors


@pytest.mark.parametrize("weight", [0.3, 0.5])
def test_smoothing_reduces_the_error_of_noisy_poses_of_a_smooth_motion(weight):
    raw, smoothed = smooth_noisy_motion(weight)
    assert smoothed[0] < 0.75 * raw[0] and smoothed[1] < 0.75 * raw[1]


@pytest.mark.parametrize("weight", [0.3, 0.5])
def test_a_moving_average_without_velocity_lags_behind_the_moving_object(weight):
    raw, averaged = smooth_noisy_motion(weight, velocity=False)
    assert averaged[0] < raw[0]  # rotation: 20 degrees/s lags little
    assert averaged[1] > raw[1]  # translation: 6.7 mm per frame lags (1 - w) / w frames behind


def test_weight_one_keeps_the_poses_and_a_jump_starts_afresh():
    first = Pose6D.from_rotation_vector([0, 0, 0], [0, 0, 0.5], "a")
    second = Pose6D.from_rotation_vector([0.1, 0, 0], [0.01, 0, 0.5], "a")
    keep = PoseSmoother(weight=1.0)
    assert keep([first], Frame(0, 0.0, None)) == [first] and keep([second], Frame(1, 0.1, None)) == [second]
    smoother = PoseSmoother(weight=0.5)
    smoother([first], Frame(0, 0.0, None))
    [blended] = smoother([second], Frame(1, 0.1, None))
    np.testing.assert_allclose(blended.translation, [0.005, 0, 0.5])
    np.testing.assert_allclose(Rotation.from_quat(blended.quaternion).as_rotvec(), [0.05, 0, 0], atol=1e-12)
    far = Pose6D.from_rotation_vector([0, 0, 0], [0.3, 0, 0.5], "a")  # 30 cm away: another object or a real move
    assert smoother([far], Frame(2, 0.2, None)) == [far]
    turned = Pose6D.from_rotation_vector([0, 1.0, 0], [0.3, 0, 0.5], "a")  # 57 degrees turned
    assert smoother([turned], Frame(3, 0.3, None)) == [turned]
    late = Pose6D.from_rotation_vector([0, 1.0, 0], [0.3, 0, 0.5], "a")
    assert smoother([late], Frame(4, 2.0, None)) == [late]  # after a gap of 1.7 s


def test_two_objects_of_one_class_and_head_detections_are_tracked_apart():
    left, right = (Pose6D.from_rotation_vector([0, 0, 0], [x, 0, 0.5], "head") for x in (-0.2, 0.2))
    smoother = PoseSmoother(weight=0.5)
    heads = [HeadDetection(pose, Box2D(0, 0, 1, 1), Keypoints2D(np.zeros((0, 2))), 1.0) for pose in (left, right)]
    smoother(heads, Frame(0, 0.0, None))
    moved = [HeadDetection(Pose6D(pose.quaternion, pose.translation + [0.02, 0, 0], "head"), Box2D(0, 0, 1, 1),
                           Keypoints2D(np.zeros((0, 2))), 1.0) for pose in (right, left)]  # listed the other way
    result = smoother(moved, Frame(1, 1 / FPS, None))
    np.testing.assert_allclose([head.pose.translation[0] for head in result], [0.21, -0.19])
    assert isinstance(result[0], HeadDetection) and result[0].reprojection_error == 1.0


@pytest.mark.parametrize("options", [{"weight": 0.0}, {"weight": 1.5}, {"max_jump_m": 0}, {"max_gap_s": float("nan")}])
def test_bad_parameters_are_refused(options):
    with pytest.raises(ValueError, match=next(iter(options))):
        PoseSmoother(**options)
