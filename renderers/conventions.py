"""The one place where OpenCV camera conventions become OpenGL ones (and back).

OpenCV camera frame: x right, y down, z forward; pixel ``(u, v) = (col, row)`` is the centre of
that pixel. OpenGL (pyrender) camera frame: x right, y up, z backward; window coordinates count
pixel *edges*, so an OpenCV pixel centre ``u`` sits at OpenGL window coordinate ``u + 0.5``.

The renderer uses the OpenGL camera frame as its world frame (camera pose = identity), so an
object pose ``T_model2cam`` (OpenCV) becomes ``FLIP @ T_model2cam`` in the scene graph.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.camera import opengl_projection
from paz6d.backend.checks import as_array, as_camera_matrix

#: Homogeneous change of axes between the OpenCV and OpenGL camera frames (its own inverse).
FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])


def model_pose_to_opengl(T_model2cam) -> np.ndarray:
    """Maps an OpenCV ``T_model2cam`` ``(4, 4)`` to the pose of the model in the OpenGL camera frame."""
    return FLIP_YZ @ as_array(T_model2cam, "T_model2cam", (4, 4))


def emitter_pose_to_opengl(T_emitter2cam) -> np.ndarray:
    """Maps the pose ``(4, 4)`` of a camera-like emitter (looks along its own +z, OpenCV style)
    to the pyrender pose of the same emitter (looks along its own -z, OpenGL style)."""
    return FLIP_YZ @ as_array(T_emitter2cam, "T_emitter2cam", (4, 4)) @ FLIP_YZ


def projection_matrix(K, width: int, height: int, znear: float, zfar: float) -> np.ndarray:
    """OpenGL projection ``(4, 4)`` that puts OpenCV pixel centres of ``K`` at OpenGL pixel centres."""
    K_edges = as_camera_matrix(K).copy()
    K_edges[0, 2] += 0.5
    K_edges[1, 2] += 0.5
    return opengl_projection(K_edges, width, height, znear, zfar)

