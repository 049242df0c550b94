"""Drawing on ``uint8`` RGB images: keypoints with stable colours, boxes, projected 3D boxes, grids,
a pose's axes and the outline of a posed mesh (:func:`model_silhouette`, :func:`draw_model_outline`).

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

from paz6d.backend.camera import project_points
from paz6d.backend.checks import as_array, as_camera_matrix, as_points
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


def _posed(points, T_model2cam) -> np.ndarray:
    """``(N, 3)`` model points (metres) in the camera frame of ``T_model2cam`` ``(4, 4)``."""
    T = as_array(T_model2cam, "T_model2cam", (4, 4)).reshape(4, 4)
    return as_points(points, "vertices", dimension=3, min_count=0) @ T[:3, :3].T + T[:3, 3]


def model_silhouette(vertices, faces, T_model2cam, K, width: int, height: int, near: float = 1e-3) -> np.ndarray:
    """``(height, width)`` bool mask of the pixels a posed triangle mesh covers (its projected silhouette).

    Each triangle in front of the camera is filled (pixel centres at integer coordinates, as
    :func:`paz6d.backend.camera.project_points`); triangles with a vertex closer than ``near`` metres
    are left out.

    Args:
        vertices: ``(V, 3)`` model points in metres; faces: ``(F, 3)`` vertex indices.
        T_model2cam: ``(4, 4)`` pose (metres); K: ``(3, 3)`` intrinsics.
        width, height: image size in pixels.
    """
    if int(width) < 1 or int(height) < 1:
        raise ValueError(f"width/height: expected a positive image size, got {width}x{height}")
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
        raise ValueError(f"faces: expected (F, 3) integer vertex indices, got {faces.dtype} {faces.shape}")
    camera_points = _posed(vertices, T_model2cam)
    if faces.size and (faces.min() < 0 or faces.max() >= len(camera_points)):
        raise ValueError(f"faces: indices must lie in [0, {len(camera_points)}), got {faces.min()}..{faces.max()}")
    mask = np.zeros((int(height), int(width)), np.uint8)
    in_front = camera_points[:, 2] > near
    faces = faces[np.all(in_front[faces], axis=1)]
    if len(faces) == 0:
        return mask.astype(bool)
    pixels = np.zeros((len(camera_points), 2))
    pixels[in_front] = project_points(camera_points[in_front], as_camera_matrix(K))
    triangles = pixels[faces]  # (F, 3, 2)
    limit = 4.0 * max(width, height)  # fixed-point coordinates must fit int32; clip far-off vertices
    triangles = _fixed_point(np.clip(triangles, -limit, limit)).astype(np.int32)
    inside = ((triangles[..., 0].max(axis=1) >= 0) & (triangles[..., 1].max(axis=1) >= 0)
              & (triangles[..., 0].min(axis=1) < (width << 4)) & (triangles[..., 1].min(axis=1) < (height << 4)))
    for triangle in triangles[inside]:
        cv2.fillConvexPoly(mask, triangle, 1, cv2.LINE_8, 4)
    return mask.astype(bool)


def draw_mask_outline(image, mask, color=(0, 255, 0), thickness: int = 1) -> np.ndarray:
    """The outer and inner contours of a ``(H, W)`` bool ``mask`` of the image's size, drawn on a copy."""
    canvas = as_image(image).copy()
    mask = np.asarray(mask)
    if mask.shape != canvas.shape[:2]:
        raise ValueError(f"mask: expected the image's shape {canvas.shape[:2]}, got {mask.shape}")
    if thickness < 1:
        raise ValueError(f"thickness: expected a positive line width in pixels, got {thickness}")
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(canvas, contours, -1, tuple(int(v) for v in color), thickness, cv2.LINE_8)
    return canvas


def draw_model_outline(image, vertices, faces, T_model2cam, K, color=(0, 255, 0), thickness: int = 1) -> np.ndarray:
    """The silhouette contour of a posed mesh (:func:`model_silhouette`) drawn on a copy of ``image``.

    The contour runs along the silhouette's own boundary pixels, so every changed pixel lies inside the
    projected model (``thickness`` > 1 widens the line by up to ``thickness // 2`` pixels outside).
    """
    canvas = as_image(image)
    mask = model_silhouette(vertices, faces, T_model2cam, K, canvas.shape[1], canvas.shape[0])
    return draw_mask_outline(canvas, mask, color, thickness)


def draw_projected_points(image, points, T_model2cam, K, color=(0, 255, 0), radius: int = 1) -> np.ndarray:
    """``(N, 3)`` model points (metres, e.g. a mesh's surface samples) posed by ``T_model2cam`` and projected
    by ``K``, drawn as dots of ``radius`` pixels; points behind the camera or outside the image are skipped."""
    canvas = as_image(image).copy()
    camera_points = _posed(points, T_model2cam)
    camera_points = camera_points[camera_points[:, 2] > 1e-3]
    if len(camera_points) == 0:
        return canvas
    pixels = np.rint(project_points(camera_points, as_camera_matrix(K))).astype(np.int64)
    height, width = canvas.shape[:2]
    pixels = pixels[(pixels[:, 0] >= 0) & (pixels[:, 0] < width) & (pixels[:, 1] >= 0) & (pixels[:, 1] < height)]
    colour = tuple(int(v) for v in color)
    if radius <= 0:
        canvas[pixels[:, 1], pixels[:, 0]] = colour
        return canvas
    for u, v in pixels:
        cv2.circle(canvas, (int(u), int(v)), int(radius), colour, -1, cv2.LINE_8)
    return canvas


def draw_pose_axes(image, T_model2cam, K, length: float = 0.05, thickness: int = 2) -> np.ndarray:
    """The model frame's x (red), y (green) and z (blue) axes, ``length`` metres long, from its origin posed
    by ``T_model2cam`` ``(4, 4)`` and projected by ``K`` ``(3, 3)``; nothing is drawn when the origin or an
    axis end lies behind the camera."""
    canvas = as_image(image).copy()
    if not length > 0:
        raise ValueError(f"length: expected a positive axis length in metres, got {length}")
    ends = _posed(np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0], [0.0, length, 0.0], [0.0, 0.0, length]]),
                  T_model2cam)
    if np.any(ends[:, 2] <= 1e-3):
        return canvas
    pixels = _fixed_point(np.clip(project_points(ends, as_camera_matrix(K)), -1e5, 1e5))
    origin = (int(pixels[0, 0]), int(pixels[0, 1]))
    for end, colour in zip(pixels[1:], ((255, 0, 0), (0, 255, 0), (0, 0, 255))):
        cv2.line(canvas, origin, (int(end[0]), int(end[1])), colour, thickness, cv2.LINE_AA, 4)
    return canvas
