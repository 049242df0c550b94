"""The viewpoint convention (elevation, in-plane angle): hand-made cameras, the generator's draws, rolls."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from paz6d.backend.viewpoints import ViewpointRange, elevation_and_inplane
from paz6d.synthesis.sampling import random_rotation

# A camera on the model's +x axis looking at the origin, model z up in the image (OpenCV: x right, y down, z
# forward): rows are the camera axes in model coordinates.
SIDE_VIEW = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])


def _rolled(rotation, degrees):
    """The camera turned about its optical axis by ``degrees`` (image x towards image y)."""
    return Rotation.from_euler("z", degrees, degrees=True).as_matrix() @ rotation


def test_hand_made_cameras():
    above = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # looking straight down the z axis
    below = np.diag([1.0, 1.0, 1.0])                                         # looking up along +z
    sine, cosine = np.sin(np.radians(40)), np.cos(np.radians(40))  # the side camera raised to 40 degrees
    tilted = np.array([[0.0, 1.0, 0.0], [sine, 0.0, -cosine], [-cosine, 0.0, -sine]])
    elevation, inplane = elevation_and_inplane(np.stack([SIDE_VIEW, above, below, tilted, _rolled(SIDE_VIEW, 30)]))
    np.testing.assert_allclose(elevation, [0.0, 90.0, -90.0, 40.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(inplane, [0.0, 0.0, 0.0, 0.0, 30.0], atol=1e-9)
    # a positive in-plane angle tilts the model's up axis towards the image's right
    assert (_rolled(SIDE_VIEW, 30) @ [0.0, 0.0, 1.0])[0] > 0
    # the tilted camera sees the model origin from above: its centre lies at +z in the model frame
    assert (-tilted.T @ [0.0, 0.0, 1.0])[2] > 0 and np.isclose(np.linalg.det(tilted), 1.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(-90, 90), st.floats(0, 90), st.floats(0, 180), st.integers(0, 2**32 - 1))
def test_every_rotation_the_generator_draws_lies_in_the_range_of_its_settings(low, width, inplane, seed):
    elevations = (low, min(low + width, 90.0))
    rotations = [random_rotation(np.random.default_rng(seed + i), "view-sphere", elevations, inplane) for i in range(5)]
    assert ViewpointRange(elevations, inplane).widened(1e-6).contains(np.stack(rotations)).all()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-170, 170))
def test_a_roll_about_the_optical_axis_adds_to_the_in_plane_angle_only(seed, roll):
    rotation = Rotation.random(random_state=seed).as_matrix()
    elevation, inplane = elevation_and_inplane(rotation)
    if abs(elevation[0]) > 85:  # no in-plane angle near the poles
        return
    rolled_elevation, rolled_inplane = elevation_and_inplane(_rolled(rotation, roll))
    np.testing.assert_allclose(rolled_elevation, elevation, atol=1e-7)
    np.testing.assert_allclose((rolled_inplane - inplane - roll + 180) % 360 - 180, 0.0, atol=1e-6)
    # the elevation is the angle of the object->camera direction (model frame) above the model's xy plane
    direction = rotation.T @ [0.0, 0.0, -1.0]
    np.testing.assert_allclose(elevation, np.degrees(np.arcsin(direction[2])), atol=1e-7)


def test_range_contains_widens_and_describes():
    from_below = np.diag([1.0, 1.0, 1.0])  # elevation -90
    rotations = np.stack([SIDE_VIEW, _rolled(SIDE_VIEW, 50), from_below, _rolled(SIDE_VIEW, 180)])
    upright = ViewpointRange((-10, 80), 45)
    assert upright.contains(rotations).tolist() == [True, False, False, False]
    assert upright.widened(10).contains(rotations).tolist() == [True, True, False, False]
    assert ViewpointRange((15, 80), 30).widened(15) == ViewpointRange((0, 90), 45)
    assert ViewpointRange((-85, 85), 170).widened(20) == ViewpointRange()
    assert ViewpointRange().is_everything and not upright.is_everything and ViewpointRange().contains(rotations).all()
    assert upright.describe() == "elevation -10..80 degrees, in-plane within ±45 degrees"


@pytest.mark.parametrize("arguments, message", [
    (((50, 10), 30), "elevation_degrees: expected"), (((-100, 10), 30), "elevation_degrees: expected"),
    (((0, 10, 20), 30), "elevation_degrees: expected"), (((0, float("nan")), 30), "elevation_degrees: expected"),
    (((0, 90), -1), "inplane_degrees: expected"), (((0, 90), 181), "inplane_degrees: expected"),
    (((0, 90), float("nan")), "inplane_degrees: expected"),
])
def test_bad_ranges_are_refused(arguments, message):
    with pytest.raises(ValueError, match=message):
        ViewpointRange(*arguments)
    with pytest.raises(ValueError, match="margin_degrees"):
        ViewpointRange().widened(-1)
