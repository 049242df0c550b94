"""Pinhole camera in the OpenCV convention (x right, y down, z forward), distances in metres.

``K`` is the 3×3 intrinsics matrix. As in OpenCV, integer pixel coordinates are pixel centres:
``u = fx * x / z + s * y / z + cx`` and image column ``i`` is centred at ``u = i``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from paz6d.backend.checks import as_array, as_camera_matrix, as_points
from paz6d.backend.transform import apply


def _as_distortion(distortion) -> np.ndarray | None:
    if distortion is None:
        return None
    values = np.atleast_1d(distortion)
    coefficients = as_array(values, "distortion", (values.shape[-1],)).ravel()
    if coefficients.size not in (4, 5, 8, 12, 14):
        raise ValueError(f"distortion: expected 4, 5, 8, 12 or 14 OpenCV coefficients, got {coefficients.size}")
    return None if not np.any(coefficients) else coefficients


def project_points(points_cam, K, distortion=None) -> np.ndarray:
    """Projects ``(N, 3)`` camera-frame points (metres) to ``(N, 2)`` pixels.

    Points with ``z <= 0`` produce non-finite pixels (they are behind the camera). With
    ``distortion`` (OpenCV coefficients) OpenCV's model is applied.
    """
    points = as_array(points_cam, "points_cam", (3,))
    K = as_camera_matrix(K)
    distortion = _as_distortion(distortion)
    if distortion is not None:
        flat = points.reshape(-1, 3)
        pixels, _ = cv2.projectPoints(flat, np.zeros(3), np.zeros(3), K, distortion)
        return pixels.reshape(points.shape[:-1] + (2,))
    z = points[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(z > 0, points[..., 0] / z, np.nan)
        y = np.where(z > 0, points[..., 1] / z, np.nan)
    u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
    v = K[1, 1] * y + K[1, 2]
    return np.stack([u, v], axis=-1)


def transform_and_project(points_model, T_model2cam, K, distortion=None) -> np.ndarray:
    """Projects ``(N, 3)`` model points posed by ``T_model2cam`` ``(4, 4)`` to ``(N, 2)`` pixels."""
    return project_points(apply(T_model2cam, points_model), K, distortion)


def unproject(pixels, depths, K) -> np.ndarray:
    """Back-projects ``(N, 2)`` pixels at depths ``(N,)`` (metres, along z) to ``(N, 3)`` camera points."""
    pixels = as_array(pixels, "pixels", (2,))
    depths = np.asarray(depths, dtype=np.float64)
    if depths.shape != pixels.shape[:-1]:
        raise ValueError(f"depths: expected shape {pixels.shape[:-1]} to match pixels, got {depths.shape}")
    K = as_camera_matrix(K)
    y = (pixels[..., 1] - K[1, 2]) / K[1, 1]
    x = (pixels[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return np.stack([x * depths, y * depths, depths], axis=-1)


def points_from_depth(depth, K) -> np.ndarray:
    """Back-projects a depth image ``(H, W)`` (metres, 0 = none) to ``(N, 3)`` camera points.

    Pixel ``(row, col)`` is taken at its centre coordinate ``(u, v) = (col, row)``.
    """
    depth = np.asarray(depth, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth: expected shape (H, W), got {depth.shape}")
    rows, cols = np.nonzero(depth > 0)
    pixels = np.stack([cols, rows], axis=-1).astype(np.float64)
    return unproject(pixels, depth[rows, cols], K)


@dataclass(frozen=True)
class Camera:
    """Intrinsics ``K`` (3×3), image ``width``/``height`` (px) and optional OpenCV distortion."""

    K: np.ndarray
    width: int
    height: int
    distortion: np.ndarray | None = field(default=None)

    def __post_init__(self):
        object.__setattr__(self, "K", as_camera_matrix(self.K))
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"width/height: expected positive pixel sizes, got {self.width}x{self.height}")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "distortion", _as_distortion(self.distortion))

    def project(self, points_cam) -> np.ndarray:
        """``(N, 3)`` camera points (m) to ``(N, 2)`` pixels."""
        return project_points(points_cam, self.K, self.distortion)

    def unproject(self, pixels, depths) -> np.ndarray:
        """``(N, 2)`` undistorted pixels + depths (m) to ``(N, 3)`` camera points."""
        return unproject(pixels, depths, self.K)

    def undistort_points(self, pixels) -> np.ndarray:
        """Removes lens distortion from ``(N, 2)`` pixel coordinates (returns pixels for ``K``).

        Iterates to convergence (OpenCV's default 5 iterations leave errors of ~0.1 px near the
        corners of strongly distorted images).
        """
        pixels = as_points(pixels, "pixels", dimension=2)
        if self.distortion is None:
            return pixels
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
        undistorted = cv2.undistortPointsIter(pixels.reshape(-1, 1, 2), self.K, self.distortion, None, self.K,
                                              criteria)
        return undistorted.reshape(-1, 2)

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """Undistorts an image with this camera's distortion (identity when there is none)."""
        if self.distortion is None:
            return image
        return cv2.undistort(image, self.K, self.distortion)

    def scaled(self, factor: float) -> "Camera":
        """Camera for an image resized by ``factor`` (pixel-centre convention preserved)."""
        K = self.K.copy()
        K[:2] *= factor
        K[0, 2] = (self.K[0, 2] + 0.5) * factor - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * factor - 0.5
        return Camera(K, round(self.width * factor), round(self.height * factor), self.distortion)

    def to_dict(self) -> dict:
        """JSON-safe dictionary."""
        return {"K": self.K.tolist(), "width": self.width, "height": self.height,
                "distortion": None if self.distortion is None else self.distortion.tolist()}

    @classmethod
    def from_dict(cls, data: dict) -> "Camera":
        for key in ("K", "width", "height"):
            if key not in data:
                raise ValueError(f"camera dict: missing field {key!r}")
        return cls(np.asarray(data["K"], dtype=np.float64), data["width"], data["height"], data.get("distortion"))


def check_principal_point(K: np.ndarray, width: int, height: int, where: str) -> None:
    """``ValueError`` naming ``where`` when the principal point of ``K`` lies further outside the
    ``width × height`` image than the image's own size (``cx`` outside ``[-width, 2 width]`` or ``cy``
    outside ``[-height, 2 height]``): intrinsics of another camera, or a corrupt file, whose poses
    would land at absurd distances. Crops' intrinsics (whose principal point may be far outside
    the crop) are not meant."""
    cx, cy = float(K[0, 2]), float(K[1, 2])
    if not (-width <= cx <= 2 * width and -height <= cy <= 2 * height):
        raise ValueError(f"{where}: principal point ({cx:.6g}, {cy:.6g}) px lies outside the {width} x {height} px "
                         "image by more than its size; expected the intrinsics of this image's camera")


def as_camera(camera, width: int | None = None, height: int | None = None, name: str = "camera") -> Camera:
    """The :class:`Camera` of an image of ``width x height`` pixels, from a Camera or a 3×3 ``K``.

    Args:
        camera: a :class:`Camera` (returned as is) or a ``(3, 3)`` intrinsics matrix.
        width, height: the image's size in pixels; required with a ``K``, checked against a Camera.
        name: argument name used in error messages.
    Raises:
        ValueError: a Camera of another size than the image, a ``K`` without the image size, or an invalid ``K``.
    """
    if isinstance(camera, Camera):
        if (width is not None and int(width) != camera.width) or (height is not None and int(height) != camera.height):
            raise ValueError(f"image: {width}x{height} pixels does not match the camera's "
                             f"{camera.width}x{camera.height} (width x height)")
        return camera
    if camera is None:
        raise ValueError(f"{name}: none given; expected a paz6d.backend.camera.Camera or a 3x3 K (a pipeline "
                         "takes it in its constructor or per call)")
    if width is None or height is None:
        raise ValueError(f"{name}: a 3x3 K needs the image size (width, height); pass a Camera or the size")
    return Camera(as_camera_matrix(camera, name), width, height)
