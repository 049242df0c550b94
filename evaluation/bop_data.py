"""The parts of a BOP data set that pose evaluation needs, in millimetres (BOP mode).

Evaluation works in millimetres, as the BOP toolkit does: ground truth, ``models_info.json``,
model meshes and depth are read through :mod:`paz6d.datasets.bop` with ``units="mm"``, so they
arrive exactly as stored and errors, thresholds and reports use BOP's units. The one metre
crossing is the renderer VSD uses (a metre device, see :meth:`BopEvaluationData.render_mesh`).
Ground-truth rotations are kept as stored (``snap_rotations=False``): the BOP toolkit evaluates
with the stored matrices (LM-O's differ from rotations by up to 0.0094), and so do we. Error
meshes come from ``models_eval/`` when the data set has it (as the BOP toolkit does), else
``models/``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from evaluation.pose_errors import MAX_SYMMETRY_STEP, ObjectModel, symmetry_transformations
from paz6d.backend.paths import check_plain_name
from paz6d.datasets.bop.camera import load_camera, load_scene_camera
from paz6d.datasets.bop.models import MODELS_INFO, load_model, load_model_points, load_models_info, model_path
from paz6d.datasets.bop.scene import DEPTH_SUFFIXES, find_image, load_scene_gt, load_scene_gt_info, read_depth
from paz6d.datasets.bop.targets import TARGETS_FILE, Target, read_targets


@dataclass(frozen=True)
class ImageGroundTruth:
    """Annotated instances of one test image (millimetres).

    Attributes:
        scene_id, im_id: BOP ids.
        K: ``(3, 3)`` intrinsics (px).
        depth_scale: millimetres per depth-image unit (``None`` when not given).
        obj_ids: ``(G,)`` object id of each instance (``scene_gt.json`` order).
        T_model2cam: ``(G, 4, 4)`` poses with translations in millimetres.
        visib_fract: ``(G,)`` visible fraction of each instance (``scene_gt_info.json``).
    """

    scene_id: int
    im_id: int
    K: np.ndarray
    depth_scale: float | None
    obj_ids: np.ndarray
    T_model2cam: np.ndarray
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
        return model_path(self.models_folder, obj_id)

    def object_model(self, obj_id: int) -> ObjectModel:
        """Points (all mesh vertices, mm), diameter and symmetries of ``obj_id`` (cached)."""
        if obj_id not in self._models:
            points = load_model_points(self.models_folder, obj_id, units="mm")
            self._models[obj_id] = ObjectModel(points, self.diameters[obj_id], self.symmetries[obj_id])
        return self._models[obj_id]

    def render_mesh(self, obj_id: int):
        """The error mesh of ``obj_id`` in metres, for the renderer, which works in metres (cached)."""
        if obj_id not in self._meshes:
            self._meshes[obj_id] = load_model(self.models_folder, obj_id, units="m")
        return self._meshes[obj_id]

    def scene_folder(self, scene_id: int) -> Path:
        return self.root / self.split / f"{scene_id:06d}"

    def depth_path(self, scene_id: int, im_id: int) -> Path | None:
        """The depth image of an image, ``None`` when the data set has none."""
        return find_image(self.scene_folder(scene_id) / "depth", im_id, DEPTH_SUFFIXES)

    def read_depth(self, scene_id: int, im_id: int) -> np.ndarray:
        """Depth of an image in millimetres, ``(H, W)`` float64 (0 = missing)."""
        path = self.depth_path(scene_id, im_id)
        if path is None:
            raise ValueError(f"{self.scene_folder(scene_id) / 'depth'}: no depth image for image {im_id} "
                             "(VSD needs depth images)")
        scale = self.images[(scene_id, im_id)].depth_scale
        if scale is None:
            raise ValueError(f"{self.scene_folder(scene_id) / 'scene_camera.json'}: image {im_id}: "
                             "missing field 'depth_scale'")
        depth = read_depth(path, scale, units="mm")
        if depth.shape != (self.height, self.width):
            raise ValueError(f"{path}: expected {self.width}x{self.height} px, got {depth.shape[1]}x{depth.shape[0]}")
        return depth


def _models_folder(root: Path) -> Path:
    for name in ("models_eval", "models"):
        if (root / name / MODELS_INFO).is_file():
            return root / name
    raise ValueError(f"{root}: no models_eval/models_info.json or models/models_info.json")


def _scene_images(scene_folder: Path, scene_id: int) -> dict[tuple[int, int], ImageGroundTruth]:
    gt = load_scene_gt(scene_folder / "scene_gt.json", snap_rotations=False, units="mm")
    cameras = load_scene_camera(scene_folder / "scene_camera.json", units="mm")
    info_path = scene_folder / "scene_gt_info.json"
    if not info_path.is_file():
        raise ValueError(f"{info_path}: file not found (the visible fractions of the GT are needed)")
    infos = load_scene_gt_info(info_path)
    images = {}
    for im_id, instances in gt.items():
        obj_ids = np.array([instance.obj_id for instance in instances], dtype=np.int64)
        poses = np.array([instance.T_model2cam for instance in instances]).reshape(-1, 4, 4)
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
    check_plain_name(split, "split")
    if not (root / split).is_dir():
        raise ValueError(f"{root / split}: split folder not found")
    camera_path = root / "camera.json"
    if not camera_path.is_file():
        raise ValueError(f"{camera_path}: file not found (the image width is needed for MSPD)")
    camera = load_camera(camera_path)
    targets_file = root / TARGETS_FILE if targets_path is None else Path(targets_path)
    targets = read_targets(targets_file)
    models_folder = _models_folder(root)
    info = load_models_info(models_folder / MODELS_INFO, units="mm")
    diameters, symmetries = {}, {}
    for obj_id, entry in info.items():
        diameters[obj_id] = entry.diameter
        symmetries[obj_id] = symmetry_transformations(entry.symmetries_discrete, entry.symmetries_continuous,
                                                      max_symmetry_step)
    images = {}
    for scene_id in sorted({target.scene_id for target in targets}):
        folder = root / split / f"{scene_id:06d}"
        if not folder.is_dir():
            raise ValueError(f"{folder}: scene folder of the targets not found")
        images.update(_scene_images(folder, scene_id))
    for index, target in enumerate(targets):
        if (target.scene_id, target.im_id) not in images:
            raise ValueError(f"{targets_file}: target {index} names scene {target.scene_id}, image {target.im_id}, "
                             "which has no ground truth")
        if target.obj_id not in diameters:
            raise ValueError(f"{targets_file}: target {index} names object {target.obj_id}, which is not in "
                             f"{models_folder / MODELS_INFO}")
        present = int(np.count_nonzero(images[(target.scene_id, target.im_id)].obj_ids == target.obj_id))
        if target.inst_count > present:
            raise ValueError(f"{targets_file}: target {index} asks for {target.inst_count} instances of object "
                             f"{target.obj_id} in scene {target.scene_id}, image {target.im_id}; the ground truth "
                             f"has {present} (field 'inst_count')")
    return BopEvaluationData(root, split, models_folder, camera.width, camera.height, diameters, symmetries,
                             images, targets)
