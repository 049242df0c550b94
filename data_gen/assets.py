"""Everything a generator loads once: meshes (metres), object ids, sizes, distractors, backgrounds."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import trimesh

from data_gen.config import GenerationConfig, list_backgrounds
from paz6d.backend.files import load_json
from paz6d.backend.mesh import MeshError, diameter, load_mesh
from paz6d.datasets.bop.models import parse_symmetries
from paz6d.datasets.bop.units import MM_PER_M
from paz6d.synthesis.household import household_library
from paz6d.synthesis.mesh_distractors import textured_distractor_library
from paz6d.synthesis.occluders import distractor_library
from paz6d.synthesis.photo_backgrounds import sample_photographs
from paz6d.synthesis.sampling import hull_points
from paz6d.synthesis.scene import ZNEAR
_OBJECT_ID = re.compile(r"^obj_(\d+)$")
_SYMMETRY_FIELDS = ("symmetries_discrete", "symmetries_continuous")


@dataclass
class Assets:
    """Loaded inputs of a run.

    Attributes:
        meshes: annotated object meshes in metres.
        object_ids: BOP object id of each mesh.
        centres: ``(M, 3)`` bounding-box centres of the meshes (model frame, metres).
        radii: ``(M,)`` radius of the bounding sphere about ``centres`` (metres).
        diameters: ``(M,)`` largest vertex distance (metres).
        outlines: convex-hull vertices of each mesh (a mesh is inside the image iff they are).
        distractors: unannotated primitives (white vertex colours, tinted by a random colour when rendered)
            and, with ``distractor_style="textured"``, photo-textured ones (colour-jittered when rendered).
        distractor_tinted: ``(D,)`` bool, whether each distractor is a white primitive to tint.
        distractor_radii: their bounding-sphere radii (metres, centred at the origin).
        distractor_outlines: their convex-hull vertices.
        backgrounds: background image files (empty: procedural backgrounds).
        distance: ``(min, max)`` distance range (metres) in which every object fits the image.
        symmetries: ``{obj_id: {field: value}}`` for ``models_info.json``.
    """

    meshes: list[trimesh.Trimesh]
    object_ids: list[int]
    centres: np.ndarray
    radii: np.ndarray
    diameters: np.ndarray
    outlines: list[np.ndarray]
    distractors: list[trimesh.Trimesh]
    distractor_tinted: np.ndarray
    distractor_radii: np.ndarray
    distractor_outlines: list[np.ndarray]
    backgrounds: list[Path]
    distance: tuple[float, float]
    symmetries: dict[int, dict]


def object_ids_for(paths) -> list[int]:
    """Ids from ``obj_XXXXXX`` stems when all files are named so (and distinct), else 1..M."""
    matches = [_OBJECT_ID.match(Path(path).stem) for path in paths]
    if all(matches):
        ids = [int(match.group(1)) for match in matches]
        if len(set(ids)) == len(ids) and min(ids) > 0:
            return ids
    return list(range(1, len(paths) + 1))


def _load_meshes(config: GenerationConfig) -> list[trimesh.Trimesh]:
    meshes = []
    for path in config.meshes:
        try:
            mesh = load_mesh(path, scale=config.mesh_scale)
        except MeshError as error:
            raise ValueError(f"mesh: {error}") from error
        if mesh.area <= 0:
            raise ValueError(f"mesh: {path}: all triangles are degenerate (zero surface area)")
        meshes.append(mesh)
    return meshes


def _projected_radius_px(radius: float, distance: float, focal: float) -> float:
    """Pixel radius of the image of a sphere of ``radius`` centred on the optical axis at ``distance``."""
    return focal * radius / math.sqrt(distance ** 2 - radius ** 2)


def _distance_range(config: GenerationConfig, radii: np.ndarray, diameters: np.ndarray) -> tuple[float, float]:
    K = np.asarray(config.K)
    focal = min(K[0, 0], K[1, 1])
    half_side = min(K[0, 2] + 0.5, config.width - K[0, 2] - 0.5, K[1, 2] + 0.5, config.height - K[1, 2] - 0.5)
    shorter = min(config.width, config.height)
    largest, largest_radius = float(diameters.max()), float(radii.max())
    if config.distance is None:
        low, high = focal * largest / (0.6 * shorter), focal * largest / (0.15 * shorter)
    else:
        low, high = config.distance
    if low <= largest_radius + ZNEAR:
        raise ValueError(f"distance: minimum {low:.4g} m puts the camera inside the largest object "
                         f"(bounding-sphere radius {largest_radius:.4g} m); use a minimum above "
                         f"{largest_radius + ZNEAR:.4g} m (or check --mesh-scale: meshes in mm need 0.001)")
    if half_side <= 0 or _projected_radius_px(largest_radius, high, focal) >= half_side:
        raise ValueError(f"distance: even at the maximum {high:.4g} m the largest object (radius "
                         f"{largest_radius:.4g} m) does not fit in the {config.width}x{config.height} image; "
                         "increase the distance range (or check --mesh-scale)")
    deepest = (high + largest_radius) * MM_PER_M / config.depth_scale
    if deepest > 65535:
        raise ValueError(f"depth_scale: {config.depth_scale} mm per unit cannot store depths up to "
                         f"{high + largest_radius:.3g} m in 16-bit PNGs; use at least "
                         f"{(high + largest_radius) * MM_PER_M / 65535:.3g}")
    # Smallest distance at which the largest object fits inside the image.
    fits = largest_radius * math.sqrt(1 + (focal / half_side) ** 2)
    return max(low, fits * 1.0001), high


def _load_symmetries(path: Path | None, object_ids: list[int]) -> dict[int, dict]:
    if path is None:
        return {}
    path = Path(path)
    try:
        data = load_json(path)
    except ValueError as error:
        raise ValueError(f"symmetries: {error}") from error
    if not isinstance(data, dict):
        raise ValueError(f"symmetries: {path}: expected an object keyed by object id")
    symmetries = {}
    for key, fields in data.items():
        if not str(key).isdigit() or int(key) not in object_ids:
            raise ValueError(f"symmetries: {path}: key {key!r} is not one of the object ids {object_ids}")
        if not isinstance(fields, dict) or set(fields) - set(_SYMMETRY_FIELDS):
            raise ValueError(f"symmetries: {path}: object {key}: expected only fields {_SYMMETRY_FIELDS}")
        parse_symmetries(fields, f"symmetries: {path}: object {key}", units="mm")  # well-formed, as BOP reads them
        symmetries[int(key)] = fields
    return symmetries


def check_backgrounds(folder: Path) -> list[Path]:
    """Background files, each checked to have a format OpenCV can read."""
    files = list_backgrounds(folder)
    for path in files:
        if not cv2.haveImageReader(str(path)):
            raise ValueError(f"backgrounds: {path} is not an image OpenCV can read")
    return files


def load_assets(config: GenerationConfig) -> Assets:
    """Loads and checks all inputs; raises ``ValueError`` naming the file/field on bad input."""
    meshes = _load_meshes(config)
    object_ids = object_ids_for(config.meshes)
    centres = np.array([mesh.bounds.mean(axis=0) for mesh in meshes])
    radii = np.array([np.linalg.norm(mesh.vertices - centre, axis=1).max() for mesh, centre in zip(meshes, centres)])
    diameters = np.array([diameter(mesh.vertices) for mesh in meshes])
    distractors, textured = [], []
    if config.distractors or (config.occluder_probability > 0 and config.occluders > 0):
        size = float(np.mean(diameters))  # the distractors' scale: the meshes' mean diameter (metres)
        distractors = distractor_library(size)
        if config.distractor_style == "household":
            distractors += household_library(size)
        if config.distractor_style == "textured":
            textured = textured_distractor_library(size, sample_photographs(), seed=config.seed)
    distractor_tinted = np.array([True] * len(distractors) + [False] * len(textured), dtype=bool)
    distractors = distractors + textured
    distractor_radii = np.array([np.linalg.norm(mesh.vertices, axis=1).max() for mesh in distractors])
    backgrounds = check_backgrounds(config.backgrounds) if config.backgrounds is not None else []
    return Assets(meshes, object_ids, centres, radii, diameters, [hull_points(mesh.vertices) for mesh in meshes],
                  distractors, distractor_tinted, distractor_radii,
                  [hull_points(mesh.vertices) for mesh in distractors], backgrounds,
                  _distance_range(config, radii, diameters), _load_symmetries(config.symmetries, object_ids))
