"""Choice of the OpenGL platform: explicit, environment, mixing, and the missing-packages error."""

from __future__ import annotations

import os

import pytest

from renderers import PlatformUnavailableError, Renderer, platform


@pytest.fixture(autouse=True)
def keep_environment(monkeypatch):
    monkeypatch.delenv("PAZ6D_GL_PLATFORM", raising=False)
    monkeypatch.setenv("PYOPENGL_PLATFORM", os.environ.get("PYOPENGL_PLATFORM", ""))


def test_unknown_platform_names_the_argument_or_variable(monkeypatch):
    with pytest.raises(ValueError, match="platform: expected one of"):
        platform.select_platform("vulkan")
    monkeypatch.setenv("PAZ6D_GL_PLATFORM", "glx")
    with pytest.raises(ValueError, match="PAZ6D_GL_PLATFORM: expected one of"):
        platform.select_platform()


def test_a_process_cannot_mix_platforms():
    with Renderer(8, 8) as renderer:
        other = {"egl": "osmesa", "osmesa": "egl"}[renderer.platform]
        assert platform.select_platform() == renderer.platform
        with pytest.raises(ValueError, match="cannot be mixed in one process"):
            platform.select_platform(other)


def test_neither_platform_working_lists_the_missing_debian_packages(monkeypatch):
    monkeypatch.setattr(platform, "_active_platform", lambda: None)
    monkeypatch.setitem(platform._PROBES, "egl", lambda: "libEGL not found")
    monkeypatch.setitem(platform._PROBES, "osmesa", lambda: "libOSMesa not found")
    monkeypatch.setattr(platform, "missing_debian_packages", lambda packages: ["libegl1", "libosmesa6"])
    with pytest.raises(PlatformUnavailableError) as error:
        platform.select_platform()
    message = str(error.value)
    assert "egl: libEGL not found" in message and "osmesa: libOSMesa not found" in message
    assert "sudo apt-get install libegl1 libosmesa6" in message


def test_a_requested_platform_is_probed_alone(monkeypatch):
    monkeypatch.setattr(platform, "_active_platform", lambda: None)
    monkeypatch.setitem(platform._PROBES, "egl", lambda: "eglInitialize failed")
    monkeypatch.setitem(platform._PROBES, "osmesa", lambda: None)
    assert platform.select_platform() == "osmesa"  # auto falls back
    with pytest.raises(PlatformUnavailableError, match="egl: eglInitialize failed"):
        platform.select_platform("egl")


def test_egl_makes_pyglet_headless_unless_the_user_chose(monkeypatch):
    monkeypatch.setattr(platform, "_active_platform", lambda: None)
    monkeypatch.setitem(platform._PROBES, "egl", lambda: None)
    monkeypatch.setitem(platform._PROBES, "osmesa", lambda: None)
    monkeypatch.delenv("PYGLET_HEADLESS", raising=False)
    assert platform.select_platform("osmesa") == "osmesa"
    assert "PYGLET_HEADLESS" not in os.environ
    assert platform.select_platform("egl") == "egl"
    assert os.environ["PYGLET_HEADLESS"] == "true"
    monkeypatch.setenv("PYGLET_HEADLESS", "false")
    platform.select_platform("egl")
    assert os.environ["PYGLET_HEADLESS"] == "false"


def test_missing_debian_packages_asks_dpkg():
    assert platform.missing_debian_packages(["libc6", "paz6d-no-such-package"]) == ["paz6d-no-such-package"]


def test_real_probes_find_both_platforms_on_this_machine():
    # run.sh setup installs both; a failure here means the machine lacks a package it lists.
    assert platform._probe_egl() is None
    assert platform._probe_osmesa() is None


def test_a_missing_or_unloadable_library_is_named_with_the_reason(monkeypatch):
    assert platform._load_library("paz6d_no_such_library") == (None, "libpaz6d_no_such_library not found")
    monkeypatch.setattr(platform.ctypes.util, "find_library", lambda stem: f"lib{stem}.so.9")
    library, reason = platform._load_library("Gone")
    assert library is None and reason.startswith("cannot load libGone.so.9: ")
