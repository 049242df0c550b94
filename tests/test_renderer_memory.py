"""One renderer, 2,000 frames: resident memory stays flat (no per-frame GL or Python leak)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from paz6d.backend import quaternion
from paz6d.backend.transform import from_rotation_translation
from renderers import Light, Lighting, Renderer


def resident_megabytes() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("VmRSS not in /proc/self/status")


@pytest.mark.slow  # 2,000 renders
def test_two_thousand_frames_do_not_grow_memory():
    meshes = [trimesh.creation.icosphere(subdivisions=2, radius=0.03), trimesh.creation.box((0.04, 0.05, 0.03))]
    K = np.array([[80.0, 0, 31.5], [0, 80.0, 31.5], [0, 0, 1]])
    rotations = quaternion.to_rotation_matrix(quaternion.random(2000, seed=0))
    generator = np.random.default_rng(0)
    with Renderer(64, 64) as renderer:
        baseline = None
        for frame in range(2000):
            T = from_rotation_translation(rotations[frame], [0.0, 0.0, 0.5])
            lighting = Lighting(ambient=tuple(generator.uniform(0, 0.5, 3)),
                                lights=(Light("point", intensity=generator.uniform(0.5, 2),
                                              position=tuple(generator.uniform(-0.2, 0.2, 3))),))
            out = renderer.render(K, [(meshes[frame % 2], T)], lighting=lighting,
                                  tints=generator.uniform(0.5, 1.5, (1, 3)))
            assert out.masks[0].any()
            if frame == 199:
                baseline = resident_megabytes()
        growth = resident_megabytes() - baseline
    assert growth < 8.0, f"resident memory grew by {growth:.1f} MB over 1,800 frames"
