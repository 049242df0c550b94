"""Typed, validated, immutable messages passed between processors and returned by pipelines.

All lengths are metres and all pixel coordinates follow ``docs/conventions.md``. Every message
converts to/from a JSON-safe ``dict`` (``to_dict`` / ``from_dict``) and to numpy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from paz6d.backend import quaternion as quaternion_backend
from paz6d.backend.checks import as_array, as_points, as_rotation_matrix, as_unit_quaternion


def _frozen_array(value: np.ndarray) -> np.ndarray:
    array = np.array(value, dtype=np.float64)
    array.setflags(write=False)
    return array


def _require(data: dict, keys: tuple[str, ...], kind: str) -> None:
    if not isinstance(data, dict):
        raise ValueError(f"{kind}.from_dict: expected a dict, got {type(data).__name__}")
    missing = [key for key in keys if key not in data]
    if missing:
        raise ValueError(f"{kind}.from_dict: missing field(s) {missing}")


@dataclass(frozen=True)
class Box2D:
    """Axis-aligned 2D box in pixels, ``x_min <= x_max`` and ``y_min <= y_max``."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    score: float = 1.0
    class_name: str | None = None

    def __post_init__(self):
        coordinates = as_array([self.x_min, self.y_min, self.x_max, self.y_max], "Box2D coordinates", (4,))
        if coordinates[2] < coordinates[0] or coordinates[3] < coordinates[1]:
            raise ValueError(f"Box2D: expected x_min <= x_max and y_min <= y_max, got {coordinates.tolist()}")
        if not np.isfinite(self.score):
            raise ValueError(f"Box2D.score: expected a finite number, got {self.score}")
        for name, value in zip(("x_min", "y_min", "x_max", "y_max"), coordinates):
            object.__setattr__(self, name, float(value))
        object.__setattr__(self, "score", float(self.score))

    @property
    def width(self) -> float:
        return self.x_max - self.x_min

    @property
    def height(self) -> float:
        return self.y_max - self.y_min

    @property
    def center(self) -> tuple[float, float]:
        return (0.5 * (self.x_min + self.x_max), 0.5 * (self.y_min + self.y_max))

    @property
    def area(self) -> float:
        return self.width * self.height

    def to_array(self) -> np.ndarray:
        """``(4,)`` array ``[x_min, y_min, x_max, y_max]``."""
        return np.array([self.x_min, self.y_min, self.x_max, self.y_max])

    @classmethod
    def coordinates_of(cls, box):
        """``box.to_array()`` for a :class:`Box2D`, any other value as given (a pixel box
        ``(x_min, y_min, x_max, y_max)`` that the caller checks)."""
        return box.to_array() if isinstance(box, cls) else box

    @classmethod
    def from_array(cls, coordinates, score: float = 1.0, class_name: str | None = None) -> "Box2D":
        x_min, y_min, x_max, y_max = as_array(coordinates, "coordinates", (4,)).reshape(4)
        return cls(x_min, y_min, x_max, y_max, score, class_name)

    @classmethod
    def coerce(cls, box) -> "Box2D":
        """``box`` itself when it is a :class:`Box2D`, else :meth:`from_array` of its
        ``(x_min, y_min, x_max, y_max)`` pixels (a pipeline's ``box2d`` argument).

        Raises:
            ValueError: naming ``box2d``.
        """
        if isinstance(box, cls):
            return box
        try:
            return cls.from_array(box)
        except ValueError as error:
            raise ValueError(f"box2d: expected a Box2D or (x_min, y_min, x_max, y_max) pixels ({error})") from error

    def to_dict(self) -> dict[str, Any]:
        return {"x_min": self.x_min, "y_min": self.y_min, "x_max": self.x_max, "y_max": self.y_max,
                "score": self.score, "class_name": self.class_name}

    @classmethod
    def from_dict(cls, data: dict) -> "Box2D":
        _require(data, ("x_min", "y_min", "x_max", "y_max"), "Box2D")
        return cls(data["x_min"], data["y_min"], data["x_max"], data["y_max"],
                   data.get("score", 1.0), data.get("class_name"))


@dataclass(frozen=True, eq=False)
class Pose6D:
    """Rigid pose of an object in the camera frame (``x_cam = R @ x_model + t``).

    Attributes:
        quaternion: ``(4,)`` unit quaternion, scalar-last ``(x, y, z, w)``, stored canonical (``w >= 0``).
        translation: ``(3,)`` metres.
    """

    quaternion: np.ndarray
    translation: np.ndarray
    class_name: str | None = None
    score: float = 1.0

    def __post_init__(self):
        q = as_unit_quaternion(self.quaternion, "Pose6D.quaternion")
        if q.shape != (4,):
            raise ValueError(f"Pose6D.quaternion: expected shape (4,), got {q.shape}")
        t = as_array(self.translation, "Pose6D.translation", (3,))
        if t.shape != (3,):
            raise ValueError(f"Pose6D.translation: expected shape (3,), got {t.shape}")
        object.__setattr__(self, "quaternion", _frozen_array(quaternion_backend.canonical(q / np.linalg.norm(q))))
        object.__setattr__(self, "translation", _frozen_array(t))
        if isinstance(self.score, bool) or not isinstance(self.score, (int, float, np.number)) or \
                not np.isfinite(self.score):
            raise ValueError(f"Pose6D.score: expected a finite number, got {self.score!r}")
        object.__setattr__(self, "score", float(self.score))

    @property
    def rotation_matrix(self) -> np.ndarray:
        """``(3, 3)`` rotation ``R_model2cam``."""
        return quaternion_backend.to_rotation_matrix(self.quaternion)

    @property
    def rotation_vector(self) -> np.ndarray:
        """``(3,)`` axis-angle (radians)."""
        return quaternion_backend.to_rotation_vector(self.quaternion)

    def to_matrix(self) -> np.ndarray:
        """``(4, 4)`` homogeneous ``T_model2cam``."""
        T = np.eye(4)
        T[:3, :3] = self.rotation_matrix
        T[:3, 3] = self.translation
        return T

    @classmethod
    def from_matrix(cls, T, class_name: str | None = None, score: float = 1.0) -> "Pose6D":
        T = as_array(T, "T", (4, 4))
        if T.shape != (4, 4):
            raise ValueError(f"T: expected shape (4, 4), got {T.shape}")
        return cls.from_rotation_matrix(T[:3, :3], T[:3, 3], class_name, score)

    @classmethod
    def from_rotation_matrix(cls, rotation_matrix, translation, class_name: str | None = None,
                             score: float = 1.0) -> "Pose6D":
        rotation_matrix = as_rotation_matrix(rotation_matrix, "rotation_matrix")
        return cls(quaternion_backend.from_rotation_matrix(rotation_matrix), translation, class_name, score)

    @classmethod
    def from_rotation_vector(cls, rotation_vector, translation, class_name: str | None = None,
                             score: float = 1.0) -> "Pose6D":
        return cls(quaternion_backend.from_rotation_vector(rotation_vector), translation, class_name, score)

    def to_array(self) -> np.ndarray:
        """``(7,)`` array ``[qx, qy, qz, qw, tx, ty, tz]``."""
        return np.concatenate([self.quaternion, self.translation])

    @classmethod
    def from_array(cls, values, class_name: str | None = None, score: float = 1.0) -> "Pose6D":
        values = as_array(values, "values", (7,)).reshape(7)
        return cls(values[:4], values[4:], class_name, score)

    def __eq__(self, other: object) -> bool:
        """Exact equality of all fields (quaternions are stored canonical, so ``q`` equals ``-q``)."""
        if not isinstance(other, Pose6D):
            return NotImplemented
        return (np.array_equal(self.quaternion, other.quaternion) and np.array_equal(self.translation,
                                                                                     other.translation)
                and self.class_name == other.class_name and self.score == other.score)

    def to_dict(self) -> dict[str, Any]:
        return {"quaternion": self.quaternion.tolist(), "translation": self.translation.tolist(),
                "class_name": self.class_name, "score": self.score}

    @classmethod
    def from_dict(cls, data: dict) -> "Pose6D":
        _require(data, ("quaternion", "translation"), "Pose6D")
        return cls(data["quaternion"], data["translation"], data.get("class_name"), data.get("score", 1.0))


@dataclass(frozen=True, eq=False)
class _Keypoints:
    """``(N, dimension)`` keypoints with optional ``(N,)`` scores; subclasses set ``dimension``."""

    points: np.ndarray
    scores: np.ndarray | None = field(default=None)
    class_name: str | None = None
    dimension: ClassVar[int] = 0

    def __post_init__(self):
        kind = type(self).__name__
        points = _frozen_array(as_points(self.points, f"{kind}.points", dimension=self.dimension, min_count=0))
        object.__setattr__(self, "points", points)
        if self.scores is not None:
            scores = _frozen_array(np.asarray(self.scores, dtype=np.float64).reshape(-1))
            if len(scores) != len(points):
                raise ValueError(f"{kind}.scores: expected {len(points)} scores, got {len(scores)}")
            object.__setattr__(self, "scores", scores)

    def __len__(self) -> int:
        return len(self.points)

    def __eq__(self, other: object) -> bool:
        """Exact equality of points, scores and class name (same keypoint type only)."""
        if type(other) is not type(self):
            return NotImplemented
        scores_equal = (self.scores is None and other.scores is None) or (
            self.scores is not None and other.scores is not None and np.array_equal(self.scores, other.scores))
        return np.array_equal(self.points, other.points) and scores_equal and self.class_name == other.class_name

    def to_array(self) -> np.ndarray:
        """Writable copy of ``points``."""
        return np.array(self.points)

    def to_dict(self) -> dict[str, Any]:
        return {"points": self.points.tolist(),
                "scores": None if self.scores is None else self.scores.tolist(),
                "class_name": self.class_name}

    @classmethod
    def from_dict(cls, data: dict):
        _require(data, ("points",), cls.__name__)
        points = np.asarray(data["points"], dtype=np.float64).reshape(-1, cls.dimension)
        return cls(points, data.get("scores"), data.get("class_name"))


@dataclass(frozen=True, eq=False)
class Keypoints2D(_Keypoints):
    """``(N, 2)`` pixel keypoints, optional ``(N,)`` scores."""

    dimension: ClassVar[int] = 2


@dataclass(frozen=True, eq=False)
class Keypoints3D(_Keypoints):
    """``(N, 3)`` keypoints in metres (frame given by the producer, usually the camera frame)."""

    dimension: ClassVar[int] = 3
