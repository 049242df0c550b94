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
6. optional ICP refinement (open3d) against a depth image (:class:`~paz6d.processors.refine.RefineWithDepth`:
   a shift along the ray, then multi-scale ICP; a refinement that fails its checks keeps the pose).

:class:`ImplicitPose6D` runs them as named steps (``crop``, ``encode``, ``lookup``,
``pose_from_codebook``, ``refine_with_depth``) that can be read, replaced, inserted or removed.
Boxes follow ``docs/conventions.md`` (pixel ``i`` covers ``[i, i+1)``; ``K`` puts pixel centres on integers).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from paz6d.aae import run_dir as run_files
from paz6d.aae.codebook import Codebook
from paz6d.aae.model import encode_function, encoder_of, to_model_input
from paz6d.aae.run_dir import AAERunDir
from paz6d.abstract import Box2D, KeyedStep, Pose6D, Processor, SequentialProcessor
from paz6d.backend import quaternion
from paz6d.backend.boxes import check_box_in_image, overlaps_image
from paz6d.backend.camera import Camera, as_camera, project_points, unproject
from paz6d.backend.checks import as_array, as_camera_matrix, check_depth
from paz6d.backend.image import as_image
from paz6d.backend.viewpoints import ViewpointRange
from paz6d.processors.crops import BoxVariants, SquareCrop
from paz6d.processors.refine import RefineWithDepth


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
    normalized = unproject(corners, np.ones(2), K)[:, :2]
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
    pixels = project_points(np.asarray(points, dtype=np.float64) @ np.asarray(R).T + t, K)
    return np.concatenate([pixels.min(axis=0), pixels.max(axis=0)]) + 0.5


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
        u, v = project_points(camera, K).T
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


# ------------------------------------------------------------------------------------------ steps
def _as_box(box, image_shape: tuple[int, ...], name: str = "box") -> np.ndarray:
    height, width = image_shape[:2]
    return check_box_in_image(Box2D.coordinates_of(box), width, height, name)


class EncodeCrops(Processor):
    """uint8 crops ``(B, S, S, 3)`` (or a list of ``(S, S, 3)``) -> latent codes ``(B, L)`` by the AAE encoder.

    Args:
        encode: compiled encoder (:func:`paz6d.aae.model.encode_function`), float32 ``[0, 1]`` input.
        crop_size: the encoder's input side ``S``.
    """

    def __init__(self, encode, crop_size: int, name: str | None = None):
        super().__init__(name)
        self.encode, self.crop_size = encode, int(crop_size)

    def call(self, crops) -> np.ndarray:
        inputs = to_model_input(np.stack(crops) if isinstance(crops, list) else crops)
        if inputs.shape[1:3] != (self.crop_size, self.crop_size):
            raise ValueError(f"crops: expected {self.crop_size}x{self.crop_size} crops, got {inputs.shape[1:3]}")
        return self.encode(inputs)


class CodebookLookup(Processor):
    """``(codes (B, L), top_k) -> (indices (B, k), similarities (B, k), rotations (B, 3, 3))``: the ``top_k``
    nearest codebook entries (cosine similarity) and the refined best rotation per code.

    Args:
        codebook: the run's :class:`~paz6d.aae.codebook.Codebook`.
        neighbours: matches averaged into the best rotation (within ``radius_deg`` of the best, weighted by
            similarity, :meth:`~paz6d.aae.codebook.Codebook.neighbour_average`); 1 uses the best match alone.
        radius_deg: only matches this close to the best one are averaged.
    """

    def __init__(self, codebook: Codebook, neighbours: int = 10, radius_deg: float = 15.0, name: str | None = None):
        super().__init__(name)
        if int(neighbours) < 1:
            raise ValueError(f"neighbours: expected at least 1, got {neighbours}")
        self.codebook, self.neighbours, self.radius_deg = codebook, int(neighbours), float(radius_deg)

    def call(self, codes: np.ndarray, top_k: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = min(max(top_k, self.neighbours), len(self.codebook))
        indices, similarities = self.codebook.nearest(codes, k)
        if self.neighbours > 1:
            best = self.codebook.neighbour_average(indices[:, :self.neighbours], similarities[:, :self.neighbours],
                                                   self.radius_deg)
        else:
            best = self.codebook.rotations[indices[:, 0]]
        return indices[:, :top_k], similarities[:, :top_k], best


class PosesFromCodebook(Processor):
    """``(indices (k,), similarities (k,), best_rotation (3, 3), box (4,), camera) -> [Pose6D]``: one pose per
    matched codebook view (:func:`pose_from_codebook_view`), best first, ``score`` = cosine similarity; the
    first carries ``best_rotation`` (the neighbour-averaged one).

    Args:
        codebook: the run's codebook; hull_points: ``(M, 3)`` metres, for ``refine``.
        refine: depth-free translation refinement (box fitting).
        class_name: written into the poses.
    """

    def __init__(self, codebook: Codebook, hull_points, refine: bool = True, class_name: str | None = None,
                 name: str | None = None):
        super().__init__(name)
        self.codebook, self.hull_points = codebook, hull_points
        self.refine, self.class_name = refine, class_name

    def pose(self, index: int, similarity: float, R_codebook: np.ndarray, box: np.ndarray, camera: Camera) -> Pose6D:
        """Pose from codebook entry ``index`` with rotation ``R_codebook``."""
        codebook = self.codebook
        R, t = pose_from_codebook_view(R_codebook, box, camera.K, codebook.render_boxes[index], codebook.render_K,
                                       codebook.render_distance, self.hull_points, self.refine)
        return Pose6D.from_rotation_matrix(R, t, class_name=self.class_name, score=float(similarity))

    def call(self, indices, similarities, best_rotation, box, camera: Camera) -> list[Pose6D]:
        return [self.pose(int(index), float(similarity), best_rotation if rank == 0 else self.codebook.rotations[index],
                          box, camera)
                for rank, (index, similarity) in enumerate(zip(indices, similarities))]


class ExpandBoxes(Processor):
    """``(images, boxes, cameras, depths) -> (images, boxes, cameras, depths, groups)``: every box replaced by
    its :class:`~paz6d.processors.crops.BoxVariants` that overlap the image (the box itself first), the other
    values repeated with it; ``groups (N,)`` holds the index of the box each entry came from."""

    def __init__(self, variants: BoxVariants, name: str | None = None):
        super().__init__(name)
        self.variants = variants

    def call(self, images, boxes, cameras, depths) -> tuple[list, list, list, list, np.ndarray]:
        expanded, groups = ([], [], [], []), []
        for group, (image, box, camera, depth) in enumerate(zip(images, boxes, cameras, depths)):
            height, width = image.shape[:2]
            for variant in self.variants(box):
                if not overlaps_image(variant, width, height):
                    continue  # a shifted copy of a box at the border may leave the image
                for values, value in zip(expanded, (image, variant, camera, depth)):
                    values.append(value)
                groups.append(group)
        return (*expanded, np.asarray(groups))


class PickBestCrop(Processor):
    """``(groups, indices, similarities, rotations, boxes, cameras, depths) -> (indices, similarities, rotations,
    boxes, cameras, depths)``, one entry per group: the box variant whose crop matches its codebook best (the
    highest cosine similarity; the box itself, first in its group, wins ties)."""

    def call(self, groups, indices, similarities, rotations, boxes, cameras, depths) -> tuple:
        best = [members[np.argmax(similarities[members, 0])]
                for members in (np.flatnonzero(groups == group) for group in range(int(groups.max()) + 1))]
        return (indices[best], similarities[best], rotations[best], [boxes[i] for i in best],
                [cameras[i] for i in best], [depths[i] for i in best])


# ------------------------------------------------------------------------------------------ pipeline
class ImplicitPose6D(SequentialProcessor):
    """Estimates an object's 6D pose from an RGB image and its 2D box with a trained AAE run directory.

    The steps pass a dict of per-sample lists (a batch) along; each is a
    :class:`~paz6d.abstract.KeyedStep` that reads and writes named values:

    - ``crop``: ``images``, ``boxes`` -> ``crops``, ``windows`` (:class:`~paz6d.processors.crops.SquareCrop`);
    - ``encode``: ``crops`` -> ``codes`` (:class:`EncodeCrops`);
    - ``lookup``: ``codes``, ``top_k`` -> ``indices``, ``similarities``, ``rotations`` (:class:`CodebookLookup`);
    - ``pose_from_codebook``: ``indices``, ``similarities``, ``rotations``, ``boxes``, ``cameras`` ->
      ``candidates`` (:class:`PosesFromCodebook`);
    - ``refine_with_depth``: ``candidates``, ``depths``, ``boxes``, ``cameras`` -> ``poses``
      (:class:`~paz6d.processors.refine.RefineWithDepth`; without a depth image the first candidate).

    With ``box_variants``, two steps search around each box: ``vary`` (before ``crop``,
    :class:`ExpandBoxes`) replaces it by its variants, and ``pick`` (after ``lookup``, :class:`PickBestCrop`)
    keeps the variant whose crop matches the codebook best; its box also places the translation.

    Args:
        run_dir: folder written by ``paz6d train aae`` (:mod:`paz6d.aae.run_dir`).
        camera: default camera of the images: a :class:`~paz6d.backend.camera.Camera` or a ``(3, 3)``
            intrinsics matrix ``K`` (then each image's size completes it); a call may pass another one.
        refine: depth-free translation refinement (box fitting), see module docstring.
        neighbours: codebook matches averaged into the rotation (within ``neighbour_radius_deg`` of the best,
            weighted by similarity, :meth:`~paz6d.aae.codebook.Codebook.neighbour_average`), which refines
            it below the codebook's spacing; 1 uses the best match alone.
        neighbour_radius_deg: only matches this close to the best one are averaged.
        top_k: codebook candidates kept; with a depth image the candidate ICP fits best wins.
        class_name: written into the returned poses.
        box_variants: shifted and scaled copies of each box to choose from
            (:class:`~paz6d.processors.crops.BoxVariants`), for boxes from a detector: on the real LM-O frames
            they raise the scores with detections and lower them with exact ground-truth boxes
            (``docs/real_photos.md``). ``None`` (default): the box as given.
        viewpoints: answer only with codebook views in this :class:`~paz6d.backend.viewpoints.ViewpointRange`
            (the camera's possible viewpoints, e.g. the training scenes' range widened by a margin): on the
            real LM-O frames it removes views from below the table (``docs/real_photos.md``). ``None``
            (default): every view.

    Example:
        >>> estimator = ImplicitPose6D("demo_output/model", K)        # doctest: +SKIP
        >>> pose = estimator(image, (310, 200, 420, 290))             # doctest: +SKIP
        >>> pose.translation                                          # metres  # doctest: +SKIP
    """

    def __init__(self, run_dir: str | Path, camera=None, refine: bool = True, neighbours: int = 10,
                 neighbour_radius_deg: float = 15.0, top_k: int = 1, class_name: str | None = None,
                 box_variants: BoxVariants | None = None, viewpoints: ViewpointRange | None = None):
        super().__init__(name="ImplicitPose6D")
        config = AAERunDir.read_config(run_dir)["config"]
        self.crop_size, self.padding = int(config["crop_size"]), float(config["padding"])
        if int(top_k) < 1 or int(neighbours) < 1:
            raise ValueError(f"top_k/neighbours: expected at least 1, got {top_k}, {neighbours}")
        self.camera, self.top_k, self.class_name = camera, int(top_k), class_name
        self.autoencoder = run_files.read_model(run_dir)
        encoder = encoder_of(self.autoencoder)
        self.codebook = run_files.read_codebook(run_dir)
        if self.codebook.latent_size != encoder.output.shape[-1]:
            raise ValueError(f"{run_files.codebook_path(run_dir)}: latent size {self.codebook.latent_size} does not "
                             f"match the model's {encoder.output.shape[-1]}")
        if viewpoints is not None:
            try:
                self.codebook = self.codebook.within(viewpoints)
            except ValueError as error:
                raise ValueError(f"{run_files.codebook_path(run_dir)}: {error}") from None
        geometry = run_files.read_object(run_dir)
        self.hull_points, self.surface_points = geometry["hull_points"], geometry["surface_points"]
        self.diameter = geometry["diameter"]
        batch = ("boxes", "cameras", "depths")
        if box_variants is not None:
            self.add(KeyedStep(ExpandBoxes(box_variants), ("images", *batch), ("images", *batch, "groups"), "vary"))
        self.add(KeyedStep(SquareCrop(self.padding, self.crop_size), ("images", "boxes"), ("crops", "windows"),
                           "crop", per_sample=True))
        self.add(KeyedStep(EncodeCrops(encode_function(encoder), self.crop_size), "crops", "codes", "encode"))
        self.add(KeyedStep(CodebookLookup(self.codebook, neighbours, neighbour_radius_deg), ("codes", "top_k"),
                           ("indices", "similarities", "rotations"), "lookup"))
        if box_variants is not None:
            match = ("indices", "similarities", "rotations")
            self.add(KeyedStep(PickBestCrop(), ("groups", *match, *batch), (*match, *batch), "pick"))
        self.add(KeyedStep(PosesFromCodebook(self.codebook, self.hull_points, refine, class_name),
                           ("indices", "similarities", "rotations", "boxes", "cameras"), "candidates",
                           "pose_from_codebook", per_sample=True))
        self.add(KeyedStep(RefineWithDepth(self.surface_points, self.diameter),
                           ("candidates", "depths", "boxes", "cameras"), "poses", "refine_with_depth",
                           per_sample=True))

    # -- inputs ---------------------------------------------------------------------------------
    def _sample(self, image, box, camera, name: str = "image", box_name: str = "box"):
        image = as_image(image, name, channels=3)
        camera = as_camera(self.camera if camera is None else camera, image.shape[1], image.shape[0])
        return image, _as_box(box, image.shape, box_name), camera

    def _values(self, images, boxes, cameras, depths, top_k: int) -> dict:
        samples = [self._sample(image, box, camera, f"images[{i}]" if len(images) > 1 else "image",
                                f"boxes[{i}]" if len(images) > 1 else "box")
                   for i, (image, box, camera) in enumerate(zip(images, boxes, cameras))]
        return {"images": [sample[0] for sample in samples], "boxes": [sample[1] for sample in samples],
                "cameras": [sample[2] for sample in samples], "depths": list(depths), "top_k": int(top_k)}

    # -- pieces ---------------------------------------------------------------------------------
    def crop(self, image, box, camera=None) -> np.ndarray:
        """The model input crop ``(S, S, 3)`` uint8 of ``box`` in ``image`` (the ``crop`` step)."""
        image, box, _ = self._sample(image, box, camera)
        return self["crop"].processor(image, box)[0]

    def encode(self, crops) -> np.ndarray:
        """Latent codes ``(B, L)`` of uint8 crops ``(B, S, S, 3)`` (the ``encode`` step)."""
        return self["encode"].processor(crops)

    def reconstruct(self, crops) -> np.ndarray:
        """The autoencoder's reconstructions ``(B, S, S, 3)`` uint8 of crops."""
        output = np.asarray(self.autoencoder(to_model_input(crops), training=False))
        return np.clip(np.rint(output * 255), 0, 255).astype(np.uint8)

    # -- public API -----------------------------------------------------------------------------
    def candidates(self, image, box, top_k: int | None = None, camera=None) -> list[Pose6D]:
        """The ``top_k`` codebook matches as poses, best first (``score`` = cosine similarity); the first
        one carries the neighbour-averaged rotation (the steps before ``refine_with_depth``)."""
        values = self._values([image], [box], [camera], [None], top_k or self.top_k)
        return self.run_steps(values, stop="refine_with_depth")["candidates"][0]

    @property
    def model_points(self) -> np.ndarray:
        """``(P, 3)`` surface points of the object (metres, model frame), e.g. to draw it under a pose."""
        return self.surface_points

    def call(self, image, box, *, camera=None, depth=None) -> Pose6D:
        """Pose of the object in ``box``: ``Box2D`` or ``(x_min, y_min, x_max, y_max)`` pixels.

        Args:
            image: ``(H, W, 3)`` uint8 RGB.
            box: the object's 2D box.
            camera: this image's Camera or ``K`` (default: the constructor's).
            depth: optional ``(H, W)`` float32 depth in metres (0 = none): refines with ICP (open3d).
        """
        return self.run_steps(self._values([image], [box], [camera], [depth], self.top_k))["poses"][0]

    def estimate_batch(self, images, boxes: Sequence, cameras: Sequence | None = None) -> list[Pose6D]:
        """Poses for many boxes in one encoder call and one codebook product (no depth).

        Args:
            images: one ``(H, W, 3)`` image (all boxes in it) or a sequence of images, one per box.
            boxes: sequence of ``Box2D`` / 4-tuples.
            cameras: one Camera or ``K`` per box (default: the constructor's).
        """
        if isinstance(images, np.ndarray) and images.ndim == 3:
            images = [images] * len(boxes)
        if len(images) != len(boxes):
            raise ValueError(f"images/boxes: expected one image per box, got {len(images)} images, {len(boxes)} boxes")
        cameras = [None] * len(boxes) if cameras is None else list(cameras)
        if len(cameras) != len(boxes):
            raise ValueError(f"cameras: expected one per box ({len(boxes)}), got {len(cameras)}")
        if len(boxes) == 0:
            return []
        return self.run_steps(self._values(images, boxes, cameras, [None] * len(boxes), 1))["poses"]

    def refine_with_depth(self, candidates: Sequence[Pose6D], depth, box, camera=None) -> Pose6D:
        """The ``refine_with_depth`` step: ICP of the depth points inside ``box`` from each candidate
        (see :class:`~paz6d.processors.refine.RefineWithDepth`); the camera's size is the depth image's."""
        depth = check_depth(depth)
        camera = as_camera(self.camera if camera is None else camera, depth.shape[1], depth.shape[0])
        return self["refine_with_depth"].processor(candidates, depth, np.asarray(box, dtype=np.float64), camera)
