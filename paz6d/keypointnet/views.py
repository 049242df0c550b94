"""Synthetic views of one mesh for KeypointNet: poses, crops, rendering in worker processes, batches.

Every view ``i`` of a set is drawn from ``numpy.random.default_rng([seed, i])``: a uniformly random
rotation, a distance of ``distance`` object diameters and an image position inside the central part
of a ``camera`` image, plus random lights. Training views are the ``input_size``² square
crops around the object's silhouette box (``margin`` × its longer side) with their own intrinsics
``K_crop`` (see :mod:`paz6d.backend.square_crop`): only the crop window is rendered, at about its
resolution in the camera image, then resampled like a crop of a whole image; test views are whole
camera images over random backgrounds with their ground-truth boxes.

Rendering runs in the *spawn* worker processes of :mod:`paz6d.synthesis.workers`, which never import TensorFlow
(Mesa llvmpipe and TensorFlow's LLVM must not share a process unguarded); ``workers=0`` renders in
the calling process (only safe if TensorFlow, if present, was imported through
``paz6d.backend.tensorflow_guard``). The same seed gives the same views for any number of workers.

Batches (:func:`training_batch`) pair two views of the object, composite them over random
backgrounds, jitter the crop (updating ``K_crop``) and the colours; the relative pose of a pair is
``T_model2cam[b] @ inv(T_model2cam[a])``.

This module imports neither TensorFlow nor pyrender at import time.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract.processor import SequentialProcessor
from paz6d.backend import image as image_backend
from paz6d.backend.camera import Camera
from paz6d.backend.files import load_npz, save_npz_atomically
from paz6d.backend.mesh import diameter, load_mesh
from paz6d.backend.square_crop import crop_intrinsics, crop_square, projected_box, square_window
from paz6d.keypointnet.config import Augmentation
from paz6d.synthesis.augment import (BlendBackground, RandomBrightness, RandomContrast, RandomGaussianBlur, RandomHue,
                                     RandomImageNoise, RandomSaturation, relight, sensor_noise, share_generator)
from paz6d.synthesis.lighting import LIGHTING_STYLES, random_lighting
from paz6d.synthesis.photo_backgrounds import photo_collage, sample_photographs
from paz6d.synthesis.sampling import hull_points, random_pose_in_view
from paz6d.synthesis.workers import chunks, progress_bar, run_in_workers

#: LINEMOD-like 640×480 camera used when no camera is given.
DEFAULT_CAMERA = Camera(np.array([[572.4114, 0.0, 325.2611], [0.0, 573.5704, 242.0490], [0.0, 0.0, 1.0]]), 640, 480)


@dataclass(frozen=True)
class ViewSampling:
    """How views are drawn.

    Attributes:
        input_size: crop side ``S`` in pixels.
        camera: the full camera whose images are cropped.
        distance: range of the object's distance (along z) in object diameters.
        border: fraction of the image width/height kept free at each side for the object centre.
        margin: crop side = ``margin`` × the longer side of the silhouette box.
        lighting: light styles of :func:`~paz6d.synthesis.lighting.random_lighting` for the training crops,
            one drawn uniformly per view, so a style listed twice is drawn twice as often (test images
            always use ``"key-fill"``).
    """

    input_size: int = 128
    camera: Camera = field(default=DEFAULT_CAMERA)
    distance: tuple[float, float] = (3.0, 7.0)
    border: float = 0.15
    margin: float = 1.25
    lighting: tuple[str, ...] = ("key-fill",)

    def __post_init__(self):
        if self.input_size < 8:
            raise ValueError(f"input_size: expected at least 8 pixels, got {self.input_size}")
        low, high = self.distance
        if not 0 < low <= high:
            raise ValueError(f"distance: expected 0 < low <= high (object diameters), got {self.distance}")
        if not 0 <= self.border < 0.5:
            raise ValueError(f"border: expected a fraction in [0, 0.5), got {self.border}")
        if self.margin < 1.0:
            raise ValueError(f"margin: expected >= 1 so the crop holds the whole box, got {self.margin}")
        if not self.lighting or any(style not in LIGHTING_STYLES for style in self.lighting):
            raise ValueError(f"lighting: expected one or more of {LIGHTING_STYLES}, got {self.lighting}")

    def to_dict(self) -> dict:
        data = asdict(self)
        data["camera"] = self.camera.to_dict()
        data["distance"] = list(self.distance)
        data["lighting"] = list(self.lighting)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "ViewSampling":
        data = dict(data)
        data["camera"] = Camera.from_dict(data["camera"])
        data["distance"] = tuple(data["distance"])
        data["lighting"] = tuple(data.get("lighting", ("key-fill",)))
        return cls(**data)


@dataclass
class ViewSet:
    """Rendered crops of one object.

    Attributes:
        rgb: ``(V, S, S, 3)`` uint8 renderings on black.
        alpha: ``(V, S, S)`` uint8 anti-aliased coverage (255 = object).
        masks: ``(V, S, S)`` bool silhouettes.
        K: ``(V, 3, 3)`` crop intrinsics (pixels of the crop).
        T_model2cam: ``(V, 4, 4)`` poses (metres).
    """

    rgb: np.ndarray
    alpha: np.ndarray
    masks: np.ndarray
    K: np.ndarray
    T_model2cam: np.ndarray

    def __post_init__(self):
        count, size = len(self.rgb), self.rgb.shape[1] if self.rgb.ndim == 4 else -1
        expected = {"rgb": (count, size, size, 3), "alpha": (count, size, size), "masks": (count, size, size),
                    "K": (count, 3, 3), "T_model2cam": (count, 4, 4)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"ViewSet.{name}: expected shape {shape}, got {getattr(self, name).shape}")
        empty = np.flatnonzero(~self.masks.reshape(count, -1).any(axis=1))
        if len(empty):
            raise ValueError(f"ViewSet.masks: views {empty[:10].tolist()} have empty masks (object not visible); "
                             "every view needs a non-empty silhouette")

    def __len__(self) -> int:
        return len(self.rgb)

    def save(self, path: str | Path) -> Path:
        """Writes an ``.npz`` (temporary file, then rename)."""
        return save_npz_atomically(path, **asdict(self))

    @classmethod
    def load(cls, path: str | Path) -> "ViewSet":
        path = Path(path)
        arrays = load_npz(path, "a view set")
        missing = [name for name in ("rgb", "alpha", "masks", "K", "T_model2cam") if name not in arrays]
        if missing:
            raise ValueError(f"{path}: not a view set (missing arrays {missing})")
        return cls(**{name: arrays[name] for name in ("rgb", "alpha", "masks", "K", "T_model2cam")})


@dataclass
class TestImages:
    """Whole camera images of the object over random backgrounds.

    Attributes:
        images: ``(V, H, W, 3)`` uint8; boxes: ``(V, 4)`` silhouette boxes ``xyxy`` (pixels);
        T_model2cam: ``(V, 4, 4)``; masks: ``(V, H, W)`` bool.
    """

    images: np.ndarray
    boxes: np.ndarray
    T_model2cam: np.ndarray
    masks: np.ndarray


# ------------------------------------------------------------------------------- rendering

#: Resolutions at which crop windows are rendered before being resampled to the input size
#: (the nearest to the window's side in the camera image).
RENDER_SIZES = (64, 96, 128, 192, 256, 384)


class _ViewRenderer:
    """Render-worker state: the mesh, its hull and diameter, and one renderer per image size
    (opened on first use; no TensorFlow here)."""

    def __init__(self, mesh_path: str, mesh_scale: float):
        self.mesh = load_mesh(mesh_path, mesh_scale)
        vertices = np.asarray(self.mesh.vertices)
        self.hull, self.diameter = hull_points(vertices), diameter(vertices)
        self.renderers: dict = {}

    def renderer(self, width: int, height: int):
        from renderers import Renderer

        if (width, height) not in self.renderers:
            self.renderers[(width, height)] = Renderer(width, height)
        return self.renderers[(width, height)]

    def close(self) -> None:
        for renderer in self.renderers.values():
            renderer.close()
        self.renderers = {}


def sample_pose(rng: np.random.Generator, vertices: np.ndarray, object_diameter: float,
                sampling: ViewSampling) -> np.ndarray:
    """``T_model2cam (4, 4)`` of a view: a random rotation; the bounding-box centre at a random pixel
    and depth (:func:`paz6d.synthesis.sampling.random_pose_in_view`)."""
    return random_pose_in_view(rng, vertices, sampling.camera, sampling.border, sampling.distance, object_diameter)


def _light_style(rng: np.random.Generator, styles: tuple[str, ...]) -> str:
    """One of ``styles`` (no draw when there is only one, so single-style views stay as they were)."""
    return styles[0] if len(styles) == 1 else styles[int(rng.integers(len(styles)))]


def _render_crops(state: _ViewRenderer, indices: list[int], seed: int, sampling: ViewSampling) -> dict[str, np.ndarray]:
    """Renders each view's crop window at about its resolution in the camera image, then resamples it
    to ``input_size`` with :func:`crop_square`, exactly as test crops are cut from whole images."""
    size = sampling.input_size
    out = {"rgb": np.zeros((len(indices), size, size, 3), np.uint8),
           "alpha": np.zeros((len(indices), size, size), np.uint8),
           "masks": np.zeros((len(indices), size, size), bool), "K": np.zeros((len(indices), 3, 3)),
           "T_model2cam": np.zeros((len(indices), 4, 4))}
    for row, index in enumerate(indices):
        rng = np.random.default_rng([seed, index])
        T = sample_pose(rng, state.hull, state.diameter, sampling)
        window = square_window(projected_box(state.hull, T, sampling.camera.K), sampling.margin)
        resolution = min(RENDER_SIZES, key=lambda candidate: abs(np.log(candidate / window[2])))
        rendered = state.renderer(resolution, resolution).render(
            crop_intrinsics(sampling.camera.K, window, resolution), [(state.mesh, T)],
            lighting=random_lighting(rng, _light_style(rng, sampling.lighting)))
        whole = (0, 0, resolution)
        out["rgb"][row] = crop_square(rendered.rgb, whole, size)
        out["alpha"][row] = crop_square(rendered.alpha, whole, size)
        out["masks"][row] = crop_square(rendered.masks[0].astype(np.uint8) * 255, whole, size) > 127
        out["K"][row], out["T_model2cam"][row] = crop_intrinsics(sampling.camera.K, window, size), T
    return out


def _render_full(state: _ViewRenderer, indices: list[int], seed: int, sampling: ViewSampling) -> dict[str, np.ndarray]:
    camera = sampling.camera
    renderer = state.renderer(camera.width, camera.height)
    images, boxes, poses, masks = [], [], [], []
    for index in indices:
        rng = np.random.default_rng([seed, index])
        T = sample_pose(rng, state.hull, state.diameter, sampling)
        rendered = renderer.render(camera.K, [(state.mesh, T)], lighting=random_lighting(rng, "key-fill"))
        mask = rendered.masks[0]
        if not mask.any():
            raise ValueError(f"view {index}: the object is not visible (empty mask)")
        share_generator(BACKGROUND, rng)
        images.append(BACKGROUND(rendered.rgb, rendered.alpha))
        boxes.append(image_backend.mask_box(mask))
        poses.append(T)
        masks.append(mask)
    return {"images": np.stack(images), "boxes": np.asarray(boxes, float), "T_model2cam": np.stack(poses),
            "masks": np.stack(masks)}


def _run_job(state: _ViewRenderer, job: tuple) -> dict[str, np.ndarray]:
    kind, indices, seed, sampling = job
    return (_render_crops if kind == "crops" else _render_full)(state, indices, seed, sampling)


def _render(kind: str, mesh_path: Path, mesh_scale: float, count: int, seed: int, sampling: ViewSampling,
            workers: int, chunk: int, progress: bool, description: str) -> dict[str, np.ndarray]:
    if count <= 0:
        raise ValueError(f"count: expected a positive number of views, got {count}")
    mesh_path = Path(mesh_path)
    if not mesh_path.is_file():
        raise ValueError(f"{mesh_path}: mesh file not found")
    jobs = [(kind, indices, seed, sampling) for indices in chunks(list(range(count)), chunk)]
    with progress_bar(count, description, "view", progress) as bar:
        parts = run_in_workers(_ViewRenderer, (str(mesh_path), mesh_scale), _run_job, jobs, max(0, int(workers)),
                               bar, task_size=lambda job: len(job[1]))
    return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}


def render_views(mesh_path: str | Path, count: int, seed: int, sampling: ViewSampling = ViewSampling(),
                 mesh_scale: float = 1.0, workers: int = 2, chunk: int = 64, progress: bool = True) -> ViewSet:
    """Renders ``count`` crop views (see module docstring); ``mesh_scale`` converts the file to metres."""
    rendered = _render("crops", Path(mesh_path), mesh_scale, count, seed, sampling, workers, chunk, progress,
                       "render views")
    try:
        return ViewSet(**rendered)
    except ValueError as error:
        raise ValueError(f"{mesh_path}: {error}") from error


def cached_views(path: str | Path, render) -> ViewSet:
    """The :class:`ViewSet` cached at ``path``, or ``render()``'s, saved there (a training cache of the
    run directory: a resumed run renders nothing)."""
    if Path(path).exists():
        return ViewSet.load(path)
    views = render()
    views.save(path)
    return views


def render_test_images(mesh_path: str | Path, count: int, seed: int, sampling: ViewSampling = ViewSampling(),
                       mesh_scale: float = 1.0, workers: int = 2, chunk: int = 25,
                       progress: bool = True) -> TestImages:
    """Renders ``count`` whole camera images over random backgrounds with their GT boxes and poses."""
    return TestImages(**_render("full", Path(mesh_path), mesh_scale, count, seed, sampling, workers, chunk,
                                progress, "render test images"))


# ------------------------------------------------------------------------------- batches

@functools.cache
def _photographs() -> tuple[np.ndarray, ...]:
    """scikit-image's sample photographs, loaded once per process."""
    return tuple(sample_photographs())


def _jitter_crop(views: ViewSet, index: int, rng: np.random.Generator, augmentation: Augmentation):
    size = views.rgb.shape[1]
    scale = rng.uniform(1 - augmentation.crop_scale, 1 + augmentation.crop_scale)
    shift = rng.uniform(-augmentation.crop_shift, augmentation.crop_shift, 2) * size
    centre = (size - 1) / 2.0
    A = np.array([[scale, 0.0, (1 - scale) * centre + shift[0]], [0.0, scale, (1 - scale) * centre + shift[1]],
                  [0.0, 0.0, 1.0]])
    rgb = cv2.warpAffine(views.rgb[index], A[:2], (size, size), flags=cv2.INTER_LINEAR)
    alpha = cv2.warpAffine(views.alpha[index], A[:2], (size, size), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(views.masks[index].astype(np.uint8), A[:2], (size, size), flags=cv2.INTER_NEAREST) > 0
    return rgb, alpha, mask, A @ views.K[index]


#: Composites a view over random clutter (``"shapes"`` style); :func:`augmented_view` and the test images
#: make it draw from the view's generator.
BACKGROUND = BlendBackground(style="shapes", name="background")
#: Batch-time colour jitter (brightness, contrast, saturation, hue, blur with probability 0.3, noise);
#: :func:`augmented_view` makes it draw from the sample's generator.
COLOUR_JITTER = SequentialProcessor([
    RandomBrightness(max_delta=30.0), RandomContrast(0.7, 1.3), RandomSaturation(0.7, 1.3), RandomHue(8.0),
    RandomGaussianBlur((3,), probability=0.3), RandomImageNoise(6.0)], name="colour jitter")


def augmented_view(views: ViewSet, index: int, rng: np.random.Generator,
                   augmentation: Augmentation = Augmentation()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One augmented crop: ``image (S, S, 3) uint8``, ``mask (S, S) bool`` and its ``K (3, 3)``."""
    rgb, alpha, mask, K = _jitter_crop(views, index, rng, augmentation)
    if augmentation.relight > 0:
        rgb = np.clip(relight(rgb, rng, augmentation.relight), 0, 255).astype(np.uint8)
    if augmentation.background:
        if augmentation.photos > 0 and rng.random() < augmentation.photos:
            collage = photo_collage(rng, _photographs(), rgb.shape[1], rgb.shape[0])
            picture = image_backend.alpha_blend(rgb, alpha, collage)
        else:
            share_generator(BACKGROUND, rng)
            picture = BACKGROUND(rgb, alpha)
        if augmentation.background_noise > 0 and rng.random() < 0.5:
            noisy = sensor_noise(rng, picture, float(rng.uniform(0.0, augmentation.background_noise)))
            picture = image_backend.alpha_blend(picture, alpha, noisy)
    else:
        picture = image_backend.alpha_blend(rgb, alpha, np.zeros_like(rgb))
    if augmentation.colour:
        share_generator(COLOUR_JITTER, rng)
        picture = COLOUR_JITTER(picture)
    return picture, mask, K


def downsample_masks(masks: np.ndarray, factor: int) -> np.ndarray:
    """``(B, S, S)`` bool masks to ``(B, S/f, S/f)`` float32 occupancy fractions (area average)."""
    batch, height, width = masks.shape
    if height % factor or width % factor:
        raise ValueError(f"masks: expected sides divisible by {factor}, got {masks.shape}")
    blocks = masks.reshape(batch, height // factor, factor, width // factor, factor)
    return blocks.mean(axis=(2, 4), dtype=np.float32)


def relative_angles(rotations: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Angles ``(V,)`` in degrees of the relative rotations ``rotations[v] @ rotation.T`` (``(V, 3, 3)``
    and ``(3, 3)``): how far each view's camera turned from ``rotation``'s, about any axis."""
    cosine = (np.einsum("vij,ij->v", rotations, rotation) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def pair_partners(rotations: np.ndarray, first: np.ndarray, rng: np.random.Generator,
                  max_angle: float | None = None, nearest: int = 8) -> np.ndarray:
    """Second views ``(P,)`` for the first views ``first (P,)`` of pairs: uniformly another view, or
    with ``max_angle`` (degrees) another view whose relative rotation to the first is at most
    ``max_angle`` (one of the ``nearest`` closest views when none is that close).

    Args:
        rotations: ``(V, 3, 3)`` model-to-camera rotations of the views.
    """
    count = len(rotations)
    if max_angle is None or max_angle >= 180.0:
        return (first + rng.integers(1, count, len(first))) % count
    if max_angle <= 0:
        raise ValueError(f"max_angle: expected a positive angle in degrees, got {max_angle}")
    partners = np.empty(len(first), dtype=np.int64)
    for row, index in enumerate(first):
        angles = relative_angles(rotations, rotations[index])
        angles[index] = np.inf
        candidates = np.flatnonzero(angles <= max_angle)
        if len(candidates) == 0:
            candidates = np.argsort(angles)[:min(nearest, count - 1)]
        partners[row] = candidates[rng.integers(0, len(candidates))]
    return partners


def training_batch(views: ViewSet, rng: np.random.Generator, pairs: int, downsample: int,
                   augmentation: Augmentation = Augmentation(),
                   max_angle: float | None = None) -> dict[str, np.ndarray]:
    """A batch of ``pairs`` view pairs ``(a, b)`` of the object, views A first then views B; with
    ``max_angle`` (degrees) the two views of a pair differ by at most that rotation
    (:func:`pair_partners`).

    Returns:
        ``images (2P, S, S, 3) float32`` (0..255), ``masks (2P, S/d, S/d) float32``, ``K (2P, 3, 3)``
        and ``T_model2cam (2P, 4, 4)`` (float32).
    """
    if len(views) < 2:
        raise ValueError(f"views: expected at least 2 views to form pairs, got {len(views)}")
    first = rng.integers(0, len(views), pairs)
    second = pair_partners(views.T_model2cam[:, :3, :3], first, rng, max_angle)
    order = np.concatenate([first, second])
    images, masks, intrinsics = [], [], []
    for index in order:
        picture, mask, K = augmented_view(views, int(index), rng, augmentation)
        images.append(picture)
        masks.append(mask)
        intrinsics.append(K)
    return {"images": np.stack(images).astype(np.float32),
            "masks": downsample_masks(np.stack(masks), downsample),
            "K": np.stack(intrinsics).astype(np.float32),
            "T_model2cam": views.T_model2cam[order].astype(np.float32)}
