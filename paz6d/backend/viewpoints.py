"""Where a camera may see an object from: the viewpoint convention of ``paz6d generate --rotation view-sphere``.

For a rotation ``R_model2cam`` (model z up):

- **elevation**: angle (degrees) of the camera above the model's xy plane, seen along the optical axis:
  ``asin(-R[2, 2])``; 90 looks straight down the model's z axis, negative values look from below.
- **in-plane angle**: angle (degrees) of the model's z axis, projected into the image, from image-up
  towards image-right (``atan2(R[0, 2], -R[1, 2])``); 0 keeps the model upright in the image. Near the poles
  (``|sin(elevation)| >= POLE_SINE``, within 2.6 degrees of ±90) the model's z axis points nearly along the
  optical axis, the angle is ill-defined, and it counts as 0.

:func:`paz6d.synthesis.sampling.random_rotation` draws exactly these two angles, so a
:class:`ViewpointRange` of its settings contains every rotation it draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from paz6d.backend.checks import as_array

#: ``|sin(elevation)|`` from which a view counts as looking along the model's z axis (no in-plane angle).
POLE_SINE = 0.999


def look_at_rotation(forward, up) -> np.ndarray:
    """``(..., 3, 3)`` rotation whose rows are an OpenCV camera's axes (x right, y down, z forward) in the
    frame of ``forward`` and ``up``: z is the unit viewing direction ``forward`` ``(..., 3)``, x = z × up
    (normalised) and y = z × x, so that ``up`` ``(3,)`` or ``(..., 3)`` points image-up. As a rotation it maps
    that frame into the camera's (``R_world2cam``, or ``R_model2cam`` for a camera looking at a model).

    Raises:
        ValueError: ``up`` parallel to a viewing direction.
    """
    forward = np.asarray(forward, dtype=np.float64)
    x_axis = np.cross(forward, np.broadcast_to(np.asarray(up, dtype=np.float64), forward.shape))
    length = np.linalg.norm(x_axis, axis=-1, keepdims=True)
    if np.any(length < 1e-9):
        raise ValueError("up: expected a direction not parallel to the viewing direction")
    x_axis = x_axis / length
    return np.stack([x_axis, np.cross(forward, x_axis), forward], axis=-2)


def in_plane_rotation(angles) -> np.ndarray:
    """``(..., 3, 3)`` rotations about the camera z axis by ``angles`` (radians, any shape); in the image
    (x right, y down) a positive angle turns the x axis towards the y axis."""
    angles = np.asarray(angles, dtype=np.float64)
    cos, sin = np.cos(angles), np.sin(angles)
    rotations = np.zeros(angles.shape + (3, 3))
    rotations[..., 0, 0], rotations[..., 0, 1] = cos, -sin
    rotations[..., 1, 0], rotations[..., 1, 1] = sin, cos
    rotations[..., 2, 2] = 1.0
    return rotations


def elevation_and_inplane(rotations) -> tuple[np.ndarray, np.ndarray]:
    """``(elevation (N,), in-plane angle (N,))`` in degrees of ``(N, 3, 3)`` (or one ``(3, 3)``)
    rotations ``R_model2cam`` (see the module docstring)."""
    rotations = as_array(rotations, "rotations", (3, 3)).reshape(-1, 3, 3)
    elevation = np.degrees(np.arcsin(np.clip(-rotations[:, 2, 2], -1.0, 1.0)))
    pole = np.abs(rotations[:, 2, 2]) >= POLE_SINE
    inplane = np.where(pole, 0.0, np.degrees(np.arctan2(rotations[:, 0, 2], -rotations[:, 1, 2])))
    return elevation, inplane


@dataclass(frozen=True)
class ViewpointRange:
    """The viewpoints a camera can have of an object: elevations in ``elevation_degrees`` (min, max) and
    in-plane angles within ``±inplane_degrees`` (see the module docstring). The default is every viewpoint.

    Example: objects resting upright on a table, seen from 15-80 degrees above it by a camera rolled by at
    most 30 degrees: ``ViewpointRange((15, 80), 30)``.
    """

    elevation_degrees: tuple[float, float] = (-90.0, 90.0)
    inplane_degrees: float = 180.0

    def __post_init__(self):
        values = np.asarray(self.elevation_degrees, dtype=np.float64).reshape(-1)
        if values.shape != (2,) or not -90.0 <= values[0] <= values[1] <= 90.0:
            raise ValueError(f"elevation_degrees: expected (min, max) with -90 <= min <= max <= 90, got "
                             f"{self.elevation_degrees}")
        low, high = float(values[0]), float(values[1])
        inplane = float(self.inplane_degrees)
        if not 0.0 <= inplane <= 180.0:
            raise ValueError(f"inplane_degrees: expected a maximum absolute angle in [0, 180], got "
                             f"{self.inplane_degrees}")
        object.__setattr__(self, "elevation_degrees", (low, high))
        object.__setattr__(self, "inplane_degrees", inplane)

    @property
    def is_everything(self) -> bool:
        """Whether every rotation lies in the range."""
        return self.elevation_degrees == (-90.0, 90.0) and self.inplane_degrees == 180.0

    def contains(self, rotations) -> np.ndarray:
        """``(N,)`` bool: which of the ``(N, 3, 3)`` rotations ``R_model2cam`` lie in the range."""
        elevation, inplane = elevation_and_inplane(rotations)
        low, high = self.elevation_degrees
        return (elevation >= low) & (elevation <= high) & (np.abs(inplane) <= self.inplane_degrees)

    def widened(self, margin_degrees: float) -> "ViewpointRange":
        """The range grown by ``margin_degrees`` on every side (clipped to the whole sphere)."""
        if not np.isfinite(margin_degrees) or margin_degrees < 0:
            raise ValueError(f"margin_degrees: expected a non-negative angle, got {margin_degrees}")
        low, high = self.elevation_degrees
        return ViewpointRange((max(low - margin_degrees, -90.0), min(high + margin_degrees, 90.0)),
                              min(self.inplane_degrees + margin_degrees, 180.0))

    def describe(self) -> str:
        """``"elevation LOW..HIGH degrees, in-plane within ±D degrees"``."""
        low, high = self.elevation_degrees
        return f"elevation {low:g}..{high:g} degrees, in-plane within ±{self.inplane_degrees:g} degrees"
