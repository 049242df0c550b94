"""BOP-format data sets (real ones and those ``paz6d generate`` writes) for the library, in metres.

Everything returned here is in metres (poses ``T_model2cam`` ``(4, 4)``, OpenCV camera frame,
depth float32); the millimetre files are converted once, by the parsers of this package
(:mod:`paz6d.datasets.bop.scene`, :mod:`~paz6d.datasets.bop.models`). Parts a data set lacks
(depth, masks, some RGB frames) come back as ``None``. Malformed files raise ``ValueError`` naming
the file, image/object and field.

Example:
    >>> dataset = BOPDataset("/data/lmo", split="test")                      # doctest: +SKIP
    >>> sample = next(iter(dataset))                                         # doctest: +SKIP
    >>> sample.objects[0].T_model2cam.shape                                  # doctest: +SKIP
    (4, 4)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from paz6d.backend.camera import Camera, check_principal_point
from paz6d.backend.paths import check_plain_name
from paz6d.backend.image import load_image
from paz6d.datasets.bop.camera import load_camera, load_scene_camera
from paz6d.datasets.bop.models import MODELS_INFO, ModelInfo, load_model, load_models_info
from paz6d.datasets.sample import Sample, SampleSequence
from paz6d.datasets.bop.scene import (DEPTH_SUFFIXES, find_image, load_scene_gt, load_scene_gt_info, read_depth,
                                      read_mask)


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


class BOPScene:
    """One ``<root>/<split>/<scene_id>`` folder; iterating yields :class:`BOPSample` per GT image.

    Args:
        folder: the scene folder.
        image_size: ``(width, height)`` of every image (``camera.json``'s); ``None``: each image's own.
        ground_truth: read ``scene_gt.json`` (and ``scene_gt_info.json``); ``False``: the images are those
            of ``scene_camera.json`` and the samples have no objects (a split without annotations).
    """

    def __init__(self, folder: str | Path, image_size: tuple[int, int] | None = None, ground_truth: bool = True):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise ValueError(f"{self.folder}: scene folder not found")
        if not self.folder.name.isdigit():
            raise ValueError(f"{self.folder}: expected a numeric BOP scene folder name")
        self.scene_id = int(self.folder.name)
        self.ground_truth = load_scene_gt(self.folder / "scene_gt.json", units="m") if ground_truth else None
        self.cameras = load_scene_camera(self.folder / "scene_camera.json", units="m")
        info_path = self.folder / "scene_gt_info.json"
        self.infos = load_scene_gt_info(info_path) if ground_truth and info_path.is_file() else {}
        self._image_size = image_size

    @property
    def image_ids(self) -> list[int]:
        return list(self.cameras if self.ground_truth is None else self.ground_truth)

    def __len__(self) -> int:
        return len(self.image_ids)

    def __iter__(self) -> Iterator[BOPSample]:
        for im_id in self.image_ids:
            yield self.sample(im_id)

    def sample(self, im_id: int) -> BOPSample:
        """The sample of image ``im_id`` (files read now)."""
        if self.ground_truth is not None and im_id not in self.ground_truth:
            raise ValueError(f"{self.folder / 'scene_gt.json'}: no image {im_id}")
        if im_id not in self.cameras:
            raise ValueError(f"{self.folder / 'scene_camera.json'}: no entry for image {im_id}")
        scene_camera = self.cameras[im_id]
        image_path = find_image(self.folder / "rgb", im_id)
        image = load_image(image_path) if image_path is not None else None
        if self._image_size is not None:
            width, height = self._image_size
        elif image is not None:
            height, width = image.shape[:2]
        else:
            width, height = round(2 * scene_camera.K[0, 2] + 1), round(2 * scene_camera.K[1, 2] + 1)
        check_principal_point(scene_camera.K, width, height,
                              f"{self.folder / 'scene_camera.json'}: image {im_id}, field 'cam_K'")
        depth = None
        depth_path = find_image(self.folder / "depth", im_id, DEPTH_SUFFIXES)
        if depth_path is not None:
            if scene_camera.depth_scale is None:
                raise ValueError(f"{self.folder / 'scene_camera.json'}: image {im_id}: missing field 'depth_scale'")
            depth = read_depth(depth_path, scene_camera.depth_scale, units="m").astype(np.float32)
        infos = self.infos.get(im_id)
        objects = []
        for index, pose in enumerate([] if self.ground_truth is None else self.ground_truth[im_id]):
            name = f"{im_id:06d}_{index:06d}.png"
            objects.append(BOPObject(pose.obj_id, pose.T_model2cam, read_mask(self.folder / "mask" / name),
                                     read_mask(self.folder / "mask_visib" / name),
                                     infos[index] if infos is not None and index < len(infos) else None))
        return BOPSample(self.scene_id, im_id, Camera(scene_camera.K, width, height), image, depth, objects)


class BOPDataset:
    """A BOP data set root (``camera.json``, ``models/``, ``<split>/<scene>/...``).

    Args:
        root: data set folder.
        split: split folder (``test``, ``train``, ``train_pbr``...).
        scene_ids: scenes to read (default: all numeric folders of the split).
        ground_truth: read the annotations (see :class:`BOPScene`); ``False`` for a split without them.
    """

    def __init__(self, root: str | Path, split: str = "test", scene_ids: list[int] | None = None,
                 ground_truth: bool = True):
        self.root = Path(root)
        check_plain_name(split, "split")
        split_folder = self.root / split
        if not split_folder.is_dir():
            raise ValueError(f"{split_folder}: split folder not found")
        camera_path = self.root / "camera.json"
        self.camera = load_camera(camera_path) if camera_path.is_file() else None
        if scene_ids is None:
            scene_ids = sorted(int(path.name) for path in split_folder.iterdir() if path.name.isdigit())
        size = None if self.camera is None else (self.camera.width, self.camera.height)
        self.scenes = [BOPScene(split_folder / f"{scene_id:06d}", size, ground_truth) for scene_id in scene_ids]

    @property
    def models_folder(self) -> Path:
        return self.root / "models"

    def models_info(self) -> dict[int, ModelInfo]:
        """``models/models_info.json`` in metres."""
        return load_models_info(self.models_folder / MODELS_INFO, units="m")

    def model(self, obj_id: int):
        """Mesh of ``obj_id`` in metres."""
        return load_model(self.models_folder, obj_id, units="m")

    def __len__(self) -> int:
        return sum(len(scene) for scene in self.scenes)

    def __iter__(self) -> Iterator[BOPSample]:
        for scene in self.scenes:
            yield from scene


def check_object_in_split(root: str | Path, split: str, obj_id: int | None = None) -> None:
    """Checks a split before long work: its scene folders and their ground truth are read (each
    file checked as :class:`BOPScene` does) and, with ``obj_id``, at least one instance of it is annotated.

    Raises:
        ValueError: naming the file or field (``object_id: ...`` when the object is not annotated).
    """
    dataset = BOPDataset(root, split)
    if not dataset.scenes:
        raise ValueError(f"{Path(root) / split}: no scene folders (000000, 000001, ...) in the split")
    if obj_id is not None and not any(pose.obj_id == obj_id for scene in dataset.scenes
                                      for poses in scene.ground_truth.values() for pose in poses):
        raise ValueError(f"object_id: no instance of object {obj_id} in {Path(root) / split}/*/scene_gt.json")


def load(root: str | Path, split: str = "test", box: str = "visib") -> SampleSequence:
    """A BOP split as the shared :class:`~paz6d.datasets.sample.Sample` interface (lazy: a sample's files
    are read when it is asked for; the pixels are not read at all).

    Each annotated image gives one sample: ``image`` (the RGB path, named even when the file is absent),
    ``boxes`` ``(N, 4)`` pixels (``bbox_<box>`` of ``scene_gt_info.json``; an instance with no such box,
    BOP's ``-1`` entries of an object out of sight, gets the empty box ``(0, 0, 0, 0)``), ``class_names``
    ``obj_XXXXXX`` and ``class_ids`` into the split's sorted object ids, ``poses`` ``(N, 4, 4)``
    ``T_model2cam`` in metres, ``camera_matrix`` and ``extras``: ``scene_id``, ``im_id``, ``obj_ids``
    ``(N,)``, ``visibility`` ``(N,)`` (``visib_fract``; NaN without ``scene_gt_info.json``), ``depth``
    (the depth file's path or ``None``), ``depth_scale`` (``scene_camera.json``'s, mm per unit) and
    ``image_size`` (``camera.json``'s ``(width, height)`` or ``None``).

    Args:
        root: the data set folder; split: its split folder; box: ``"visib"`` or ``"obj"``.
    Raises:
        ValueError: a missing split or malformed file (naming it), or another ``box``.
    """
    if box not in ("visib", "obj"):
        raise ValueError(f"box: expected 'visib' or 'obj', got {box!r}")
    dataset = BOPDataset(root, split)
    size = None if dataset.camera is None else (dataset.camera.width, dataset.camera.height)
    entries = [(scene, im_id) for scene in dataset.scenes for im_id in scene.image_ids]
    object_ids = sorted({pose.obj_id for scene in dataset.scenes for poses in scene.ground_truth.values()
                         for pose in poses})
    class_names = [f"obj_{obj_id:06d}" for obj_id in object_ids]

    def read(position: int) -> Sample:
        scene, im_id = entries[position]
        if im_id not in scene.cameras:
            raise ValueError(f"{scene.folder / 'scene_camera.json'}: no entry for image {im_id}")
        poses, infos = scene.ground_truth[im_id], scene.infos.get(im_id) or []
        boxes = np.zeros((len(poses), 4))
        visibility = np.full(len(poses), np.nan)
        for index, info in enumerate(infos[:len(poses)]):
            x, y, width, height = info.get(f"bbox_{box}", (-1, -1, -1, -1))
            if width > 0 and height > 0:
                boxes[index] = (x, y, x + width, y + height)
            visibility[index] = info.get("visib_fract", np.nan)
        obj_ids = np.array([pose.obj_id for pose in poses], dtype=np.int64)
        image = find_image(scene.folder / "rgb", im_id) or scene.folder / "rgb" / f"{im_id:06d}.png"
        return Sample(image=image, boxes=boxes, class_ids=np.searchsorted(object_ids, obj_ids).astype(np.int64),
                      class_names=[f"obj_{obj_id:06d}" for obj_id in obj_ids],
                      poses=np.array([pose.T_model2cam for pose in poses]).reshape(-1, 4, 4),
                      camera_matrix=scene.cameras[im_id].K,
                      extras={"scene_id": scene.scene_id, "im_id": im_id, "obj_ids": obj_ids,
                              "visibility": visibility, "depth": find_image(scene.folder / "depth", im_id,
                                                                            DEPTH_SUFFIXES),
                              "depth_scale": scene.cameras[im_id].depth_scale, "image_size": size},
                      source=f"{scene.folder / 'scene_gt.json'}, image {im_id}")

    return SampleSequence(len(entries), read, class_names)
