"""Keypoint-based 6D pose: KeypointNet keypoints in a box crop + 3D keypoints + PnP (RANSAC, LM).

A KeypointNet run directory (written by ``paz6d train keypointnet``) holds:

- ``config.json`` — ``input_size``, ``margin`` (crop side = margin × longer box side), ``mode``, mesh info;
- ``model.keras`` — the network (safe-mode loadable);
- ``object.json`` — ``diameter`` (m) and ``hull_points`` ``(M, 3)`` (m, the convex hull of the mesh);
- ``keypoints.json`` — ``points_model`` ``(N, 3)`` metres in the object frame, ``usable`` flags,
  ``method`` (``"triangulated"`` or ``"lifted-median"``: lifted from the network's keypoints in
  views with known poses; the supervised mode also keeps its farthest-point ``targets``).

:class:`KeypointPose6D` crops the square around a box, predicts the ``N`` keypoints, maps them back
to image pixels and solves PnP with :func:`paz6d.backend.pnp.solve_pnp`.

Example:
    >>> estimator = KeypointPose6D("runs/keypoints", camera)          # doctest: +SKIP
    >>> pose = estimator(image, (210, 140, 330, 260))                  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, Keypoints2D, Pose6D, Processor
from paz6d.backend.camera import Camera, unproject
from paz6d.backend.checks import as_array, as_camera_matrix
from paz6d.backend.files import load_json, write_json_atomically
from paz6d.backend.image import as_image
from paz6d.backend.pnp import PnPError, solve_pnp
from paz6d.backend.square_crop import crop_square, projected_box, square_window, to_full_image
from paz6d.backend.transform import apply, invert

CONFIG_FILE = "config.json"
MODEL_FILE = "model.keras"
KEYPOINTS_FILE = "keypoints.json"
OBJECT_FILE = "object.json"
DECODERS = ("local", "global")


def lift_keypoints(uv, depth, K, T_model2cam) -> tuple[np.ndarray, np.ndarray]:
    """3D keypoints in the object frame from views with known poses (median over views).

    Args:
        uv: ``(V, N, 2)`` keypoints in pixels of each view's ``K``.
        depth: ``(V, N)`` keypoint depths (metres, along z).
        K: ``(V, 3, 3)`` intrinsics; T_model2cam: ``(V, 4, 4)`` ground-truth poses.
    Returns:
        ``points_model (N, 3)`` (metres) and ``spread (N,)``: median distance of the per-view
        estimates to that median (metres), a reliability measure.
    """
    uv = as_array(uv, "uv", (2,))
    views, count = uv.shape[:2]
    depth = np.asarray(depth, dtype=np.float64)
    K = as_array(K, "K", (3, 3))
    T_model2cam = as_array(T_model2cam, "T_model2cam", (4, 4))
    if uv.ndim != 3 or depth.shape != (views, count) or K.shape != (views, 3, 3) or T_model2cam.shape != (views, 4, 4):
        raise ValueError(f"uv/depth/K/T_model2cam: expected (V, N, 2), (V, N), (V, 3, 3), (V, 4, 4), got "
                         f"{uv.shape}, {depth.shape}, {K.shape}, {T_model2cam.shape}")
    if views == 0:
        raise ValueError("uv: expected at least one view to lift keypoints from")
    per_view = np.stack([apply(invert(T_model2cam[v]), unproject(uv[v], depth[v], K[v])) for v in range(views)])
    points = np.median(per_view, axis=0)
    spread = np.median(np.linalg.norm(per_view - points[None], axis=-1), axis=0)
    return points, spread


def triangulate_keypoints(uv, K, T_model2cam, outlier_factor: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """3D keypoints in the object frame that best explain 2D detections in views with known poses.

    Linear triangulation (DLT, least squares over all views) per keypoint, repeated once without
    the views whose re-projection error exceeds ``outlier_factor`` × the median error. Uses the 2D
    keypoints only, so systematic 2D biases of a detector (e.g. a constellation shrunk towards the
    crop centre) are absorbed into the 3D model and cancel in PnP.

    Args:
        uv: ``(V, N, 2)`` keypoints in pixels of each view's ``K``.
        K: ``(V, 3, 3)``; T_model2cam: ``(V, 4, 4)`` ground-truth poses.
    Returns:
        ``points_model (N, 3)`` (metres) and ``rms (N,)`` re-projection error in pixels over the kept views.
    """
    uv = as_array(uv, "uv", (2,))
    K = as_array(K, "K", (3, 3))
    T_model2cam = as_array(T_model2cam, "T_model2cam", (4, 4))
    if uv.ndim != 3 or K.shape != (len(uv), 3, 3) or T_model2cam.shape != (len(uv), 4, 4):
        raise ValueError(f"uv/K/T_model2cam: expected (V, N, 2), (V, 3, 3), (V, 4, 4), got {uv.shape}, {K.shape}, "
                         f"{T_model2cam.shape}")
    if len(uv) < 2:
        raise ValueError(f"uv: triangulation needs at least 2 views, got {len(uv)}")
    projections = K @ T_model2cam[:, :3, :]  # (V, 3, 4) model -> pixels

    def solve(rows_u, rows_v, weights):
        system = np.concatenate([rows_u, rows_v]) * np.concatenate([weights, weights])[:, None]
        _, _, vt = np.linalg.svd(system)
        return vt[-1, :3] / vt[-1, 3]

    def errors(point):
        projected = projections @ np.append(point, 1.0)
        return np.linalg.norm(projected[:, :2] / projected[:, 2:] - keypoint, axis=1)

    points, rms = np.zeros((uv.shape[1], 3)), np.zeros(uv.shape[1])
    for index in range(uv.shape[1]):
        keypoint = uv[:, index]
        rows_u = keypoint[:, 0:1] * projections[:, 2] - projections[:, 0]
        rows_v = keypoint[:, 1:2] * projections[:, 2] - projections[:, 1]
        # rows are scaled by 1 / depth (third projection row) so each view weighs about its pixel error
        scale = 1.0 / np.maximum(np.abs(projections[:, 2, 3]), 1e-9)
        point = solve(rows_u, rows_v, scale)
        residual = errors(point)
        keep = residual <= outlier_factor * max(np.median(residual), 1e-9)
        if keep.sum() >= 2 and not keep.all():
            point = solve(rows_u[keep], rows_v[keep], scale[keep])
            residual = errors(point)
        points[index] = point
        rms[index] = float(np.sqrt(np.mean(residual[keep] ** 2)))
    return points, rms


def keypoint_spread(probabilities, uv, stride: int) -> np.ndarray:
    """Standard deviation ``(B, N)`` (pixels) of each probability map ``(B, h, w, N)`` about ``uv (B, N, 2)``."""
    probabilities = np.asarray(probabilities, dtype=np.float64)
    _, height, width, _ = probabilities.shape
    offset = (stride - 1) / 2.0
    u = np.arange(width) * stride + offset
    v = np.arange(height) * stride + offset
    uv = np.asarray(uv, dtype=np.float64)
    du = (u[None, None, :, None] - uv[:, None, None, :, 0]) ** 2
    dv = (v[None, :, None, None] - uv[:, None, None, :, 1]) ** 2
    return np.sqrt(np.sum(probabilities * (du + dv), axis=(1, 2)))


def local_expectation(probabilities, stride: int, radius: int = 2) -> np.ndarray:
    """Keypoints ``(B, N, 2)`` (input pixels) as the expectation of each probability map ``(B, h, w, N)``
    over the ``(2 radius + 1)²`` cells around its most probable cell (renormalised).

    Unlike the global expectation, mass far from the peak (e.g. a second, weaker mode) does not
    pull the keypoint towards the crop centre.
    """
    probabilities = np.asarray(probabilities, dtype=np.float64)
    batch, height, width, count = probabilities.shape
    flat = probabilities.transpose(0, 3, 1, 2).reshape(batch, count, height * width)
    peak_rows, peak_columns = np.divmod(flat.argmax(axis=-1), width)
    offsets = np.arange(-radius, radius + 1)
    rows = np.clip(peak_rows[..., None] + offsets, 0, height - 1)  # (B, N, 2r+1)
    columns = np.clip(peak_columns[..., None] + offsets, 0, width - 1)
    valid_rows = (peak_rows[..., None] + offsets >= 0) & (peak_rows[..., None] + offsets < height)
    valid_columns = (peak_columns[..., None] + offsets >= 0) & (peak_columns[..., None] + offsets < width)
    b, n = np.meshgrid(np.arange(batch), np.arange(count), indexing="ij")
    window = probabilities[b[..., None, None], rows[..., :, None], columns[..., None, :], n[..., None, None]]
    window = window * (valid_rows[..., :, None] & valid_columns[..., None, :])
    total = window.sum(axis=(-2, -1))
    offset = (stride - 1) / 2.0
    u = (window.sum(axis=-2) * columns).sum(axis=-1) / total * stride + offset
    v = (window.sum(axis=-1) * rows).sum(axis=-1) / total * stride + offset
    return np.stack([u, v], axis=-1)


def decode_keypoints(outputs: dict, stride: int, method: str = "local") -> np.ndarray:
    """Keypoints ``(B, N, 2)`` in crop pixels from KeypointNet outputs (``method``: ``"local"`` or ``"global"``)."""
    if method == "global":
        return np.asarray(outputs["uv"], dtype=np.float64)
    if method == "local":
        return local_expectation(outputs["probabilities"], stride)
    raise ValueError(f"method: expected one of {DECODERS}, got {method!r}")


def infer_in_batches(infer, crops: np.ndarray, batch_size: int = 32) -> dict[str, np.ndarray]:
    """KeypointNet outputs (numpy, ``{"uv", "depth", "probabilities"}``) of ``(B, S, S, 3)`` crops,
    ``batch_size`` crops per call of ``infer`` (:func:`paz6d.keypointnet.model.inference_function`)."""
    parts: dict[str, list] = {}
    for start in range(0, len(crops), batch_size):
        batch = np.asarray(crops[start:start + batch_size], dtype=np.float32)
        for name, value in infer(batch).items():
            parts.setdefault(name, []).append(np.asarray(value))
    return {name: np.concatenate(values) for name, values in parts.items()}


def predict_keypoints(infer, crops: np.ndarray, stride: int, decode: str = "local",
                      batch_size: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints ``(B, N, 2)`` (crop pixels, :func:`decode_keypoints`) and their spread ``(B, N)``
    (:func:`keypoint_spread`) of ``(B, S, S, 3)`` crops, ``batch_size`` crops per network call.

    Args:
        infer: the model's inference function (:func:`paz6d.keypointnet.model.inference_function`).
    """
    outputs = infer_in_batches(infer, crops, batch_size)
    uv = decode_keypoints(outputs, stride, decode)
    return uv, keypoint_spread(outputs["probabilities"], uv, stride)


def write_keypoints(run_dir: str | Path, points_model, usable, method: str, error=None, targets=None) -> Path:
    """Writes ``keypoints.json`` (temporary file, then rename).

    Args:
        points_model: ``(N, 3)`` metres, object frame; usable: ``(N,)`` flags.
        method: how the points were obtained (e.g. ``"triangulated"``).
        error: optional ``(N,)`` per-keypoint fit error (pixels for lifted keypoints).
        targets: optional ``(N, 3)`` keypoints the network was trained on (supervised mode).
    """
    points_model = as_array(points_model, "points_model", (3,))
    usable = np.asarray(usable, dtype=bool)
    if usable.shape != (len(points_model),):
        raise ValueError(f"usable: expected {len(points_model)} flags, got shape {usable.shape}")
    data = {"points_model": points_model.tolist(), "usable": usable.tolist(), "method": method, "units": "metres",
            "error": None if error is None else np.asarray(error, dtype=np.float64).tolist(),
            "targets": None if targets is None else as_array(targets, "targets", (3,)).tolist()}
    return write_json_atomically(Path(run_dir) / KEYPOINTS_FILE, data, indent=2)


def _read_json(path: Path, fields: tuple[str, ...]) -> dict:
    if not path.is_file():
        raise ValueError(f"{path}: file not found (is {path.parent} a KeypointNet run directory?)")
    data = load_json(path)
    missing = [name for name in fields if name not in data]
    if missing:
        raise ValueError(f"{path}: missing field(s) {missing}")
    return data


def read_keypoints(run_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``points_model (N, 3)`` metres and ``usable (N,)`` flags from a run's ``keypoints.json``."""
    path = Path(run_dir) / KEYPOINTS_FILE
    data = _read_json(path, ("points_model", "usable"))
    points = np.asarray(data["points_model"], dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ValueError(f"{path}: points_model: expected finite (N, 3) metres, got shape {points.shape}")
    usable = np.asarray(data["usable"], dtype=bool)
    if usable.shape != (len(points),):
        raise ValueError(f"{path}: usable: expected {len(points)} flags, got shape {usable.shape}")
    return points, usable


def write_object(run_dir: str | Path, diameter: float, hull_points) -> Path:
    """Writes ``object.json``: the object's diameter and convex-hull points (metres)."""
    hull_points = as_array(hull_points, "hull_points", (3,))
    return write_json_atomically(Path(run_dir) / OBJECT_FILE, {"diameter": float(diameter),
                                                               "hull_points": hull_points.tolist(), "units": "metres"})


def read_object(run_dir: str | Path) -> dict:
    """``{"diameter": float, "hull_points": (M, 3)}`` (metres) from a run's ``object.json``."""
    path = Path(run_dir) / OBJECT_FILE
    data = _read_json(path, ("diameter", "hull_points"))
    hull = np.asarray(data["hull_points"], dtype=np.float64)
    if hull.ndim != 2 or hull.shape[1] != 3 or len(hull) < 4 or not np.all(np.isfinite(hull)):
        raise ValueError(f"{path}: hull_points: expected finite (M >= 4, 3) metres, got shape {hull.shape}")
    return {"diameter": float(data["diameter"]), "hull_points": hull}


def depth_from_box(pose: Pose6D, hull_points, box, K, iterations: int = 3) -> Pose6D:
    """Scales ``pose.translation`` so that the projected silhouette box matches ``box`` in size.

    Moving the object along the ray through its origin scales its image by ``1 / factor``; the
    factor is the mean of the width and height ratios of the projected box to ``box``, applied
    ``iterations`` times (perspective makes one step approximate). Rotation is unchanged.
    """
    box = _as_box(box)
    if box.width <= 0 or box.height <= 0:
        raise ValueError(f"box: expected positive width and height, got {box.to_array().tolist()}")
    T = pose.to_matrix()
    for _ in range(iterations):
        projected = projected_box(hull_points, T, K)
        factor = 0.5 * ((projected[2] - projected[0]) / box.width + (projected[3] - projected[1]) / box.height)
        T[:3, 3] *= factor
    return Pose6D.from_matrix(T, pose.class_name, pose.score)


def _as_box(box) -> Box2D:
    if isinstance(box, Box2D):
        return box
    try:
        return Box2D.from_array(box)
    except ValueError as error:
        raise ValueError(f"box2d: expected a Box2D or (x_min, y_min, x_max, y_max) pixels ({error})") from error


class KeypointPose6D(Processor):
    """``(image, box2d) -> Pose6D`` with a trained KeypointNet run and PnP.

    Args:
        run_dir: KeypointNet run directory (see module docstring).
        camera: :class:`~paz6d.backend.camera.Camera` or ``3×3`` ``K`` of the images.
        ransac_threshold: RANSAC inlier threshold in pixels *of the crop* (scaled to the image).
        max_spread: keypoints whose probability map has a standard deviation above this many crop
            pixels are not used (default: ``input_size / 4``).
        min_keypoints: fewest usable keypoints accepted (PnP needs 4).
        decode: ``"local"`` (expectation around each map's peak, :func:`local_expectation`) or
            ``"global"`` (the network's expectation over the whole map).
        depth_from_box: after PnP, move the object along its viewing ray until its projected
            silhouette box has the size of ``box2d`` (:func:`depth_from_box`). Much more accurate in
            depth when boxes are tight (ground truth, unoccluded objects); wrong for occluded or
            truncated objects and as noisy as the detector's boxes otherwise.
        class_name: written into the returned poses.
    """

    def __init__(self, run_dir: str | Path, camera: Camera | np.ndarray, ransac_threshold: float = 5.0,
                 max_spread: float | None = None, min_keypoints: int = 4, decode: str = "local",
                 depth_from_box: bool = False, class_name: str | None = None):
        super().__init__()
        from paz6d.keypointnet.model import inference_function, load_keypointnet

        self.run_dir = Path(run_dir)
        if isinstance(camera, Camera):
            self.camera: Camera | None = camera
            self.K, self.distortion = camera.K, camera.distortion
        else:
            self.camera, self.K, self.distortion = None, as_camera_matrix(camera, "camera"), None
        config = _read_json(self.run_dir / CONFIG_FILE, ("input_size", "margin", "downsample"))
        self.input_size, self.margin = int(config["input_size"]), float(config["margin"])
        self.stride = int(config["downsample"])
        self.points_model, self.usable = read_keypoints(self.run_dir)
        self.model = load_keypointnet(self.run_dir / MODEL_FILE)
        self._infer = inference_function(self.model)
        count = int(self.model.output["uv"].shape[1])
        if count != len(self.points_model):
            raise ValueError(f"{self.run_dir / KEYPOINTS_FILE}: {len(self.points_model)} keypoints, but the model "
                             f"predicts {count}")
        if decode not in DECODERS:
            raise ValueError(f"decode: expected one of {DECODERS}, got {decode!r}")
        self.decode = decode
        self.depth_from_box = bool(depth_from_box)
        self.hull_points = read_object(self.run_dir)["hull_points"] if self.depth_from_box else None
        if min_keypoints < 4:
            raise ValueError(f"min_keypoints: PnP needs at least 4, got {min_keypoints}")
        if self.usable.sum() < min_keypoints:
            raise PnPError(f"{self.run_dir / KEYPOINTS_FILE}: only {int(self.usable.sum())} usable keypoints, "
                           f"PnP needs at least {min_keypoints}")
        self.ransac_threshold = float(ransac_threshold)
        self.max_spread = self.input_size / 4.0 if max_spread is None else float(max_spread)
        self.min_keypoints = int(min_keypoints)
        self.class_name = class_name if class_name is not None else config.get("class_name")

    def _crop(self, image, box) -> tuple[np.ndarray, tuple[int, int, int], Box2D]:
        image = as_image(image)
        if self.camera is not None and image.shape[:2] != (self.camera.height, self.camera.width):
            raise ValueError(f"image: expected {self.camera.width}x{self.camera.height} pixels (the camera), "
                             f"got {image.shape[1]}x{image.shape[0]}")
        box = _as_box(box)
        if box.width <= 0 or box.height <= 0:
            raise ValueError(f"box2d: expected a box with positive width and height, got {box.to_array().tolist()}")
        height, width = image.shape[:2]
        if box.x_max <= 0 or box.y_max <= 0 or box.x_min >= width or box.y_min >= height:
            raise ValueError(f"box2d: {box.to_array().tolist()} lies outside the {width}x{height} image")
        window = square_window(box.to_array(), self.margin)
        return crop_square(image, window, self.input_size), window, box

    def detect_batch(self, images, boxes) -> list[Keypoints2D]:
        """Keypoints in image pixels for each ``(image, box)``; scores are ``1 / (1 + spread_px)``
        (spread in crop pixels), and keypoints with an unusable 3D point or a spread above
        ``max_spread`` get score 0."""
        if len(images) != len(boxes):
            raise ValueError(f"images/boxes: expected equal lengths, got {len(images)} and {len(boxes)}")
        if len(images) == 0:
            return []
        crops, windows = [], []
        for image, box in zip(images, boxes):
            crop, window, _ = self._crop(image, box)
            crops.append(crop)
            windows.append(window)
        uv, spread = predict_keypoints(self._infer, np.stack(crops), self.stride, self.decode)
        results = []
        for index, window in enumerate(windows):
            scores = 1.0 / (1.0 + spread[index])
            scores[(spread[index] > self.max_spread) | ~self.usable] = 0.0
            results.append(Keypoints2D(to_full_image(uv[index], window, self.input_size), scores, self.class_name))
        return results

    def detect(self, image, box2d) -> Keypoints2D:
        """Keypoints of one ``(image, box)`` (see :meth:`detect_batch`)."""
        return self.detect_batch([image], [box2d])[0]

    def pose_from_keypoints(self, keypoints: Keypoints2D, window_side: float) -> Pose6D:
        """PnP (RANSAC + Levenberg–Marquardt) on the keypoints with a positive score.

        Args:
            window_side: side of the crop window in image pixels (scales the RANSAC threshold).
        Raises:
            PnPError: fewer than ``min_keypoints`` usable keypoints, or no PnP solution.
        """
        usable = np.asarray(keypoints.scores) > 0
        if usable.sum() < self.min_keypoints:
            raise PnPError(f"keypoints: only {int(usable.sum())} of {len(usable)} keypoints are usable "
                           f"(need at least {self.min_keypoints} for PnP)")
        threshold = self.ransac_threshold * window_side / self.input_size
        return solve_pnp(self.points_model[usable], keypoints.points[usable], self.K, method="epnp", ransac=True,
                         distortion=self.distortion, reprojection_threshold=threshold, class_name=self.class_name)

    def _estimate(self, keypoints: Keypoints2D, box) -> Pose6D:
        box = _as_box(box)
        pose = self.pose_from_keypoints(keypoints, square_window(box.to_array(), self.margin)[2])
        if self.depth_from_box:
            pose = depth_from_box(pose, self.hull_points, box, self.K)
        return pose

    def estimate_batch(self, images, boxes) -> list[Pose6D | None]:
        """Poses for many ``(image, box)`` pairs with one network call; ``None`` where PnP fails."""
        poses: list[Pose6D | None] = []
        for box, keypoints in zip(boxes, self.detect_batch(images, boxes)):
            try:
                poses.append(self._estimate(keypoints, box))
            except PnPError:
                poses.append(None)
        return poses

    def call(self, image, box2d) -> Pose6D:
        """Pose ``T_model2cam`` (metres) of the object inside ``box2d`` (``Box2D`` or ``xyxy`` pixels)."""
        return self._estimate(self.detect(image, box2d), box2d)
