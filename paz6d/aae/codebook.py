"""Orientation codebook of the Augmented Autoencoder: latent codes of clean views at known rotations.

Rotations are sampled as in the paper: ``num_views`` camera directions spread uniformly over the
view sphere (a Fibonacci lattice; the paper uses the 2,562 vertices of a subdivided icosahedron)
times ``in_plane`` rotations about the camera axis (paper: 36), i.e. ``R = R_z(angle) @ R_view``.
Each codebook entry renders the object at ``T = (R, [0, 0, render_distance])`` (on the optical axis)
with ``render_K``; ``render_boxes`` are the silhouette boxes of those renderings, used to recover
translation from a test box (see :mod:`paz6d.aae.pipeline`).

Lookup is one batched matrix product of L2-normalised codes (cosine similarity) plus a top-k
selection.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.checks import as_array, as_camera_matrix
from paz6d.backend.files import load_npz, save_npz_atomically
from paz6d.backend.viewpoints import POLE_SINE, ViewpointRange, in_plane_rotation, look_at_rotation

CODEBOOK_FORMAT = 1


def fibonacci_sphere(count: int) -> np.ndarray:
    """``(count, 3)`` unit vectors spread near-uniformly over the sphere (golden-angle spiral)."""
    if int(count) <= 0:
        raise ValueError(f"count: expected a positive number of view directions, got {count}")
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    azimuth = np.pi * (1.0 + np.sqrt(5.0)) * index
    return np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth), z], axis=-1)


def look_at_rotations(directions) -> np.ndarray:
    """``(N, 3, 3)`` rotations ``R_model2cam`` of cameras placed along ``directions`` (model frame,
    from the object towards the camera) looking at the model origin (OpenCV: camera z towards the
    object). The in-plane angle is fixed by keeping camera x horizontal in the model's xy plane, with the
    model's -z axis image-up (the generator's views are the same turned by 180 degrees in-plane; the
    codebook's in-plane angles cover the whole circle, so this only orders them)."""
    directions = as_array(directions, "directions", (3,))
    z_axis = -directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    down = np.where(np.abs(z_axis[:, 2:3]) < POLE_SINE, np.array([0.0, 0.0, -1.0]), np.array([0.0, -1.0, 0.0]))
    return look_at_rotation(z_axis, down)


def codebook_angles(in_plane: int) -> np.ndarray:
    """The ``in_plane`` equally spaced in-plane angles (radians) of the codebook, starting at 0."""
    if int(in_plane) <= 0:
        raise ValueError(f"in_plane: expected a positive number of in-plane rotations, got {in_plane}")
    return 2.0 * np.pi * np.arange(in_plane) / in_plane


def codebook_rotations(view_rotations, in_plane: int) -> np.ndarray:
    """``(V * in_plane, 3, 3)`` rotations ``R_z(angle_k) @ R_view_v`` ordered view-major (index
    ``v * in_plane + k``)."""
    view_rotations = as_array(view_rotations, "view_rotations", (3, 3))
    planes = in_plane_rotation(codebook_angles(in_plane))
    return np.einsum("kij,vjl->vkil", planes, view_rotations).reshape(-1, 3, 3)


def normalize_codes(codes) -> np.ndarray:
    """Rows scaled to unit L2 norm, float32 ``(N, L)``; a zero row raises ``ValueError``."""
    codes = np.asarray(codes, dtype=np.float32)
    if codes.ndim != 2:
        raise ValueError(f"codes: expected shape (N, latent_size), got {codes.shape}")
    if not np.all(np.isfinite(codes)):
        raise ValueError("codes: contain NaN or infinite values")
    norms = np.linalg.norm(codes, axis=1, keepdims=True)
    if np.any(norms == 0):
        raise ValueError("codes: a latent code is all zeros, its direction (cosine similarity) is undefined")
    return codes / norms


@dataclass(frozen=True)
class Codebook:
    """Latent codes of clean on-axis views and the geometry needed to turn a match into a pose.

    Attributes:
        codes: ``(N, L)`` float32 unit-norm latent codes.
        rotations: ``(N, 3, 3)`` ``R_model2cam`` of each view (object on the optical axis).
        render_boxes: ``(N, 4)`` silhouette box of each view rendered at ``render_distance`` with
            ``render_K`` (pixels, box convention).
        render_K: ``(3, 3)`` intrinsics of those renderings.
        render_distance: metres from the camera to the model origin in those renderings.
    """

    codes: np.ndarray
    rotations: np.ndarray
    render_boxes: np.ndarray
    render_K: np.ndarray
    render_distance: float

    def __post_init__(self):
        codes = normalize_codes(self.codes)
        rotations = as_array(self.rotations, "rotations", (3, 3))
        boxes = as_array(self.render_boxes, "render_boxes", (4,))
        if rotations.shape != (len(codes), 3, 3) or boxes.shape != (len(codes), 4):
            raise ValueError(f"Codebook: codes {codes.shape}, rotations {rotations.shape} and render_boxes "
                             f"{boxes.shape} must describe the same number of entries")
        if not np.isfinite(self.render_distance) or self.render_distance <= 0:
            raise ValueError(f"render_distance: expected a positive distance in metres, got {self.render_distance}")
        object.__setattr__(self, "codes", codes)
        object.__setattr__(self, "rotations", rotations)
        object.__setattr__(self, "render_boxes", boxes)
        object.__setattr__(self, "render_K", as_camera_matrix(self.render_K))
        object.__setattr__(self, "render_distance", float(self.render_distance))

    def __len__(self) -> int:
        return len(self.codes)

    @property
    def latent_size(self) -> int:
        return self.codes.shape[1]

    def nearest(self, codes, top_k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Most similar entries (cosine similarity) of each query code.

        Args:
            codes: ``(B, L)`` (or one ``(L,)``) latent codes, any norm.
            top_k: number of entries per query, best first.

        Returns:
            ``indices (B, top_k)`` int and ``similarities (B, top_k)`` float32 in [-1, 1].
        """
        queries = np.asarray(codes, dtype=np.float32)
        if queries.ndim == 1:
            queries = queries[None]
        if queries.ndim != 2 or queries.shape[1] != self.latent_size:
            raise ValueError(f"codes: expected shape (B, {self.latent_size}), got {np.shape(codes)}")
        if not 1 <= int(top_k) <= len(self):
            raise ValueError(f"top_k: expected 1..{len(self)}, got {top_k}")
        similarities = normalize_codes(queries) @ self.codes.T  # (B, N): the one batched product
        if top_k == 1:
            indices = np.argmax(similarities, axis=1)[:, None]
        else:
            indices = np.argpartition(-similarities, top_k - 1, axis=1)[:, :top_k]
            order = np.argsort(-np.take_along_axis(similarities, indices, axis=1), axis=1, kind="stable")
            indices = np.take_along_axis(indices, order, axis=1)
        return indices, np.take_along_axis(similarities, indices, axis=1)

    def neighbour_average(self, indices, similarities, radius_deg: float = 15.0,
                          temperature: float = 0.02) -> np.ndarray:
        """Rotations ``(B, 3, 3)`` refined below the codebook's spacing: per query, the mean (chordal L2,
        scipy ``Rotation.mean``) of its matched rotations within ``radius_deg`` of the best one, weighted by
        ``exp((similarity - best) / temperature)``.

        Args:
            indices / similarities: ``(B, k)`` from :meth:`nearest`, best first.
        """
        from scipy.spatial.transform import Rotation

        indices, similarities = np.atleast_2d(indices), np.atleast_2d(similarities)
        if radius_deg <= 0 or temperature <= 0:
            raise ValueError(f"radius_deg/temperature: expected positive values, got {radius_deg}, {temperature}")
        cosine_limit = np.cos(np.radians(radius_deg))
        output = np.empty((len(indices), 3, 3))
        for row, (chosen, values) in enumerate(zip(indices, similarities)):
            rotations = self.rotations[chosen]
            # cos(angle to the best) = (trace(R_best^T R) - 1) / 2
            cosines = (np.einsum("ij,kij->k", rotations[0], rotations) - 1) / 2
            keep = cosines >= cosine_limit
            weights = np.exp((values[keep] - values[0]) / temperature)
            output[row] = Rotation.from_matrix(rotations[keep]).mean(weights=weights).as_matrix()
        return output

    def within(self, viewpoints: ViewpointRange) -> "Codebook":
        """The entries whose rotation lies in ``viewpoints`` (a camera that never sees the object from
        below, say), in their order; ``ValueError`` when none does."""
        keep = viewpoints.contains(self.rotations)
        if not keep.any():
            raise ValueError(f"viewpoints: none of the codebook's {len(self)} views lies within "
                             f"{viewpoints.describe()}")
        return Codebook(self.codes[keep], self.rotations[keep], self.render_boxes[keep], self.render_K,
                        self.render_distance)

    def save(self, path: str | Path) -> Path:
        """Writes an ``.npz`` (temp file, then atomic rename)."""
        return save_npz_atomically(path, format=CODEBOOK_FORMAT, codes=self.codes, rotations=self.rotations,
                                   render_boxes=self.render_boxes, render_K=self.render_K,
                                   render_distance=self.render_distance)

    @classmethod
    def load(cls, path: str | Path) -> "Codebook":
        """Reads a codebook written by :meth:`save`; ``ValueError`` naming the file when it is unusable."""
        path = Path(path)
        fields = load_npz(path, "codebook")
        missing = {"codes", "rotations", "render_boxes", "render_K", "render_distance"} - set(fields)
        if missing:
            raise ValueError(f"{path}: codebook is missing field(s) {sorted(missing)}")
        try:
            return cls(fields["codes"], fields["rotations"], fields["render_boxes"], fields["render_K"],
                       float(fields["render_distance"]))
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from error
