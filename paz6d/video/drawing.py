"""Drawing a pipeline's output on a frame where the pipeline has no drawing of its own."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from paz6d.abstract import Box2D, Keypoints2D, Pose6D
from paz6d.backend.camera import Camera
from paz6d.backend.draw import draw_box, draw_keypoints, draw_pose_axes
from paz6d.video.records import result_entries

BOX_COLOR = (0, 255, 0)


def _labelled_box(canvas: np.ndarray, box: Box2D, color=BOX_COLOR) -> np.ndarray:
    canvas = draw_box(canvas, box.to_array(), color, thickness=2)
    label = f"{box.class_name or ''} {box.score:.2f}".strip()
    cv2.putText(canvas, label, (int(box.x_min), max(int(box.y_min) - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, color,
                1, cv2.LINE_AA)
    return canvas


def draw_entries(image: np.ndarray, output: Any, camera: Camera | None = None, axis_length: float = 0.05) -> np.ndarray:
    """A copy of ``image`` (uint8 RGB) with every box of a pipeline's output
    (:func:`~paz6d.video.records.result_entries`) labelled with its class and score, its 2D keypoints and,
    given a ``camera``, the axes (``axis_length`` metres) of its poses."""
    canvas = np.array(image, copy=True)
    for entry in result_entries(output):
        for value in entry.values():
            if isinstance(value, Box2D):
                canvas = _labelled_box(canvas, value)
            elif isinstance(value, Keypoints2D) and len(value):
                canvas = draw_keypoints(canvas, value.points, radius=1)
            elif isinstance(value, Pose6D) and camera is not None:
                canvas = draw_pose_axes(canvas, value.to_matrix(), camera.K, axis_length)
    return canvas


def draw_heads(image: np.ndarray, heads, camera: Camera) -> np.ndarray:
    """A copy of ``image`` with each head (:class:`~paz6d.faces.head_pose.HeadDetection`): its face box, its
    landmarks, its pose's axes (:func:`~paz6d.faces.head_pose.draw_axes`, 8 cm) and its yaw, pitch and roll
    in degrees."""
    from paz6d.faces.head_pose import draw_axes, yaw_pitch_roll_degrees

    canvas = np.array(image, copy=True)
    for head in heads:
        canvas = draw_box(canvas, head.box.to_array(), BOX_COLOR, thickness=1)
        canvas = draw_keypoints(canvas, head.landmarks.points, colors=[(255, 255, 0)] * len(head.landmarks),
                                radius=1, outline=False)
        canvas = draw_axes(canvas, head.pose, camera)
        yaw, pitch, roll = yaw_pitch_roll_degrees(head.pose)
        cv2.putText(canvas, f"yaw {yaw:.0f} pitch {pitch:.0f} roll {roll:.0f}",
                    (int(head.box.x_min), max(int(head.box.y_min) - 4, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    BOX_COLOR, 1, cv2.LINE_AA)
    return canvas
