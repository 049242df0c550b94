"""The camera JSON file that ``--camera`` reads and ``paz6d calibrate`` writes.

The fields are those of a BOP data set's ``camera.json`` (``fx, fy, cx, cy`` in pixels, ``width,
height`` in pixels, optional ``depth_scale`` in millimetres per depth unit) plus two optional ones:
``dist``, the lens distortion in OpenCV's order ``[k1, k2, p1, p2, k3]`` (4, 5, 8, 12 or 14
coefficients), and ``rms_px``, the calibration's root-mean-square re-projection error in pixels::

    {"fx": 572.4, "fy": 573.6, "cx": 325.3, "cy": 242.0, "width": 640, "height": 480,
     "depth_scale": 1.0, "dist": [0.1, -0.2, 0.0, 0.0, 0.05], "rms_px": 0.21}

A BOP ``camera.json`` is therefore a valid camera file (without distortion).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend.camera import Camera
from paz6d.backend.checks import integer_field, number_field, required_field, short_repr
from paz6d.backend.files import json_bytes, load_json, write_bytes_atomically

#: Numbers of OpenCV distortion coefficients a ``dist`` field may hold.
DISTORTION_SIZES = (4, 5, 8, 12, 14)


def _distortion_field(data: dict, where: str) -> np.ndarray | None:
    value = data.get("dist")
    if value is None:
        return None
    if not isinstance(value, list) or len(value) not in DISTORTION_SIZES:
        raise ValueError(f"{where}: field 'dist' must be a list of {', '.join(map(str, DISTORTION_SIZES))} "
                         f"OpenCV distortion coefficients [k1, k2, p1, p2, k3, ...], got {short_repr(value)}")
    if any(isinstance(item, bool) or not isinstance(item, (int, float)) for item in value):
        raise ValueError(f"{where}: field 'dist' must hold numbers, got {short_repr(value)}")
    return required_field(data, "dist", where, len(value))


def read_camera_json(path: str | Path) -> Camera:
    """The :class:`~paz6d.backend.camera.Camera` of a camera JSON file (see the module docstring).

    Raises:
        ValueError: the file is missing or not JSON, or a field is missing or invalid (naming the file and field).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: camera file not found (expected a JSON object with fx, fy, cx, cy, width, "
                         "height)")
    data = load_json(path)
    where = str(path)
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a JSON object with fx, fy, cx, cy, width, height, "
                         f"got {type(data).__name__}")
    fx, fy = (number_field(data, name, where, positive=True) for name in ("fx", "fy"))
    cx, cy = (number_field(data, name, where) for name in ("cx", "cy"))
    width, height = (integer_field(data, name, where, minimum=1) for name in ("width", "height"))
    for name in ("depth_scale", "rms_px"):
        if data.get(name) is not None:
            number_field(data, name, where, minimum=0.0, positive=name == "depth_scale")
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return Camera(K, width, height, _distortion_field(data, where))


def camera_json(camera: Camera, dist=None, rms: float | None = None, depth_scale: float | None = None) -> dict:
    """The camera file's JSON object for ``camera``.

    Args:
        camera: intrinsics and image size; its ``K`` must have zero skew (BOP has no skew field).
        dist: OpenCV distortion coefficients written as ``dist`` (default: ``camera.distortion``).
        rms: re-projection RMS error (px) of a calibration, written as ``rms_px``.
        depth_scale: millimetres per depth unit, for a camera with a depth sensor.
    Raises:
        ValueError: a skewed ``K``, or a ``dist``/``rms``/``depth_scale`` that is not valid.
    """
    if camera.K[0, 1] != 0:
        raise ValueError(f"camera: K has skew {camera.K[0, 1]}; the camera file (BOP fields) holds none")
    data = {"fx": float(camera.K[0, 0]), "fy": float(camera.K[1, 1]), "cx": float(camera.K[0, 2]),
            "cy": float(camera.K[1, 2]), "width": camera.width, "height": camera.height}
    if depth_scale is not None:
        data["depth_scale"] = number_field({"depth_scale": depth_scale}, "depth_scale", "camera", positive=True)
    coefficients = camera.distortion if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if coefficients is not None:
        data["dist"] = [float(value) for value in coefficients]
        _distortion_field(data, "camera")
    if rms is not None:
        data["rms_px"] = number_field({"rms_px": rms}, "rms_px", "camera", minimum=0.0)
    return data


def write_camera_json(path: str | Path, camera: Camera, dist=None, rms: float | None = None,
                      depth_scale: float | None = None) -> Path:
    """Writes ``camera`` as a camera JSON file (atomically; see :func:`camera_json` for the arguments)."""
    return write_bytes_atomically(path, json_bytes(camera_json(camera, dist, rms, depth_scale), indent=2))
