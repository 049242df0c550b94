"""Writing BOP files: ``camera.json``, models and ``models_info.json``, and the entries of
``scene_gt.json``, ``scene_camera.json`` and ``scene_gt_info.json``.

Callers hand lengths in metres (the default, ``units="m"``) or millimetres; they are converted to
BOP's millimetres once, here. ``data_gen.bop_writer`` lays the files out for ``paz6d generate``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend.files import write_bytes_atomically, write_json_atomically
from paz6d.backend.image import nonzero_window
from paz6d.backend.mesh import bounding_box
from paz6d.datasets.bop.models import MODELS_INFO, model_path
from paz6d.datasets.bop.units import DEPTH_PNG_MAX, Units, mm_from_lengths, mm_per_unit


def write_camera(path: str | Path, K, width: int, height: int, depth_scale: float) -> Path:
    """A data set's ``camera.json``: ``K`` ``(3, 3)`` px, image size px, ``depth_scale`` mm per unit."""
    K = np.asarray(K)
    return write_json_atomically(path, {"cx": K[0, 2], "cy": K[1, 2], "depth_scale": depth_scale, "fx": K[0, 0],
                                        "fy": K[1, 1], "height": height, "width": width})


def write_models(folder: str | Path, meshes, object_ids, diameters, extra_fields: dict[int, dict] | None = None,
                 units: Units = "m") -> list[Path]:
    """``<folder>/obj_XXXXXX.ply`` (binary, millimetres, texture baked to vertex colours) per mesh and
    ``<folder>/models_info.json`` (diameter and bounding box in mm, plus ``extra_fields[obj_id]``
    such as symmetries, copied as given).

    Args:
        folder: the ``models`` folder.
        meshes: ``trimesh.Trimesh`` per object, vertices in ``units``.
        object_ids: BOP id per mesh.
        diameters: diameter per mesh in ``units``.
        extra_fields: ``{obj_id: {field: value}}`` added to the object's ``models_info`` entry.
        units: ``"m"`` or ``"mm"``.

    Returns:
        The PLY paths in ``object_ids`` order, then ``models_info.json``.
    """
    extra_fields = extra_fields or {}
    written, models_info = [], {}
    for mesh, object_id, diameter in zip(meshes, object_ids, diameters):
        millimetres = mesh.copy()
        if millimetres.visual.kind == "texture":
            millimetres.visual = millimetres.visual.to_color()
        millimetres.apply_scale(mm_per_unit(units))
        path = model_path(folder, object_id)
        write_bytes_atomically(path, millimetres.export(file_type="ply", encoding="binary"))
        written.append(path)
        low, high = bounding_box(millimetres.vertices)
        info = {"diameter": float(mm_from_lengths(diameter, units)), "min_x": float(low[0]), "min_y": float(low[1]),
                "min_z": float(low[2]), "size_x": float(high[0] - low[0]), "size_y": float(high[1] - low[1]),
                "size_z": float(high[2] - low[2])}
        info.update(extra_fields.get(object_id, {}))
        models_info[str(object_id)] = info
    written.append(write_json_atomically(Path(folder) / MODELS_INFO, models_info))
    return written


def pose_entry(T_model2cam, units: Units = "m") -> dict:
    """``{"cam_R_m2c": 9 values row-major, "cam_t_m2c": 3 values in mm}`` of a ``(4, 4)`` pose
    whose translation is in ``units``."""
    T = np.asarray(T_model2cam, dtype=np.float64)
    return {"cam_R_m2c": T[:3, :3].ravel().tolist(), "cam_t_m2c": mm_from_lengths(T[:3, 3], units).tolist()}


def gt_entry(obj_id: int, T_model2cam, units: Units = "m") -> dict:
    """A ``scene_gt.json`` instance: :func:`pose_entry` and ``obj_id``."""
    return {**pose_entry(T_model2cam, units), "obj_id": obj_id}


def scene_camera_entry(K, depth_scale: float) -> dict:
    """A ``scene_camera.json`` entry: ``cam_K`` (9 values row-major, px) and ``depth_scale`` (mm per unit)."""
    return {"cam_K": np.asarray(K).ravel().tolist(), "depth_scale": depth_scale}


def bbox_xywh(mask: np.ndarray) -> list[int]:
    """Tight ``[x, y, width, height]`` of a mask's pixels; ``[-1, -1, -1, -1]`` when empty (BOP)."""
    window = nonzero_window(mask)
    if window is None:
        return [-1, -1, -1, -1]
    rows, columns = window
    return [columns.start, rows.start, columns.stop - columns.start, rows.stop - rows.start]


def gt_info_entry(visible: np.ndarray, full: np.ndarray, depth_valid: np.ndarray) -> dict:
    """A ``scene_gt_info.json`` instance from its ``(H, W)`` bool masks: visible part, whole
    (unoccluded) object and pixels with a depth value."""
    px_count_all = int(full.sum())
    px_count_visib = int(visible.sum())
    return {"bbox_obj": bbox_xywh(full), "bbox_visib": bbox_xywh(visible), "px_count_all": px_count_all,
            "px_count_valid": int((full & depth_valid).sum()), "px_count_visib": px_count_visib,
            "visib_fract": px_count_visib / px_count_all if px_count_all else 0.0}


def depth_png_from_lengths(depth: np.ndarray, depth_scale: float, units: Units = "m") -> np.ndarray:
    """``(H, W)`` depth in ``units`` (0 = none) to the uint16 values of a BOP depth PNG
    (``depth_scale`` mm per unit, rounded, clipped at :data:`DEPTH_PNG_MAX`)."""
    stored = np.round(np.asarray(depth) * (mm_per_unit(units) / depth_scale))
    return np.minimum(stored, DEPTH_PNG_MAX).astype(np.uint16)
