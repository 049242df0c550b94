"""Images of a flat board seen by a camera of known ``K`` and distortion, made with numpy and OpenCV.

For each pixel of the distorted image, its undistorted location (``cv2.undistortPointsIter``, iterated
to 1e-10) is carried through the inverse of the board-to-image homography into the board's texture,
which is sampled there (``cv2.remap``); four samples per pixel average out the aliasing, and a light
blur stands in for a lens.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from paz6d.backend.camera import project_points

#: The camera the renders are taken with: 640 x 480 px, off-centre principal point, barrel distortion.
K_TRUE = np.array([[610.0, 0.0, 327.5], [0.0, 604.0, 236.5], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.22, 0.09, 0.0012, -0.0008, 0.0])
SIZE = (640, 480)


def chessboard_texture(columns: int, rows: int, pixels_per_square: int) -> np.ndarray:
    """``uint8 (H, W)`` chessboard of ``(columns + 1) x (rows + 1)`` squares (``columns x rows`` inner
    corners) with a white margin of one square."""
    squares = (np.add.outer(np.arange(rows + 1), np.arange(columns + 1)) % 2 == 0)
    board = np.where(squares, 0, 255).astype(np.uint8)
    board = np.kron(board, np.ones((pixels_per_square, pixels_per_square), np.uint8))
    return np.pad(board, pixels_per_square, constant_values=255)


@lru_cache(maxsize=4)
def _undistorted_samples(K: tuple, dist: tuple, size: tuple) -> list[np.ndarray]:
    """For four sample points in each pixel of the distorted image, ``(H * W, 1, 2)`` their undistorted pixels."""
    K, dist = np.reshape(K, (3, 3)), np.asarray(dist)
    columns, rows = np.meshgrid(np.arange(size[0], dtype=np.float64), np.arange(size[1], dtype=np.float64))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    samples = []
    for du, dv in ((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)):
        distorted = np.stack([columns + du, rows + dv], axis=-1).reshape(-1, 1, 2)
        samples.append(cv2.undistortPointsIter(distorted, K, dist, None, K, criteria))
    return samples


def render_board(texture: np.ndarray, width_m: float, R: np.ndarray, t: np.ndarray, K=K_TRUE, dist=DIST_TRUE,
                 size=SIZE, blur_sigma: float = 0.6) -> np.ndarray:
    """``uint8 (H, W, 3)`` RGB image of ``texture`` printed ``width_m`` metres wide on the board plane
    (board x right, y down, z = 0; origin at the texture's top-left corner) at pose ``R, t``; grey
    background."""
    metres_per_pixel = width_m / texture.shape[1]
    # texture pixel centre (i, j) <-> board point ((j + 0.5), (i + 0.5)) * metres_per_pixel
    texture_to_board = np.array([[metres_per_pixel, 0, 0.5 * metres_per_pixel],
                                 [0, metres_per_pixel, 0.5 * metres_per_pixel], [0, 0, 1]])
    H = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ texture_to_board
    H_inv = np.linalg.inv(H)
    total = np.zeros((size[1], size[0]), np.float64)
    for undistorted in _undistorted_samples(tuple(map(float, K.ravel())), tuple(map(float, dist)), tuple(size)):
        maps = cv2.perspectiveTransform(undistorted, H_inv).astype(np.float32).reshape(size[1], size[0], 2)
        total += cv2.remap(texture, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=128)
    image = cv2.GaussianBlur(total / 4, (0, 0), blur_sigma) if blur_sigma > 0 else total / 4
    return np.repeat(np.clip(np.rint(image), 0, 255).astype(np.uint8)[..., None], 3, axis=-1)


def board_poses(count: int, width_m: float, height_m: float, seed: int, K=K_TRUE, dist=DIST_TRUE,
                size=SIZE, margin_px: float = 12.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` poses ``(R (3, 3), t (3,))`` of a ``width_m x height_m`` board, tilted up to 40 degrees
    about its x and y axes and turned up to 25 degrees in plane, filling much of the image, with all
    four board corners at least ``margin_px`` inside it."""
    generator = np.random.default_rng(seed)
    corners = np.array([[0, 0, 0], [width_m, 0, 0], [0, height_m, 0], [width_m, height_m, 0]])
    centre = np.array([width_m / 2, height_m / 2, 0.0])
    poses = []
    while len(poses) < count:
        tilt = generator.uniform(-40, 40, size=2)
        R = Rotation.from_euler("xyz", [tilt[0], tilt[1], generator.uniform(-25, 25)], degrees=True).as_matrix()
        distance = generator.uniform(1.3, 1.9) * width_m * K[0, 0] / size[0]
        offset = generator.uniform(-0.25, 0.25, size=2) * np.array(size) / K[0, 0] * distance
        t = np.array([offset[0], offset[1], distance]) - R @ centre
        pixels = project_points(corners @ R.T + t, K, dist)
        if np.all(pixels >= margin_px) and np.all(pixels <= np.array(size) - 1 - margin_px):
            poses.append((R, t))
    return poses
