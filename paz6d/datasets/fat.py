"""NVIDIA Falling Things (FAT, Tremblay et al. 2018) and other NDDS exports: per-frame JSON with
``_object_settings.json`` and ``_camera_settings.json``, read as :class:`~paz6d.datasets.sample.Sample`
objects in paz6d's conventions (metres, OpenCV camera frame, ``T_model2cam``).

Layout (``root`` = ``fat/``)::

    mixed/<scene>/                         kitchen_0 ... temple_4: several objects per frame
    single/<object>_16k/<scene>/           one object per frame
    <scene folder>/_object_settings.json   exported_object_classes; exported_objects: class,
                                           segmentation_class_id, fixed_model_transform, cuboid_dimensions
    <scene folder>/_camera_settings.json   camera_settings: [{name: left|right, intrinsic_settings:
                                           {fx, fy, cx, cy, s}, captured_image_size: {width, height}}]
    <scene folder>/<frame>.<camera>.jpg    image (camera ``left`` or ``right``)
    <scene folder>/<frame>.<camera>.json   camera_data; objects: class, visibility, location (cm),
                                           quaternion_xyzw, pose_transform_permuted, cuboid_centroid (cm),
                                           projected_cuboid_centroid (px), bounding_box {top_left,
                                           bottom_right} as (y, x) px, cuboid (8 x 3 cm), projected_cuboid
                                           (8 x 2 px)
    <scene folder>/<frame>.<camera>.depth.png   uint16 depth, 10,000 units per metre (0.1 mm)
    <scene folder>/<frame>.<camera>.seg.png     per-pixel segmentation_class_id (0 = background)

**Split.** FAT has no train/test lists; ``split`` is a folder under ``root``: ``"mixed"``,
``"single"``, or a narrower one such as ``"mixed/kitchen_0"`` or ``"single/003_cracker_box_16k"``.
Every scene folder (one holding ``_object_settings.json``) at or below it is read, sorted by path,
frames sorted by name. ``"."`` reads ``root`` itself (a single NDDS export folder).

**Conventions** (pinned by ``tests/test_datasets_fat.py``, including a record written by NDDS, the
exporter FAT was made with): ``location`` and ``cuboid`` are in the OpenCV camera frame (x right,
y down, z forward) in centimetres, so ``K @ location`` gives the pixel of the object origin and
``K @ cuboid`` the stored ``projected_cuboid``; ``quaternion_xyzw`` (scalar last) rotates the
*exported* model frame into the camera: ``cuboid[i] = R(q) @ c_i + cuboid_centroid`` with the corners
``c_i`` of :data:`CUBOID_CORNER_SIGNS` × half ``cuboid_dimensions`` (in that frame y points down,
"top" is -y). ``fixed_model_transform`` maps the original YCB model (``google_16k``, metres) into the
exported frame; it is stored transposed (row-vector form) and scaled to centimetres:
``x_exported_cm = M[:3, :3].T @ x_ycb_m + M[3, :3]``. ``pose_transform_permuted`` repeats the pose
in UE4's permuted form and is not used. Everything is converted to metres here.

``Sample.poses`` is ``T_model2cam`` of the original YCB model (``model_frame="ycb"``, default:
``T_exported2cam @ T_ycb2exported``) or of the exported frame (``model_frame="exported"``, the
frame of NDDS's ``aligned`` meshes and of the cuboid). ``Sample.keypoints`` are the 8 projected
cuboid corners ``(N, 8, 2)`` in the stored order; ``bounding_box`` becomes ``x_min, y_min, x_max,
y_max`` (stored values, reordered from ``(y, x)``). Masks are ``seg == segmentation_class_id`` (two
instances of one class in a frame share that mask; FAT frames hold each class at most once).

Example:
    >>> samples = load("fat", "mixed/kitchen_0", camera="left")  # doctest: +SKIP
    >>> samples[0].poses.shape, samples[0].keypoints.shape  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend import quaternion
from paz6d.backend.checks import required_field, short_repr
from paz6d.backend.files import load_json_object
from paz6d.backend.paths import path_inside
from paz6d.datasets.sample import Sample, SampleSequence
from paz6d.datasets.ycb_video import YCB_VIDEO_CLASSES, read_depth, read_label_image

CM_PER_M = 100.0
#: FAT's depth PNGs: units per metre (0.1 mm).
DEPTH_UNITS_PER_METRE = 10000.0
#: The 21 FAT classes (the YCB-Video objects, named after their ``google_16k`` meshes).
FAT_CLASSES = tuple(f"{name}_16k" for name in YCB_VIDEO_CLASSES)
CAMERAS = ("left", "right")
MODEL_FRAMES = ("ycb", "exported")
OBJECT_SETTINGS = "_object_settings.json"
CAMERA_SETTINGS = "_camera_settings.json"
#: Signs of the cuboid corners in the exported frame, in NDDS's order: front-top-right, front-top-left,
#: front-bottom-left, front-bottom-right, then the same four at the rear (front = +z, top = -y).
CUBOID_CORNER_SIGNS = np.array([[1, -1, 1], [-1, -1, 1], [-1, 1, 1], [1, 1, 1],
                                [1, -1, -1], [-1, -1, -1], [-1, 1, -1], [1, 1, -1]], dtype=np.float64)
#: Tolerance on the norm of a stored quaternion (FAT stores float32 values).
QUATERNION_TOLERANCE = 1e-3


def scene_folders(root: str | Path, split: str) -> list[Path]:
    """Scene folders (holding ``_object_settings.json``) at or below ``root/split``, sorted.

    Raises:
        ValueError: ``split`` leaves ``root``, does not exist, or holds no scene folder.
    """
    root = Path(root)
    top = path_inside(root, split, "split")  # mixed, single, mixed/kitchen_0, ...
    if not top.is_dir():
        available = sorted(path.name for path in root.iterdir() if path.is_dir()) if root.is_dir() else []
        raise ValueError(f"split: {top} is not a folder (folders in {root}: {available})")
    folders = sorted({path.parent for path in top.rglob(OBJECT_SETTINGS)})
    if not folders:
        raise ValueError(f"split: no scene folder with {OBJECT_SETTINGS} at or below {top}")
    return folders


def _matrix(value, path: Path, where: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{path}, {where}: expected numbers of shape {shape}, got {short_repr(value)}") from None
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise ValueError(f"{path}, {where}: expected finite numbers of shape {shape}, got shape {array.shape}")
    return array


def read_object_settings(folder: str | Path) -> dict[str, dict]:
    """``_object_settings.json``: class -> ``segmentation_class_id`` (int), ``T_ycb2exported`` (4, 4, metres),
    ``cuboid_dimensions`` (3,) metres, in ``exported_object_classes`` order.

    Raises:
        ValueError: naming the file, the object and the field.
    """
    path = Path(folder) / OBJECT_SETTINGS
    settings = load_json_object(path)
    exported = required_field(settings, "exported_objects", str(path))
    if not isinstance(exported, list):
        raise ValueError(f"{path}: field 'exported_objects' must be a list, got {short_repr(exported)}")
    objects: dict[str, dict] = {}
    for number, entry in enumerate(exported):
        where = f"{path}, exported_objects[{number}]"
        name = required_field(entry, "class", where)
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}: field 'class' must be a class name, got {short_repr(name)}")
        segmentation = required_field(entry, "segmentation_class_id", where)
        if isinstance(segmentation, bool) or not isinstance(segmentation, int) or not 0 <= segmentation <= 65535:
            raise ValueError(f"{where}: field 'segmentation_class_id' must be an integer in 0..65535, "
                             f"got {short_repr(segmentation)}")
        stored = _matrix(required_field(entry, "fixed_model_transform", where), path,
                         f"exported_objects[{number}] field 'fixed_model_transform'", (4, 4))
        T = np.eye(4)
        T[:3, :3] = stored[:3, :3].T / CM_PER_M
        T[:3, 3] = stored[3, :3] / CM_PER_M
        if not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-3) or np.linalg.det(T[:3, :3]) <= 0:
            raise ValueError(f"{where}: field 'fixed_model_transform' must be a rotation scaled by 100 (metres to "
                             "centimetres) with the translation in its last row")
        dimensions = _matrix(entry.get("cuboid_dimensions", [0.0, 0.0, 0.0]), path,
                             f"exported_objects[{number}] field 'cuboid_dimensions'", (3,))
        objects[name] = {"segmentation_class_id": segmentation, "T_ycb2exported": T,
                         "cuboid_dimensions": dimensions / CM_PER_M}
    return objects


def read_camera_settings(folder: str | Path, camera: str = "left") -> tuple[np.ndarray, tuple[int, int]]:
    """``_camera_settings.json``: the intrinsics ``K (3, 3)`` and image size ``(width, height)`` of the
    camera named ``camera`` (the only one when the file lists one, as single-camera NDDS exports do).

    Raises:
        ValueError: naming the file and the missing or malformed field.
    """
    path = Path(folder) / CAMERA_SETTINGS
    settings = required_field(load_json_object(path), "camera_settings", str(path))
    if not isinstance(settings, list) or not settings:
        raise ValueError(f"{path}: field 'camera_settings' must be a non-empty list")
    named = [entry for entry in settings if isinstance(entry, dict) and entry.get("name") == camera]
    if not named and len(settings) > 1:
        names = [entry.get("name") for entry in settings if isinstance(entry, dict)]
        raise ValueError(f"{path}: no camera named {camera!r} in 'camera_settings' (have {names})")
    entry = named[0] if named else settings[0]
    where = f"{path}, camera {entry.get('name', 0)!r}" if isinstance(entry, dict) else str(path)
    intrinsics = required_field(entry, "intrinsic_settings", where)
    values = {}
    for name in ("fx", "fy", "cx", "cy"):
        values[name] = float(required_field(intrinsics, name, f"{where} intrinsic_settings", size=1)[0])
    if values["fx"] <= 0 or values["fy"] <= 0:
        raise ValueError(f"{where}: intrinsic_settings fx and fy must be positive, got {values['fx']}, {values['fy']}")
    skew = 0.0
    if "s" in intrinsics:
        skew = float(required_field(intrinsics, "s", f"{where} intrinsic_settings", size=1)[0])
    size = required_field(entry, "captured_image_size", where)
    width, height = (int(required_field(size, name, f"{where} captured_image_size", size=1)[0])
                     for name in ("width", "height"))
    K = np.array([[values["fx"], skew, values["cx"]], [0.0, values["fy"], values["cy"]], [0.0, 0.0, 1.0]])
    return K, (width, height)


def _object_record(entry, path: Path, number: int, settings: dict[str, dict]) -> dict:
    """One entry of a frame's ``objects`` list, checked and converted to metres."""
    where = f"{path}, objects[{number}]"
    name = required_field(entry, "class", where)
    if not isinstance(name, str) or name not in settings:
        raise ValueError(f"{where}: field 'class' holds unknown class {short_repr(name)} "
                         f"(not in {OBJECT_SETTINGS}: {sorted(settings)})")
    location = required_field(entry, "location", where, size=3) / CM_PER_M
    q = required_field(entry, "quaternion_xyzw", where, size=4)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise ValueError(f"{where}: field 'quaternion_xyzw' must be a unit quaternion (x, y, z, w), "
                         f"got norm {norm:.6g}")
    box = required_field(entry, "bounding_box", where)
    corners = [required_field(box, name, f"{where} bounding_box", size=2) for name in ("top_left", "bottom_right")]
    (y_min, x_min), (y_max, x_max) = corners
    T = np.eye(4)
    T[:3, :3] = quaternion.to_rotation_matrix(q / norm)
    T[:3, 3] = location
    visibility = float(required_field(entry, "visibility", where, size=1)[0]) if "visibility" in entry else np.nan
    projected = required_field(entry, "projected_cuboid", where, size=16).reshape(8, 2)
    centroid_px = (required_field(entry, "projected_cuboid_centroid", where, size=2)
                   if "projected_cuboid_centroid" in entry else np.full(2, np.nan))
    cuboid = (required_field(entry, "cuboid", where, size=24).reshape(8, 3) / CM_PER_M
              if "cuboid" in entry else np.full((8, 3), np.nan))
    centroid = (required_field(entry, "cuboid_centroid", where, size=3) / CM_PER_M
                if "cuboid_centroid" in entry else np.full(3, np.nan))
    return {"class": name, "T_exported2cam": T, "box": np.array([x_min, y_min, x_max, y_max]),
            "visibility": visibility, "keypoints": projected, "projected_centroid": centroid_px,
            "cuboid": cuboid, "cuboid_centroid": centroid}


def read_frame(json_path: str | Path, settings: dict[str, dict], model_frame: str = "ycb") -> dict:
    """One ``<frame>.<camera>.json`` file: per object ``class``, ``T_model2cam`` (metres, see the module
    docstring for ``model_frame``), ``box``, ``keypoints``, ``visibility`` and the cuboid fields (metres).

    Raises:
        ValueError: naming the file, the object (``objects[i]``) and the field.
    """
    path = Path(json_path)
    if model_frame not in MODEL_FRAMES:
        raise ValueError(f"model_frame: expected one of {MODEL_FRAMES}, got {model_frame!r}")
    objects = required_field(load_json_object(path), "objects", str(path))
    if not isinstance(objects, list):
        raise ValueError(f"{path}: field 'objects' must be a list, got {short_repr(objects)}")
    records = [_object_record(entry, path, number, settings) for number, entry in enumerate(objects)]
    for record in records:
        T = record["T_exported2cam"]
        record["T_model2cam"] = T @ settings[record["class"]]["T_ycb2exported"] if model_frame == "ycb" else T
    return {"objects": records}


def load(root: str | Path, split: str = "mixed", camera: str = "left", masks: bool = True, depth: bool = False,
         model_frame: str = "ycb") -> SampleSequence:
    """The frames of a FAT split as a lazy :class:`SampleSequence` (a frame's files are read per sample).

    Args:
        root: ``fat`` folder (or any NDDS export folder, with ``split="."``).
        split: folder under ``root`` (see the module docstring): ``mixed``, ``single``, ``mixed/kitchen_0``...
        camera: ``left`` or ``right`` (each frame has both in FAT).
        masks: read ``.seg.png`` into ``Sample.masks`` ``(N, H, W) bool``.
        depth: read ``.depth.png`` into ``extras["depth"]`` (``float32`` metres).
        model_frame: ``ycb`` (poses of the original YCB ``google_16k`` model, metres) or ``exported``
            (poses of FAT's exported/cuboid frame).

    Returns:
        Samples with ``image`` (path of the ``.jpg``), ``boxes``, ``class_ids``/``class_names``,
        ``poses (N, 4, 4)``, ``keypoints (N, 8, 2)`` (projected cuboid), ``camera_matrix`` and ``extras``:
        ``frame``, ``visibility``, ``projected_centroid``, ``cuboid`` and ``cuboid_centroid`` (metres),
        ``depth_path``, ``seg_path``, ``image_size`` (+ ``depth``).
    Raises:
        ValueError: a bad split, camera, or settings file (at once); malformed frame files when read.
    """
    root = Path(root)
    if camera not in CAMERAS:
        raise ValueError(f"camera: expected one of {CAMERAS}, got {camera!r}")
    if model_frame not in MODEL_FRAMES:
        raise ValueError(f"model_frame: expected one of {MODEL_FRAMES}, got {model_frame!r}")
    frames: list[tuple[Path, str]] = []
    scenes: dict[Path, tuple[dict, np.ndarray, tuple[int, int]]] = {}
    for folder in scene_folders(root, split):
        names = sorted(path.name[:-len(f".{camera}.json")] for path in folder.glob(f"*.{camera}.json"))
        if not names:
            continue
        scenes[folder] = (read_object_settings(folder),) + read_camera_settings(folder, camera)
        frames += [(folder, name) for name in names]
    if not frames:
        raise ValueError(f"split: no <frame>.{camera}.json files in the scene folders of {root / split}")
    class_names = sorted({name for settings, _, _ in scenes.values() for name in settings})
    class_index = {name: index for index, name in enumerate(class_names)}

    def read(index: int) -> Sample:
        folder, name = frames[index]
        settings, K, size = scenes[folder]
        prefix = folder / f"{name}.{camera}"
        records = read_frame(f"{prefix}.json", settings, model_frame)["objects"]
        count = len(records)
        instance_masks = None
        seg_path = Path(f"{prefix}.seg.png")
        if masks:
            seg = read_label_image(seg_path, "segmentation image")
            ids = np.array([settings[record["class"]]["segmentation_class_id"] for record in records], dtype=np.int64)
            instance_masks = seg[None] == ids[:, None, None]
        def stacked(key: str, shape: tuple[int, ...]) -> np.ndarray:
            return np.array([record[key] for record in records], dtype=np.float64).reshape((count,) + shape)

        extras = {"frame": str(prefix.relative_to(root)), "image_size": size, "camera": camera,
                  "visibility": stacked("visibility", ()), "projected_centroid": stacked("projected_centroid", (2,)),
                  "cuboid": stacked("cuboid", (8, 3)), "cuboid_centroid": stacked("cuboid_centroid", (3,)),
                  "depth_path": Path(f"{prefix}.depth.png"), "seg_path": seg_path}
        if depth:
            extras["depth"] = read_depth(extras["depth_path"], DEPTH_UNITS_PER_METRE)
        return Sample(image=Path(f"{prefix}.jpg"),
                      boxes=np.array([record["box"] for record in records]).reshape(count, 4),
                      class_ids=np.array([class_index[record["class"]] for record in records], dtype=np.int64),
                      class_names=[record["class"] for record in records], masks=instance_masks,
                      keypoints=np.array([record["keypoints"] for record in records]).reshape(count, 8, 2),
                      poses=np.array([record["T_model2cam"] for record in records]).reshape(count, 4, 4),
                      camera_matrix=K.copy(), extras=extras, source=f"{prefix}.json")

    return SampleSequence(len(frames), read, class_names)


def cuboid_corners(dimensions) -> np.ndarray:
    """``(8, 3)`` corners of a cuboid of ``dimensions`` ``(3,)`` centred at the origin, in NDDS's order."""
    return CUBOID_CORNER_SIGNS * (np.asarray(dimensions, dtype=np.float64) / 2.0)
