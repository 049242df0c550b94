"""The viewpoint convention (elevation, in-plane angle): hand-made cameras, the generator's draws, rolls; the
look-at and in-plane rotations every camera construction shares."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from paz6d.backend.viewpoints import ViewpointRange, elevation_and_inplane, in_plane_rotation, look_at_rotation
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


def test_look_at_of_the_side_camera_and_a_parallel_up_is_refused():
    np.testing.assert_allclose(look_at_rotation([-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]), SIDE_VIEW, atol=1e-12)
    with pytest.raises(ValueError, match="up: expected a direction not parallel"):
        look_at_rotation([0.0, 0.0, -1.0], [0.0, 0.0, 2.0])


unit_vectors = st.tuples(*[st.floats(-1, 1)] * 3).map(np.array).filter(lambda v: np.linalg.norm(v) > 0.1)


@settings(max_examples=200, deadline=None)
@given(forward=unit_vectors, up=unit_vectors)
def test_look_at_points_the_camera_along_forward_with_up_image_up(forward, up):
    forward = forward / np.linalg.norm(forward)
    if np.linalg.norm(np.cross(forward, up)) < 1e-3:
        return
    rotation = look_at_rotation(forward, up)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(rotation @ forward, [0.0, 0.0, 1.0], atol=1e-12)  # forward is the optical axis
    up_in_camera = rotation @ up
    assert abs(up_in_camera[0]) < 1e-12 and up_in_camera[1] < 0  # up: no sideways part, towards image-up (-y)
    # batched over leading axes, the same as one at a time
    np.testing.assert_allclose(look_at_rotation(np.stack([forward, -forward]), up)[0], rotation, atol=0)


@settings(max_examples=100, deadline=None)
@given(angle=st.floats(-10, 10))
def test_in_plane_rotation_matches_scipy_about_the_optical_axis(angle):
    expected = Rotation.from_euler("z", angle).as_matrix()
    np.testing.assert_allclose(in_plane_rotation(angle), expected, atol=1e-12)
    np.testing.assert_allclose(in_plane_rotation([[angle, 0.0]])[0, 0], expected, atol=1e-12)
    assert in_plane_rotation(np.zeros((2, 5))).shape == (2, 5, 3, 3)
