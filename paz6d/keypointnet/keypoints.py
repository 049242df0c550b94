"""KeypointNet keypoint geometry: decoding probability maps to pixels, their spread, and 3D keypoints
from views with known poses (lifting, triangulation). Used by the trainer and the pipeline."""

from __future__ import annotations

import numpy as np

from paz6d.backend.camera import unproject
from paz6d.backend.checks import as_array
from paz6d.backend.transform import apply, invert

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
    per_view = per_view_points(uv, depth, K, T_model2cam)
    points = np.median(per_view, axis=0)
    spread = np.median(np.linalg.norm(per_view - points[None], axis=-1), axis=0)
    return points, spread


def per_view_points(uv: np.ndarray, depth: np.ndarray, K: np.ndarray, T_model2cam: np.ndarray) -> np.ndarray:
    """Each view's keypoints ``uv (V, N, 2)`` at depths ``(V, N)`` (metres) moved to the object frame:
    ``(V, N, 3)`` metres (``K (V, 3, 3)``, ``T_model2cam (V, 4, 4)``)."""
    return np.stack([apply(invert(T_model2cam[v]), unproject(uv[v], depth[v], K[v])) for v in range(len(uv))])


def spread_modes(per_view: np.ndarray, radius: float, delta: float) -> np.ndarray:
    """One 3D point per keypoint where that keypoint lands most often, at least ``delta`` apart.

    The density of a candidate (one view's estimate of keypoint ``n``, ``per_view[v, n]``) is how many
    of keypoint ``n``'s estimates lie within ``radius`` of it. Keypoints are taken from the most
    concentrated (highest peak density) to the least; each gets its densest candidate at least ``delta``
    from the points already chosen, or, when none is that far, the candidate farthest from them.
    Unlike the mean or median, this does not pull keypoints that wander over the object to its centre.

    Args:
        per_view: ``(V, N, 3)`` per-view estimates (e.g. :func:`per_view_points`).
        radius, delta: same unit as ``per_view``.
    Returns:
        ``(N, 3)``.
    """
    per_view = np.asarray(per_view, dtype=np.float64)
    if per_view.ndim != 3 or per_view.shape[-1] != 3 or len(per_view) == 0:
        raise ValueError(f"per_view: expected (V >= 1, N, 3) points, got shape {per_view.shape}")
    if radius <= 0 or delta < 0:
        raise ValueError(f"radius/delta: expected radius > 0 and delta >= 0, got {radius}, {delta}")
    clouds = per_view.transpose(1, 0, 2)  # (N, V, 3)
    density = np.stack([(np.linalg.norm(cloud[:, None] - cloud[None], axis=-1) <= radius).sum(axis=1)
                        for cloud in clouds])  # (N, V)
    chosen = np.zeros((len(clouds), 3))
    taken: list[int] = []
    for index in np.argsort(-density.max(axis=1), kind="stable"):
        if taken:
            gap = np.linalg.norm(clouds[index][:, None] - chosen[taken][None], axis=-1).min(axis=1)
            far = gap >= delta
            best = np.argmax(np.where(far, density[index], -1)) if far.any() else np.argmax(gap)
        else:
            best = np.argmax(density[index])
        chosen[index] = clouds[index][best]
        taken.append(int(index))
    return chosen


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
