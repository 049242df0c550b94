"""Drawing on ``uint8`` RGB images: keypoints with stable colours, boxes, projected 3D boxes, grids.

Every function returns a new image and leaves its input untouched. Point coordinates are camera
pixels (pixel centres at integers, :mod:`paz6d.backend.camera`); boxes are ``xyxy`` with pixel ``i``
covering ``[i, i + 1)``.

Example:
    >>> import numpy as np
    >>> canvas = np.zeros((32, 32, 3), np.uint8)
    >>> drawn = draw_keypoints(canvas, [[8, 8], [20, 24]])
    >>> drawn[8, 8].tolist() == keypoint_colors(2)[0].tolist()
    True
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from paz6d.backend.checks import as_array, as_points
from paz6d.backend.image import as_image

#: Fixed, well-separated colours for the first keypoints (keypoint ``i`` always gets colour ``i``).
PALETTE = np.array([[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
                    [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [250, 190, 212],
                    [0, 128, 128], [220, 190, 255], [170, 110, 40], [255, 250, 200], [128, 0, 0],
                    [170, 255, 195], [128, 128, 0], [255, 215, 180], [0, 0, 128], [128, 128, 128]], dtype=np.uint8)

#: Edges of the 8 corners ordered as :func:`paz6d.backend.mesh.bounding_box_corners` (x, then y, then z).
BOX_EDGES = ((0, 1), (0, 2), (1, 3), (2, 3), (4, 5), (4, 6), (5, 7), (6, 7), (0, 4), (1, 5), (2, 6), (3, 7))


def keypoint_colors(count: int) -> np.ndarray:
    """``(count, 3)`` uint8 RGB colours; colour ``i`` depends only on ``i``.

    The first 20 come from :data:`PALETTE`, later ones walk the hue circle by the golden ratio.
    """
    if count < 0:
        raise ValueError(f"count: expected a non-negative number of colours, got {count}")
    colours = [PALETTE[index] if index < len(PALETTE) else _golden_hue(index) for index in range(count)]
    return np.array(colours, dtype=np.uint8).reshape(count, 3)


def _golden_hue(index: int) -> np.ndarray:
    hue = int(((index * 0.618033988749895) % 1.0) * 180)
    hsv = np.array([[[hue, 200, 230]]], dtype=np.uint8)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0]


def _fixed_point(points: np.ndarray, shift: int = 4) -> np.ndarray:
    """Pixel coordinates to OpenCV's fixed-point integers (sub-pixel drawing)."""
    return np.rint(points * (1 << shift)).astype(np.int64)


def draw_keypoints(image, points, colors=None, radius: int = 3, visible: Sequence[bool] | None = None,
                   outline: bool = True) -> np.ndarray:
    """Filled circles at ``(N, 2)`` pixel keypoints, keypoint ``i`` in colour ``i``.

    Args:
        colors: ``(N, 3)`` RGB colours; default :func:`keypoint_colors`.
        visible: ``(N,)`` flags; hidden keypoints are drawn as hollow circles.
        outline: draw a thin black ring around each keypoint for contrast.
    """
    canvas = as_image(image).copy()
    points = as_points(points, "points", dimension=2, min_count=0)
    colors = keypoint_colors(len(points)) if colors is None else np.asarray(colors, dtype=np.uint8)
    if colors.shape != (len(points), 3):
        raise ValueError(f"colors: expected shape ({len(points)}, 3), got {colors.shape}")
    if visible is not None and len(visible) != len(points):
        raise ValueError(f"visible: expected {len(points)} flags, got {len(visible)}")
    if radius < 1:
        raise ValueError(f"radius: expected a positive radius in pixels, got {radius}")
    for index, (centre, colour) in enumerate(zip(_fixed_point(points), colors)):
        centre = (int(centre[0]), int(centre[1]))
        thickness = -1 if visible is None or visible[index] else max(1, radius // 2)
        if outline:
            cv2.circle(canvas, centre, (radius + 1) << 4, (0, 0, 0), 1, cv2.LINE_AA, 4)
        cv2.circle(canvas, centre, radius << 4, tuple(int(value) for value in colour), thickness, cv2.LINE_AA, 4)
    return canvas


def draw_box(image, box, color=(0, 255, 0), thickness: int = 1) -> np.ndarray:
    """Rectangle outline of ``xyxy`` ``box`` (drawn on the pixels it covers)."""
    canvas = as_image(image).copy()
    x_min, y_min, x_max, y_max = as_array(box, "box", (4,)).reshape(4)
    corner_a = _fixed_point(np.array([x_min, y_min]))
    corner_b = _fixed_point(np.array([x_max - 1, y_max - 1]))
    cv2.rectangle(canvas, tuple(int(v) for v in corner_a), tuple(int(v) for v in corner_b),
                  tuple(int(v) for v in color), thickness, cv2.LINE_AA, 4)
    return canvas


def draw_cube(image, corners, color=(0, 255, 0), thickness: int = 1) -> np.ndarray:
    """Edges of a projected 3D box from its ``(8, 2)`` pixel corners (order of :data:`BOX_EDGES`)."""
    canvas = as_image(image).copy()
    corners = _fixed_point(as_points(corners, "corners", dimension=2, min_count=8))
    if len(corners) != 8:
        raise ValueError(f"corners: expected 8 corners, got {len(corners)}")
    colour = tuple(int(value) for value in color)
    for start, end in BOX_EDGES:
        cv2.line(canvas, tuple(int(v) for v in corners[start]), tuple(int(v) for v in corners[end]), colour,
                 thickness, cv2.LINE_AA, 4)
    return canvas


def image_grid(images: Sequence[np.ndarray], columns: int, padding: int = 2, pad_value: int = 255) -> np.ndarray:
    """Tiles equal-size ``uint8`` RGB images row by row into one image (blank cells at the end)."""
    if len(images) == 0:
        raise ValueError("images: expected at least one image")
    if columns < 1:
        raise ValueError(f"columns: expected a positive number of columns, got {columns}")
    tiles = [as_image(tile, f"images[{index}]") for index, tile in enumerate(images)]
    height, width = tiles[0].shape[:2]
    for index, tile in enumerate(tiles):
        if tile.shape[:2] != (height, width):
            raise ValueError(f"images[{index}]: expected size {width}x{height} like images[0], "
                             f"got {tile.shape[1]}x{tile.shape[0]}")
    columns = min(columns, len(tiles))
    rows = -(-len(tiles) // columns)
    grid = np.full((rows * height + (rows + 1) * padding, columns * width + (columns + 1) * padding, 3),
                   pad_value, dtype=np.uint8)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        top, left = padding + row * (height + padding), padding + column * (width + padding)
        grid[top:top + height, left:left + width] = tile
    return grid
