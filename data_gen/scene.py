"""Random scenes: which objects, where, in which orientation; distractors and occluders.

Every draw comes from the ``numpy.random.Generator`` passed in, so a scene depends only on the
image's seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_gen.assets import ZNEAR, Assets
from data_gen.config import GenerationConfig
from paz6d.backend import quaternion
from paz6d.backend.camera import project_points, unproject
from paz6d.backend.transform import from_rotation_translation

PLACEMENT_ATTEMPTS = 30


@dataclass
class Scene:
    """One image's content.

    Attributes:
        object_indices: index into ``Assets.meshes`` of each annotated object.
        poses: ``(N, 4, 4)`` ``T_model2cam`` of the annotated objects (metres, OpenCV).
        clutter_indices: index into ``Assets.distractors`` of each distractor/occluder.
        clutter_poses: ``(C, 4, 4)`` their poses.
    """

    object_indices: list[int]
    poses: np.ndarray
    clutter_indices: list[int]
    clutter_poses: np.ndarray


def random_rotation(generator: np.random.Generator, config: GenerationConfig) -> np.ndarray:
    """``R_model2cam`` ``(3, 3)``: uniform on SO(3), or a view-sphere viewpoint + in-plane angle."""
    if config.rotation == "so3":
        return quaternion.to_rotation_matrix(quaternion.random(seed=generator))
    low, high = np.radians(config.elevation_degrees)
    # Uniform on the spherical band between the two elevations.
    elevation = np.arcsin(generator.uniform(np.sin(low), np.sin(high)))
    azimuth = generator.uniform(0.0, 2 * np.pi)
    inplane = np.radians(generator.uniform(-config.inplane_degrees, config.inplane_degrees))
    # Camera position (model frame) on the unit sphere; the camera looks at the model origin.
    eye = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    z_axis = -eye
    up = np.array([0.0, 0.0, 1.0]) if abs(eye[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    x_axis = np.cross(z_axis, up)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    R_cam2model = np.stack([x_axis, y_axis, z_axis], axis=1)
    cosine, sine = np.cos(inplane), np.sin(inplane)
    R_inplane = np.array([[cosine, -sine, 0.0], [sine, cosine, 0.0], [0.0, 0.0, 1.0]])
    return R_inplane @ R_cam2model.T


def _inside_image(pixels: np.ndarray, width: int, height: int) -> bool:
    return bool(np.all(np.isfinite(pixels)) and np.all(pixels >= -0.5)
                and np.all(pixels[:, 0] <= width - 0.5) and np.all(pixels[:, 1] <= height - 0.5))


def _place(generator, rotation, centre, radius, outline, K, config, distance, placed) -> np.ndarray | None:
    """Translation putting the object (bounding sphere ``centre``/``radius``, model frame) fully in
    the image at a random distance without intersecting ``placed`` spheres; ``None`` if no luck."""
    width, height = config.width, config.height
    for _ in range(PLACEMENT_ATTEMPTS):
        z = generator.uniform(*distance)
        margin = min(K[0, 0], K[1, 1]) * radius / (z - radius)
        u = generator.uniform(min(margin - 0.5, K[0, 2]), max(width - 0.5 - margin, K[0, 2]))
        v = generator.uniform(min(margin - 0.5, K[1, 2]), max(height - 0.5 - margin, K[1, 2]))
        centre_cam = unproject(np.array([[u, v]]), np.array([z]), K)[0]
        translation = centre_cam - rotation @ centre
        if not _inside_image(project_points(outline @ rotation.T + translation, K), width, height):
            continue
        if all(np.linalg.norm(centre_cam - other) >= radius + other_radius for other, other_radius in placed):
            placed.append((centre_cam, radius))
            return translation
    return None


def sample_scene(generator: np.random.Generator, assets: Assets, config: GenerationConfig) -> Scene:
    """Draws the objects, poses, distractors and occluders of one image."""
    K = np.asarray(config.K)
    count = int(generator.integers(config.objects_per_image[0], config.objects_per_image[1] + 1))
    candidates = generator.choice(len(assets.meshes), size=count, replace=count > len(assets.meshes))
    placed: list[tuple[np.ndarray, float]] = []
    object_indices, poses = [], []
    for index in candidates.tolist():
        rotation = random_rotation(generator, config)
        outline = assets.outlines[index]
        translation = _place(generator, rotation, assets.centres[index], assets.radii[index], outline, K, config,
                             assets.distance, placed)
        if translation is None and not object_indices:
            # The first object always fits at the principal point (the distance range ensures it).
            centre_cam = unproject(K[:2, 2][None], np.array([generator.uniform(*assets.distance)]), K)[0]
            translation = centre_cam - rotation @ assets.centres[index]
            placed.append((centre_cam, assets.radii[index]))
        if translation is not None:
            object_indices.append(index)
            poses.append(from_rotation_translation(rotation, translation))
    clutter_indices, clutter_poses = [], []
    if assets.distractors:
        for _ in range(int(generator.integers(0, config.distractors + 1))):
            choice = int(generator.integers(len(assets.distractors)))
            rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
            outline = assets.distractor_outlines[choice]
            translation = _place(generator, rotation, np.zeros(3), assets.distractor_radii[choice], outline, K,
                                 config, assets.distance, placed)
            if translation is not None:
                clutter_indices.append(choice)
                clutter_poses.append(from_rotation_translation(rotation, translation))
        if generator.random() < config.occluder_probability:
            target = int(generator.integers(len(poses)))
            choice = int(generator.integers(len(assets.distractors)))
            target_centre = poses[target][:3, :3] @ assets.centres[object_indices[target]] + poses[target][:3, 3]
            fraction = generator.uniform(0.5, 0.8)
            offset = generator.uniform(-0.6, 0.6, size=2) * assets.radii[object_indices[target]] * fraction
            centre = target_centre * fraction + np.array([offset[0], offset[1], 0.0])
            if centre[2] - assets.distractor_radii[choice] > 2 * ZNEAR:
                rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
                clutter_indices.append(choice)
                clutter_poses.append(from_rotation_translation(rotation, centre))
    return Scene(object_indices, np.array(poses), clutter_indices,
                 np.array(clutter_poses).reshape(-1, 4, 4))
