"""Building an Augmented Autoencoder codebook from clean on-axis views and a trained encoder."""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from paz6d.aae.model import crop_object, encode_function, to_model_input
from paz6d.aae.codebook import Codebook, codebook_angles, codebook_rotations
from paz6d.aae.views import ViewGeometry, coverage_box, rotate_view, silhouette_boxes


def codebook_crops(rgb: np.ndarray, alpha: np.ndarray, geometry: ViewGeometry, in_plane: int, crop_size: int,
                   padding: float, views: range | None = None) -> np.ndarray:
    """Clean crops ``(len(views) * in_plane, S, S, 3)`` uint8 of views ``views`` (default all) at the
    codebook's in-plane angles, ordered like :func:`paz6d.aae.codebook.codebook_rotations`."""
    views = range(len(rgb)) if views is None else views
    crops = np.empty((len(views) * in_plane, crop_size, crop_size, 3), np.uint8)
    angles = codebook_angles(in_plane)
    index = 0
    for view in views:
        for angle in angles:
            rotated_rgb, rotated_alpha = rotate_view(rgb[view], alpha[view], float(angle), geometry.K)
            box = coverage_box(rotated_alpha)
            if box is None:
                raise ValueError(f"view {view}: the object is not visible in the rendering")
            crops[index] = crop_object(rotated_rgb, box, crop_size, padding)
            index += 1
    return crops


def build_codebook(encoder, rgb: np.ndarray, alpha: np.ndarray, view_rotations: np.ndarray, geometry: ViewGeometry,
                   hull_points: np.ndarray, in_plane: int, crop_size: int, padding: float, batch_size: int = 256,
                   progress: bool = True) -> Codebook:
    """Encodes every (view, in-plane angle) crop into a :class:`Codebook`.

    Args:
        encoder: Keras encoder ``(B, S, S, 3) -> (B, L)``.
        rgb / alpha: ``(V, R, R, 3)`` / ``(V, R, R)`` clean on-axis views.
        view_rotations: ``(V, 3, 3)`` their ``R_model2cam``.
        geometry: camera and distance of the views.
        hull_points: ``(M, 3)`` convex-hull vertices of the object (metres), for the silhouette boxes.
        in_plane: in-plane rotations per view.
        crop_size / padding: crop settings of the model.
        batch_size: crops encoded per call.
    """
    encode = encode_function(encoder)
    rotations = codebook_rotations(view_rotations, in_plane)
    views_per_batch = max(1, batch_size // in_plane)
    codes = []
    with tqdm(total=len(rotations), desc="codebook", unit="view", disable=not progress, dynamic_ncols=True) as bar:
        for start in range(0, len(rgb), views_per_batch):
            views = range(start, min(start + views_per_batch, len(rgb)))
            crops = codebook_crops(rgb, alpha, geometry, in_plane, crop_size, padding, views)
            codes.append(encode(to_model_input(crops)))
            bar.update(len(crops))
    boxes = silhouette_boxes(hull_points, rotations, geometry.K, [0.0, 0.0, geometry.distance])
    return Codebook(np.concatenate(codes), rotations, boxes, geometry.K, geometry.distance)
