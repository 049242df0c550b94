"""`--backend ray` on a local Ray instance writes the same bytes as the local backend."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import pytest

from data_gen.config import GenerationConfig
from data_gen.generator import generate

ray = pytest.importorskip("ray")


def tree_digest(root: Path) -> dict[str, str]:
    return {str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(root.rglob("*")) if path.is_file()}


@pytest.mark.slow  # starting Ray takes about a minute on 2 shared cores
def test_ray_backend_matches_local_backend(shared_data, tmp_path):
    mesh = shared_data / "bop_lmo" / "models" / "obj_000001.ply"
    config = GenerationConfig(meshes=(mesh,), out=tmp_path / "local", num_images=4, width=64, height=48, seed=11,
                              mesh_scale=0.001, objects_per_image=(1, 2), images_per_scene=3)
    generate(config, show_progress=False)
    distributed = dataclasses.replace(config, out=tmp_path / "ray")
    summary = generate(distributed, workers=2, backend="ray", show_progress=False)
    assert summary.images_rendered == 4
    assert tree_digest(distributed.out) == tree_digest(config.out)
