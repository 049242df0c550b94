"""Choice of the headless OpenGL platform (EGL or OSMesa) before OpenGL is first imported.

PyOpenGL binds to one platform per process, read from ``PYOPENGL_PLATFORM`` at its first
import, so the choice is made here, once, and cannot change later in the same process.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import shutil
import subprocess
import sys

PLATFORMS = ("egl", "osmesa")
#: Debian packages each platform needs (the same list as ``run.sh setup``).
DEBIAN_PACKAGES = {"egl": ("libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libgl1"),
                   "osmesa": ("libosmesa6", "libgl1-mesa-dri")}
ENVIRONMENT_VARIABLE = "PAZ6D_GL_PLATFORM"


class PlatformUnavailableError(RuntimeError):
    """Neither EGL nor OSMesa can create an offscreen OpenGL context on this machine."""


def _load_library(stem: str) -> tuple[ctypes.CDLL | None, str]:
    """``(library, its file name)`` of ``lib<stem>``, or ``(None, the reason it did not load)``."""
    name = ctypes.util.find_library(stem)
    if name is None:
        return None, f"lib{stem} not found"
    try:
        return ctypes.CDLL(name), name
    except OSError as error:
        return None, f"cannot load {name}: {error}"


def _probe_egl() -> str | None:
    """Returns ``None`` when an EGL display initializes, else the reason it did not."""
    egl, name = _load_library("EGL")
    if egl is None:
        return name
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    egl.eglGetDisplay.restype = ctypes.c_void_p
    egl.eglGetDisplay.argtypes = [ctypes.c_void_p]
    egl.eglInitialize.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)]
    display = None
    query_address = egl.eglGetProcAddress(b"eglQueryDevicesEXT")
    platform_address = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
    if query_address and platform_address:
        query = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                                 ctypes.POINTER(ctypes.c_int))(query_address)
        get_display = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p,
                                       ctypes.c_void_p)(platform_address)
        devices = (ctypes.c_void_p * 8)()
        count = ctypes.c_int(0)
        if query(8, devices, ctypes.byref(count)) and count.value > 0:
            display = get_display(0x313F, devices[0], None)  # EGL_PLATFORM_DEVICE_EXT
    if not display:
        display = egl.eglGetDisplay(None)
    if not display:
        return "no EGL display (eglGetDisplay failed)"
    major, minor = ctypes.c_int(0), ctypes.c_int(0)
    if not egl.eglInitialize(display, ctypes.byref(major), ctypes.byref(minor)):
        return "eglInitialize failed (no usable EGL driver, e.g. Mesa's libegl-mesa0)"
    # No eglTerminate: the display is per process and shared with every later GL context.
    return None


def _probe_osmesa() -> str | None:
    """Returns ``None`` when libOSMesa loads, else the reason it did not."""
    library, name = _load_library("OSMesa")
    if library is None:
        return name
    if not hasattr(library, "OSMesaCreateContextAttribs"):
        return f"{name} lacks OSMesaCreateContextAttribs (too old)"
    return None


_PROBES = {"egl": _probe_egl, "osmesa": _probe_osmesa}


def missing_debian_packages(packages) -> list[str]:
    """Those of ``packages`` that ``dpkg`` reports as not installed (all of them without dpkg)."""
    if shutil.which("dpkg-query") is None:
        return list(packages)
    missing = []
    for package in packages:
        result = subprocess.run(["dpkg-query", "-W", "-f=${Status}", package], capture_output=True, text=True)
        if "install ok installed" not in result.stdout:
            missing.append(package)
    return missing


def _unavailable_message(reasons: dict[str, str]) -> str:
    packages = sorted({package for platform in reasons for package in DEBIAN_PACKAGES[platform]})
    missing = missing_debian_packages(packages)
    lines = ["no headless OpenGL platform works:"]
    lines += [f"  {platform}: {reason}" for platform, reason in reasons.items()]
    if missing:
        lines.append(f"  missing Debian packages: {' '.join(missing)}")
        lines.append(f"  install them with: sudo apt-get install {' '.join(missing)}")
    else:
        lines.append(f"  the Debian packages {' '.join(packages)} are installed; check the driver setup")
    return "\n".join(lines)


def _active_platform() -> str | None:
    """The platform PyOpenGL is already bound to in this process, if OpenGL was imported."""
    if "OpenGL.platform" in sys.modules or "OpenGL" in sys.modules:
        return os.environ.get("PYOPENGL_PLATFORM")
    return None


def select_platform(platform: str | None = None) -> str:
    """Chooses the OpenGL platform and sets ``PYOPENGL_PLATFORM`` for this process.

    Order: ``platform`` argument, environment variable ``PAZ6D_GL_PLATFORM``, the platform
    OpenGL is already bound to, then EGL if it initializes, else OSMesa. With EGL it also sets
    ``PYGLET_HEADLESS=true`` unless set: pyglet, which pyrender imports for its viewer, then loads no X11
    libraries (a GPU machine without them failed at ``import pyrender``).

    Raises:
        ValueError: unknown platform, or a platform other than the one this process already uses.
        PlatformUnavailableError: neither platform works (lists the missing Debian packages).
    """
    requested = platform if platform is not None else os.environ.get(ENVIRONMENT_VARIABLE) or None
    if requested is not None and requested not in PLATFORMS:
        source = "platform" if platform is not None else ENVIRONMENT_VARIABLE
        raise ValueError(f"{source}: expected one of {PLATFORMS} or None (auto), got {requested!r}")
    active = _active_platform()
    if active is not None:
        if requested is not None and requested != active:
            raise ValueError(f"platform: this process already uses OpenGL platform {active!r}; EGL and OSMesa "
                             f"cannot be mixed in one process (render with {requested!r} in a subprocess)")
        return active
    candidates = (requested,) if requested is not None else PLATFORMS
    reasons = {}
    for candidate in candidates:
        reason = _PROBES[candidate]()
        if reason is None:
            os.environ["PYOPENGL_PLATFORM"] = candidate
            if candidate == "egl":  # pyrender imports pyglet, whose X11 window code a headless machine may lack
                os.environ.setdefault("PYGLET_HEADLESS", "true")
            return candidate
        reasons[candidate] = reason
    raise PlatformUnavailableError(_unavailable_message(reasons))
