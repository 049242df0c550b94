"""Shared fixtures (the read-only test data folder next to the repository) and the session's
TensorFlow/OpenGL ordering."""

from __future__ import annotations

from collections.abc import Callable
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
def two_object_scenes(tmp_path_factory, shared_data) -> Callable[[int], Path]:
    """``scenes(seed)``: the folder of six 160x120 images of two LM-O meshes (the can and the driller) with
    visible masks, as `paz6d generate` writes them with that seed; made once per seed, read-only."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    made: dict[int, Path] = {}

    def scenes(seed: int) -> Path:
        if seed not in made:
            out = tmp_path_factory.mktemp(f"two_object_scenes_{seed}")
            models = shared_data / "bop_lmo" / "models"
            config = GenerationConfig(meshes=(models / "obj_000005.ply", models / "obj_000008.ply"), out=out,
                                      num_images=6, width=160, height=120, mesh_scale=0.001,
                                      objects_per_image=(2, 2), distractors=1, seed=seed)
            generate(config, workers=1, show_progress=False)
            made[seed] = out
        return made[seed]

    return scenes
