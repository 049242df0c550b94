"""Shared fixtures (the read-only test data folder next to the repository) and the session's
TensorFlow/OpenGL ordering."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (skips the test when it is absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")
    return SHARED_DATA


def pytest_collection_finish(session: pytest.Session) -> None:
    """Imports TensorFlow (through the guard) before any test runs when a collected test uses it.

    Mesa's llvmpipe and TensorFlow's LLVM crash together unless TensorFlow is loaded first; a
    test that imports TensorFlow lazily after a renderer test created a GL context would
    segfault the whole session.
    """
    files = {Path(str(item.fspath)) for item in session.items}
    if any("tensorflow_guard" in path.read_text(errors="ignore") for path in files if path.suffix == ".py"):
        from paz6d.backend.tensorflow_guard import import_tensorflow

        import_tensorflow()
