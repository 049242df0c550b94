"""The one place where OpenCV camera conventions become OpenGL ones (and back).

OpenCV camera frame: x right, y down, z forward; pixel ``(u, v) = (col, row)`` is the centre of
that pixel. OpenGL (pyrender) camera frame: x right, y up, z backward; window coordinates count
pixel *edges*, so an OpenCV pixel centre ``u`` sits at OpenGL window coordinate ``u + 0.5``.

The renderer uses the OpenGL camera frame as its world frame (camera pose = identity), so an
object pose ``T_model2cam`` (OpenCV) becomes ``FLIP @ T_model2cam`` in the scene graph.
"""

from __future__ import annotations

import numpy as np

from paz6d.backend.checks import as_array, as_camera_matrix

#: Homogeneous change of axes between the OpenCV and OpenGL camera frames (its own inverse).
FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_transform_from_model2cam(T_model2cam) -> np.ndarray:
    """Maps an OpenCV ``T_model2cam`` ``(4, 4)`` to the pose of the model in the OpenGL camera frame."""
    return FLIP_YZ @ as_array(T_model2cam, "T_model2cam", (4, 4))


def opengl_transform_from_emitter2cam(T_emitter2cam) -> np.ndarray:
    """Maps the pose ``(4, 4)`` of a camera-like emitter (looks along its own +z, OpenCV style)
    to the pyrender pose of the same emitter (looks along its own -z, OpenGL style)."""
    return FLIP_YZ @ as_array(T_emitter2cam, "T_emitter2cam", (4, 4)) @ FLIP_YZ


def projection_matrix(K, width: int, height: int, znear: float, zfar: float) -> np.ndarray:
    """OpenGL projection ``(4, 4)`` equivalent to the OpenCV intrinsics ``K`` for a ``width x height`` image.

    The OpenGL camera looks down -z with y up and NDC in ``[-1, 1]``. OpenCV's integer pixel
    coordinates are pixel centres and OpenGL's window coordinates count pixel edges, so the
    principal point moves by half a pixel: a camera-frame point lands in the pixel whose centre
    :func:`paz6d.backend.camera.project_points` gives. ``znear``/``zfar`` are metres.
    """
    K = as_camera_matrix(K)
    if not 0 < znear < zfar:
        raise ValueError(f"znear/zfar: expected 0 < znear < zfar, got znear={znear}, zfar={zfar}")
    fx, fy, skew = K[0, 0], K[1, 1], K[0, 1]
    cx, cy = K[0, 2] + 0.5, K[1, 2] + 0.5  # pixel centres -> window coordinates (edges)
    P = np.zeros((4, 4))
    P[0, 0] = 2 * fx / width
    P[0, 1] = -2 * skew / width
    P[0, 2] = 1 - 2 * cx / width
    P[1, 1] = 2 * fy / height
    P[1, 2] = 2 * cy / height - 1
    P[2, 2] = -(zfar + znear) / (zfar - znear)
    P[2, 3] = -2 * zfar * znear / (zfar - znear)
    P[3, 2] = -1
    return P
