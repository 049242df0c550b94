"""Clean on-axis views of one object for Augmented Autoencoder training and codebooks.

Every view renders the object at ``T = (R, [0, 0, distance])`` in a square ``render_size`` image whose
focal length makes the object's bounding sphere (about the model origin) project to a circle of radius
``render_size / 3``, so an image rotation about the principal point (an in-plane rotation of the
camera, :func:`rotate_view`) never cuts the object. Rendering runs in the ``spawn`` worker processes of
:mod:`paz6d.synthesis.workers`, which never import TensorFlow (Mesa llvmpipe and TensorFlow's LLVM cannot
share a process unguarded).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.checks import as_array
from paz6d.backend.image import mask_box
from paz6d.backend.mesh import load_mesh
from paz6d.synthesis.workers import progress_bar, run_in_workers

#: The bounding sphere projects to a circle of radius render_size / SPHERE_FRACTION.
SPHERE_FRACTION = 3.0


@dataclass(frozen=True)
class ViewGeometry:
    """Camera of the on-axis views: ``render_size`` px square image, intrinsics ``K``, object origin at
    ``distance`` metres on the optical axis."""

    render_size: int
    K: np.ndarray
    distance: float

    @classmethod
    def for_points(cls, points, render_size: int, distance: float = 1.0) -> "ViewGeometry":
        """Geometry for an object with model ``points`` ``(N, 3)`` (metres)."""
        points = as_array(points, "points", (3,))
        radius = float(np.max(np.linalg.norm(points, axis=1)))
        if radius <= 0:
            raise ValueError("points: the object has zero extent")
        if int(render_size) < 8:
            raise ValueError(f"render_size: expected at least 8 pixels, got {render_size}")
        distance = max(float(distance), 3.0 * radius)
        half_angle = np.arcsin(radius / distance)
        focal = (render_size / SPHERE_FRACTION) / np.tan(half_angle)
        centre = (render_size - 1) / 2.0
        K = np.array([[focal, 0.0, centre], [0.0, focal, centre], [0.0, 0.0, 1.0]])
        return cls(int(render_size), K, distance)


def silhouette_boxes(points, rotations, K, translation) -> np.ndarray:
    """Exact silhouette boxes ``(N, 4)`` (box convention: ``+0.5`` from pixel-centre coordinates) of the
    object posed at ``(rotations[i], translation)``; ``points`` should be the convex-hull vertices
    (the extremes of a projected convex set are at its vertices)."""
    points = as_array(points, "points", (3,))
    rotations = as_array(rotations, "rotations", (3, 3)).reshape(-1, 3, 3)
    camera = np.einsum("nij,pj->npi", rotations, points) + np.asarray(translation, dtype=np.float64)
    u = K[0, 0] * camera[..., 0] / camera[..., 2] + K[0, 1] * camera[..., 1] / camera[..., 2] + K[0, 2]
    v = K[1, 1] * camera[..., 1] / camera[..., 2] + K[1, 2]
    return np.stack([u.min(1), v.min(1), u.max(1), v.max(1)], axis=1) + 0.5


def coverage_box(alpha: np.ndarray, threshold: int = 128) -> np.ndarray | None:
    """Box ``(4,)`` (box convention, pixel ``i`` covers ``[i, i+1)``) of the pixels an object covers at
    least half (uint8 ``alpha >= threshold``); None when there are none."""
    return mask_box(alpha >= threshold)


def rotation_about_principal_point(angle: float, K) -> np.ndarray:
    """``(2, 3)`` affine map of pixel coordinates for an in-plane camera rotation by ``angle`` (radians,
    :func:`paz6d.backend.viewpoints.in_plane_rotation` convention) about ``K``'s principal point (fx = fy)."""
    cos, sin = np.cos(angle), np.sin(angle)
    cx, cy = K[0, 2], K[1, 2]
    return np.array([[cos, -sin, cx - cos * cx + sin * cy], [sin, cos, cy - sin * cx - cos * cy]])


def rotate_view(rgb: np.ndarray, alpha: np.ndarray, angle: float, K) -> tuple[np.ndarray, np.ndarray]:
    """The view of the object rotated in-plane by ``angle`` (radians): image warp about the principal point.

    Exact up to resampling for an object on the optical axis (``R -> R_z(angle) @ R``).
    """
    if angle == 0.0:
        return rgb, alpha
    matrix = rotation_about_principal_point(angle, K)
    size = (rgb.shape[1], rgb.shape[0])
    return (cv2.warpAffine(rgb, matrix, size, flags=cv2.INTER_LINEAR),
            cv2.warpAffine(alpha, matrix, size, flags=cv2.INTER_LINEAR))


# ------------------------------------------------------------------------------------ rendering
class _ObjectRenderer:
    """Render-worker state: the mesh and one square renderer (never imports TensorFlow)."""

    def __init__(self, mesh_path: str, mesh_scale: float, size: int, platform: str | None):
        from renderers import Renderer  # GL is loaded only in the processes that render

        self.mesh = load_mesh(mesh_path, mesh_scale)
        self.renderer = Renderer(size, size, platform=platform)

    def close(self) -> None:
        self.renderer.close()


def _render_chunk(state: _ObjectRenderer, task: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Worker task: renders the object at each ``(K, pose)`` of ``task``."""
    Ks, T_model2cam = task
    size = state.renderer.width
    rgb = np.empty((len(T_model2cam), size, size, 3), np.uint8)
    alpha = np.empty((len(T_model2cam), size, size), np.uint8)
    for index, (K, T) in enumerate(zip(Ks, T_model2cam)):
        output = state.renderer.render(K, [(state.mesh, T)], masks=False)
        rgb[index], alpha[index] = output.rgb, output.alpha
    return rgb, alpha


def render_at_transforms(mesh_path: str | Path, mesh_scale: float, Ks, T_model2cam, size: int, workers: int = 2,
                         platform: str | None = None, chunk: int = 32, progress: bool = True,
                         description: str = "render") -> tuple[np.ndarray, np.ndarray]:
    """Renders the object alone (black background, default lighting) once per ``(K, T_model2cam)``.

    Args:
        mesh_path: mesh file (PLY/OBJ/GLB...).
        mesh_scale: factor to metres (0.001 for BOP millimetre meshes).
        Ks: ``(N, 3, 3)`` intrinsics of ``size × size`` images.
        T_model2cam: ``(N, 4, 4)`` object poses (metres).
        size: image side in pixels.
        workers: rendering processes (:func:`paz6d.synthesis.workers.run_in_workers`); 0 renders in
            this process, after loading TensorFlow through the RTLD_LOCAL guard so that the two can share it.
        platform: ``"egl"``, ``"osmesa"`` or None (auto).
        chunk: renderings per task.

    Returns:
        ``rgb (N, size, size, 3)`` uint8 on black and ``alpha (N, size, size)`` uint8 coverage (255 = object).
    """
    T_model2cam = as_array(T_model2cam, "T_model2cam", (4, 4)).reshape(-1, 4, 4)
    Ks = np.broadcast_to(as_array(Ks, "Ks", (3, 3)), (len(T_model2cam), 3, 3))
    if int(workers) < 0:
        raise ValueError(f"workers: expected 0 (this process) or more rendering processes, got {workers}")
    if int(workers) == 0:
        from paz6d.backend.tensorflow_guard import import_tensorflow

        import_tensorflow()
    tasks = [(Ks[start:start + chunk], T_model2cam[start:start + chunk]) for start in range(0, len(T_model2cam), chunk)]
    with progress_bar(len(T_model2cam), description, "view", progress) as bar:
        results = run_in_workers(_ObjectRenderer, (str(Path(mesh_path).resolve()), float(mesh_scale), size, platform),
                                 _render_chunk, tasks, int(workers), bar, task_size=lambda task: len(task[1]))
    return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])


def render_views(mesh_path: str | Path, mesh_scale: float, rotations, geometry: ViewGeometry, workers: int = 2,
                 platform: str | None = None, progress: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Renders the object at each rotation ``(V, 3, 3)`` on the optical axis (see :func:`render_at_transforms`)."""
    rotations = as_array(rotations, "rotations", (3, 3)).reshape(-1, 3, 3)
    T_model2cam = np.tile(np.eye(4), (len(rotations), 1, 1))
    T_model2cam[:, :3, :3] = rotations
    T_model2cam[:, 2, 3] = geometry.distance
    return render_at_transforms(mesh_path, mesh_scale, geometry.K, T_model2cam, geometry.render_size, workers, platform,
                                progress=progress, description="render views")
