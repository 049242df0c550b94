"""Offscreen rendering of meshes posed in the OpenCV camera frame (pyrender on EGL/OSMesa).

``Renderer(width, height, platform=None).render(K, [(mesh, T_model2cam), ...])`` returns a
:class:`RenderOutput` with RGB, depth (metres), full and visible masks. All OpenGL↔OpenCV
conversion lives in :mod:`renderers.conventions`. Importing this package does not import
pyrender or OpenGL; that happens when the first :class:`Renderer` is created.
"""

from __future__ import annotations

from paz6d.backend.lazy_exports import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "lights": ("DEFAULT_LIGHTS", "Light", "Lighting"),
    "platform": ("PlatformUnavailableError", "select_platform"),
    "antialias": ("ANTIALIAS_MODES",),
    "renderer": ("Renderer", "RenderOutput"),
})
