"""Photo-textured 3D distractors: primitives (boxes, cylinders, spheres, capsules, cones, tori) whose
surface carries crops of photographs, as the real clutter around tabletop objects does (boxes with
print, toys, mugs, books).

The renderer shades vertex colours, so a texture is baked into a densely subdivided mesh: every
vertex takes the colour of a photo crop at its tri-planar coordinate (the two model coordinates
across its dominant normal axis, so each face of a box shows an undistorted piece of the photo).
Edges are at most :data:`TEXELS_PER_SIDE`-th of the shape's size, so a distractor 100 px wide shows
the photo at about 2-3 px per texel.
"""

from __future__ import annotations

import numpy as np
import trimesh
from trimesh import remesh

from paz6d.synthesis.photo_backgrounds import photo_collage

#: Vertices along a shape's largest side (the baked texture's resolution).
TEXELS_PER_SIDE = 32
#: Shape sizes relative to the ``size`` passed to :func:`textured_distractor_library`.
SIZE_FACTORS = (0.3, 0.6, 1.0)


def primitive_shapes(side: float) -> list[trimesh.Trimesh]:
    """Six primitives of largest extent about ``side`` metres, centred at the origin: a flat box,
    a cylinder, a sphere, a capsule, a cone and a torus."""
    return [trimesh.creation.box((side, 0.6 * side, 0.4 * side)),
            trimesh.creation.cylinder(radius=0.3 * side, height=side, sections=32),
            trimesh.creation.icosphere(subdivisions=2, radius=0.45 * side),
            trimesh.creation.capsule(height=0.6 * side, radius=0.2 * side, count=(16, 16)),
            trimesh.creation.cone(radius=0.35 * side, height=0.8 * side, sections=32).apply_translation(
                (0.0, 0.0, -0.4 * side)),
            trimesh.creation.torus(major_radius=0.35 * side, minor_radius=0.12 * side, major_sections=32,
                                   minor_sections=16)]


def bake_texture(mesh: trimesh.Trimesh, texture: np.ndarray) -> trimesh.Trimesh:
    """A copy of ``mesh`` (metres), subdivided to edges of at most 1/:data:`TEXELS_PER_SIDE` of its
    largest extent, with vertex colours sampled (nearest texel) from ``texture`` ``(T, T, 3)`` uint8 by tri-planar
    projection (coordinates across each vertex's dominant normal axis, spanning the texture once
    over the shape's largest extent)."""
    texture = np.asarray(texture)
    if texture.ndim != 3 or texture.shape[2] != 3 or texture.dtype != np.uint8:
        raise ValueError(f"texture: expected a (T, T, 3) uint8 image, got {texture.shape} {texture.dtype}")
    extent = float(mesh.extents.max())
    if not np.isfinite(extent) or extent <= 0:
        raise ValueError(f"mesh: expected a positive extent, got {extent}")
    vertices, faces = remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=extent / TEXELS_PER_SIDE,
                                               max_iter=20)
    dense = trimesh.Trimesh(vertices, faces, process=True)
    normals = np.abs(dense.vertex_normals)
    axis = np.argmax(normals, axis=1)
    # Plane coordinates across the dominant axis: (y, z) for x, (x, z) for y, (x, y) for z.
    first = np.where(axis == 0, 1, 0)
    second = np.where(axis == 2, 1, 2)
    rows = np.arange(len(dense.vertices))
    low = dense.vertices.min(axis=0)
    uv = np.stack([dense.vertices[rows, first] - low[first], dense.vertices[rows, second] - low[second]], axis=1)
    side_y, side_x = texture.shape[:2]
    x = np.clip(np.round(uv[:, 0] / extent * (side_x - 1)), 0, side_x - 1).astype(np.int64)
    y = np.clip(np.round(uv[:, 1] / extent * (side_y - 1)), 0, side_y - 1).astype(np.int64)
    colours = texture[y, x]
    dense.visual.vertex_colors = np.column_stack([colours, np.full(len(colours), 255, np.uint8)])
    return dense


def textured_distractor_library(size: float, photographs: list[np.ndarray], textures_per_shape: int = 2,
                                seed: int = 0) -> list[trimesh.Trimesh]:
    """Every shape of :func:`primitive_shapes` at the :data:`SIZE_FACTORS` of ``size`` (metres), each
    baked with ``textures_per_shape`` photographic collages of the ``photographs`` (fixed by ``seed``,
    so all workers of a run hold the same library): ``6 * 3 * textures_per_shape`` meshes."""
    if int(textures_per_shape) < 1:
        raise ValueError(f"textures_per_shape: expected >= 1, got {textures_per_shape}")
    if not np.isfinite(size) or size <= 0:
        raise ValueError(f"size: expected a positive size in metres, got {size}")
    generator = np.random.default_rng(np.random.SeedSequence([seed, 0x7E47]))
    library = []
    for factor in SIZE_FACTORS:
        for shape in primitive_shapes(size * factor):
            for _ in range(int(textures_per_shape)):
                texture = photo_collage(generator, photographs, 2 * TEXELS_PER_SIDE, 2 * TEXELS_PER_SIDE,
                                        pieces=(0, 4))
                library.append(bake_texture(shape, texture))
    return library
