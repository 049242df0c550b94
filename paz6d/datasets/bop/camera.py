"""BOP cameras: the data set's ``camera.json`` and the per-image ``scene_camera.json``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.camera import Camera
from paz6d.backend.files import load_json
from paz6d.datasets.bop.fields import entries_by_id, integer_field, number_field, required_field
from paz6d.datasets.bop.scene import pose_from_bop
from paz6d.datasets.bop.units import Units


def load_camera(path: str | Path) -> Camera:
    """A data set's ``camera.json`` (``fx, fy, cx, cy`` px, ``width, height``) as a :class:`Camera`.

    Raises:
        ValueError: the file is missing or lacks one of those fields.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: camera file not found")
    data = load_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object with fx, fy, cx, cy, width, height")
    where = str(path)
    fx, fy = (number_field(data, name, where, positive=True) for name in ("fx", "fy"))
    cx, cy = (number_field(data, name, where) for name in ("cx", "cy"))
    width, height = (integer_field(data, name, where, minimum=1) for name in ("width", "height"))
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return Camera(K, width, height)


@dataclass(frozen=True)
class SceneCamera:
    """``scene_camera.json`` entry: ``K`` (3×3 px), ``depth_scale`` (mm per depth unit) and,
    when given, ``T_world2cam`` (4×4, translation in the units asked for)."""

    K: np.ndarray
    depth_scale: float | None
    T_world2cam: np.ndarray | None = None


def load_scene_camera(path: str | Path, units: Units = "m") -> dict[int, SceneCamera]:
    """``scene_camera.json`` → ``{im_id: SceneCamera}`` (``T_world2cam`` in ``units``)."""
    path = Path(path)
    result = {}
    for im_id, entry in entries_by_id(path).items():
        where = f"{path}: image {im_id}"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected an object with cam_K (and depth_scale)")
        K = required_field(entry, "cam_K", where, 9).reshape(3, 3)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or K[1, 0] != 0 or np.any(K[2] != [0, 0, 1]):
            raise ValueError(f"{where}: field 'cam_K' must be [fx, s, cx, 0, fy, cy, 0, 0, 1] with fx, fy > 0, "
                             f"got {K.ravel().tolist()}")
        depth_scale = None if entry.get("depth_scale") is None else \
            number_field(entry, "depth_scale", where, positive=True)
        T_world2cam = None
        if "cam_R_w2c" in entry:
            T_world2cam = pose_from_bop(required_field(entry, "cam_R_w2c", where, 9),
                                        required_field(entry, "cam_t_w2c", where, 3), where, units=units)
        result[im_id] = SceneCamera(K, None if depth_scale is None else float(depth_scale), T_world2cam)
    return result
