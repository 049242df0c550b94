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
    """Imports TensorFlow (through the guard) before any test runs.

    Mesa's llvmpipe and TensorFlow's LLVM crash together unless TensorFlow is loaded first; a
    test that imports TensorFlow lazily (directly or through a model/pipeline module) after a
    renderer test created a GL context would segfault the whole session. Importing it up front
    costs a few seconds once per session and removes the ordering hazard entirely.
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()


@pytest.fixture(scope="session")
def two_object_scenes(tmp_path_factory, shared_data) -> Path:
    """Six 160x120 images of two LM-O meshes (the can and the driller), as `paz6d generate` writes them
    (read-only: the SSD tests train on them)."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    out = tmp_path_factory.mktemp("two_object_scenes")
    models = shared_data / "bop_lmo" / "models"
    config = GenerationConfig(meshes=(models / "obj_000005.ply", models / "obj_000008.ply"), out=out, num_images=6,
                              width=160, height=120, mesh_scale=0.001, objects_per_image=(2, 2), distractors=1,
                              seed=3)
    generate(config, workers=1, show_progress=False)
    return out
