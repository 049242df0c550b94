"""Random object and camera poses: rotations, placement of an object inside the image, hulls.

All draws come from the ``numpy.random.Generator`` passed in (metres, OpenCV camera frame,
``T_model2cam``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from paz6d.backend import quaternion
from paz6d.backend.camera import Camera, project_points, unproject
from paz6d.backend.viewpoints import POLE_SINE, in_plane_rotation, look_at_rotation

ROTATION_MODES = ("so3", "view-sphere")
#: Tries of :func:`place_object` before it gives up.
PLACEMENT_ATTEMPTS = 30


def hull_points(vertices: np.ndarray) -> np.ndarray:
    """Vertices ``(M, 3)`` of the convex hull of ``vertices`` ``(N, 3)`` (all of them when the hull is
    degenerate): an object is inside the image iff they are, and they give its projected box."""
    vertices = np.asarray(vertices)
    try:
        return vertices[ConvexHull(vertices).vertices]
    except QhullError:
        return vertices


def random_rotation(generator: np.random.Generator, mode: str = "so3",
                    elevation_degrees: tuple[float, float] = (-90.0, 90.0),
                    inplane_degrees: float = 180.0) -> np.ndarray:
    """``R_model2cam`` ``(3, 3)``: uniform on SO(3) (``mode="so3"``), or (``"view-sphere"``) a
    viewpoint uniform on the spherical band between the two elevations (degrees) looking at the
    model origin, turned in-plane by up to ``±inplane_degrees``."""
    if mode == "so3":
        return quaternion.to_rotation_matrix(quaternion.random(seed=generator))
    if mode != "view-sphere":
        raise ValueError(f"mode: expected one of {ROTATION_MODES}, got {mode!r}")
    low, high = np.radians(elevation_degrees)
    elevation = np.arcsin(generator.uniform(np.sin(low), np.sin(high)))
    azimuth = generator.uniform(0.0, 2 * np.pi)
    inplane = np.radians(generator.uniform(-inplane_degrees, inplane_degrees))
    # Camera position (model frame) on the unit sphere; the camera looks at the model origin.
    eye = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    up = np.array([0.0, 0.0, 1.0]) if abs(eye[2]) < POLE_SINE else np.array([0.0, 1.0, 0.0])
    return in_plane_rotation(inplane) @ look_at_rotation(-eye, up)


def inside_image(pixels: np.ndarray, width: int, height: int) -> bool:
    """Whether all ``(N, 2)`` pixel-centre coordinates are finite and inside a ``width × height`` image."""
    return bool(np.all(np.isfinite(pixels)) and np.all(pixels >= -0.5)
                and np.all(pixels[:, 0] <= width - 0.5) and np.all(pixels[:, 1] <= height - 0.5))


#: Image distance of a clustered object's centre from its neighbour's, in their summed projected radii.
CLUSTER_SPACING = (0.2, 0.9)


def place_object(generator: np.random.Generator, rotation: np.ndarray, centre: np.ndarray, radius: float,
                 outline: np.ndarray, K: np.ndarray, width: int, height: int, distance: tuple[float, float],
                 placed: list[tuple[np.ndarray, float]], cluster: float = 0.0) -> np.ndarray | None:
    """Translation ``(3,)`` putting an object fully inside the image at a random depth in
    ``distance`` (metres) without intersecting the ``placed`` bounding spheres.

    Args:
        rotation: ``R_model2cam (3, 3)``.
        centre / radius: bounding sphere in the model frame (metres).
        outline: ``(M, 3)`` hull vertices (:func:`hull_points`) that must project inside the image.
        placed: ``(centre_cam, radius)`` of the objects already placed; the new one is appended.
        cluster: chance (per try) that the object's image centre is drawn next to a random placed
            object's (:data:`CLUSTER_SPACING` of their summed projected radii away), so that the two
            overlap in the image and the nearer one hides part of the other; 0 draws nothing for it.

    Returns:
        The translation, or ``None`` after :data:`PLACEMENT_ATTEMPTS` failed tries.
    """
    focal = min(K[0, 0], K[1, 1])
    for _ in range(PLACEMENT_ATTEMPTS):
        z = generator.uniform(*distance)
        margin = focal * radius / (z - radius)
        if cluster > 0 and placed and generator.random() < cluster:
            other, other_radius = placed[int(generator.integers(len(placed)))]
            (u0, v0), = project_points(other[None], K)
            spacing = generator.uniform(*CLUSTER_SPACING) * (margin + focal * other_radius / other[2])
            angle = generator.uniform(0.0, 2 * np.pi)
            u, v = u0 + spacing * np.cos(angle), v0 + spacing * np.sin(angle)
        else:
            u = generator.uniform(min(margin - 0.5, K[0, 2]), max(width - 0.5 - margin, K[0, 2]))
            v = generator.uniform(min(margin - 0.5, K[1, 2]), max(height - 0.5 - margin, K[1, 2]))
        centre_cam = unproject(np.array([[u, v]]), np.array([z]), K)[0]
        translation = centre_cam - rotation @ centre
        if not inside_image(project_points(outline @ rotation.T + translation, K), width, height):
            continue
        if all(np.linalg.norm(centre_cam - other) >= radius + other_radius for other, other_radius in placed):
            placed.append((centre_cam, radius))
            return translation
    return None


def random_pose_in_view(generator: np.random.Generator, vertices: np.ndarray, camera: Camera, border: float,
                        distance: tuple[float, float], distance_unit: float = 1.0) -> np.ndarray:
    """``T_model2cam (4, 4)``: a uniform rotation, the bounding-box centre of ``vertices`` ``(N, 3)``
    (metres) at a depth uniform in ``distance`` × ``distance_unit`` metres (e.g. a range in object
    diameters times the diameter) and at a pixel uniform in the ``camera`` image less a ``border``
    fraction at each side (the object may still cross the image edge)."""
    rotation = quaternion.to_rotation_matrix(quaternion.random(seed=generator))
    depth = generator.uniform(*distance) * distance_unit
    u = generator.uniform(border, 1 - border) * camera.width - 0.5
    v = generator.uniform(border, 1 - border) * camera.height - 0.5
    centre_cam = camera.unproject(np.array([[u, v]]), np.array([depth]))[0]
    centre_model = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = centre_cam - rotation @ centre_model
    return T
