"""The camera JSON file (paz6d.backend.camera_file): BOP fields plus distortion, round trip and errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from paz6d.backend.camera import Camera
from paz6d.backend.camera_file import camera_json, read_camera_json, write_camera_json

K = np.array([[572.4114, 0.0, 325.2611], [0.0, 573.57043, 242.04899], [0.0, 0.0, 1.0]])
DIST = [-0.28, 0.07, 0.001, -0.0005, 0.01]


def test_write_read_round_trip_keeps_intrinsics_size_and_distortion(tmp_path):
    path = write_camera_json(tmp_path / "camera.json", Camera(K, 640, 480), dist=DIST, rms=0.25, depth_scale=0.1)
    data = json.loads(path.read_text())
    assert data == {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "width": 640, "height": 480,
                    "depth_scale": 0.1, "dist": DIST, "rms_px": 0.25}
    camera = read_camera_json(path)
    np.testing.assert_array_equal(camera.K, K)
    assert (camera.width, camera.height) == (640, 480)
    np.testing.assert_array_equal(camera.distortion, DIST)


def test_a_bop_camera_json_reads_without_distortion(tmp_path):
    path = tmp_path / "camera.json"
    path.write_text(json.dumps({"cx": 325.0, "cy": 242.0, "depth_scale": 1.0, "fx": 572.0, "fy": 573.0,
                                "height": 480, "width": 640}))
    camera = read_camera_json(path)
    assert camera.distortion is None
    np.testing.assert_array_equal(camera.K, [[572.0, 0, 325.0], [0, 573.0, 242.0], [0, 0, 1]])
    assert "dist" not in camera_json(camera)


@pytest.mark.parametrize("change, field", [
    ({"fx": 0}, "'fx'"), ({"width": 640.5}, "'width'"), ({"dist": [0.1, 0.2, 0.3]}, "'dist'"),
    ({"dist": [0.1, "a", 0, 0, 0]}, "'dist'"), ({"dist": "abc"}, "'dist'"), ({"depth_scale": -1}, "'depth_scale'"),
    ({"rms_px": "x"}, "'rms_px'"), ({"cy": None}, "'cy'")])
def test_invalid_fields_name_the_file_and_field(tmp_path, change, field):
    path = tmp_path / "camera.json"
    path.write_text(json.dumps({**camera_json(Camera(K, 640, 480)), **change}))
    with pytest.raises(ValueError, match=field) as error:
        read_camera_json(path)
    assert str(path) in str(error.value)


def test_missing_file_and_skewed_K_are_refused(tmp_path):
    with pytest.raises(ValueError, match="camera file not found"):
        read_camera_json(tmp_path / "none.json")
    skewed = K.copy()
    skewed[0, 1] = 1.0
    with pytest.raises(ValueError, match="skew"):
        write_camera_json(tmp_path / "camera.json", Camera(skewed, 640, 480))
    assert not (tmp_path / "camera.json").exists()
