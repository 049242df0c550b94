"""One image's content: which objects, where and in which orientation, plus distractors and an
occluder. Every draw comes from the ``numpy.random.Generator`` passed in, so a scene depends only on
the image's seed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from paz6d.backend import quaternion
from paz6d.backend.camera import unproject
from paz6d.backend.transform import from_rotation_translation
from paz6d.synthesis.occluders import occluder_pose
from paz6d.synthesis.sampling import place_object, random_rotation

#: Camera near plane (metres) of the scene renderers; occluders stay beyond twice this.
ZNEAR = 0.01


class SceneSettings(Protocol):
    """What :func:`sample_scene` reads from a configuration (e.g. ``data_gen.config.GenerationConfig``)."""

    K: list[list[float]]
    width: int
    height: int
    objects_per_image: tuple[int, int]
    rotation: str
    elevation_degrees: tuple[float, float]
    inplane_degrees: float
    distractors: int
    occluder_probability: float
    occluders: int
    cluster: float


class SceneAssets(Protocol):
    """What :func:`sample_scene` reads from the loaded meshes (e.g. ``data_gen.assets.Assets``):
    per object mesh its bounding sphere (``centres (M, 3)``, ``radii (M,)``) and hull ``outlines``;
    per distractor its radius (centred at the origin) and outline; the distance range (metres)."""

    meshes: list
    centres: np.ndarray
    radii: np.ndarray
    outlines: list[np.ndarray]
    distractors: list
    distractor_radii: np.ndarray
    distractor_outlines: list[np.ndarray]
    distance: tuple[float, float]


@dataclass
class Scene:
    """One image's content.

    Attributes:
        object_indices: index into ``assets.meshes`` of each annotated object.
        T_model2cam: ``(N, 4, 4)`` poses of the annotated objects (metres, OpenCV).
        clutter_indices: index into ``assets.distractors`` of each distractor/occluder.
        clutter_T_model2cam: ``(C, 4, 4)`` their poses (metres, OpenCV).
        support: ``(mesh, T_model2cam)`` of a surface the objects rest on (a tabletop scene's table,
            :mod:`paz6d.synthesis.tabletop`), rendered untinted and unannotated; ``None`` for floating scenes.
    """

    object_indices: list[int]
    T_model2cam: np.ndarray
    clutter_indices: list[int]
    clutter_T_model2cam: np.ndarray
    support: tuple | None = None


def add_occluders(generator: np.random.Generator, assets: SceneAssets, settings: SceneSettings,
                  object_indices: list[int], poses: list[np.ndarray], clutter_indices: list[int],
                  clutter_poses: list[np.ndarray]) -> None:
    """``settings.occluders`` times, with ``occluder_probability``, puts a random distractor between
    the camera and a random object (``poses``: ``T_model2cam`` of ``object_indices``); appends to
    ``clutter_indices`` / ``clutter_poses`` in place. Two occluders may hide the same object."""
    for _ in range(settings.occluders):
        if generator.random() >= settings.occluder_probability:
            continue
        target = int(generator.integers(len(poses)))
        choice = int(generator.integers(len(assets.distractors)))
        target_centre = poses[target][:3, :3] @ assets.centres[object_indices[target]] + poses[target][:3, 3]
        pose = occluder_pose(generator, target_centre, assets.radii[object_indices[target]],
                             assets.distractor_radii[choice], ZNEAR)
        if pose is not None:
            clutter_indices.append(choice)
            clutter_poses.append(pose)


def sample_scene(generator: np.random.Generator, assets: SceneAssets, settings: SceneSettings) -> Scene:
    """Draws the objects (fully inside the image, bounding spheres apart; with ``settings.cluster``, often
    next to each other in the image so that they hide each other), distractors and occluders
    (:func:`add_occluders`)."""
    K = np.asarray(settings.K)
    width, height = settings.width, settings.height
    count = int(generator.integers(settings.objects_per_image[0], settings.objects_per_image[1] + 1))
    candidates = generator.choice(len(assets.meshes), size=count, replace=count > len(assets.meshes))
    placed: list[tuple[np.ndarray, float]] = []
    object_indices, poses = [], []
    for index in candidates.tolist():
        rotation = random_rotation(generator, settings.rotation, settings.elevation_degrees, settings.inplane_degrees)
        translation = place_object(generator, rotation, assets.centres[index], assets.radii[index],
                                   assets.outlines[index], K, width, height, assets.distance, placed,
                                   settings.cluster)
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
        for _ in range(int(generator.integers(0, settings.distractors + 1))):
            choice = int(generator.integers(len(assets.distractors)))
            rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
            translation = place_object(generator, rotation, np.zeros(3), assets.distractor_radii[choice],
                                       assets.distractor_outlines[choice], K, width, height, assets.distance, placed,
                                       settings.cluster)
            if translation is not None:
                clutter_indices.append(choice)
                clutter_poses.append(from_rotation_translation(rotation, translation))
        add_occluders(generator, assets, settings, object_indices, poses, clutter_indices, clutter_poses)
    return Scene(object_indices, np.array(poses), clutter_indices, np.array(clutter_poses).reshape(-1, 4, 4))
