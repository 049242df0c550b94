"""Farthest-point sampling: a well-spread subset of a point cloud (e.g. keypoints on a mesh)."""

from __future__ import annotations

import numpy as np

from paz6d.backend.checks import as_points


def farthest_point_sampling(points, count: int, start: int | None = None) -> np.ndarray:
    """Indices ``(count,)`` of points chosen greedily, each the farthest from those already chosen.

    Args:
        points: ``(M, D)`` points.
        count: how many to choose (``<= M``).
        start: first index; default the point farthest from the centroid (deterministic).
    """
    points = as_points(points, "points", dimension=np.shape(points)[-1] if np.ndim(points) == 2 else 3)
    if not 1 <= count <= len(points):
        raise ValueError(f"count: expected 1 <= count <= {len(points)} (number of points), got {count}")
    if start is None:
        start = int(np.argmax(np.sum((points - points.mean(axis=0)) ** 2, axis=1)))
    elif not 0 <= start < len(points):
        raise ValueError(f"start: expected an index in [0, {len(points)}), got {start}")
    chosen = [int(start)]
    distance = np.sum((points - points[start]) ** 2, axis=1)
    for _ in range(count - 1):
        index = int(np.argmax(distance))
        chosen.append(index)
        distance = np.minimum(distance, np.sum((points - points[index]) ** 2, axis=1))
    return np.array(chosen)
