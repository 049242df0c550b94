"""The parts of a BOP data set that pose evaluation needs, in millimetres (BOP mode).

Cameras, visibilities and models info are read with :mod:`paz6d.datasets.bop` (which returns
metres) and converted back to millimetres here, so errors, thresholds and reports use BOP's
units. Ground-truth rotations are kept as stored (``snap_rotations=False``): the BOP toolkit
evaluates with the stored matrices (LM-O's differ from rotations by up to 0.0094), and so do we.
Error meshes come from ``models_eval/`` when the data set has it (as the BOP toolkit does), else
``models/``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from evaluation.pose_errors import MAX_SYMMETRY_STEP, ObjectModel, symmetry_transformations
from paz6d.backend.camera import Camera
from paz6d.backend.files import load_json
from paz6d.backend.mesh import load_mesh
from paz6d.datasets import bop as bop_files

METRES_TO_MILLIMETRES = 1000.0
DEFAULT_TARGETS = "test_targets_bop19.json"
DEPTH_SUFFIXES = (".png", ".tif", ".tiff")


@dataclass(frozen=True)
class Target:
    """One BOP'19 estimation target: ``inst_count`` instances of ``obj_id`` in an image."""

    scene_id: int
    im_id: int
    obj_id: int
    inst_count: int


def read_targets(path: str | Path) -> list[Target]:
    """Reads ``test_targets_bop19.json`` (a list of ``{scene_id, im_id, obj_id, inst_count}``)."""
    path = Path(path)
    data = load_json(path)
    if not isinstance(data, list):
        raise ValueError(f"{path}: expected a list of targets")
    targets = []
    for index, entry in enumerate(data):
        values = []
        for name in ("scene_id", "im_id", "obj_id", "inst_count"):
            value = entry.get(name) if isinstance(entry, dict) else None
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{path}: target {index}: field {name!r} must be a non-negative integer, "
                                 f"got {value!r}")
            values.append(value)
        if values[3] == 0:
            raise ValueError(f"{path}: target {index}: field 'inst_count' must be positive")
        targets.append(Target(*values))
    return targets


@dataclass(frozen=True)
class ImageGroundTruth:
    """Annotated instances of one test image (millimetres).

    Attributes:
        scene_id, im_id: BOP ids.
        K: ``(3, 3)`` intrinsics (px).
        depth_scale: millimetres per depth-image unit (``None`` when not given).
        obj_ids: ``(G,)`` object id of each instance (``scene_gt.json`` order).
        poses: ``(G, 4, 4)`` ``T_model2cam`` with translations in millimetres.
        visib_fract: ``(G,)`` visible fraction of each instance (``scene_gt_info.json``).
    """

    scene_id: int
    im_id: int
    K: np.ndarray
    depth_scale: float | None
    obj_ids: np.ndarray
    poses: np.ndarray
    visib_fract: np.ndarray


@dataclass
class BopEvaluationData:
    """Ground truth, targets and object models of one BOP split, in millimetres.

    Attributes:
        root: data set folder.
        split: split name (``test``...).
        models_folder: ``models_eval/`` when present, else ``models/``.
        width, height: image size (px) from ``camera.json``.
        diameters: ``{obj_id: diameter (mm)}`` from the models' ``models_info.json``.
        symmetries: ``{obj_id: (S, 4, 4)}`` symmetry transformations (mm), identity first.
        images: ``{(scene_id, im_id): ImageGroundTruth}`` for every image of the targets' scenes.
        targets: the estimation targets.
    """

    root: Path
    split: str
    models_folder: Path
    width: int
    height: int
    diameters: dict[int, float]
    symmetries: dict[int, np.ndarray]
    images: dict[tuple[int, int], ImageGroundTruth]
    targets: list[Target]
    _models: dict[int, ObjectModel] = field(default_factory=dict, repr=False)
    _meshes: dict = field(default_factory=dict, repr=False)

    @property
    def object_ids(self) -> list[int]:
        return sorted(self.diameters)

    def model_path(self, obj_id: int) -> Path:
        return bop_files.model_path(self.models_folder, obj_id)

    def object_model(self, obj_id: int) -> ObjectModel:
        """Points (all mesh vertices, mm), diameter and symmetries of ``obj_id`` (cached)."""
        if obj_id not in self._models:
            mesh = load_mesh(self.model_path(obj_id))
            self._models[obj_id] = ObjectModel(np.asarray(mesh.vertices, dtype=np.float64),
                                               self.diameters[obj_id], self.symmetries[obj_id])
        return self._models[obj_id]

    def render_mesh(self, obj_id: int):
        """The error mesh of ``obj_id`` in metres, for the renderer (cached)."""
        if obj_id not in self._meshes:
            self._meshes[obj_id] = load_mesh(self.model_path(obj_id), scale=1.0 / METRES_TO_MILLIMETRES)
        return self._meshes[obj_id]

    def scene_folder(self, scene_id: int) -> Path:
        return self.root / self.split / f"{scene_id:06d}"

    def depth_path(self, scene_id: int, im_id: int) -> Path | None:
        """The depth image of an image, ``None`` when the data set has none."""
        folder = self.scene_folder(scene_id) / "depth"
        for suffix in DEPTH_SUFFIXES:
            candidate = folder / f"{im_id:06d}{suffix}"
            if candidate.is_file():
                return candidate
        return None

    def read_depth(self, scene_id: int, im_id: int) -> np.ndarray:
        """Depth of an image in millimetres, ``(H, W)`` float64 (0 = missing)."""
        path = self.depth_path(scene_id, im_id)
        if path is None:
            raise ValueError(f"{self.scene_folder(scene_id) / 'depth'}: no depth image for image {im_id} "
                             "(VSD needs depth images)")
        raw = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH)
        if raw is None or raw.ndim != 2:
            raise ValueError(f"{path}: could not decode a single-channel depth image")
        if raw.shape != (self.height, self.width):
            raise ValueError(f"{path}: expected {self.width}x{self.height} px, got {raw.shape[1]}x{raw.shape[0]}")
        scale = self.images[(scene_id, im_id)].depth_scale
        if scale is None:
            raise ValueError(f"{self.scene_folder(scene_id) / 'scene_camera.json'}: image {im_id}: "
                             "missing field 'depth_scale'")
        return raw.astype(np.float64) * scale


def _models_folder(root: Path) -> Path:
    for name in ("models_eval", "models"):
        if (root / name / "models_info.json").is_file():
            return root / name
    raise ValueError(f"{root}: no models_eval/models_info.json or models/models_info.json")


def _scene_images(scene_folder: Path, scene_id: int) -> dict[tuple[int, int], ImageGroundTruth]:
    gt = bop_files.load_scene_gt(scene_folder / "scene_gt.json", snap_rotations=False)
    cameras = bop_files.load_scene_camera(scene_folder / "scene_camera.json")
    info_path = scene_folder / "scene_gt_info.json"
    if not info_path.is_file():
        raise ValueError(f"{info_path}: file not found (the visible fractions of the GT are needed)")
    infos = bop_files.load_scene_gt_info(info_path)
    images = {}
    for im_id, instances in gt.items():
        obj_ids = np.array([instance.obj_id for instance in instances], dtype=np.int64)
        poses = np.array([instance.T_model2cam for instance in instances]).reshape(-1, 4, 4)
        poses[:, :3, 3] *= METRES_TO_MILLIMETRES
        if im_id not in cameras:
            raise ValueError(f"{scene_folder / 'scene_camera.json'}: no entry for image {im_id}")
        info = infos.get(im_id, [])
        if len(info) != len(obj_ids):
            raise ValueError(f"{info_path}: image {im_id}: expected {len(obj_ids)} entries "
                             f"(one per scene_gt instance), got {len(info)}")
        images[(scene_id, im_id)] = ImageGroundTruth(
            scene_id, im_id, cameras[im_id].K, cameras[im_id].depth_scale, obj_ids, poses,
            np.array([float(entry["visib_fract"]) for entry in info]))
    return images


def load_evaluation_data(root: str | Path, split: str = "test", targets_path: str | Path | None = None,
                         max_symmetry_step: float = MAX_SYMMETRY_STEP) -> BopEvaluationData:
    """Loads ground truth, camera, models info and targets of a BOP split (millimetres).

    Args:
        root: data set folder (``camera.json``, ``models[_eval]/``, ``<split>/<scene>/``).
        split: split folder name.
        targets_path: targets JSON (default ``<root>/test_targets_bop19.json``).
        max_symmetry_step: discretization of continuous symmetries (see
            :func:`evaluation.pose_errors.symmetry_transformations`).
    """
    root = Path(root)
    if not (root / split).is_dir():
        raise ValueError(f"{root / split}: split folder not found")
    camera_path = root / "camera.json"
    if not camera_path.is_file():
        raise ValueError(f"{camera_path}: file not found (the image width is needed for MSPD)")
    camera = Camera.from_bop_json(camera_path)
    targets = read_targets(root / DEFAULT_TARGETS if targets_path is None else targets_path)
    models_folder = _models_folder(root)
    info = bop_files.load_models_info(models_folder / "models_info.json")
    diameters, symmetries = {}, {}
    for obj_id, entry in info.items():
        diameters[obj_id] = entry.diameter * METRES_TO_MILLIMETRES
        discrete = entry.symmetries_discrete.copy()
        discrete[:, :3, 3] *= METRES_TO_MILLIMETRES
        continuous = [(axis, offset * METRES_TO_MILLIMETRES) for axis, offset in entry.symmetries_continuous]
        symmetries[obj_id] = symmetry_transformations(discrete, continuous, max_symmetry_step)
    images = {}
    for scene_id in sorted({target.scene_id for target in targets}):
        folder = root / split / f"{scene_id:06d}"
        if not folder.is_dir():
            raise ValueError(f"{folder}: scene folder of the targets not found")
        images.update(_scene_images(folder, scene_id))
    for index, target in enumerate(targets):
        if (target.scene_id, target.im_id) not in images:
            raise ValueError(f"targets: target {index} names scene {target.scene_id}, image {target.im_id}, "
                             "which has no ground truth")
        if target.obj_id not in diameters:
            raise ValueError(f"targets: target {index} names object {target.obj_id}, which is not in "
                             f"{models_folder / 'models_info.json'}")
    return BopEvaluationData(root, split, models_folder, camera.width, camera.height, diameters, symmetries,
                             images, targets)
