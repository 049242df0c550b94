"""Implicit 6D pose (Augmented Autoencoder): image + object box -> :class:`~paz6d.abstract.Pose6D` in metres.

Steps (Sundermeyer et al., 2018):

1. crop a square around the box (``padding`` × longest side) and resize it to the model's input;
2. encode it and look the code up in the codebook (cosine similarity): an on-axis rotation ``R_cb``;
3. translation from the box (the paper's method): distance from the ratio of the codebook view's
   silhouette-box diagonal to the test box diagonal times the focal-length ratio, x/y from the box
   centre corrected by where the object origin sat inside the codebook view's box;
4. the crop shows the object along the ray to its centre, not along the optical axis, so the
   camera-frame rotation is ``R = R_ray(t) @ R_cb`` with ``R_ray`` the rotation taking the optical
   axis onto that ray;
5. optional depth-free refinement (default on): ``t`` is refined by Gauss-Newton so the silhouette box
   of the object's convex hull under ``(R, t)`` matches the given box (alternating with step 4);
6. optional ICP refinement (open3d) against a depth image.

Boxes follow ``docs/conventions.md`` (pixel ``i`` covers ``[i, i+1)``; ``K`` puts pixel centres on integers).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.abstract import Box2D, Pose6D, Processor
from paz6d.backend import quaternion
from paz6d.backend.camera import Camera
from paz6d.backend.checks import as_array, as_camera_matrix
from paz6d.backend.image import as_image


# ------------------------------------------------------------------------------------------ geometry
def ray_rotation(direction) -> np.ndarray:
    """``(3, 3)`` smallest rotation taking the optical axis ``(0, 0, 1)`` onto ``direction`` ``(3,)``."""
    direction = as_array(direction, "direction", (3,)).reshape(3)
    norm = np.linalg.norm(direction)
    if norm == 0:
        raise ValueError("direction: expected a non-zero vector")
    direction = direction / norm
    axis = np.cross([0.0, 0.0, 1.0], direction)
    sine, cosine = np.linalg.norm(axis), direction[2]
    if sine < 1e-15:
        if cosine > 0:
            return np.eye(3)
        return np.diag([1.0, -1.0, -1.0])
    rotation_vector = axis / sine * np.arctan2(sine, cosine)
    return quaternion.to_rotation_matrix(quaternion.from_rotation_vector(rotation_vector))


def _box_in_normalized_coordinates(box: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(2,)`` and size ``(2,)`` of a box (box convention) in normalized image coordinates."""
    corners = np.array([[box[0], box[1]], [box[2], box[3]]]) - 0.5  # to pixel-centre coordinates
    y = (corners[:, 1] - K[1, 2]) / K[1, 1]
    x = (corners[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    normalized = np.stack([x, y], axis=1)
    return normalized.mean(axis=0), normalized[1] - normalized[0]


def translation_from_box(box, K, render_box, render_K, render_distance: float) -> np.ndarray:
    """The paper's translation from a 2D box, ``(3,)`` metres.

    ``z = render_distance * |render box diagonal| / |test box diagonal|`` with both diagonals in
    normalized image coordinates (the focal-length ratio); x/y put the object origin where it sat,
    relative to the box, in the codebook rendering (origin on the optical axis).
    """
    box, render_box = np.asarray(box, dtype=np.float64), np.asarray(render_box, dtype=np.float64)
    centre, size = _box_in_normalized_coordinates(box, as_camera_matrix(K))
    render_centre, render_size = _box_in_normalized_coordinates(render_box, as_camera_matrix(render_K))
    diagonal = np.linalg.norm(size)
    if diagonal <= 0:
        raise ValueError(f"box: expected a box with positive size, got {box.tolist()}")
    z = render_distance * np.linalg.norm(render_size) / diagonal
    origin = centre - render_centre * render_distance / z
    return np.array([origin[0] * z, origin[1] * z, z])


def silhouette_box(points, R, t, K) -> np.ndarray:
    """Box ``(4,)`` (box convention) of convex-hull ``points`` ``(M, 3)`` posed by ``(R, t)`` and projected by ``K``."""
    camera = points @ R.T + t
    u = K[0, 0] * camera[:, 0] / camera[:, 2] + K[0, 1] * camera[:, 1] / camera[:, 2] + K[0, 2]
    v = K[1, 1] * camera[:, 1] / camera[:, 2] + K[1, 2]
    return np.array([u.min(), v.min(), u.max(), v.max()]) + 0.5


def fit_translation_to_box(points, R, box, K, t_initial, iterations: int = 20, tolerance: float = 1e-10) -> np.ndarray:
    """Gauss-Newton on ``t`` ``(3,)`` so that the silhouette box of ``points`` under ``(R, t)`` equals ``box``.

    The box sides are set by the extreme projected hull vertices, whose projections are
    differentiable in ``t``; each iteration solves the 4×3 linearised system in least squares.
    """
    points, K = np.asarray(points, dtype=np.float64), np.asarray(K, dtype=np.float64)
    box = np.asarray(box, dtype=np.float64)
    t = np.array(t_initial, dtype=np.float64)
    for _ in range(iterations):
        camera = points @ R.T + t
        if np.any(camera[:, 2] <= 1e-9):
            break  # the object would straddle the camera plane; keep the last valid estimate
        inverse_z = 1.0 / camera[:, 2]
        u = (K[0, 0] * camera[:, 0] + K[0, 1] * camera[:, 1]) * inverse_z + K[0, 2]
        v = K[1, 1] * camera[:, 1] * inverse_z + K[1, 2]
        extremes = [np.argmin(u), np.argmin(v), np.argmax(u), np.argmax(v)]
        residual = np.array([u[extremes[0]], v[extremes[1]], u[extremes[2]], v[extremes[3]]]) + 0.5 - box
        jacobian = np.empty((4, 3))
        for row, (index, is_u) in enumerate(zip(extremes, (True, False, True, False))):
            X, Y, inv = camera[index, 0], camera[index, 1], inverse_z[index]
            if is_u:
                jacobian[row] = [K[0, 0] * inv, K[0, 1] * inv, -(K[0, 0] * X + K[0, 1] * Y) * inv * inv]
            else:
                jacobian[row] = [0.0, K[1, 1] * inv, -K[1, 1] * Y * inv * inv]
        step, *_ = np.linalg.lstsq(jacobian, -residual, rcond=None)
        t = t + step
        if np.linalg.norm(step) < tolerance * max(1.0, np.linalg.norm(t)):
            break
    return t


def pose_from_codebook_view(R_codebook, box, K, render_box, render_K, render_distance: float,
                            hull_points=None, refine: bool = True, rounds: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame ``(R (3, 3), t (3,))`` of an object whose crop matched an on-axis codebook view.

    Args:
        R_codebook: ``(3, 3)`` rotation of the matched codebook view.
        box: ``(4,)`` the object's box in the test image (box convention).
        K: ``(3, 3)`` test camera.
        render_box / render_K / render_distance: the matched view's silhouette box, camera, distance.
        hull_points: ``(M, 3)`` convex-hull vertices (metres), needed for ``refine``.
        refine: fit ``t`` to the box exactly (see :func:`fit_translation_to_box`).
        rounds: alternations of ray correction and box fitting.
    """
    K = as_camera_matrix(K)
    t = translation_from_box(box, K, render_box, render_K, render_distance)
    R = ray_rotation(t) @ R_codebook
    if not refine:
        return R, t
    if hull_points is None:
        raise ValueError("hull_points: required for the depth-free refinement (refine=True)")
    for _ in range(rounds):
        t_new = fit_translation_to_box(hull_points, R, box, K, t)
        R = ray_rotation(t_new) @ R_codebook
        converged = np.linalg.norm(t_new - t) < 1e-12 * max(1.0, np.linalg.norm(t))
        t = t_new
        if converged:
            break
    return R, t


# ------------------------------------------------------------------------------------------ pipeline
def _as_box(box, image_shape: tuple[int, ...], name: str = "box") -> np.ndarray:
    if isinstance(box, Box2D):
        coordinates = box.to_array()
    else:
        coordinates = as_array(box, name, (4,))
        if coordinates.shape != (4,):
            raise ValueError(f"{name}: expected (x_min, y_min, x_max, y_max) or a Box2D, got shape {coordinates.shape}")
    x_min, y_min, x_max, y_max = coordinates
    if not (x_max > x_min and y_max > y_min):
        raise ValueError(f"{name}: empty box {coordinates.tolist()}; expected x_max > x_min and y_max > y_min")
    height, width = image_shape[:2]
    if x_max <= 0 or y_max <= 0 or x_min >= width or y_min >= height:
        raise ValueError(f"{name}: {coordinates.tolist()} lies outside the {width}x{height} image")
    return coordinates


class ImplicitPose6D(Processor):
    """Estimates an object's 6D pose from an RGB image and its 2D box with a trained AAE run directory.

    Args:
        run_dir: folder written by ``paz6d train aae`` (config.json, model.keras, codebook.npz, object.npz).
        camera: :class:`~paz6d.backend.camera.Camera` or a ``(3, 3)`` intrinsics matrix ``K``.
        refine: depth-free translation refinement (box fitting), see module docstring.
        neighbours: codebook matches averaged into the rotation (within ``neighbour_radius_deg`` of the best,
            weighted by similarity, :meth:`~paz6d.aae.codebook.Codebook.neighbour_average`), which refines
            it below the codebook's spacing; 1 uses the best match alone.
        neighbour_radius_deg: only matches this close to the best one are averaged.
        top_k: codebook candidates kept; with a depth image the candidate ICP fits best wins.
        class_name: written into the returned poses.

    Example:
        >>> estimator = ImplicitPose6D("demo_output/model", K)        # doctest: +SKIP
        >>> pose = estimator(image, (310, 200, 420, 290))             # doctest: +SKIP
        >>> pose.translation                                          # metres  # doctest: +SKIP
    """

    def __init__(self, run_dir: str | Path, camera, refine: bool = True, neighbours: int = 10,
                 neighbour_radius_deg: float = 15.0, top_k: int = 1, class_name: str | None = None):
        super().__init__()
        from paz6d.aae.model import encode_function, encoder_of, load_model
        from paz6d.aae.codebook import Codebook

        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise ValueError(f"run_dir: {run_dir} is not a directory")
        config_path = run_dir / "config.json"
        try:
            config = json.loads(config_path.read_text())["config"]
            self.crop_size, self.padding = int(config["crop_size"]), float(config["padding"])
        except FileNotFoundError as error:
            raise ValueError(f"{config_path}: missing; is {run_dir} an AAE run directory?") from error
        except (json.JSONDecodeError, KeyError, TypeError) as error:
            raise ValueError(f"{config_path}: unreadable AAE configuration ({error})") from error
        if isinstance(camera, Camera):
            self.camera: Camera | None = camera
            self.K = camera.K
        else:
            self.camera, self.K = None, as_camera_matrix(camera)
        if int(top_k) < 1 or int(neighbours) < 1:
            raise ValueError(f"top_k/neighbours: expected at least 1, got {top_k}, {neighbours}")
        self.refine, self.top_k, self.class_name = refine, int(top_k), class_name
        self.neighbours, self.neighbour_radius_deg = int(neighbours), float(neighbour_radius_deg)
        self.autoencoder = load_model(run_dir / "model.keras")
        self.encoder = encoder_of(self.autoencoder)
        self._encode = encode_function(self.encoder)
        self.codebook = Codebook.load(run_dir / "codebook.npz")
        if self.codebook.latent_size != self.encoder.output.shape[-1]:
            raise ValueError(f"{run_dir / 'codebook.npz'}: latent size {self.codebook.latent_size} does not match "
                             f"the model's {self.encoder.output.shape[-1]}")
        object_path = run_dir / "object.npz"
        if not object_path.is_file():
            raise ValueError(f"{object_path}: missing object geometry")
        with np.load(object_path) as data:
            self.hull_points = data["hull_points"]
            self.surface_points = data["surface_points"]
            self.diameter = float(data["diameter"])

    # -- pieces ---------------------------------------------------------------------------------
    def _check_image(self, image, name: str = "image") -> np.ndarray:
        image = as_image(image, name, channels=3)
        if self.camera is not None and image.shape[:2] != (self.camera.height, self.camera.width):
            raise ValueError(f"{name}: shape {image.shape[:2]} does not match the camera's "
                             f"{self.camera.height}x{self.camera.width}")
        return image

    def crop(self, image, box) -> np.ndarray:
        """The model input crop ``(S, S, 3)`` uint8 of ``box`` in ``image``."""
        from paz6d.aae.model import crop_object

        image = self._check_image(image)
        return crop_object(image, _as_box(box, image.shape), self.crop_size, self.padding)

    def encode(self, crops) -> np.ndarray:
        """Latent codes ``(B, L)`` of uint8 crops ``(B, S, S, 3)``."""
        from paz6d.aae.model import to_model_input

        inputs = to_model_input(crops)
        if inputs.shape[1:3] != (self.crop_size, self.crop_size):
            raise ValueError(f"crops: expected {self.crop_size}x{self.crop_size} crops, got {inputs.shape[1:3]}")
        return self._encode(inputs)

    def reconstruct(self, crops) -> np.ndarray:
        """The autoencoder's reconstructions ``(B, S, S, 3)`` uint8 of crops."""
        from paz6d.aae.model import to_model_input

        output = np.asarray(self.autoencoder(to_model_input(crops), training=False))
        return np.clip(np.rint(output * 255), 0, 255).astype(np.uint8)

    def _pose(self, index: int, box: np.ndarray, similarity: float, R_codebook: np.ndarray | None = None) -> Pose6D:
        """Pose from codebook entry ``index`` (its rotation replaced by ``R_codebook`` when given)."""
        codebook = self.codebook
        R_codebook = codebook.rotations[index] if R_codebook is None else R_codebook
        R, t = pose_from_codebook_view(R_codebook, box, self.K, codebook.render_boxes[index], codebook.render_K,
                                       codebook.render_distance, self.hull_points, self.refine)
        return Pose6D.from_rotation_matrix(R, t, class_name=self.class_name, score=float(similarity))

    def _lookup(self, codes: np.ndarray, top_k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``indices (B, k)``, ``similarities (B, k)`` and the refined best rotations ``(B, 3, 3)``."""
        k = min(max(top_k, self.neighbours), len(self.codebook))
        indices, similarities = self.codebook.nearest(codes, k)
        if self.neighbours > 1:
            best = self.codebook.neighbour_average(indices[:, :self.neighbours], similarities[:, :self.neighbours],
                                                   self.neighbour_radius_deg)
        else:
            best = self.codebook.rotations[indices[:, 0]]
        return indices[:, :top_k], similarities[:, :top_k], best

    # -- public API -----------------------------------------------------------------------------
    def candidates(self, image, box, top_k: int | None = None) -> list[Pose6D]:
        """The ``top_k`` codebook matches as poses, best first (``score`` = cosine similarity); the first
        one carries the neighbour-averaged rotation."""
        image = self._check_image(image)
        box = _as_box(box, image.shape)
        code = self.encode(self.crop(image, box)[None])
        indices, similarities, best = self._lookup(code, top_k or self.top_k)
        return [self._pose(int(i), box, float(s), best[0] if rank == 0 else None)
                for rank, (i, s) in enumerate(zip(indices[0], similarities[0]))]

    def call(self, image, box, depth=None) -> Pose6D:
        """Pose of the object in ``box``: ``Box2D`` or ``(x_min, y_min, x_max, y_max)`` pixels.

        Args:
            image: ``(H, W, 3)`` uint8 RGB.
            box: the object's 2D box.
            depth: optional ``(H, W)`` float32 depth in metres (0 = none): refines with ICP (open3d).
        """
        candidates = self.candidates(image, box)
        if depth is None:
            return candidates[0]
        return self.refine_with_depth(candidates, depth, _as_box(box, np.shape(image)))

    def estimate_batch(self, images, boxes: Sequence) -> list[Pose6D]:
        """Poses for many boxes in one encoder call and one codebook product.

        Args:
            images: one ``(H, W, 3)`` image (all boxes in it) or a sequence of images, one per box.
            boxes: sequence of ``Box2D`` / 4-tuples.
        """
        if isinstance(images, np.ndarray) and images.ndim == 3:
            images = [images] * len(boxes)
        if len(images) != len(boxes):
            raise ValueError(f"images/boxes: expected one image per box, got {len(images)} images, {len(boxes)} boxes")
        if len(boxes) == 0:
            return []
        checked = [self._check_image(image, f"images[{i}]") for i, image in enumerate(images)]
        boxes = [_as_box(box, image.shape, f"boxes[{i}]") for i, (box, image) in enumerate(zip(boxes, checked))]
        from paz6d.aae.model import crop_object

        crops = np.stack([crop_object(image, box, self.crop_size, self.padding) for image, box in zip(checked, boxes)])
        indices, similarities, best = self._lookup(self.encode(crops), 1)
        return [self._pose(int(i[0]), box, float(s[0]), R) for i, s, box, R in zip(indices, similarities, boxes, best)]

    def refine_with_depth(self, candidates: Sequence[Pose6D], depth, box, max_iterations: int = 30) -> Pose6D:
        """ICP (open3d, point-to-point) of the depth points inside ``box`` onto the object's surface points,
        started from each candidate; returns the refined pose with the smallest inlier RMSE.

        The scene points (a partial, visible surface) are registered to the full model surface, so every
        scene point has a true counterpart; points farther than one diameter in depth from a candidate
        (background, clutter in front) are ignored.
        """
        import open3d as o3d

        from paz6d.backend.camera import depth_to_points
        from paz6d.backend.transform import invert

        depth = np.asarray(depth, dtype=np.float32)
        if depth.ndim != 2:
            raise ValueError(f"depth: expected shape (H, W) in metres, got {depth.shape}")
        box = np.asarray(box, dtype=np.float64)
        masked = np.zeros_like(depth)
        x0, y0 = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
        x1, y1 = min(int(np.ceil(box[2])), depth.shape[1]), min(int(np.ceil(box[3])), depth.shape[0])
        masked[y0:y1, x0:x1] = depth[y0:y1, x0:x1]
        scene = depth_to_points(masked, self.K)
        model = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.surface_points))
        estimation = o3d.pipelines.registration.TransformationEstimationPointToPoint()
        criteria = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=max_iterations)
        best, best_error = candidates[0], np.inf
        for candidate in candidates:
            T_model2cam = candidate.to_matrix()
            near = scene[np.abs(scene[:, 2] - T_model2cam[2, 3]) < self.diameter]
            if len(near) < 10:
                continue
            source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(near))
            T_cam2model = invert(T_model2cam)
            for threshold in (0.2 * self.diameter, 0.05 * self.diameter, 0.02 * self.diameter):
                result = o3d.pipelines.registration.registration_icp(source, model, threshold, T_cam2model,
                                                                     estimation, criteria)
                T_cam2model = np.asarray(result.transformation)
            if result.fitness > 0.5 and result.inlier_rmse < best_error:
                best_error = result.inlier_rmse
                best = Pose6D.from_matrix(invert(T_cam2model), class_name=self.class_name, score=candidate.score)
        return best
