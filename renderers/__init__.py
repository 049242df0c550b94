"""Offscreen rendering of meshes posed in the OpenCV camera frame (pyrender on EGL/OSMesa).

``Renderer(width, height, platform=None).render(K, [(mesh, T_model2cam), ...])`` returns a
:class:`RenderOutput` with RGB, depth (metres), full and visible masks. All OpenGL↔OpenCV
conversion lives in :mod:`renderers.conventions`. Importing this package does not import
pyrender or OpenGL; that happens when the first :class:`Renderer` is created.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "lights": ("DEFAULT_LIGHTS", "Light", "Lighting"),
    "platform": ("PlatformUnavailableError", "select_platform"),
    "antialias": ("ANTIALIAS_MODES",),
    "renderer": ("Renderer", "RenderOutput"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    """The exported ``name``, imported from its module on first use (``renderers.platform`` alone,
    e.g. for the list of platforms, loads neither numpy nor OpenCV)."""
    if name not in _MODULE_OF:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_MODULE_OF[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
