"""Tabletop scenes: objects resting upright on a textured support plane, seen by a camera from above.

Real pose/detection benchmarks (LM-O, YCB-V, T-LESS) show objects standing on a table, all at about
the same distance, photographed from 30-80 degrees above the table, among other things. The floating
scenes of :mod:`paz6d.synthesis.scene` draw every object's distance and orientation independently;
:func:`sample_tabletop_scene` instead draws

* a camera on a sphere around a point of the table: distance in ``assets.distance`` (metres, camera
  to that point), elevation above the table plane in ``settings.elevation_degrees`` clipped to
  :data:`ELEVATION_LIMITS`, any azimuth, a roll of up to ``settings.inplane_degrees`` (at most
  :data:`MAX_ROLL_DEGREES`);
* the objects upright (model ``+z`` along the table normal, as BOP models of tabletop sets are
  stored), turned about the normal at random, resting on the plane (lowest hull point at height 0),
  fully inside the image and with their bounding spheres apart;
* distractor primitives resting on the table among them, and floating occluders in front of
  objects (:func:`paz6d.synthesis.scene.add_occluders`), as the floating scenes do;
* the table: a square plane of :data:`TABLE_SIDE` metres textured with a sharp photographic collage
  (:func:`paz6d.synthesis.photo_backgrounds.photo_collage`, :data:`TABLE_TEXTURE_PIXELS` pixels per side).

Frames: ``T_table2cam`` maps table coordinates (``z`` up, origin on the table) to the OpenCV camera.
"""

from __future__ import annotations

import numpy as np
import trimesh
from PIL import Image

from paz6d.backend import quaternion
from paz6d.backend.camera import project_points
from paz6d.backend.transform import from_rotation_translation
from paz6d.backend.viewpoints import in_plane_rotation, look_at_rotation
from paz6d.synthesis.photo_backgrounds import photo_collage
from paz6d.synthesis.sampling import PLACEMENT_ATTEMPTS, inside_image
from paz6d.synthesis.scene import Scene, SceneAssets, SceneSettings, add_occluders

#: Camera elevations above the table plane (degrees) a tabletop scene accepts.
ELEVATION_LIMITS = (15.0, 85.0)
MAX_ROLL_DEGREES = 30.0
#: Side of the table plane (metres) and of its texture (pixels: 2 mm per pixel, about one image pixel at 1 m).
TABLE_SIDE = 2.0
TABLE_TEXTURE_PIXELS = 1024
#: The table's collage: many small pieces (pieces per collage, piece side as a share of the texture's).
TABLE_PIECES = (20, 60)
TABLE_PIECE_SIZE = (0.03, 0.25)
#: Objects are placed within this distance (metres) of the point the camera looks at, in the plane.
PLACEMENT_RADIUS = 0.35


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray, roll_degrees: float = 0.0) -> np.ndarray:
    """``T_world2cam (4, 4)`` of an OpenCV camera at ``eye`` looking at ``target`` with image "up" as
    close to ``up`` as possible, then turned by ``roll_degrees`` about its optical axis."""
    forward = np.asarray(target, float) - np.asarray(eye, float)
    R_world2cam = in_plane_rotation(np.radians(roll_degrees)) @ look_at_rotation(forward / np.linalg.norm(forward), up)
    return from_rotation_translation(R_world2cam, -R_world2cam @ np.asarray(eye, float))


def table_mesh(generator: np.random.Generator, photographs: list[np.ndarray], side: float = TABLE_SIDE,
               texture_pixels: int = TABLE_TEXTURE_PIXELS) -> trimesh.Trimesh:
    """A ``side`` x ``side`` metres plane at height 0 (table frame, normal ``+z``) textured with a
    ``texture_pixels``² photographic collage of many small pieces (sharp, like a cluttered desk)."""
    texture = photo_collage(generator, photographs, texture_pixels, texture_pixels, pieces=TABLE_PIECES,
                            piece_size=TABLE_PIECE_SIZE)
    half = side / 2.0
    vertices = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    # the same factors as pyrender's default material of vertex-coloured meshes (the objects')
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(texture),
                                                   baseColorFactor=[255, 255, 255, 255],
                                                   metallicFactor=0.2, roughnessFactor=0.8)
    return trimesh.Trimesh(vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
                           process=False)


def _rest_on_table(rotation: np.ndarray, outline: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Translation (table frame) putting the rotated ``outline``'s lowest point on the plane at ``xy``."""
    lowest = float(np.min(outline @ rotation.T, axis=0)[2])
    return np.array([xy[0], xy[1], -lowest])


def _place_on_table(generator: np.random.Generator, rotation: np.ndarray, centre: np.ndarray, radius: float,
                    outline: np.ndarray, T_table2cam: np.ndarray, K: np.ndarray, width: int, height: int,
                    target: np.ndarray, placed: list[tuple[np.ndarray, float]]) -> np.ndarray | None:
    """``T_model2table (4, 4)`` of an object resting on the table near ``target``, inside the image and
    with its bounding sphere (``centre``, ``radius``) clear of ``placed`` (table frame; appended), or
    ``None`` after :data:`PLACEMENT_ATTEMPTS` tries."""
    for _ in range(PLACEMENT_ATTEMPTS):
        angle, distance = generator.uniform(0, 2 * np.pi), PLACEMENT_RADIUS * np.sqrt(generator.random())
        xy = target[:2] + distance * np.array([np.cos(angle), np.sin(angle)])
        T_model2table = from_rotation_translation(rotation, _rest_on_table(rotation, outline, xy))
        T_model2cam = T_table2cam @ T_model2table
        if not inside_image(project_points(outline @ T_model2cam[:3, :3].T + T_model2cam[:3, 3], K), width, height):
            continue
        centre_table = rotation @ centre + T_model2table[:3, 3]
        if all(np.linalg.norm(centre_table - other) >= radius + other_radius for other, other_radius in placed):
            placed.append((centre_table, radius))
            return T_model2table
    return None


def _yaw(generator: np.random.Generator) -> np.ndarray:
    angle = generator.uniform(0, 2 * np.pi)
    return np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])


def tabletop_camera(generator: np.random.Generator, settings: SceneSettings,
                    distance: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """``(T_table2cam (4, 4), target (3,))``: a camera above the table looking at ``target``, a point
    of the table near its centre (see the module docstring for the ranges)."""
    low = max(settings.elevation_degrees[0], ELEVATION_LIMITS[0])
    high = min(settings.elevation_degrees[1], ELEVATION_LIMITS[1])
    if low > high:
        raise ValueError(f"elevation_degrees: a tabletop camera needs elevations within {ELEVATION_LIMITS}, "
                         f"got {tuple(settings.elevation_degrees)}")
    elevation = np.radians(generator.uniform(low, high))
    azimuth = generator.uniform(0, 2 * np.pi)
    target = np.append(generator.uniform(-0.1, 0.1, 2), 0.0)
    eye = target + generator.uniform(*distance) * np.array([np.cos(elevation) * np.cos(azimuth),
                                                             np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    roll_limit = min(float(settings.inplane_degrees), MAX_ROLL_DEGREES)
    return look_at(eye, target, np.array([0.0, 0.0, 1.0]), generator.uniform(-roll_limit, roll_limit)), target


def sample_tabletop_scene(generator: np.random.Generator, assets: SceneAssets, settings: SceneSettings,
                          photographs: list[np.ndarray]) -> Scene:
    """One tabletop image's content (module docstring); the table is the scene's ``support``."""
    K = np.asarray(settings.K)
    width, height = settings.width, settings.height
    T_table2cam, target = tabletop_camera(generator, settings, assets.distance)
    count = int(generator.integers(settings.objects_per_image[0], settings.objects_per_image[1] + 1))
    candidates = generator.choice(len(assets.meshes), size=count, replace=count > len(assets.meshes))
    placed: list[tuple[np.ndarray, float]] = []
    object_indices, poses = [], []
    for index in candidates.tolist():
        T_model2table = _place_on_table(generator, _yaw(generator), assets.centres[index], assets.radii[index],
                                        assets.outlines[index], T_table2cam, K, width, height, target, placed)
        if T_model2table is not None:
            object_indices.append(index)
            poses.append(T_table2cam @ T_model2table)
    if not poses:  # the look-at point itself: the camera always sees it
        index = int(candidates[0])
        rotation = _yaw(generator)
        T_model2table = from_rotation_translation(rotation, _rest_on_table(rotation, assets.outlines[index], target))
        object_indices.append(index)
        poses.append(T_table2cam @ T_model2table)
    clutter_indices, clutter_poses = [], []
    if assets.distractors:
        for _ in range(int(generator.integers(0, settings.distractors + 1))):
            choice = int(generator.integers(len(assets.distractors)))
            rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
            T_model2table = _place_on_table(generator, rotation, np.zeros(3), assets.distractor_radii[choice],
                                            assets.distractor_outlines[choice], T_table2cam, K, width, height,
                                            target, placed)
            if T_model2table is not None:
                clutter_indices.append(choice)
                clutter_poses.append(T_table2cam @ T_model2table)
        add_occluders(generator, assets, settings, object_indices, poses, clutter_indices, clutter_poses)
    return Scene(object_indices, np.array(poses), clutter_indices, np.array(clutter_poses).reshape(-1, 4, 4),
                 support=(table_mesh(generator, photographs), T_table2cam))
