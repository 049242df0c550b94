"""Files of one BOP scene folder: ``scene_gt.json``, ``scene_gt_info.json`` and the per-image
RGB, depth and mask images. Lengths come back in the units the caller asks for (``"m"`` or
``"mm"``, see :mod:`paz6d.datasets.bop.units`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np

from paz6d.datasets.bop.fields import entries_by_id, integer_field, number_field, required_field
from paz6d.datasets.bop.units import Units, lengths_from_mm

RGB_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif")
DEPTH_SUFFIXES = (".png", ".tif", ".tiff")
GT_INFO_FIELDS = ("bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib", "visib_fract")
Instance = TypeVar("Instance")
#: Real BOP ground truth is not exactly orthonormal (LM-O: max |R^T R - I| up to ~2e-3).
ROTATION_ROUNDING_TOLERANCE = 1e-2


def nearest_rotation(matrix: np.ndarray, where: str = "rotation") -> np.ndarray:
    """Returns ``matrix`` ``(3, 3)`` unchanged when orthonormal to 1e-9, else its nearest rotation
    (SVD) when it is a rounded rotation; raises ``ValueError`` when it is no rotation at all."""
    deviation = np.abs(matrix.T @ matrix - np.eye(3)).max()
    if deviation <= 1e-9 and np.linalg.det(matrix) > 0:
        return matrix
    if deviation > ROTATION_ROUNDING_TOLERANCE or np.linalg.det(matrix) <= 0:
        raise ValueError(f"{where}: not a rotation matrix (max |R^T R - I| = {deviation:.3g}, "
                         f"det = {np.linalg.det(matrix):.3g})")
    left, _, right = np.linalg.svd(matrix)
    return left @ right


def pose_from_bop(R_values, t_mm, where: str = "cam_R_m2c", snap_rotation: bool = True,
                  units: Units = "m") -> np.ndarray:
    """``T_model2cam`` ``(4, 4)`` from BOP ``cam_R_m2c`` (9, row-major) and ``cam_t_m2c`` (mm),
    translation in ``units``.

    With ``snap_rotation`` a slightly non-orthonormal stored rotation is replaced by the nearest
    rotation (see :func:`nearest_rotation`); without it the stored matrix is kept as is (what
    bop_toolkit's evaluation uses); either way a matrix that is no rotation raises ``ValueError``.
    """
    T = np.eye(4)
    rotation = np.asarray(R_values, dtype=np.float64).reshape(3, 3)
    snapped = nearest_rotation(rotation, where)  # also checks that a kept matrix is a (rounded) rotation
    T[:3, :3] = snapped if snap_rotation else rotation
    T[:3, 3] = lengths_from_mm(np.asarray(t_mm, dtype=np.float64).reshape(3), units)
    return T


@dataclass(frozen=True)
class GroundTruthPose:
    """One annotated instance: BOP object id and ``T_model2cam`` (translation in the units asked for)."""

    obj_id: int
    T_model2cam: np.ndarray


def instances_by_id(path: Path, read_instance: Callable[[Any, str], Instance]) -> dict[int, list[Instance]]:
    """``{im_id: [read_instance(entry, where), ...]}`` of a file holding one list of instances per image
    (``scene_gt.json``, ``scene_gt_info.json``), instance order kept; ``where`` names the file, the image and
    the instance for ``read_instance``'s messages.

    Raises:
        ValueError: naming the file and image whose value is not a list, or what ``read_instance`` raises.
    """
    result = {}
    for im_id, entries in entries_by_id(path).items():
        if not isinstance(entries, list):
            raise ValueError(f"{path}: image {im_id}: expected a list of instances")
        result[im_id] = [read_instance(entry, f"{path}: image {im_id}, instance {index}")
                         for index, entry in enumerate(entries)]
    return result


def load_scene_gt(path: str | Path, snap_rotations: bool = True,
                  units: Units = "m") -> dict[int, list[GroundTruthPose]]:
    """``scene_gt.json`` → ``{im_id: [GroundTruthPose, ...]}`` (instance order kept).

    Args:
        path: the file.
        snap_rotations: see :func:`pose_from_bop` (``False`` keeps the stored matrices).
        units: units of the returned translations (``"m"`` or ``"mm"``, the file's).
    """

    def read_pose(entry, where: str) -> GroundTruthPose:
        R = required_field(entry, "cam_R_m2c", where, 9)
        t = required_field(entry, "cam_t_m2c", where, 3)
        T = pose_from_bop(R, t, f"{where}, field 'cam_R_m2c'", snap_rotations, units)
        return GroundTruthPose(integer_field(entry, "obj_id", where), T)

    return instances_by_id(Path(path), read_pose)


def load_scene_gt_info(path: str | Path) -> dict[int, list[dict]]:
    """``scene_gt_info.json`` → ``{im_id: [info, ...]}`` with the six BOP fields checked (pixels)."""

    def read_info(entry, where: str) -> dict:
        for name in GT_INFO_FIELDS:
            required_field(entry, name, where, 4 if name.startswith("bbox") else 1)
        number_field(entry, "visib_fract", where, minimum=0.0, maximum=1.0)
        return entry

    return instances_by_id(Path(path), read_info)


def find_image(folder: Path, im_id: int, suffixes: tuple[str, ...] = RGB_SUFFIXES) -> Path | None:
    """``<folder>/<im_id:06d><suffix>`` for the first suffix that exists, else ``None``."""
    for suffix in suffixes:
        candidate = folder / f"{im_id:06d}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def read_depth(path: str | Path, depth_scale: float, units: Units = "m") -> np.ndarray:
    """A BOP depth image ``(H, W)`` as float64 in ``units`` (0 = no data).

    Args:
        path: single-channel depth image (16-bit PNG or float TIFF).
        depth_scale: millimetres per stored unit (``scene_camera.json``).
        units: ``"m"`` or ``"mm"``.
    """
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.ndim != 2:
        raise ValueError(f"{path}: could not decode a single-channel depth image")
    return lengths_from_mm(raw.astype(np.float64) * depth_scale, units)


def read_mask(path: Path) -> np.ndarray | None:
    """A BOP mask PNG as ``(H, W)`` bool (pixels > 127), ``None`` when the file is absent."""
    if not path.is_file():
        return None
    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise ValueError(f"{path}: could not decode mask image")
    return mask > 127
