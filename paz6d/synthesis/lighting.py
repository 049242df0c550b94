"""Random lights, object colour jitter and materials (descriptions only: no GL is loaded here)."""

from __future__ import annotations

import numpy as np

from renderers.lights import Light, Lighting

#: ``"scene"``: ambient plus 1..n directional/point lights of random colour on the camera's side
#: (``paz6d generate``); ``"key-fill"``: grey ambient, one directional key light and a point fill
#: light at the camera (KeypointNet views); ``"surround"``: grey ambient and one or two directional
#: lights of random warm or cool white from any direction, behind and above the object included.
LIGHTING_STYLES = ("scene", "key-fill", "surround")


def random_lighting(generator: np.random.Generator, style: str = "scene", light_count: tuple[int, int] = (1, 3),
                    distance: float = 1.0) -> Lighting:
    """Random :class:`renderers.Lighting` of one of :data:`LIGHTING_STYLES`.

    Args:
        light_count: ``"scene"``: range of the number of lights (inclusive).
        distance: ``"scene"``: typical object distance (metres), to place point lights and scale
            their power.
    """
    if style == "key-fill":
        direction = generator.normal(size=3)
        direction[2] = abs(direction[2]) + 0.5  # travelling away from the camera, into the scene
        ambient = float(generator.uniform(0.25, 0.5))
        return Lighting(ambient=(ambient, ambient, ambient),
                        lights=(Light("directional", intensity=float(generator.uniform(1.5, 3.5)),
                                      direction=tuple(direction)),
                                Light("point", intensity=float(generator.uniform(0.3, 1.5)), position=(0.0, 0.0, 0.0))))
    if style == "surround":
        ambient = float(generator.uniform(0.1, 0.35))
        lights = []
        for _ in range(int(generator.integers(1, 3))):
            direction = generator.normal(size=3)  # uniform on the sphere
            warm = generator.uniform(0.75, 1.0)
            color = (1.0, float(0.5 * (1.0 + warm)), float(warm)) if generator.random() < 0.5 else \
                (float(warm), float(0.5 * (1.0 + warm)), 1.0)
            lights.append(Light("directional", color=color, intensity=float(generator.uniform(1.5, 4.0)),
                                direction=tuple(direction.tolist())))
        return Lighting(ambient=(ambient, ambient, ambient), lights=tuple(lights))
    if style != "scene":
        raise ValueError(f"style: expected one of {LIGHTING_STYLES}, got {style!r}")
    ambient = tuple(float(a) for a in generator.uniform(0.1, 0.45) * generator.uniform(0.85, 1.0, 3))
    lights = []
    for _ in range(int(generator.integers(light_count[0], light_count[1] + 1))):
        color = tuple(float(c) for c in generator.uniform(0.75, 1.0, 3))
        # A direction in the camera's front hemisphere (the light travels into the scene).
        direction = generator.normal(size=3)
        direction[2] = abs(direction[2]) + 0.3
        if generator.random() < 0.5:
            lights.append(Light("directional", color=color, intensity=float(generator.uniform(1.0, 4.0)),
                                direction=tuple(direction.tolist())))
        else:
            position = -direction / np.linalg.norm(direction) * distance * generator.uniform(0.5, 1.5)
            position[2] += distance  # around the objects, on the camera's side
            power = float(generator.uniform(1.0, 4.0)) * distance ** 2
            lights.append(Light("point", color=color, intensity=power, position=tuple(position.tolist())))
    return Lighting(ambient=ambient, lights=tuple(lights))


def random_tints(generator: np.random.Generator, count: int, jitter: float) -> np.ndarray:
    """``(count, 3)`` per-channel colour factors in ``[1 - jitter, 1 + jitter]`` for ``count`` objects."""
    return generator.uniform(1.0 - jitter, 1.0 + jitter, size=(count, 3))


def random_materials(generator: np.random.Generator, count: int, roughness: tuple[float, float] | None,
                     metallic: tuple[float, float] | None) -> np.ndarray | None:
    """``(count, 2)`` ``(roughness, metallic)`` of :meth:`renderers.Renderer.render`, each uniform in its range
    (a range of None: pyrender's vertex-colour default, 0.8 and 0.2); None (and nothing drawn) when both are None."""
    if roughness is None and metallic is None:
        return None
    low_high = [roughness or (0.8, 0.8), metallic or (0.2, 0.2)]
    return np.stack([generator.uniform(low, high, size=count) for low, high in low_high], axis=1)
