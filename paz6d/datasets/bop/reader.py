"""BOP-format data sets (real ones and those `paz6d generate` writes), converted to metres.

BOP files store millimetres; everything returned here is in metres (poses ``T_model2cam``
``(4, 4)``, OpenCV camera frame). Parts a data set lacks (depth, masks, some RGB frames) come back
as ``None``. Malformed files raise ``ValueError`` naming the file, image/object and field.

Example:
    >>> dataset = BOPDataset("/data/lmo", split="test")                      # doctest: +SKIP
    >>> sample = next(iter(dataset))                                         # doctest: +SKIP
    >>> sample.objects[0].T_model2cam.shape                                  # doctest: +SKIP
    (4, 4)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from paz6d.backend.camera import Camera
from paz6d.backend.files import load_json
from paz6d.backend.image import load_image

MILLIMETRES_TO_METRES = 0.001
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif")


def _field(entry, name: str, where: str, size: int | None = None):
    if not isinstance(entry, dict) or name not in entry:
        raise ValueError(f"{where}: missing field {name!r}")
    value = entry[name]
    if size is not None:
        try:
            array = np.asarray(value, dtype=np.float64).ravel()
        except (TypeError, ValueError) as error:
            raise ValueError(f"{where}: field {name!r} is not numeric") from error
        if array.size != size or not np.all(np.isfinite(array)):
            raise ValueError(f"{where}: field {name!r} must hold {size} finite numbers, got {array.size}")
        return array
    return value


def _image_entries(path: Path) -> dict[int, object]:
    data = load_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected an object keyed by image id")
    entries = {}
    for key, value in data.items():
        if not str(key).isdigit():
            raise ValueError(f"{path}: key {key!r} is not an image id")
        entries[int(key)] = value
    return dict(sorted(entries.items()))


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


def pose_from_bop(R_values, t_millimetres, where: str = "cam_R_m2c", snap_rotation: bool = True) -> np.ndarray:
    """``T_model2cam`` ``(4, 4)`` in metres from BOP ``cam_R_m2c`` (9, row-major) and ``cam_t_m2c`` (mm).

    With ``snap_rotation`` a slightly non-orthonormal stored rotation is replaced by the nearest
    rotation (see :func:`nearest_rotation`); without it the stored matrix is kept as is (what
    bop_toolkit's evaluation uses).
    """
    T = np.eye(4)
    rotation = np.asarray(R_values, dtype=np.float64).reshape(3, 3)
    T[:3, :3] = nearest_rotation(rotation, where) if snap_rotation else rotation
    T[:3, 3] = np.asarray(t_millimetres, dtype=np.float64).reshape(3) * MILLIMETRES_TO_METRES
    return T


@dataclass(frozen=True)
class GroundTruthPose:
    """One annotated instance: BOP object id and ``T_model2cam`` (metres)."""

    obj_id: int
    T_model2cam: np.ndarray


def load_scene_gt(path: str | Path, snap_rotations: bool = True) -> dict[int, list[GroundTruthPose]]:
    """``scene_gt.json`` → ``{im_id: [GroundTruthPose, ...]}`` (instance order kept).

    ``snap_rotations``: see :func:`pose_from_bop` (``False`` keeps the stored matrices).
    """
    path = Path(path)
    result = {}
    for im_id, entries in _image_entries(path).items():
        if not isinstance(entries, list):
            raise ValueError(f"{path}: image {im_id}: expected a list of instances")
        poses = []
        for index, entry in enumerate(entries):
            where = f"{path}: image {im_id}, instance {index}"
            R = _field(entry, "cam_R_m2c", where, 9)
            t = _field(entry, "cam_t_m2c", where, 3)
            T = pose_from_bop(R, t, where, snap_rotations)
            poses.append(GroundTruthPose(int(_field(entry, "obj_id", where)), T))
        result[im_id] = poses
    return result


@dataclass(frozen=True)
class SceneCamera:
    """``scene_camera.json`` entry: ``K`` (3×3 px), ``depth_scale`` (mm per depth unit) and,
    when given, ``T_world2cam`` (4×4, metres)."""

    K: np.ndarray
    depth_scale: float | None
    T_world2cam: np.ndarray | None = None


def load_scene_camera(path: str | Path) -> dict[int, SceneCamera]:
    """``scene_camera.json`` → ``{im_id: SceneCamera}``."""
    path = Path(path)
    result = {}
    for im_id, entry in _image_entries(path).items():
        where = f"{path}: image {im_id}"
        K = _field(entry, "cam_K", where, 9).reshape(3, 3)
        depth_scale = entry.get("depth_scale")
        if depth_scale is not None and (not np.isfinite(depth_scale) or depth_scale <= 0):
            raise ValueError(f"{where}: field 'depth_scale' must be positive, got {depth_scale}")
        T_world2cam = None
        if "cam_R_w2c" in entry:
            T_world2cam = pose_from_bop(_field(entry, "cam_R_w2c", where, 9), _field(entry, "cam_t_w2c", where, 3),
                                        where)
        result[im_id] = SceneCamera(K, None if depth_scale is None else float(depth_scale), T_world2cam)
    return result


GT_INFO_FIELDS = ("bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib", "visib_fract")


def load_scene_gt_info(path: str | Path) -> dict[int, list[dict]]:
    """``scene_gt_info.json`` → ``{im_id: [info, ...]}`` with the six BOP fields checked (pixels)."""
    path = Path(path)
    result = {}
    for im_id, entries in _image_entries(path).items():
        infos = []
        for index, entry in enumerate(entries):
            where = f"{path}: image {im_id}, instance {index}"
            for name in GT_INFO_FIELDS:
                _field(entry, name, where, 4 if name.startswith("bbox") else 1)
            infos.append(entry)
        result[im_id] = infos
    return result


@dataclass(frozen=True)
class ModelInfo:
    """``models_info.json`` entry in metres.

    Attributes:
        diameter: largest distance between two model points (m).
        minimum: ``(3,)`` corner of the model's axis-aligned box (m).
        size: ``(3,)`` box extent (m).
        symmetries_discrete: ``(S, 4, 4)`` symmetry transforms (translation in m).
        symmetries_continuous: ``[(axis (3,), offset (3,) in m), ...]``.
    """

    diameter: float
    minimum: np.ndarray | None
    size: np.ndarray | None
    symmetries_discrete: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    symmetries_continuous: list = field(default_factory=list)


def load_models_info(path: str | Path) -> dict[int, ModelInfo]:
    """``models_info.json`` → ``{obj_id: ModelInfo}`` converted from mm to metres."""
    path = Path(path)
    data = load_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected an object keyed by object id")
    result = {}
    for key, entry in data.items():
        if not str(key).isdigit():
            raise ValueError(f"{path}: key {key!r} is not an object id")
        where = f"{path}: object {key}"
        diameter = float(_field(entry, "diameter", where, 1)[0]) * MILLIMETRES_TO_METRES
        minimum = size = None
        if "min_x" in entry:
            minimum = np.array([_field(entry, f"min_{axis}", where, 1)[0] for axis in "xyz"]) * MILLIMETRES_TO_METRES
            size = np.array([_field(entry, f"size_{axis}", where, 1)[0] for axis in "xyz"]) * MILLIMETRES_TO_METRES
        discrete = []
        for index, values in enumerate(entry.get("symmetries_discrete", [])):
            T = _field({"value": values}, "value", f"{where}, symmetries_discrete[{index}]", 16).reshape(4, 4)
            T[:3, 3] *= MILLIMETRES_TO_METRES
            discrete.append(T)
        continuous = []
        for index, symmetry in enumerate(entry.get("symmetries_continuous", [])):
            inner = f"{where}, symmetries_continuous[{index}]"
            continuous.append((_field(symmetry, "axis", inner, 3),
                               _field(symmetry, "offset", inner, 3) * MILLIMETRES_TO_METRES))
        result[int(key)] = ModelInfo(diameter, minimum, size, np.array(discrete).reshape(-1, 4, 4), continuous)
    return dict(sorted(result.items()))


def model_path(models_folder: str | Path, obj_id: int) -> Path:
    """``<models_folder>/obj_XXXXXX.ply``."""
    return Path(models_folder) / f"obj_{obj_id:06d}.ply"


def load_model(models_folder: str | Path, obj_id: int):
    """The PLY model of ``obj_id`` as a ``trimesh.Trimesh`` in metres (vertex colours kept)."""
    from paz6d.backend.mesh import load_mesh

    return load_mesh(model_path(models_folder, obj_id), scale=MILLIMETRES_TO_METRES)


@dataclass
class BOPObject:
    """One instance of a sample: id, pose (metres), masks and ``scene_gt_info`` when present."""

    obj_id: int
    T_model2cam: np.ndarray
    mask: np.ndarray | None = None
    mask_visib: np.ndarray | None = None
    info: dict | None = None


@dataclass
class BOPSample:
    """One image of a BOP scene.

    Attributes:
        scene_id, im_id: BOP ids.
        camera: intrinsics and image size.
        image: ``(H, W, 3)`` uint8 RGB, ``None`` when the file is absent.
        depth: ``(H, W)`` float32 metres (0 = no data), ``None`` when absent.
        objects: annotated instances in ``scene_gt.json`` order.
    """

    scene_id: int
    im_id: int
    camera: Camera
    image: np.ndarray | None
    depth: np.ndarray | None
    objects: list[BOPObject]

    @property
    def K(self) -> np.ndarray:
        return self.camera.K


def _find_image(folder: Path, im_id: int) -> Path | None:
    for suffix in IMAGE_SUFFIXES:
        candidate = folder / f"{im_id:06d}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def _read_mask(path: Path) -> np.ndarray | None:
    if not path.is_file():
        return None
    mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise ValueError(f"{path}: could not decode mask image")
    return mask > 127


class BOPScene:
    """One ``<root>/<split>/<scene_id>`` folder; iterating yields :class:`BOPSample` per GT image."""

    def __init__(self, folder: str | Path, image_size: tuple[int, int] | None = None):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise ValueError(f"{self.folder}: scene folder not found")
        if not self.folder.name.isdigit():
            raise ValueError(f"{self.folder}: expected a numeric BOP scene folder name")
        self.scene_id = int(self.folder.name)
        self.ground_truth = load_scene_gt(self.folder / "scene_gt.json")
        self.cameras = load_scene_camera(self.folder / "scene_camera.json")
        info_path = self.folder / "scene_gt_info.json"
        self.infos = load_scene_gt_info(info_path) if info_path.is_file() else {}
        self._image_size = image_size

    @property
    def image_ids(self) -> list[int]:
        return list(self.ground_truth)

    def __len__(self) -> int:
        return len(self.ground_truth)

    def __iter__(self) -> Iterator[BOPSample]:
        for im_id in self.ground_truth:
            yield self.sample(im_id)

    def sample(self, im_id: int) -> BOPSample:
        """The sample of image ``im_id`` (files read now)."""
        if im_id not in self.ground_truth:
            raise ValueError(f"{self.folder / 'scene_gt.json'}: no image {im_id}")
        if im_id not in self.cameras:
            raise ValueError(f"{self.folder / 'scene_camera.json'}: no entry for image {im_id}")
        scene_camera = self.cameras[im_id]
        image_path = _find_image(self.folder / "rgb", im_id)
        image = load_image(image_path) if image_path is not None else None
        if self._image_size is not None:
            width, height = self._image_size
        elif image is not None:
            height, width = image.shape[:2]
        else:
            width, height = round(2 * scene_camera.K[0, 2] + 1), round(2 * scene_camera.K[1, 2] + 1)
        depth = None
        depth_path = _find_image(self.folder / "depth", im_id)
        if depth_path is not None:
            raw = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
            if raw is None or raw.ndim != 2:
                raise ValueError(f"{depth_path}: could not decode a single-channel depth image")
            if scene_camera.depth_scale is None:
                raise ValueError(f"{self.folder / 'scene_camera.json'}: image {im_id}: missing field 'depth_scale'")
            depth = (raw.astype(np.float64) * scene_camera.depth_scale * MILLIMETRES_TO_METRES).astype(np.float32)
        infos = self.infos.get(im_id)
        objects = []
        for index, pose in enumerate(self.ground_truth[im_id]):
            name = f"{im_id:06d}_{index:06d}.png"
            objects.append(BOPObject(pose.obj_id, pose.T_model2cam, _read_mask(self.folder / "mask" / name),
                                     _read_mask(self.folder / "mask_visib" / name),
                                     infos[index] if infos is not None and index < len(infos) else None))
        return BOPSample(self.scene_id, im_id, Camera(scene_camera.K, width, height), image, depth, objects)


class BOPDataset:
    """A BOP data set root (``camera.json``, ``models/``, ``<split>/<scene>/...``).

    Args:
        root: data set folder.
        split: split folder (``test``, ``train``, ``train_pbr``...).
        scene_ids: scenes to read (default: all numeric folders of the split).
    """

    def __init__(self, root: str | Path, split: str = "test", scene_ids: list[int] | None = None):
        self.root = Path(root)
        split_folder = self.root / split
        if not split_folder.is_dir():
            raise ValueError(f"{split_folder}: split folder not found")
        camera_path = self.root / "camera.json"
        self.camera = Camera.from_bop_json(camera_path) if camera_path.is_file() else None
        if scene_ids is None:
            scene_ids = sorted(int(path.name) for path in split_folder.iterdir() if path.name.isdigit())
        size = None if self.camera is None else (self.camera.width, self.camera.height)
        self.scenes = [BOPScene(split_folder / f"{scene_id:06d}", image_size=size) for scene_id in scene_ids]

    @property
    def models_folder(self) -> Path:
        return self.root / "models"

    def models_info(self) -> dict[int, ModelInfo]:
        """``models/models_info.json`` in metres."""
        return load_models_info(self.models_folder / "models_info.json")

    def model(self, obj_id: int):
        """Mesh of ``obj_id`` in metres."""
        return load_model(self.models_folder, obj_id)

    def __len__(self) -> int:
        return sum(len(scene) for scene in self.scenes)

    def __iter__(self) -> Iterator[BOPSample]:
        for scene in self.scenes:
            yield from scene
