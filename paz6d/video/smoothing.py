"""Temporal smoothing of 6D poses over the frames of a sequence (``paz6d run --smooth``).

Each object's pose is tracked by an alpha-beta filter (a constant-velocity model): the pose predicted
from the previous smoothed pose and velocity is moved towards the new estimate by ``weight`` (alpha), and
the velocity by ``beta = weight**2 / (2 - weight)`` times the residual per second. The translation is
filtered in metres, the rotation on the sphere (residual ``log(q_new q_predicted^-1)`` as a rotation
vector, angular velocity in the camera frame). A plain moving average would lag behind a moving object
(by ``(1 - weight) / weight`` frames of motion); the velocity term removes that lag for steady motion.
``weight`` 1 keeps every new pose as it is; smaller values trust the motion model more.

Poses are matched to the objects of earlier frames by class name and, among several of one class, by
the translation nearest to its prediction. A pose that jumps (rotation more than ``max_angle_degrees`` or
translation more than ``max_jump_m`` away from the prediction) or follows a gap longer than ``max_gap_s``
starts afresh: an object that really moved, or a wrong estimate, is not dragged along.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from paz6d.abstract import Pose6D
from paz6d.backend import quaternion


@dataclasses.dataclass
class _Track:
    pose: Pose6D
    timestamp_s: float
    velocity: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))  # m/s
    angular_velocity: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))  # rad/s, camera frame

    def predict(self, timestamp_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The pose's ``(quaternion, translation)`` extrapolated to ``timestamp_s``."""
        elapsed = timestamp_s - self.timestamp_s
        turn = quaternion.from_rotation_vector(self.angular_velocity * elapsed)
        return (quaternion.multiply(turn, self.pose.quaternion),
                self.pose.translation + self.velocity * elapsed)


class PoseSmoother:
    """``(output, frame) -> output`` with every :class:`~paz6d.abstract.Pose6D` smoothed over time: the
    ``transform`` of a :class:`~paz6d.video.player.VideoPlayer`.

    Works on the outputs pipelines return: ``[(Box2D, Pose6D)]``, ``[Pose6D]`` and dataclasses with a
    ``pose`` field (:class:`~paz6d.faces.head_pose.HeadDetection`).

    Args:
        weight: the filter's alpha in (0, 1]: how far each new pose moves the prediction (1: no smoothing).
        max_angle_degrees: a rotation this far from the predicted one starts a new track.
        max_jump_m: a translation this far (metres) from the predicted one starts a new track.
        max_gap_s: an object unseen for longer than this (seconds) starts a new track.
        velocity: track velocities (alpha-beta filter); ``False``: a plain exponential moving average of the
            poses (``beta`` 0), which lags behind a moving object.
    Raises:
        ValueError: a parameter out of range.
    """

    def __init__(self, weight: float = 0.5, max_angle_degrees: float = 30.0, max_jump_m: float = 0.05,
                 max_gap_s: float = 0.5, velocity: bool = True):
        for name, value in (("max_angle_degrees", max_angle_degrees), ("max_jump_m", max_jump_m),
                            ("max_gap_s", max_gap_s)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive number, got {value}")
        if not (math.isfinite(weight) and 0.0 < weight <= 1.0):
            raise ValueError(f"weight: expected a number in (0, 1], got {weight}")
        self.weight, self.max_angle = float(weight), math.radians(max_angle_degrees)
        self.beta = self.weight ** 2 / (2.0 - self.weight) if velocity else 0.0
        self.max_jump, self.max_gap = float(max_jump_m), float(max_gap_s)
        self.tracks: dict[str | None, list[_Track]] = {}

    def smooth(self, pose: Pose6D, timestamp_s: float, taken: set[int]) -> Pose6D:
        """The smoothed ``pose`` at ``timestamp_s``; updates (or starts) its track. ``taken``: ids of the
        tracks already matched in this frame."""
        tracks = self.tracks.setdefault(pose.class_name, [])
        candidates = [track for track in tracks if id(track) not in taken
                      and 0 < timestamp_s - track.timestamp_s <= self.max_gap]
        track = min(candidates, key=lambda track: np.linalg.norm(track.predict(timestamp_s)[1] - pose.translation),
                    default=None)
        if track is not None:
            predicted_q, predicted_t = track.predict(timestamp_s)
            if (np.linalg.norm(predicted_t - pose.translation) > self.max_jump or
                    quaternion.angle_between(predicted_q, pose.quaternion) > self.max_angle):
                track = None
        if track is None:
            track = _Track(pose, timestamp_s)
            tracks.append(track)
        else:
            elapsed = timestamp_s - track.timestamp_s
            residual_t = pose.translation - predicted_t
            residual_r = quaternion.to_rotation_vector(quaternion.multiply(pose.quaternion,
                                                                           quaternion.inverse(predicted_q)))
            smoothed_q = quaternion.multiply(quaternion.from_rotation_vector(self.weight * residual_r), predicted_q)
            track.pose = Pose6D(smoothed_q, predicted_t + self.weight * residual_t, pose.class_name, pose.score)
            track.velocity = track.velocity + self.beta * residual_t / elapsed
            track.angular_velocity = track.angular_velocity + self.beta * residual_r / elapsed
            track.timestamp_s = timestamp_s
        taken.add(id(track))
        self.tracks[pose.class_name] = [other for other in tracks if timestamp_s - other.timestamp_s <= self.max_gap]
        return track.pose

    def _item(self, item: Any, timestamp_s: float, taken: set[int]) -> Any:
        if isinstance(item, Pose6D):
            return self.smooth(item, timestamp_s, taken)
        if isinstance(item, tuple):
            return tuple(self._item(value, timestamp_s, taken) if isinstance(value, Pose6D) else value
                         for value in item)
        if dataclasses.is_dataclass(item) and isinstance(getattr(item, "pose", None), Pose6D):
            return dataclasses.replace(item, pose=self.smooth(item.pose, timestamp_s, taken))
        return item

    def __call__(self, output: Any, frame) -> Any:
        """``output`` of the pipeline on ``frame`` (a :class:`~paz6d.video.frames.Frame`) with its poses smoothed."""
        taken: set[int] = set()
        if isinstance(output, list):
            return [self._item(item, frame.timestamp_s, taken) for item in output]
        return self._item(output, frame.timestamp_s, taken)
