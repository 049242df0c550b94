"""`--backend ray` on a local Ray instance of 2 CPUs writes the same bytes as the local backend."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import pytest
import ray

from data_gen.config import GenerationConfig
from data_gen.generator import generate


def tree_digest(root: Path) -> dict[str, str]:
    return {str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(root.rglob("*")) if path.is_file()}


@pytest.fixture
def local_ray():
    """A local Ray instance limited to 2 CPUs, as a cluster that ``generate`` joins (not starts)."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        yield ray
    finally:
        ray.shutdown()


@pytest.mark.timeout(180)  # about 20 s on 2 busy shared cores; a hung actor must not hang the suite
def test_ray_backend_matches_local_backend(shared_data, tmp_path, local_ray):
    assert local_ray.cluster_resources()["CPU"] == 2
    mesh = shared_data / "bop_lmo" / "models" / "obj_000001.ply"
    config = GenerationConfig(meshes=(mesh,), out=tmp_path / "local", num_images=4, width=64, height=48, seed=11,
                              mesh_scale=0.001, objects_per_image=(1, 2), images_per_scene=3)
    generate(config, show_progress=False)
    distributed = dataclasses.replace(config, out=tmp_path / "ray")
    summary = generate(distributed, workers=2, backend="ray", show_progress=False)
    assert summary.images_rendered == 4
    assert tree_digest(distributed.out) == tree_digest(config.out)
    assert local_ray.is_initialized()  # generate used the running instance and left it to its owner
