"""Writes the tiny YCB-Video and FAT fixtures of ``tests/test_datasets_ycb_video.py`` and
``tests/test_datasets_fat.py`` (run from anywhere: ``python tests/data/datasets/make_pose_fixtures.py``).

Both follow the published on-disk formats (see ``paz6d/datasets/ycb_video.py`` and ``fat.py``) at a
tiny size. The objects are boxes, ray-cast exactly at pixel centres (OpenCV convention), so images,
depth, label/segmentation masks, boxes, projected centres and cuboids all agree with the stored poses
and intrinsics. Output is deterministic (the same content every run; .mat headers carry their creation time).
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import scipy.io

from paz6d.backend.files import write_bytes_atomically, write_text_atomically

HERE = Path(__file__).resolve().parent
YCB_VIDEO = HERE / "ycb_video"
FAT = HERE / "fat"
CLASSES = ("002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can", "006_mustard_bottle",
           "007_tuna_fish_can", "008_pudding_box", "009_gelatin_box", "010_potted_meat_can", "011_banana",
           "019_pitcher_base", "021_bleach_cleanser", "024_bowl", "025_mug", "035_power_drill", "036_wood_block",
           "037_scissors", "040_large_marker", "051_large_clamp", "052_extra_large_clamp", "061_foam_brick")
#: The two objects: box sides (metres, model axes), box centre in the model frame and face colours.
OBJECTS = {
    "003_cracker_box": {"size": (0.16, 0.21, 0.07), "centre": (0.01, -0.02, 0.005),
                        "colours": ((200, 40, 30), (160, 30, 25), (230, 200, 60), (190, 160, 40), (240, 240, 230),
                                    (200, 200, 190))},
    "006_mustard_bottle": {"size": (0.06, 0.19, 0.09), "centre": (0.0, 0.0, 0.0),
                           "colours": ((250, 220, 20), (220, 190, 10), (240, 240, 80), (200, 200, 60), (120, 60, 20),
                                       (150, 80, 30))},
}
#: FAT's segmentation ids and fixed-model-transform rotation rows (signed permutations, as FAT's
#: cracker box and tuna can have) for the two objects.
FAT_OBJECTS = {"003_cracker_box": {"segmentation_class_id": 24, "rows": ((0, 0, 100), (-100, 0, 0), (0, -100, 0))},
               "006_mustard_bottle": {"segmentation_class_id": 60, "rows": ((100, 0, 0), (0, 0, 100), (0, -100, 0))}}


def rotation(axis, degrees: float) -> np.ndarray:
    """Rotation matrix about ``axis`` (Rodrigues)."""
    vector = np.asarray(axis, dtype=np.float64)
    vector = vector / np.linalg.norm(vector) * np.radians(degrees)
    return cv2.Rodrigues(vector)[0]


def pose(axis, degrees: float, translation) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation(axis, degrees)
    T[:3, 3] = translation
    return T


def box_corners(name: str) -> np.ndarray:
    """``(8, 3)`` corners of the object's box in its model frame (metres)."""
    size, centre = np.array(OBJECTS[name]["size"]), np.array(OBJECTS[name]["centre"])
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    return centre + signs * size / 2


def render(K: np.ndarray, width: int, height: int, instances) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray-casts boxes at pixel centres. ``instances``: ``(name, T_model2cam)``.

    Returns:
        ``rgb (H, W, 3) uint8``, ``depth (H, W)`` metres (0 = background) and ``index (H, W)``
        (instance number + 1, 0 = background).
    """
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(K).T  # z = 1: the ray parameter is depth
    depth = np.full((height, width), np.inf)
    index = np.zeros((height, width), np.int64)
    rgb = np.zeros((height, width, 3), np.float64)
    rgb[:] = np.stack([40 + 60 * v / height, 60 + 40 * u / width, 80 + 0 * u], axis=-1)  # background gradient
    for number, (name, T) in enumerate(instances):
        size, centre = np.array(OBJECTS[name]["size"]), np.array(OBJECTS[name]["centre"])
        entry, exit_ = np.zeros((height, width)), np.full((height, width), np.inf)
        entry_face = np.full((height, width), -1)
        for face in range(6):
            axis, sign = face // 2, (1.0 if face % 2 == 0 else -1.0)
            normal = T[:3, :3][:, axis] * sign  # outward face normal in the camera frame
            offset = size[axis] / 2 + sign * centre[axis] + normal @ T[:3, 3]  # n . x <= offset inside
            along = rays @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = offset / along
            entering = along < 0
            better = entering & (bound > entry)
            entry = np.where(better, bound, entry)
            entry_face = np.where(better, face, entry_face)
            exit_ = np.where(along > 0, np.minimum(exit_, bound), exit_)
            exit_ = np.where((along == 0) & (offset < 0), -np.inf, exit_)
        hit = (entry_face >= 0) & (entry <= exit_) & (entry > 0) & (entry < depth)
        depth = np.where(hit, entry, depth)
        index = np.where(hit, number + 1, index)
        colours = np.array(OBJECTS[name]["colours"], dtype=np.float64)
        rgb = np.where(hit[..., None], colours[np.clip(entry_face, 0, 5)], rgb)
    depth[~np.isfinite(depth)] = 0.0
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8), depth, index


def project(K: np.ndarray, points_cam: np.ndarray) -> np.ndarray:
    uvw = points_cam @ K.T
    return uvw[:, :2] / uvw[:, 2:]


def write_png(path: Path, image: np.ndarray) -> None:
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, data = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    assert ok
    write_bytes_atomically(path, data.tobytes())


def write_jpg(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    write_bytes_atomically(path, data.tobytes())


def write_box_obj(path: Path, corners: np.ndarray) -> None:
    """A closed box mesh (12 outward triangles) over ``corners`` (the :func:`box_corners` order)."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
             (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    lines = ["# box stand-in for a YCB object (metres)"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in corners]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    write_text_atomically(path, "\n".join(lines) + "\n")


def box_surface_points(name: str, per_side: int = 4) -> np.ndarray:
    """Points on the box's faces (a grid per face), model frame, metres."""
    size, centre = np.array(OBJECTS[name]["size"]), np.array(OBJECTS[name]["centre"])
    grid = np.linspace(-0.5, 0.5, per_side)
    points = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for sign in (-0.5, 0.5):
            for a in grid:
                for b in grid:
                    point = np.zeros(3)
                    point[axis], point[others[0]], point[others[1]] = sign, a, b
                    points.append(centre + point * size)
    return np.unique(np.round(np.array(points), 6), axis=0)


# ------------------------------------------------------------------------------------------- YCB-Video
YCB_K = np.array([[106.6778, 0.0, 31.29869], [0.0, 106.7487, 24.13109], [0.0, 0.0, 1.0]])
YCB_SIZE = (64, 48)
YCB_FRAMES = {
    "data/0048/000001": [("003_cracker_box", pose((0.3, 1.0, 0.2), 35.0, (-0.06, 0.01, 0.95))),
                         ("006_mustard_bottle", pose((1.0, 0.2, -0.3), -25.0, (0.07, 0.02, 0.8)))],
    "data/0048/000002": [("003_cracker_box", pose((0.2, 1.0, 0.1), 50.0, (-0.03, 0.0, 0.9)))],
    "data/0051/000001": [("006_mustard_bottle", pose((0.0, 1.0, 0.4), 80.0, (-0.05, -0.02, 0.85))),
                         ("003_cracker_box", pose((1.0, 0.0, 0.3), 60.0, (0.06, 0.03, 1.0)))],
    "data_syn/000000": [("006_mustard_bottle", pose((0.5, 0.5, 0.5), 120.0, (0.0, 0.0, 0.7)))],
}


def make_ycb_video(root: Path = YCB_VIDEO) -> None:
    shutil.rmtree(root, ignore_errors=True)
    write_text_atomically(root / "image_sets" / "classes.txt", "\n".join(CLASSES) + "\n")
    write_text_atomically(root / "image_sets" / "train.txt", "0048/000001\n0048/000002\n")
    write_text_atomically(root / "image_sets" / "keyframe.txt", "0051/000001\n")
    for name in OBJECTS:
        write_box_obj(root / "models" / name / "textured.obj", box_corners(name))
        points = box_surface_points(name)
        write_text_atomically(root / "models" / name / "points.xyz",
                              "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in points))
    width, height = YCB_SIZE
    for frame, instances in YCB_FRAMES.items():
        prefix = root / frame
        rgb, depth, index = render(YCB_K, width, height, instances)
        label = np.zeros_like(index, dtype=np.uint8)
        for number, (name, _) in enumerate(instances):
            label[index == number + 1] = CLASSES.index(name) + 1
        write_png(Path(f"{prefix}-color.png"), rgb)
        write_png(Path(f"{prefix}-depth.png"), np.rint(depth * 10000).astype(np.uint16))
        write_png(Path(f"{prefix}-label.png"), label)
        poses = np.stack([T[:3, :] for _, T in instances], axis=2)  # (3, 4, N)
        if len(instances) == 1:
            poses = poses[:, :, 0]  # as MATLAB saves a one-object frame
        centers = np.stack([project(YCB_K, T[:3, 3][None])[0] for _, T in instances])
        camera = np.hstack([rotation((0, 0, 1), 10.0), [[0.1], [0.2], [0.3]]])
        meta = io.BytesIO()
        scipy.io.savemat(meta, {
            "cls_indexes": np.array([[CLASSES.index(name) + 1] for name, _ in instances], dtype=np.float64),
            "poses": poses, "intrinsic_matrix": YCB_K, "factor_depth": np.array([[10000.0]]), "center": centers,
            "rotation_translation_matrix": camera}, do_compression=True)
        write_bytes_atomically(f"{prefix}-meta.mat", meta.getvalue())
        if not frame.startswith("data_syn"):
            lines = []
            for name, T in instances:
                uv = project(YCB_K, box_corners(name) @ T[:3, :3].T + T[:3, 3]) + 0.5  # box convention
                lines.append(f"{name} {uv[:, 0].min():.2f} {uv[:, 1].min():.2f} {uv[:, 0].max():.2f} "
                             f"{uv[:, 1].max():.2f}")
            write_text_atomically(f"{prefix}-box.txt", "\n".join(lines) + "\n")


# ------------------------------------------------------------------------------------------------- FAT
FAT_K = np.array([[51.2107, 0.0, 32.0], [0.0, 51.2107, 18.0], [0.0, 0.0, 1.0]])
FAT_SIZE = (64, 36)
BASELINE = 0.06  # metres between the left and the right camera
FAT_FRAMES = {
    "mixed/kitchen_0/000000": [("003_cracker_box", pose((0.3, 1.0, 0.2), 30.0, (-0.07, 0.0, 0.6))),
                               ("006_mustard_bottle", pose((1.0, 0.3, 0.0), -40.0, (0.08, 0.01, 0.5)))],
    "mixed/kitchen_0/000001": [("006_mustard_bottle", pose((0.0, 1.0, 0.5), 70.0, (-0.06, 0.0, 0.55))),
                               ("003_cracker_box", pose((1.0, 0.0, 0.2), 50.0, (0.07, 0.0, 0.7)))],
    "single/003_cracker_box_16k/kitchen_0/000000": [("003_cracker_box", pose((0.1, 1.0, 0.3), -60.0, (0.0, 0.0, 0.6)))],
}
P_UE4 = np.array([[0, 0, 1], [1, 0, 0], [0, -1, 0]], dtype=np.float64)
CUBOID_SIGNS = np.array([[1, -1, 1], [-1, -1, 1], [-1, 1, 1], [1, 1, 1],
                         [1, -1, -1], [-1, -1, -1], [-1, 1, -1], [1, 1, -1]], dtype=np.float64)


def fat_model_transform(name: str) -> tuple[np.ndarray, list[list[float]], np.ndarray]:
    """``T_ycb2exported`` (metres), the stored ``fixed_model_transform`` and the cuboid dimensions (cm)."""
    rows = np.array(FAT_OBJECTS[name]["rows"], dtype=np.float64)
    R = rows.T / 100.0  # stored transposed and in centimetres
    t = -R @ np.array(OBJECTS[name]["centre"])  # the exported frame is centred on the cuboid
    stored = np.zeros((4, 4))
    stored[:3, :3], stored[3, :3], stored[3, 3] = rows, t * 100.0, 1.0
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    dimensions = np.abs(R) @ np.array(OBJECTS[name]["size"]) * 100.0
    return T, stored.tolist(), dimensions


def quaternion_xyzw(R: np.ndarray) -> list[float]:
    """Scalar-last unit quaternion of a rotation matrix (w >= 0)."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2.0
    x = np.copysign(np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2.0, R[2, 1] - R[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2.0, R[0, 2] - R[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2.0, R[1, 0] - R[0, 1])
    q = np.array([x, y, z, w])
    return (q / np.linalg.norm(q)).round(7).tolist()


def _fat_object(name: str, T_ycb2cam: np.ndarray, visible: np.ndarray, full: np.ndarray) -> dict:
    T_ycb2exp, _, dimensions = fat_model_transform(name)
    T_exp2cam = T_ycb2cam @ np.linalg.inv(T_ycb2exp)
    R, location = T_exp2cam[:3, :3], T_exp2cam[:3, 3] * 100.0
    permuted = np.eye(4)
    permuted[:3, :3] = P_UE4 @ R.T  # so that permuted[:3, :3].T @ P_UE4 = R
    permuted[3, :3] = location
    cuboid = (CUBOID_SIGNS * dimensions / 2) @ R.T + location
    projected = project(FAT_K, cuboid)
    ys, xs = np.nonzero(full)
    visibility = float(visible.sum() / max(full.sum(), 1))
    return {"class": f"{name}_16k", "visibility": round(visibility, 4), "location": location.round(4).tolist(),
            "quaternion_xyzw": quaternion_xyzw(R), "pose_transform_permuted": permuted.round(6).tolist(),
            "cuboid_centroid": location.round(4).tolist(),
            "projected_cuboid_centroid": project(FAT_K, location[None])[0].round(4).tolist(),
            "bounding_box": {"top_left": [float(ys.min()), float(xs.min())],
                             "bottom_right": [float(ys.max() + 1), float(xs.max() + 1)]},
            "cuboid": cuboid.round(4).tolist(), "projected_cuboid": projected.round(4).tolist()}


def make_fat(root: Path = FAT) -> None:
    shutil.rmtree(root, ignore_errors=True)
    width, height = FAT_SIZE
    scenes = sorted({str(Path(frame).parent) for frame in FAT_FRAMES})
    for scene in scenes:
        names = sorted({name for frame, instances in FAT_FRAMES.items() if str(Path(frame).parent) == scene
                        for name, _ in instances})
        exported = []
        for name in names:
            _, stored, dimensions = fat_model_transform(name)
            exported.append({"class": f"{name}_16k",
                             "segmentation_class_id": FAT_OBJECTS[name]["segmentation_class_id"],
                             "fixed_model_transform": stored, "cuboid_dimensions": dimensions.round(4).tolist()})
        folder = root / scene
        write_text_atomically(folder / "_object_settings.json", json.dumps(
            {"exported_object_classes": [f"{name}_16k" for name in names], "exported_objects": exported}, indent=1))
        cameras = [{"name": camera, "horizontal_fov": 64,
                    "intrinsic_settings": {"resX": width, "resY": height, "fx": FAT_K[0, 0], "fy": FAT_K[1, 1],
                                           "cx": FAT_K[0, 2], "cy": FAT_K[1, 2], "s": 0},
                    "captured_image_size": {"width": width, "height": height}} for camera in ("left", "right")]
        write_text_atomically(folder / "_camera_settings.json", json.dumps({"camera_settings": cameras}, indent=1))
    for frame, instances in FAT_FRAMES.items():
        for camera, shift in (("left", 0.0), ("right", -BASELINE)):
            posed = []
            for name, T in instances:
                T = T.copy()
                T[0, 3] += shift
                posed.append((name, T))
            rgb, depth, index = render(FAT_K, width, height, posed)
            seg = np.zeros_like(index, dtype=np.uint8)
            objects = []
            for number, (name, T) in enumerate(posed):
                seg[index == number + 1] = FAT_OBJECTS[name]["segmentation_class_id"]
                _, _, alone = render(FAT_K, width, height, [(name, T)])
                objects.append(_fat_object(name, T, index == number + 1, alone > 0))
            prefix = root / f"{frame}.{camera}"
            write_jpg(Path(f"{prefix}.jpg"), rgb)
            write_png(Path(f"{prefix}.depth.png"), np.rint(depth * 10000).astype(np.uint16))
            write_png(Path(f"{prefix}.seg.png"), seg)
            write_text_atomically(f"{prefix}.json", json.dumps({
                "camera_data": {"location_worldframe": [-shift * 100.0, 0.0, 0.0],
                                "quaternion_xyzw_worldframe": [0.0, 0.0, 0.0, 1.0]},
                "objects": objects}, indent=1))
    for name in OBJECTS:  # not part of FAT: the YCB meshes users download separately (google_16k layout)
        write_box_obj(root / "ycb_models" / name / "google_16k" / "textured.obj", box_corners(name))


if __name__ == "__main__":
    make_ycb_video()
    make_fat()
    print(f"wrote {YCB_VIDEO} and {FAT}")
