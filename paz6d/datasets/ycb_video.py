"""YCB-Video (PoseCNN, Xiang et al. 2018): per-frame ``-meta.mat`` / ``-box.txt`` / ``-label.png`` files
read as :class:`~paz6d.datasets.sample.Sample` objects in paz6d's conventions.

Layout (``root`` = ``YCB_Video_Dataset/``)::

    data/<video>/<frame>-color.png     RGB image (640 x 480)
    data/<video>/<frame>-depth.png     uint16 depth, ``factor_depth`` units per metre (10000)
    data/<video>/<frame>-label.png     uint8 class index per pixel (0 = background)
    data/<video>/<frame>-meta.mat      MATLAB file (scipy.io.loadmat), see below
    data/<video>/<frame>-box.txt       one ``<class name> x1 y1 x2 y2`` line per object (pixels)
    data_syn/<frame>-*                 the synthetic frames (same files, no -box.txt)
    image_sets/classes.txt             the 21 class names, line i = class index i (1-based)
    image_sets/<split>.txt             frames of a split, one ``<video>/<frame>`` per line
                                       (train.txt, val.txt, trainval.txt, keyframe.txt)
    models/<class>/points.xyz          model points ``x y z`` in metres (one per line)
    models/<class>/textured.obj        the mesh, metres

``-meta.mat`` fields used: ``cls_indexes`` (N) class indices (1-based, into ``classes.txt``),
``poses`` (3, 4, N) ``[R | t]`` mapping model to camera coordinates in metres (MATLAB drops the last
axis when N = 1, leaving (3, 4)), ``intrinsic_matrix`` (3, 3) pixels, ``factor_depth`` (depth units per
metre) and, when present, ``center`` (N, 2), the projected model origins in pixels.

Conventions (checked by ``tests/test_datasets_ycb_video.py``): the poses are ``T_model2cam`` already,
in the OpenCV camera frame (x right, y down, z forward) and metres, and ``intrinsic_matrix`` projects
with integer pixel coordinates at pixel centres, as :func:`paz6d.backend.camera.project_points` does;
nothing is converted but the (3, 4, N) layout. A label pixel holds the 1-based class index, so each
object's mask is ``label == cls_indexes[i]`` (a YCB-Video frame holds each class at most once).
``-box.txt`` boxes are returned as stored (``x_min y_min x_max y_max``, pixels); frames without one
(``data_syn``) get the boxes of their label masks (:func:`paz6d.backend.image.mask_box`).
``Sample.class_ids`` are 0-based indices into the class list (``cls_indexes - 1``; the 1-based
index is ``extras["label_ids"]``, equal to the BOP YCB-V object id).

Example:
    >>> samples = load("YCB_Video_Dataset", "keyframe", depth=True)  # doctest: +SKIP
    >>> samples[0].poses.shape, samples[0].extras["depth"].dtype  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import scipy.io

from paz6d.backend.files import read_input_text
from paz6d.backend.image import mask_box
from paz6d.backend.paths import path_inside
from paz6d.datasets.sample import Sample, SampleSequence

#: The 21 objects in YCB-Video's ``image_sets/classes.txt`` order (class index = position + 1).
YCB_VIDEO_CLASSES = (
    "002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can", "006_mustard_bottle",
    "007_tuna_fish_can", "008_pudding_box", "009_gelatin_box", "010_potted_meat_can", "011_banana",
    "019_pitcher_base", "021_bleach_cleanser", "024_bowl", "025_mug", "035_power_drill", "036_wood_block",
    "037_scissors", "040_large_marker", "051_large_clamp", "052_extra_large_clamp", "061_foam_brick")
#: Splits that are folders rather than ``image_sets/<split>.txt`` lists: every frame of ``data_syn/``.
SYNTHETIC_SPLIT = "data_syn"
META_FIELDS = ("cls_indexes", "poses", "intrinsic_matrix", "factor_depth")


def read_classes(root: str | Path) -> list[str]:
    """The class names of ``image_sets/classes.txt`` (or ``classes.txt`` in ``root``); the published
    list :data:`YCB_VIDEO_CLASSES` when neither exists.

    Raises:
        ValueError: the file exists but holds no names or a repeated one.
    """
    root = Path(root)
    for path in (root / "image_sets" / "classes.txt", root / "classes.txt"):
        if path.is_file():
            names = [line.strip() for line in read_input_text(path, "YCB-Video class list").splitlines()
                     if line.strip()]
            if not names:
                raise ValueError(f"{path}: no class names")
            repeated = sorted({name for name in names if names.count(name) > 1})
            if repeated:
                raise ValueError(f"{path}: class names listed twice: {repeated}")
            return names
    return list(YCB_VIDEO_CLASSES)


def read_image_set(root: str | Path, split: str) -> list[str]:
    """Frame names (``"0048/000001"``, relative to ``data/``) of ``image_sets/<split>.txt``, or of every
    ``data_syn/<frame>-meta.mat`` for ``split="data_syn"`` (names ``"data_syn/<frame>"``).

    Raises:
        ValueError: an unknown split (naming the available ones) or a malformed line.
    """
    root = Path(root)
    if split == SYNTHETIC_SPLIT:
        folder = root / SYNTHETIC_SPLIT
        frames = sorted(f"{SYNTHETIC_SPLIT}/{path.name[:-len('-meta.mat')]}" for path in folder.glob("*-meta.mat"))
        if not frames:
            raise ValueError(f"split: {folder} holds no <frame>-meta.mat files")
        return frames
    if not isinstance(split, str) or not split or "/" in split or "\\" in split or split.startswith("."):
        raise ValueError(f"split: expected a YCB-Video image set name (such as train or keyframe), got {split!r:.80}")
    path = root / "image_sets" / f"{split}.txt"
    if not path.is_file():
        available = sorted(p.stem for p in (root / "image_sets").glob("*.txt") if p.stem != "classes")
        raise ValueError(f"split: {path} does not exist (image sets in {root / 'image_sets'}: {available}; "
                         f"or {SYNTHETIC_SPLIT!r})")
    frames = []
    for number, line in enumerate(read_input_text(path, "YCB-Video image set").splitlines(), start=1):
        name = line.strip()
        if not name:
            continue
        parts = name.split("/")
        if len(parts) != 2 or not all(part and not part.startswith(".") for part in parts):
            raise ValueError(f"{path}, line {number}: expected <video>/<frame> (such as 0048/000001), got {name!r:.80}")
        path_inside(root / "data", name, f"{path}, line {number}")
        frames.append(name)
    if not frames:
        raise ValueError(f"{path}: no frames listed")
    return frames


def frame_prefix(root: str | Path, frame: str) -> Path:
    """``root/data/<video>/<frame>`` (or ``root/data_syn/<frame>``): the files are ``<prefix>-color.png`` etc."""
    root = Path(root)
    return root / frame if frame.startswith(SYNTHETIC_SPLIT + "/") else root / "data" / frame


def _matrix(meta: dict, name: str, path: Path, shape: tuple[int, ...]) -> np.ndarray:
    try:
        value = np.asarray(meta[name], dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: field {name!r} is not numeric") from error
    if value.shape != shape and value.size == int(np.prod(shape)) and name != "poses":
        value = value.reshape(shape)
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise ValueError(f"{path}: field {name!r} must be finite numbers of shape {shape}, got shape {value.shape}")
    return value


def read_meta(path: str | Path, class_count: int) -> dict:
    """One ``-meta.mat`` file, checked and converted.

    Returns:
        ``label_ids (N,) int64`` (1-based class indices), ``poses (N, 4, 4)`` ``T_model2cam`` (metres),
        ``camera_matrix (3, 3)``, ``factor_depth`` (depth units per metre) and ``centers (N, 2)`` pixels
        (NaN when the file has no ``center``).
    Raises:
        ValueError: naming the file, the field (and the object) and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: meta file not found")
    try:
        meta = scipy.io.loadmat(str(path))
    except (ValueError, TypeError, OSError, NotImplementedError, scipy.io.matlab.MatReadError) as error:
        raise ValueError(f"{path}: not a readable MATLAB .mat file ({error})") from None
    for name in META_FIELDS:
        if name not in meta:
            raise ValueError(f"{path}: missing field {name!r} (expected {', '.join(META_FIELDS)})")
    try:
        indexes = np.asarray(meta["cls_indexes"], dtype=np.float64).ravel()
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: field 'cls_indexes' is not numeric") from error
    count = len(indexes)
    for number, index in enumerate(indexes):
        if not np.isfinite(index) or index != round(index) or not 1 <= index <= class_count:
            raise ValueError(f"{path}, object {number}: field 'cls_indexes' holds {index:g}, expected a class index "
                             f"in 1..{class_count} (image_sets/classes.txt)")
    poses = np.asarray(meta["poses"])
    if poses.ndim == 2:  # MATLAB drops the trailing singleton axis of a one-object frame
        poses = poses[:, :, None]
    if poses.shape != (3, 4, count):
        raise ValueError(f"{path}: field 'poses' must have shape (3, 4, {count}) for {count} objects "
                         f"(cls_indexes), got {np.asarray(meta['poses']).shape}")
    poses = _matrix({"poses": poses}, "poses", path, (3, 4, count))
    transforms = np.tile(np.eye(4), (count, 1, 1))
    transforms[:, :3, :] = np.moveaxis(poses, 2, 0)
    for number, rotation in enumerate(transforms[:, :3, :3]):
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-3) or np.linalg.det(rotation) <= 0:
            raise ValueError(f"{path}, object {number}: field 'poses' rotation is not a rotation matrix")
    K = _matrix(meta, "intrinsic_matrix", path, (3, 3))
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise ValueError(f"{path}: field 'intrinsic_matrix' must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] "
                         f"with fx, fy > 0, got {K.tolist()}")
    factor = _matrix(meta, "factor_depth", path, (1,))[0]
    if factor <= 0:
        raise ValueError(f"{path}: field 'factor_depth' must be positive (depth units per metre), got {factor:g}")
    centers = np.full((count, 2), np.nan)
    if "center" in meta:
        centers = _matrix(meta, "center", path, (count, 2))
    return {"label_ids": indexes.astype(np.int64), "poses": transforms, "camera_matrix": K,
            "factor_depth": float(factor), "centers": centers}


def read_boxes(path: str | Path, class_names: list[str]) -> dict[str, np.ndarray]:
    """``-box.txt``: class name -> ``(4,)`` box ``x_min, y_min, x_max, y_max`` (pixels, as stored).

    Raises:
        ValueError: a line that is not ``<class> x1 y1 x2 y2``, an unknown class or one listed twice.
    """
    path = Path(path)
    boxes: dict[str, np.ndarray] = {}
    for number, line in enumerate(read_input_text(path, "YCB-Video box file").splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        try:
            if len(fields) != 5:
                raise ValueError
            box = np.array([float(value) for value in fields[1:]])
        except ValueError:
            raise ValueError(f"{path}, line {number}: expected '<class name> x1 y1 x2 y2', got {line.strip()!r:.80}") \
                from None
        name = fields[0]
        if name not in class_names:
            raise ValueError(f"{path}, line {number}: unknown class {name!r} (not in image_sets/classes.txt)")
        if name in boxes:
            raise ValueError(f"{path}, line {number}: class {name!r} has a second box")
        if not np.all(np.isfinite(box)) or box[2] < box[0] or box[3] < box[1]:
            raise ValueError(f"{path}, line {number}: box of {name!r} must be finite with x1 <= x2 and y1 <= y2, "
                             f"got {box.tolist()}")
        boxes[name] = box
    return boxes


def read_label_image(path: str | Path, what: str = "label image") -> np.ndarray:
    """A single-channel 8- or 16-bit PNG of per-pixel ids (YCB-Video ``-label.png``, FAT ``.seg.png``),
    values unchanged, ``(H, W)``.

    Raises:
        ValueError: naming the file when it is missing, undecodable or not single-channel.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: {what} not found")
    image = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: expected a single-channel 8- or 16-bit {what} (PNG of per-pixel ids)")
    return image


def read_depth(path: str | Path, factor_depth: float) -> np.ndarray:
    """``-depth.png`` as ``float32 (H, W)`` metres (stored value / ``factor_depth``; 0 = no data)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: depth image not found")
    raw = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.ndim != 2:
        raise ValueError(f"{path}: expected a single-channel 16-bit depth PNG")
    return (raw.astype(np.float64) / factor_depth).astype(np.float32)


def load(root: str | Path, split: str = "train", masks: bool = True, depth: bool = False) -> SampleSequence:
    """The frames of a YCB-Video split as a lazy :class:`SampleSequence` (files are read per sample).

    Args:
        root: ``YCB_Video_Dataset`` folder.
        split: image set (``image_sets/<split>.txt``: ``train``, ``val``, ``trainval``, ``keyframe``) or
            ``"data_syn"`` (every synthetic frame).
        masks: read ``-label.png`` into ``Sample.masks`` ``(N, H, W) bool``.
        depth: read ``-depth.png`` into ``extras["depth"]`` (``float32`` metres, via ``factor_depth``).

    Returns:
        Samples with ``image`` (path of ``-color.png``), ``boxes``, ``class_ids``/``class_names``,
        ``poses`` ``(N, 4, 4)`` ``T_model2cam`` (metres), ``camera_matrix`` and ``extras``:
        ``frame``, ``label_ids``, ``centers``, ``factor_depth``, ``depth_path``, ``label_path`` (+ ``depth``).
    Raises:
        ValueError: missing folders or split (at once); malformed frame files when a sample is read.
    """
    root = Path(root)
    if not (root / "data").is_dir() and not (root / SYNTHETIC_SPLIT).is_dir():
        raise ValueError(f"{root}: not a YCB-Video folder (expected data/ and image_sets/)")
    class_names = read_classes(root)
    frames = read_image_set(root, split)

    def read(index: int) -> Sample:
        prefix = frame_prefix(root, frames[index])
        meta = read_meta(f"{prefix}-meta.mat", len(class_names))
        names = [class_names[i - 1] for i in meta["label_ids"]]
        label_path = Path(f"{prefix}-label.png")
        label = None
        if masks or not Path(f"{prefix}-box.txt").is_file():
            label = read_label_image(label_path)
        instance_masks = None
        if label is not None:
            instance_masks = label[None] == meta["label_ids"][:, None, None]  # (N, H, W)
        boxes = np.zeros((len(names), 4))
        box_path = Path(f"{prefix}-box.txt")
        if box_path.is_file():
            stored = read_boxes(box_path, class_names)
            for number, name in enumerate(names):
                if name not in stored:
                    raise ValueError(f"{box_path}: no box for {name!r} (object {number} of {prefix}-meta.mat)")
                boxes[number] = stored[name]
        else:
            for number, mask in enumerate(instance_masks):
                box = mask_box(mask)
                boxes[number] = np.zeros(4) if box is None else box
        extras = {"frame": frames[index], "label_ids": meta["label_ids"], "centers": meta["centers"],
                  "factor_depth": meta["factor_depth"], "depth_path": Path(f"{prefix}-depth.png"),
                  "label_path": label_path}
        if depth:
            extras["depth"] = read_depth(extras["depth_path"], meta["factor_depth"])
        return Sample(image=Path(f"{prefix}-color.png"), boxes=boxes, class_ids=meta["label_ids"] - 1,
                      class_names=names, masks=instance_masks if masks else None, poses=meta["poses"],
                      camera_matrix=meta["camera_matrix"], extras=extras,
                      source=str(box_path if box_path.is_file() else Path(f"{prefix}-meta.mat")))

    return SampleSequence(len(frames), read, class_names)


def model_folder(root: str | Path, class_name: str) -> Path:
    """``root/models/<class_name>`` (``ValueError`` naming it when missing)."""
    folder = path_inside(Path(root) / "models", class_name, f"class name {class_name!r:.40}")
    if not folder.is_dir():
        raise ValueError(f"{folder}: no model folder for class {class_name!r}")
    return folder


def model_mesh_path(root: str | Path, class_name: str) -> Path:
    """The class's mesh ``models/<class>/textured.obj`` (metres)."""
    path = model_folder(root, class_name) / "textured.obj"
    if not path.is_file():
        raise ValueError(f"{path}: mesh of class {class_name!r} not found")
    return path


def model_points(root: str | Path, class_name: str) -> np.ndarray:
    """``models/<class>/points.xyz`` as ``(P, 3)`` float64 metres (model frame of the poses).

    Raises:
        ValueError: missing file or a line that is not three numbers (naming the line).
    """
    path = model_folder(root, class_name) / "points.xyz"
    points = []
    for number, line in enumerate(read_input_text(path, "YCB-Video model points").splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        try:
            if len(fields) != 3:
                raise ValueError
            points.append([float(value) for value in fields])
        except ValueError:
            raise ValueError(f"{path}, line {number}: expected 'x y z' (metres), got {line.strip()!r:.80}") from None
    if not points:
        raise ValueError(f"{path}: no points")
    points = np.asarray(points)
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{path}: non-finite coordinates")
    return points
