"""Offscreen rendering of meshes posed in the OpenCV camera frame (pyrender on EGL/OSMesa).

``Renderer(width, height, platform=None).render(K, [(mesh, T_model2cam), ...])`` returns a
:class:`RenderOutput` with RGB, depth (metres), full and visible masks. All OpenGL↔OpenCV
conversion lives in :mod:`renderers.conventions`. Importing this package does not import
pyrender or OpenGL; that happens when the first :class:`Renderer` is created.
"""

from renderers.lights import DEFAULT_LIGHTS, Light, Lighting
from renderers.platform import PlatformUnavailableError, select_platform
from renderers.renderer import ANTIALIAS_MODES, Renderer, RenderOutput

__all__ = ["ANTIALIAS_MODES", "DEFAULT_LIGHTS", "Light", "Lighting", "PlatformUnavailableError", "Renderer", "RenderOutput",
           "select_platform"]
