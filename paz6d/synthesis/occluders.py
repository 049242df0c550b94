"""Things that hide part of an object: distractor primitives rendered with it (and placed between
the camera and an object) and flat polygons drawn over a crop."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import trimesh

from paz6d.abstract.processor import RandomProcessor
from paz6d.backend import quaternion
from paz6d.backend.transform import from_rotation_translation


def distractor_library(size: float) -> list[trimesh.Trimesh]:
    """Boxes, cylinders, spheres and capsules at three sizes relative to ``size`` (metres), centred at
    the origin, with white vertex colours (a random colour tints each when rendered)."""
    library = []
    for factor in (0.3, 0.6, 1.0):
        side = size * factor
        library += [trimesh.creation.box((side, 0.6 * side, 0.4 * side)),
                    trimesh.creation.cylinder(radius=0.25 * side, height=side, sections=24),
                    trimesh.creation.icosphere(subdivisions=2, radius=0.4 * side),
                    trimesh.creation.capsule(height=0.6 * side, radius=0.2 * side, count=(12, 12))]
    return paint_white(library)


def paint_white(meshes: list[trimesh.Trimesh]) -> list[trimesh.Trimesh]:
    """``meshes`` with white vertex colours set in place (a random colour tints each when rendered)."""
    for mesh in meshes:
        mesh.visual.vertex_colors = np.full((len(mesh.vertices), 4), 255, dtype=np.uint8)
    return meshes


def random_colors(generator: np.random.Generator, count: int, neutral_share: float = 0.0,
                  palettes: Sequence[np.ndarray] = (), palette_share: float = 0.0, jitter: float = 0.0) -> np.ndarray:
    """``(count, 3)`` random colours (linear factors) for white distractor primitives: each channel uniform in
    0.05..1, or, for a ``neutral_share`` of them, a white to mid-grey level in 0.5..1 with each channel
    within ±4 % of it, or, for a ``palette_share`` of the others, a colour of a random palette (a random
    row of it, each channel times ``U(1 - jitter, 1 + jitter)``, at most 1). The shares add up to at most
    1; nothing more is drawn when both are 0.

    Args:
        palettes: colour sets ``(N, 3)`` in 0..1, e.g. :func:`mesh_palettes` of the annotated objects, so
            that some clutter has the objects' colours but not their shapes.
    """
    colors = generator.uniform(0.05, 1.0, size=(count, 3))
    palettes = [palette for palette in palettes if len(palette)]
    palette_share = palette_share if palettes else 0.0
    if neutral_share <= 0 and palette_share <= 0:
        return colors
    draws = generator.random(count)  # one draw per distractor picks its kind
    if neutral_share > 0:
        levels = generator.uniform(0.5, 1.0, size=(count, 1)) * generator.uniform(0.96, 1.04, size=(count, 3))
        neutral = draws < neutral_share
        colors[neutral] = np.minimum(levels[neutral], 1.0)
    if palette_share > 0:
        for row in np.flatnonzero((draws >= neutral_share) & (draws < neutral_share + palette_share)):
            palette = palettes[int(generator.integers(len(palettes)))]
            color = palette[int(generator.integers(len(palette)))]
            colors[row] = np.minimum(color * generator.uniform(1 - jitter, 1 + jitter, size=3), 1.0)
    return colors


def mesh_palettes(meshes: Sequence[trimesh.Trimesh]) -> list[np.ndarray]:
    """Per mesh, its vertex colours ``(N, 3)`` in 0..1 (a texture sampled at the vertices; ``(0, 3)`` for a
    mesh with neither)."""
    palettes = []
    for mesh in meshes:
        visual = mesh.visual
        if getattr(visual, "kind", None) == "texture":
            visual = visual.to_color()
        colors = np.asarray(visual.vertex_colors) if getattr(visual, "kind", None) == "vertex" else np.zeros((0, 4))
        palettes.append(colors[:, :3].astype(np.float64) / 255.0)
    return palettes


def occluder_pose(generator: np.random.Generator, target_centre: np.ndarray, target_radius: float,
                  occluder_radius: float, znear: float) -> np.ndarray | None:
    """``T_model2cam (4, 4)`` of a primitive (bounding radius ``occluder_radius``) on the way from
    the camera to an object (bounding sphere ``target_centre`` in the camera frame, ``target_radius``,
    metres): 50-80 % of the way, shifted sideways by up to 0.6 radius; ``None`` when it would come
    closer to the camera than ``2 * znear``."""
    fraction = generator.uniform(0.5, 0.8)
    offset = generator.uniform(-0.6, 0.6, size=2) * target_radius * fraction
    centre = target_centre * fraction + np.array([offset[0], offset[1], 0.0])
    if centre[2] - occluder_radius <= 2 * znear:
        return None
    rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
    return from_rotation_translation(rotation, centre)


def draw_polygon_occluders(crop: np.ndarray, generator: np.random.Generator, probability: float,
                           max_count: int, size: tuple[float, float], object_side: float) -> None:
    """With ``probability``, draws 1..``max_count`` flat-coloured random polygons (3-6 corners) over
    the outskirts of an object centred in ``crop`` ``(S, S, 3)`` uint8 (in place).

    Args:
        size: polygon diameter range as fractions of ``object_side`` (pixels).

    Larger, more central occluders were measured on the AAE demo and lowered its ADD(-S) recall
    (docs/experiments/2026-11-23-aae-demo-quick-config.md).
    """
    if generator.random() >= probability:
        return
    side = crop.shape[0]
    for _ in range(int(generator.integers(1, max_count + 1))):
        radius = 0.5 * generator.uniform(*size) * object_side
        angle = generator.uniform(0, 2 * np.pi)
        centre = side / 2 + generator.uniform(0.25, 0.6) * object_side * np.array([np.cos(angle), np.sin(angle)])
        count = int(generator.integers(3, 7))
        angles = np.sort(generator.uniform(0, 2 * np.pi, count))
        radii = radius * generator.uniform(0.5, 1.2, count)
        polygon = centre + np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1)
        cv2.fillPoly(crop, [np.round(polygon).astype(np.int32)], generator.uniform(0, 255, 3).tolist())


class PolygonOccluders(RandomProcessor):
    """:func:`draw_polygon_occluders` as a step: returns a copy of a crop ``(S, S, 3)`` uint8 of a
    centred object of side ``S / padding``, with ``probability`` covered by 1..``max_count`` polygons
    of diameter ``size`` × the object's side."""

    def __init__(self, probability: float = 0.5, max_count: int = 2, size: tuple[float, float] = (0.2, 0.5),
                 padding: float = 1.0, seed=None, name: str | None = None):
        super().__init__(seed, name)
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"probability: expected a probability in [0, 1], got {probability}")
        if int(max_count) < 1 or padding <= 0:
            raise ValueError(f"max_count/padding: expected >= 1 and > 0, got {max_count}, {padding}")
        self.probability, self.max_count, self.size, self.padding = probability, int(max_count), tuple(size), padding

    def call(self, crop: np.ndarray) -> np.ndarray:
        crop = crop.copy()
        draw_polygon_occluders(crop, self.generator, self.probability, self.max_count, self.size,
                               crop.shape[0] / self.padding)
        return crop
