"""Light descriptions in the OpenCV camera frame (metres), independent of any GL library."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LIGHT_KINDS = ("directional", "point")


@dataclass(frozen=True)
class Light:
    """One light, given in the OpenCV camera frame.

    Attributes:
        kind: ``"directional"`` (parallel rays travelling along ``direction``) or ``"point"``
            (at ``position``, metres, inverse-square falloff).
        color: linear RGB in [0, 1], shape ``(3,)``.
        intensity: W/m² for directional lights, candela for point lights (pyrender units).
        direction: ``(3,)`` travel direction of the light for ``"directional"`` (need not be unit).
        position: ``(3,)`` position in metres for ``"point"``.
    """

    kind: str
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 3.0
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if self.kind not in LIGHT_KINDS:
            raise ValueError(f"Light.kind: expected one of {LIGHT_KINDS}, got {self.kind!r}")
        color = np.asarray(self.color, dtype=np.float64)
        if color.shape != (3,) or not np.all(np.isfinite(color)) or np.any(color < 0):
            raise ValueError(f"Light.color: expected 3 non-negative finite values, got {self.color!r}")
        if not np.isfinite(self.intensity) or self.intensity < 0:
            raise ValueError(f"Light.intensity: expected a non-negative finite number, got {self.intensity!r}")
        direction = np.asarray(self.direction, dtype=np.float64)
        if direction.shape != (3,) or not np.all(np.isfinite(direction)) or np.linalg.norm(direction) < 1e-12:
            raise ValueError(f"Light.direction: expected a non-zero finite 3-vector, got {self.direction!r}")
        position = np.asarray(self.position, dtype=np.float64)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"Light.position: expected a finite 3-vector (metres), got {self.position!r}")

    def pose(self) -> np.ndarray:
        """``(4, 4)`` pose in the OpenCV camera frame whose +z axis is the travel direction and
        whose origin is ``position``."""
        z_axis = np.asarray(self.direction, dtype=np.float64)
        z_axis = z_axis / np.linalg.norm(z_axis)
        helper = np.array([1.0, 0.0, 0.0]) if abs(z_axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x_axis = np.cross(helper, z_axis)
        x_axis /= np.linalg.norm(x_axis)
        y_axis = np.cross(z_axis, x_axis)
        T = np.eye(4)
        T[:3, :3] = np.stack([x_axis, y_axis, z_axis], axis=1)
        T[:3, 3] = self.position
        return T


@dataclass(frozen=True)
class Lighting:
    """Ambient light plus a list of :class:`Light` for one frame."""

    ambient: tuple[float, float, float] = (0.35, 0.35, 0.35)
    lights: tuple[Light, ...] = field(default_factory=lambda: DEFAULT_LIGHTS)

    def __post_init__(self):
        ambient = np.asarray(self.ambient, dtype=np.float64)
        if ambient.shape != (3,) or not np.all(np.isfinite(ambient)) or np.any(ambient < 0):
            raise ValueError(f"Lighting.ambient: expected 3 non-negative finite values, got {self.ambient!r}")
        for light in self.lights:
            if not isinstance(light, Light):
                raise ValueError(f"Lighting.lights: expected Light instances, got {type(light).__name__}")


#: A key light from above-left of the camera plus a fill light at the camera.
DEFAULT_LIGHTS = (Light("directional", intensity=2.5, direction=(0.3, 0.5, 1.0)),
                  Light("point", intensity=1.5, position=(0.0, 0.0, 0.0)))
