"""Household-shaped distractors (paz6d.synthesis.household) and `paz6d generate --distractor-style household`."""

from __future__ import annotations

import numpy as np
import pytest

from data_gen.assets import load_assets
from data_gen.config import GenerationConfig
from data_gen.generator import generate
from data_gen.producer import image_generator
from paz6d.datasets.bop import BOPDataset
from paz6d.synthesis.household import SIZE_FACTORS, household_library, household_shapes
from paz6d.synthesis.occluders import distractor_library
from paz6d.synthesis.scene import sample_scene

NAMES = ("bowl", "mug", "cup", "bottle", "plate", "book")


def test_shapes_are_closed_outward_and_centred():
    side = 0.2
    for name, mesh in zip(NAMES, household_shapes(side), strict=True):
        assert mesh.is_watertight, name
        assert mesh.volume > 0, name  # outward normals
        assert np.allclose(mesh.bounds.mean(axis=0), 0.0, atol=1e-9), name
        assert 0.5 * side <= mesh.extents.max() <= 1.01 * side, name


def _axis_heights(mesh) -> np.ndarray:
    """Heights (metres above the mesh's bottom) of its vertices on the z axis."""
    on_axis = np.linalg.norm(mesh.vertices[:, :2], axis=1) < 1e-9
    return np.unique(np.round(mesh.vertices[on_axis, 2] - mesh.bounds[0, 2], 9))


def test_vessels_are_hollow_and_the_bottle_is_solid():
    side = 0.2
    bowl, mug, cup, bottle, plate, book = household_shapes(side)
    for name, vessel in (("bowl", bowl), ("cup", cup)):
        # the surface crosses the axis at the outer and inner bottom only: open above
        heights = _axis_heights(vessel)
        assert len(heights) == 2 and heights[0] == 0 and heights[1] < 0.2 * vessel.extents[2], name
    for name, vessel in (("bowl", bowl), ("mug", mug), ("cup", cup)):
        assert vessel.volume < 0.5 * vessel.convex_hull.volume, name
    assert np.allclose(_axis_heights(bottle), [0.0, side])  # closed at the top
    assert bottle.volume > 0.8 * bottle.convex_hull.volume
    assert plate.extents[2] < 0.1 * plate.extents[0] and book.extents[2] < 0.2 * book.extents[0]


def test_library_is_white_at_three_sizes():
    library = household_library(0.1)
    assert len(library) == len(NAMES) * len(SIZE_FACTORS)
    assert all(np.all(mesh.visual.vertex_colors == 255) for mesh in library)
    largest = [max(mesh.extents.max() for mesh in library[i * len(NAMES):(i + 1) * len(NAMES)])
               for i in range(len(SIZE_FACTORS))]
    assert np.allclose(largest, np.array(SIZE_FACTORS) * 0.1)


@pytest.mark.parametrize("side", [0.0, -1.0, float("nan")])
def test_bad_size_is_refused(side):
    with pytest.raises(ValueError, match="side"):
        household_shapes(side)


def test_household_style_adds_tinted_shapes_that_scenes_use(shared_data, tmp_path):
    mesh = shared_data / "bop_lmo" / "models" / "obj_000001.ply"
    config = GenerationConfig(meshes=(mesh,), out=tmp_path / "set", num_images=3, width=96, height=72, seed=7,
                              mesh_scale=0.001, objects_per_image=(1, 1), distractors=6,
                              distractor_style="household", neutral_distractors=0.5)
    assets = load_assets(config)
    primitives = len(distractor_library(1.0))
    assert len(assets.distractors) == primitives + len(NAMES) * len(SIZE_FACTORS)
    assert assets.distractor_tinted.all()
    used = np.concatenate([sample_scene(image_generator(config.seed, index), assets, config).clutter_indices
                           for index in range(20)])
    assert (used >= primitives).any() and (used < primitives).any()
    generate(config, show_progress=False)
    assert len(BOPDataset(config.out, split="train")) == 3
