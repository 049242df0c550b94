"""Messages (Box2D, Pose6D, Keypoints2D/3D): validation, immutability, dict/JSON and array round trips."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Keypoints2D, Keypoints3D, Pose6D

PROPERTY = settings(max_examples=40, deadline=None)
seeds = st.integers(0, 2**32 - 1)


def json_round_trip(message):
    return type(message).from_dict(json.loads(json.dumps(message.to_dict())))


def random_pose(seed: int) -> tuple[Rotation, np.ndarray]:
    generator = np.random.default_rng(seed)
    return Rotation.random(random_state=generator), generator.uniform(-1, 1, 3)


def test_box2d_properties_and_round_trips():
    box = Box2D(10, 20, 50, 80, score=0.7, class_name="duck")
    assert (box.width, box.height, box.area, box.center) == (40.0, 60.0, 2400.0, (30.0, 50.0))
    assert json_round_trip(box) == box
    np.testing.assert_array_equal(box.to_array(), [10, 20, 50, 80])
    assert Box2D.from_array(box.to_array(), 0.7, "duck") == box
    assert Box2D.from_dict({"x_min": 1, "y_min": 2, "x_max": 3, "y_max": 4}) == Box2D(1, 2, 3, 4)
    assert isinstance(Box2D(np.float32(1), 2, 3, 4).x_min, float)
    # coordinates_of: a message's array, any other value untouched (its caller checks it)
    np.testing.assert_array_equal(Box2D.coordinates_of(box), [10, 20, 50, 80])
    plain = (1, 2, 3)
    assert Box2D.coordinates_of(plain) is plain


def test_box2d_validation():
    with pytest.raises(ValueError, match=r"Box2D: expected x_min <= x_max and y_min <= y_max"):
        Box2D(5, 0, 1, 1)
    with pytest.raises(ValueError, match=r"Box2D coordinates: contains NaN"):
        Box2D(0, np.nan, 1, 1)
    with pytest.raises(ValueError, match=r"Box2D.score: expected a finite number"):
        Box2D(0, 0, 1, 1, score=np.inf)
    with pytest.raises(ValueError, match=r"coordinates: expected shape \(\.\.\., 4\), got \(3,\)"):
        Box2D.from_array([1, 2, 3])
    with pytest.raises(ValueError, match=r"Box2D.from_dict: missing field\(s\) \['y_max'\]"):
        Box2D.from_dict({"x_min": 1, "y_min": 2, "x_max": 3})
    with pytest.raises(ValueError, match=r"Box2D.from_dict: expected a dict, got list"):
        Box2D.from_dict([1, 2, 3, 4])


def test_messages_are_immutable():
    box = Box2D(0, 0, 1, 1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        box.x_min = 3.0
    pose = Pose6D([0, 0, 0, 1.0], [0, 0, 1.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        pose.translation = np.zeros(3)
    with pytest.raises(ValueError, match="read-only"):
        pose.translation[0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        pose.quaternion[3] = 0.0
    keypoints = Keypoints2D([[1.0, 2.0]], scores=[0.5])
    with pytest.raises(ValueError, match="read-only"):
        keypoints.points[0, 0] = 3.0
    copy = keypoints.to_array()
    copy[0, 0] = 9.0
    assert keypoints.points[0, 0] == 1.0
    source = np.array([0.0, 0.0, 1.0])
    pose = Pose6D([0, 0, 0, 1.0], source)
    source[2] = 7.0
    assert pose.translation[2] == 1.0  # the message copied its input


@PROPERTY
@given(seeds)
def test_pose6d_conversions_match_scipy(seed):
    rotation, translation = random_pose(seed)
    pose = Pose6D(rotation.as_quat(), translation, "cat", 0.9)
    assert pose.quaternion[3] >= 0
    np.testing.assert_allclose(pose.rotation_matrix, rotation.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(pose.rotation_vector, rotation.as_rotvec(), atol=1e-12)
    expected_T = np.eye(4)
    expected_T[:3, :3], expected_T[:3, 3] = rotation.as_matrix(), translation
    np.testing.assert_allclose(pose.to_matrix(), expected_T, atol=1e-12)
    for other in (Pose6D.from_matrix(expected_T, "cat", 0.9),
                  Pose6D.from_rotation_matrix(rotation.as_matrix(), translation, "cat", 0.9),
                  Pose6D.from_rotation_vector(rotation.as_rotvec(), translation, "cat", 0.9),
                  Pose6D(-rotation.as_quat(), translation, "cat", 0.9),
                  Pose6D.from_array(pose.to_array(), "cat", 0.9),
                  json_round_trip(pose)):
        np.testing.assert_allclose(other.quaternion, pose.quaternion, atol=1e-12)
        np.testing.assert_allclose(other.translation, translation, atol=1e-15)
        assert (other.class_name, other.score) == ("cat", 0.9)
    np.testing.assert_allclose(pose.to_array(), np.concatenate([pose.quaternion, translation]))


def test_pose6d_validation_names_the_field():
    with pytest.raises(ValueError, match=r"Pose6D.quaternion: expected unit quaternions \(x, y, z, w\), found norm 2"):
        Pose6D([0, 0, 0, 2.0], [0, 0, 0])
    with pytest.raises(ValueError, match=r"Pose6D.quaternion: contains NaN"):
        Pose6D([0, 0, np.nan, 1.0], [0, 0, 0])
    with pytest.raises(ValueError, match=r"Pose6D.quaternion: expected shape \(4,\), got \(2, 4\)"):
        Pose6D(np.tile([0, 0, 0, 1.0], (2, 1)), [0, 0, 0])
    with pytest.raises(ValueError, match=r"Pose6D.translation: expected shape \(\.\.\., 3\), got \(2,\)"):
        Pose6D([0, 0, 0, 1.0], [0, 0])
    with pytest.raises(ValueError, match=r"T: expected shape \(4, 4\), got \(2, 4, 4\)"):
        Pose6D.from_matrix(np.tile(np.eye(4), (2, 1, 1)))
    with pytest.raises(ValueError, match=r"rotation_matrix: expected orthonormal rotation matrices"):
        Pose6D.from_rotation_matrix(2 * np.eye(3), [0, 0, 0])
    with pytest.raises(ValueError, match=r"values: expected shape \(\.\.\., 7\), got \(6,\)"):
        Pose6D.from_array(np.zeros(6))
    with pytest.raises(ValueError, match=r"Pose6D.from_dict: missing field\(s\) \['translation'\]"):
        Pose6D.from_dict({"quaternion": [0, 0, 0, 1]})


@pytest.mark.parametrize("kind, dimension", [(Keypoints2D, 2), (Keypoints3D, 3)])
def test_keypoints_round_trips_and_validation(kind, dimension):
    points = np.arange(4 * dimension, dtype=float).reshape(4, dimension)
    keypoints = kind(points, scores=[0.1, 0.2, 0.3, 0.4], class_name="eye")
    assert len(keypoints) == 4
    restored = json_round_trip(keypoints)
    np.testing.assert_array_equal(restored.points, points)
    np.testing.assert_array_equal(restored.scores, [0.1, 0.2, 0.3, 0.4])
    assert restored.class_name == "eye"
    without_scores = json_round_trip(kind(points))
    assert without_scores.scores is None
    empty = kind(np.zeros((0, dimension)))
    assert len(empty) == 0 and len(json_round_trip(empty)) == 0
    name = kind.__name__
    with pytest.raises(ValueError, match=rf"{name}.points: expected shape \(\.\.\., {dimension}\), got \(4, 5\)"):
        kind(np.zeros((4, 5)))
    with pytest.raises(ValueError, match=rf"{name}.points: contains NaN"):
        kind(np.full((1, dimension), np.nan))
    with pytest.raises(ValueError, match=rf"{name}.scores: expected 4 scores, got 2"):
        kind(points, scores=[1.0, 2.0])
    with pytest.raises(ValueError, match=rf"{name}.from_dict: missing field\(s\) \['points'\]"):
        kind.from_dict({"scores": None})


def test_equality_compares_values_and_arrays_are_not_hashed():
    rotation, translation = random_pose(3)
    pose = Pose6D(rotation.as_quat(), translation, "cat")
    assert pose == Pose6D(-rotation.as_quat(), translation.copy(), "cat")
    assert pose != Pose6D(rotation.as_quat(), translation + 1e-9, "cat")
    assert pose != Pose6D(rotation.as_quat(), translation, "dog")
    with pytest.raises(TypeError):
        hash(pose)
    points = np.ones((2, 2))
    assert Keypoints2D(points, [1, 2]) == Keypoints2D(points.copy(), [1, 2])
    assert Keypoints2D(points, [1, 2]) != Keypoints2D(points, [1, 3])
    assert Keypoints2D(points) != Keypoints2D(points, [1, 2])
    assert Keypoints3D(np.ones((2, 3))) != Keypoints2D(points)
