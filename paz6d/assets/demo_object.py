"""The demo object: an asymmetric, procedurally coloured composite of boxes and a cylinder (and its
half-turn symmetric sibling, :func:`make_symmetric_demo_mesh`).

Built in code (no binary asset to ship): a body box with a cylindrical handle on one side, a
small block on top near one corner and a wedge-like fin at the back, so no rotation maps the
object onto itself. Every side of every part has its own colour and the body carries darker stripes,
which gives the texture cues the Augmented Autoencoder needs to tell near-symmetric views apart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from paz6d.backend.mesh import diameter
from paz6d.datasets.bop.writer import write_models

OBJECT_ID = 1
#: RGB per side (-x, +x, -y, +y, -z, +z) of each part: every side of the body differs.
_PALETTES = {
    "body": np.array([[200, 40, 40], [40, 160, 60], [230, 200, 40], [40, 80, 200], [240, 240, 235], [150, 60, 170]]),
    "handle": np.array([[60, 200, 220]] * 6),
    "block": np.array([[250, 140, 20], [250, 140, 20], [90, 50, 30], [90, 50, 30], [250, 140, 20], [30, 30, 30]]),
    "fin": np.array([[120, 120, 120], [120, 120, 120], [240, 90, 160], [20, 110, 110], [240, 90, 160], [240, 90, 160]]),
}


def _coloured_part(mesh: trimesh.Trimesh, palette: np.ndarray, cell: float) -> trimesh.Trimesh:
    """Subdivides ``mesh`` to edges <= ``cell`` metres and colours each face by the side it faces
    (``palette`` row per side: -x, +x, -y, +y, -z, +z) with a band of darker stripes along x;
    faces are unmerged so colours stay per face."""
    vertices, faces = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=cell)
    part = trimesh.Trimesh(vertices, faces, process=False)
    normals = part.face_normals
    axis = np.argmax(np.abs(normals), axis=1)
    side = axis * 2 + (normals[np.arange(len(normals)), axis] > 0)
    stripe = (np.floor(part.triangles_center[:, 0] / cell).astype(int) % 3 == 0) & (axis != 0)
    rgb = palette[side] * np.where(stripe, 0.55, 1.0)[:, None]
    face_colors = np.concatenate([np.round(rgb), np.full((len(rgb), 1), 255)], axis=1).astype(np.uint8)
    part = trimesh.Trimesh(part.vertices[part.faces].reshape(-1, 3), np.arange(3 * len(part.faces)).reshape(-1, 3),
                           process=False)
    part.visual.vertex_colors = np.repeat(face_colors, 3, axis=0)
    return part


def make_demo_mesh() -> trimesh.Trimesh:
    """The demo object in metres (about 0.12 m diameter), origin near its centre, vertex coloured."""
    body = trimesh.creation.box(extents=(0.08, 0.05, 0.04))
    handle = trimesh.creation.cylinder(radius=0.011, height=0.05, sections=16)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    handle.apply_translation((0.05, 0.0, -0.005))
    block = trimesh.creation.box(extents=(0.025, 0.02, 0.025))
    block.apply_translation((-0.022, 0.012, 0.032))
    fin = trimesh.creation.box(extents=(0.05, 0.006, 0.02))
    fin.apply_transform(trimesh.transformations.rotation_matrix(0.5, (0, 1, 0)))
    fin.apply_translation((-0.01, -0.028, 0.01))
    parts = [_coloured_part(mesh, _PALETTES[name], 0.012) for mesh, name in
             ((body, "body"), (handle, "handle"), (block, "block"), (fin, "fin"))]
    merged = trimesh.util.concatenate(parts)
    merged.apply_translation(-merged.bounds.mean(axis=0))
    return merged


def write_demo_object(directory: str | Path) -> Path:
    """Writes ``obj_000001.ply`` (millimetres, BOP convention) and ``models_info.json`` into
    ``directory`` with the BOP writer; returns the PLY path. Files are written atomically."""
    mesh = make_demo_mesh()
    ply, _ = write_models(directory, [mesh], [OBJECT_ID], [diameter(mesh.vertices)], units="m")
    return ply


#: RGB per side (-x, +x, -y, +y, -z, +z) of the parts of one half of the symmetric object.
_SYMMETRIC_PALETTES = {
    "body": np.array([[120, 30, 30], [200, 40, 40], [40, 80, 200], [40, 80, 200], [240, 240, 235], [230, 200, 40]]),
    "handle": np.array([[60, 200, 220]] * 6),
    "block": np.array([[250, 140, 20], [250, 140, 20], [90, 50, 30], [90, 50, 30], [250, 140, 20], [30, 30, 30]]),
}
#: The symmetric object's one symmetry: a half turn about its z axis (BOP ``symmetries_discrete``).
HALF_TURN_Z = np.diag([-1.0, -1.0, 1.0, 1.0])


def make_symmetric_demo_mesh() -> trimesh.Trimesh:
    """A demo object whose only symmetry is a half turn about z (:data:`HALF_TURN_Z`), in metres (about
    0.13 m diameter), vertex coloured: a body box with a handle at each end and two blocks on top at
    opposite corners; top and bottom differ, so no other rotation maps it onto itself.

    One half (x > 0: half the body, a handle, a block) is built and coloured, then joined with its copy
    turned by :data:`HALF_TURN_Z`, so geometry and colours are exactly symmetric."""
    body = trimesh.creation.box(extents=(0.04, 0.05, 0.04))
    body.apply_translation((0.02, 0.0, 0.0))
    handle = trimesh.creation.cylinder(radius=0.011, height=0.05, sections=16)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    handle.apply_translation((0.05, 0.0, -0.005))
    block = trimesh.creation.box(extents=(0.025, 0.02, 0.025))
    block.apply_translation((0.022, 0.012, 0.032))
    half = trimesh.util.concatenate([_coloured_part(mesh, _SYMMETRIC_PALETTES[name], 0.012) for mesh, name in
                                     ((body, "body"), (handle, "handle"), (block, "block"))])
    turned = half.copy()
    turned.apply_transform(HALF_TURN_Z)
    merged = trimesh.util.concatenate([half, turned])
    low, high = merged.bounds
    merged.apply_translation((0.0, 0.0, -0.5 * (low[2] + high[2])))  # centred; x and y already are
    return merged


def write_symmetric_demo_object(directory: str | Path) -> Path:
    """Writes :func:`make_symmetric_demo_mesh` as ``obj_000001.ply`` (millimetres) and ``models_info.json``
    with its ``symmetries_discrete`` into ``directory``; returns the PLY path."""
    mesh = make_symmetric_demo_mesh()
    extra = {OBJECT_ID: {"symmetries_discrete": [HALF_TURN_Z.ravel().tolist()]}}
    ply, _ = write_models(directory, [mesh], [OBJECT_ID], [diameter(mesh.vertices)], extra_fields=extra, units="m")
    return ply
