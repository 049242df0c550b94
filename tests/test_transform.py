"""paz6d.backend.transform against scipy's RigidTransform / Rotation / Slerp."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import RigidTransform, Rotation, Slerp

from paz6d.backend import transform

PROPERTY = settings(max_examples=40, deadline=None)
seeds = st.integers(0, 2**32 - 1)


def random_poses(seed: int, count: int | None = None) -> np.ndarray:
    generator = np.random.default_rng(seed)
    rotation = Rotation.random(count, random_state=generator)
    translation = generator.uniform(-2.0, 2.0, (3,) if count is None else (count, 3))
    return RigidTransform.from_components(translation, rotation).as_matrix()


@PROPERTY
@given(seeds)
def test_from_and_to_rotation_translation_round_trip(seed):
    T = random_poses(seed, 5)
    rotation, translation = transform.to_rotation_translation(T)
    np.testing.assert_array_equal(rotation, T[:, :3, :3])
    np.testing.assert_array_equal(translation, T[:, :3, 3])
    np.testing.assert_array_equal(transform.from_rotation_translation(rotation, translation), T)


def test_from_rotation_translation_broadcasts():
    rotation = Rotation.random(4, random_state=1).as_matrix()
    T = transform.from_rotation_translation(rotation, [0.1, 0.2, 0.3])
    assert T.shape == (4, 4, 4)
    np.testing.assert_array_equal(T[:, :3, 3], np.tile([0.1, 0.2, 0.3], (4, 1)))
    np.testing.assert_array_equal(T[:, 3], np.tile([0, 0, 0, 1.0], (4, 1)))


@PROPERTY
@given(seeds)
def test_compose_matches_scipy(seed):
    T_a2b, T_b2c = random_poses(seed, 3), random_poses(seed + 1, 3)
    expected = (RigidTransform.from_matrix(T_b2c) * RigidTransform.from_matrix(T_a2b)).as_matrix()
    np.testing.assert_allclose(transform.compose(T_b2c, T_a2b), expected, atol=1e-12)
    point = np.array([[0.1, -0.4, 0.9]])
    np.testing.assert_allclose(transform.apply(transform.compose(T_b2c[0], T_a2b[0]), point),
                               transform.apply(T_b2c[0], transform.apply(T_a2b[0], point)), atol=1e-12)


@PROPERTY
@given(seeds)
def test_invert_matches_scipy(seed):
    T = random_poses(seed, 4)
    inverse = transform.invert(T)
    np.testing.assert_allclose(inverse, RigidTransform.from_matrix(T).inv().as_matrix(), atol=1e-12)
    np.testing.assert_allclose(inverse @ T, np.broadcast_to(np.eye(4), (4, 4, 4)), atol=1e-12)


@PROPERTY
@given(seeds, st.integers(1, 20))
def test_apply_matches_scipy(seed, count):
    T = random_poses(seed)
    points = np.random.default_rng(seed).normal(size=(count, 3))
    np.testing.assert_allclose(transform.apply(T, points), RigidTransform.from_matrix(T).apply(points), atol=1e-12)


def test_apply_batched_poses_to_batched_point_sets():
    T = random_poses(3, 2)
    points = np.random.default_rng(3).normal(size=(2, 5, 3))
    result = transform.apply(T, points)
    assert result.shape == (2, 5, 3)
    for index in range(2):
        np.testing.assert_allclose(result[index], RigidTransform.from_matrix(T[index]).apply(points[index]),
                                   atol=1e-12)


@PROPERTY
@given(seeds, st.lists(st.floats(0.0, 1.0), min_size=1, max_size=4))
def test_interpolate_is_slerp_plus_linear_translation(seed, times):
    T0, T1 = random_poses(seed), random_poses(seed + 7)
    times = np.asarray(times)
    result = transform.interpolate(T0, T1, times)
    assert result.shape == (len(times), 4, 4)
    rotations = Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]]))
    np.testing.assert_allclose(result[:, :3, :3], Slerp([0, 1], rotations)(times).as_matrix(), atol=1e-9)
    expected_translation = T0[:3, 3] + times[:, None] * (T1[:3, 3] - T0[:3, 3])
    np.testing.assert_allclose(result[:, :3, 3], expected_translation, atol=1e-12)


def test_interpolate_endpoints():
    T0, T1 = random_poses(11), random_poses(12)
    np.testing.assert_allclose(transform.interpolate(T0, T1, 0.0), T0, atol=1e-12)
    np.testing.assert_allclose(transform.interpolate(T0, T1, 1.0), T1, atol=1e-12)


def test_bad_transforms_raise_value_error_naming_the_argument():
    T = random_poses(0)
    broken = T.copy()
    broken[3] = [0, 0, 1, 1]
    with pytest.raises(ValueError, match=r"T: expected last row \[0, 0, 0, 1\]"):
        transform.invert(broken)
    scaled = T.copy()
    scaled[:3, :3] *= 2
    with pytest.raises(ValueError, match=r"T_b2c\[\.\.\., :3, :3\]: expected orthonormal rotation matrices"):
        transform.compose(scaled, T)
    with pytest.raises(ValueError, match=r"T: expected shape \(\.\.\., 4, 4\), got \(3, 4\)"):
        transform.apply(T[:3], np.zeros((1, 3)))
    with pytest.raises(ValueError, match=r"points: expected shape \(\.\.\., 3\), got \(2, 2\)"):
        transform.apply(T, np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"translation: contains NaN"):
        transform.from_rotation_translation(np.eye(3), [0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match=r"rotation_matrix: expected orthonormal rotation matrices with det \+1"):
        transform.from_rotation_translation(np.diag([1.0, 1.0, -1.0]), [0.0, 0.0, 0.0])
