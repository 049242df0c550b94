"""paz6d.backend.quaternion against scipy.spatial.transform.Rotation (an independent implementation).

Quaternions are compared up to sign (``q`` and ``-q`` are the same rotation). Tolerances of
1e-12..1e-10 cover float64 round-off of a handful of operations; looser ones carry a comment.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.spatial.transform import Rotation, Slerp

from paz6d.backend import quaternion
from paz6d.backend.checks import BLOCK_ROWS

PROPERTY = settings(max_examples=60, deadline=None)

component = st.floats(-1.0, 1.0, allow_nan=False, allow_subnormal=False)
special = st.sampled_from([[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, -1],
                           [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], [0.5, 0.5, 0.5, 0.5], [0.5, -0.5, 0.5, -0.5]])
unit_quaternions = st.one_of(
    special.map(np.array),
    st.tuples(component, component, component, component)
    .filter(lambda q: np.linalg.norm(q) > 1e-3).map(lambda q: np.array(q) / np.linalg.norm(q)))
quaternion_batches = st.lists(unit_quaternions, min_size=1, max_size=6).map(np.array)
rotation_vectors = st.tuples(*[st.floats(-6.0, 6.0, allow_nan=False, allow_subnormal=False)] * 3).map(np.array)
points = st.lists(st.tuples(*[st.floats(-10.0, 10.0, allow_nan=False, allow_subnormal=False)] * 3),
                  min_size=1, max_size=5).map(np.array)
EULER_AXES = ["xyz", "zyx", "xzy", "yxz", "zxz", "xyx", "yzy", "XYZ", "ZYX", "YZX", "ZXZ", "XZX", "YXY"]


def assert_same_rotation(actual, expected, atol=1e-12):
    """Element-wise equality of quaternion batches up to the sign of each quaternion."""
    actual, expected = np.atleast_2d(actual), np.atleast_2d(expected)
    error = np.minimum(np.abs(actual - expected).max(-1), np.abs(actual + expected).max(-1))
    assert error.max() <= atol, f"quaternion mismatch {error.max():.3g}"


def wrapped(angles):
    return np.mod(angles + np.pi, 2 * np.pi) - np.pi


@PROPERTY
@given(quaternion_batches)
def test_to_rotation_matrix_matches_scipy(q):
    np.testing.assert_allclose(quaternion.to_rotation_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-12)


@PROPERTY
@given(quaternion_batches)
def test_from_rotation_matrix_matches_scipy_and_is_canonical(q):
    matrices = Rotation.from_quat(q).as_matrix()
    result = quaternion.from_rotation_matrix(matrices)
    assert_same_rotation(result, q)
    assert np.all(result[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(result, axis=-1), 1.0, atol=1e-14)


def test_from_rotation_matrix_keeps_batch_shape():
    q = Rotation.random(12, random_state=3).as_quat().reshape(3, 4, 4)
    result = quaternion.from_rotation_matrix(quaternion.to_rotation_matrix(q))
    assert result.shape == (3, 4, 4)
    assert_same_rotation(result.reshape(-1, 4), q.reshape(-1, 4))


@PROPERTY
@given(quaternion_batches)
def test_to_rotation_vector_matches_scipy(q):
    vectors = quaternion.to_rotation_vector(q)
    # Same rotation, angle in [0, pi].
    assert_same_rotation(Rotation.from_rotvec(vectors).as_quat(), q, atol=1e-12)
    assert np.all(np.linalg.norm(vectors, axis=-1) <= np.pi + 1e-12)
    expected = Rotation.from_quat(q).as_rotvec()
    below_pi = np.linalg.norm(expected, axis=-1) < np.pi - 1e-6  # at pi, v and -v are both valid
    np.testing.assert_allclose(vectors[below_pi], expected[below_pi], atol=1e-12)


@PROPERTY
@given(st.lists(rotation_vectors, min_size=1, max_size=6).map(np.array))
def test_from_rotation_vector_matches_scipy(vectors):
    assert_same_rotation(quaternion.from_rotation_vector(vectors), Rotation.from_rotvec(vectors).as_quat())


@PROPERTY
@given(st.floats(0.0, 1e-7, allow_subnormal=False), unit_quaternions)
def test_rotation_vector_small_angle_series(angle, q):
    axis = q[:3] / max(np.linalg.norm(q[:3]), 1e-12) if np.linalg.norm(q[:3]) > 1e-6 else np.array([1.0, 0, 0])
    vector = axis / np.linalg.norm(axis) * angle
    result = quaternion.from_rotation_vector(vector)
    assert_same_rotation(result, Rotation.from_rotvec(vector).as_quat(), atol=1e-15)
    np.testing.assert_allclose(quaternion.to_rotation_vector(result), vector, atol=1e-15)


@PROPERTY
@given(st.lists(st.tuples(*[st.floats(-3.0, 3.0, allow_nan=False, allow_subnormal=False)] * 3),
                min_size=1, max_size=4).map(np.array),
       st.sampled_from(EULER_AXES))
def test_from_euler_matches_scipy(angles, axes):
    assert_same_rotation(quaternion.from_euler(angles, axes), Rotation.from_euler(axes, angles).as_quat())


@PROPERTY
@given(quaternion_batches, st.sampled_from(EULER_AXES))
def test_to_euler_matches_scipy_away_from_gimbal_lock(q, axes):
    angles = quaternion.to_euler(q, axes)
    assert_same_rotation(quaternion.from_euler(angles, axes), q, atol=1e-10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # scipy warns at gimbal lock
        expected = Rotation.from_quat(q).as_euler(axes)
    proper = axes[0].lower() == axes[2].lower()
    lock_distance = np.abs(np.sin(expected[:, 1])) if proper else np.abs(np.cos(expected[:, 1]))
    free = lock_distance > 1e-4
    # Angles near +-pi may come out on either side of the cut; 1e-9 absorbs arctan2 round-off
    # amplified by 1/lock_distance.
    np.testing.assert_allclose(wrapped(angles[free] - expected[free]), 0.0, atol=1e-9)


GIMBAL_LOCKS = [(axes, middle) for axes in EULER_AXES
                for middle in ((0.0, np.pi) if axes[0].lower() == axes[2].lower() else (-np.pi / 2, np.pi / 2))]


@pytest.mark.parametrize("axes, middle", GIMBAL_LOCKS)
def test_euler_round_trip_at_gimbal_lock(axes, middle):
    q = Rotation.from_euler(axes, [[0.3, middle, -1.1], [-2.0, middle, 0.4]]).as_quat()
    angles = quaternion.to_euler(q, axes)
    assert_same_rotation(quaternion.from_euler(angles, axes), q, atol=1e-9)
    np.testing.assert_allclose(angles[:, 2], 0.0)


def test_euler_axes_are_validated():
    for axes in ["xxy", "xYz", "xy", "abc"]:
        with pytest.raises(ValueError, match="axes"):
            quaternion.from_euler([0.0, 0.0, 0.0], axes)


@PROPERTY
@given(quaternion_batches, quaternion_batches)
def test_multiply_matches_scipy_composition(q1, q2):
    count = min(len(q1), len(q2))
    q1, q2 = q1[:count], q2[:count]
    expected = (Rotation.from_quat(q1) * Rotation.from_quat(q2)).as_quat()
    assert_same_rotation(quaternion.multiply(q1, q2), expected)
    # Composition order: applying q2 first then q1.
    point = np.array([0.3, -1.2, 2.0])
    np.testing.assert_allclose(quaternion.rotate(quaternion.multiply(q1, q2), point),
                               quaternion.rotate(q1, quaternion.rotate(q2, point)), atol=1e-12)


@PROPERTY
@given(quaternion_batches)
def test_inverse_and_conjugate_match_scipy(q):
    assert_same_rotation(quaternion.inverse(q), Rotation.from_quat(q).inv().as_quat())
    np.testing.assert_array_equal(quaternion.conjugate(q), q * [-1, -1, -1, 1])
    assert_same_rotation(quaternion.multiply(q, quaternion.inverse(q)), quaternion.identity((len(q),)))


@PROPERTY
@given(unit_quaternions, points)
def test_rotate_matches_scipy_apply(q, vectors):
    np.testing.assert_allclose(quaternion.rotate(q, vectors), Rotation.from_quat(q).apply(vectors), atol=1e-12)


@PROPERTY
@given(quaternion_batches, st.data())
def test_rotate_broadcasts_batches(q, data):
    vectors = data.draw(st.lists(st.tuples(*[st.floats(-5.0, 5.0, allow_nan=False)] * 3),
                                 min_size=len(q), max_size=len(q)).map(np.array))
    np.testing.assert_allclose(quaternion.rotate(q, vectors), Rotation.from_quat(q).apply(vectors), atol=1e-12)


@PROPERTY
@given(unit_quaternions, unit_quaternions, st.lists(st.floats(0.0, 1.0), min_size=1, max_size=5).map(np.array))
def test_slerp_matches_scipy(q0, q1, times):
    angle = (Rotation.from_quat(q0).inv() * Rotation.from_quat(q1)).magnitude()
    assume(angle < np.pi - 1e-3)  # the shortest arc is ambiguous at exactly pi
    expected = Slerp([0.0, 1.0], Rotation.from_quat([q0, q1]))(times).as_quat()
    result = quaternion.slerp(q0, q1, times)
    assert result.shape == (len(times), 4)
    assert_same_rotation(result, expected, atol=1e-10)


def test_slerp_endpoints_and_midpoint():
    q0 = quaternion.from_rotation_vector([0.0, 0.0, 0.2])
    q1 = -quaternion.from_rotation_vector([0.0, 0.0, 1.0])  # opposite sign: still the short way
    np.testing.assert_allclose(quaternion.slerp(q0, q1, 0.0), q0, atol=1e-15)
    assert_same_rotation(quaternion.slerp(q0, q1, 1.0), q1, atol=1e-15)
    assert_same_rotation(quaternion.slerp(q0, q1, 0.5), quaternion.from_rotation_vector([0, 0, 0.6]), atol=1e-15)
    assert_same_rotation(quaternion.slerp(q0, q0, 0.3), q0)


@PROPERTY
@given(quaternion_batches, quaternion_batches)
def test_angle_between_matches_scipy_magnitude(q0, q1):
    count = min(len(q0), len(q1))
    q0, q1 = q0[:count], q1[:count]
    expected = (Rotation.from_quat(q0).inv() * Rotation.from_quat(q1)).magnitude()
    np.testing.assert_allclose(quaternion.angle_between(q0, q1), expected, atol=1e-10)
    np.testing.assert_allclose(quaternion.angle_between(q0, -q0), 0.0, atol=1e-7)


def test_angle_between_is_accurate_for_tiny_angles():
    q0 = quaternion.random(seed=1)
    q1 = quaternion.multiply(q0, quaternion.from_rotation_vector([1e-9, 0.0, 0.0]))
    np.testing.assert_allclose(quaternion.angle_between(q0, q1), 1e-9, rtol=1e-6)


def test_random_is_seeded_unit_and_uniform():
    q = quaternion.random(20000, seed=7)
    assert q.shape == (20000, 4)
    np.testing.assert_array_equal(q, quaternion.random(20000, seed=7))
    assert not np.array_equal(q, quaternion.random(20000, seed=8))
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    assert quaternion.random(seed=np.random.default_rng(0)).shape == (4,)
    # Haar measure on SO(3): E[R] = 0 and the rotation angle has CDF (theta - sin theta) / pi.
    matrices = quaternion.to_rotation_matrix(q)
    assert np.abs(matrices.mean(axis=0)).max() < 0.02  # ~3 standard errors of 1/sqrt(3 * 20000)
    angles = Rotation.from_quat(q).magnitude()
    assert stats.kstest(angles, lambda theta: (theta - np.sin(theta)) / np.pi).pvalue > 0.01
    with pytest.raises(ValueError, match="n: expected a non-negative count"):
        quaternion.random(-1)


@PROPERTY
@given(quaternion_batches)
def test_canonical_picks_non_negative_w(q):
    result = quaternion.canonical(-q)
    assert np.all(result[:, 3] >= 0)
    assert_same_rotation(result, q, atol=0.0)


def test_canonical_breaks_w_zero_ties_on_xyz():
    q = np.array([[0.0, -0.6, 0.8, 0.0], [0.0, 0.6, -0.8, 0.0], [0.0, 0.0, -1.0, 0.0]])
    np.testing.assert_array_equal(quaternion.canonical(q), [[0, 0.6, -0.8, 0], [0, 0.6, -0.8, 0], [0, 0, 1, 0]])


def test_normalize_and_identity():
    np.testing.assert_allclose(quaternion.normalize([[0, 0, 0, 2.0], [1, 1, 1, 1]]),
                               [[0, 0, 0, 1], [0.5, 0.5, 0.5, 0.5]])
    with pytest.raises(ValueError, match="zero quaternion"):
        quaternion.normalize([0, 0, 0, 0])
    identity = quaternion.identity((2, 3))
    assert identity.shape == (2, 3, 4)
    np.testing.assert_array_equal(quaternion.to_rotation_matrix(identity), np.broadcast_to(np.eye(3), (2, 3, 3, 3)))


@pytest.mark.parametrize("function", [quaternion.to_rotation_matrix, quaternion.to_rotation_vector,
                                      quaternion.inverse, quaternion.canonical,
                                      lambda q: quaternion.rotate(q, [1.0, 0.0, 0.0]),
                                      lambda q: quaternion.to_euler(q, "xyz")])
def test_bad_quaternions_raise_value_error_naming_the_argument(function):
    with pytest.raises(ValueError, match=r"q: expected unit quaternions \(x, y, z, w\), found norm 1\.1"):
        function([0.0, 0.0, 0.0, 1.1])
    with pytest.raises(ValueError, match=r"q: contains NaN"):
        function([np.nan, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"q: expected shape \(\.\.\., 4\), got \(3,\)"):
        function([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"q: expected a numeric array of shape \(\.\.\., 4\)"):
        function("not a quaternion")


def test_other_bad_inputs_name_their_argument():
    with pytest.raises(ValueError, match=r"matrix: expected orthonormal rotation matrices"):
        quaternion.from_rotation_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match=r"matrix: expected shape \(\.\.\., 3, 3\), got \(2, 3\)"):
        quaternion.from_rotation_matrix(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"vector: expected shape \(\.\.\., 3\), got \(4,\)"):
        quaternion.from_rotation_vector([0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"points: expected shape \(\.\.\., 3\), got \(2, 2\)"):
        quaternion.rotate([0, 0, 0, 1.0], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"q1: expected unit quaternions"):
        quaternion.slerp([0, 0, 0, 1.0], [0, 0, 0, 2.0], 0.5)
    with pytest.raises(ValueError, match=r"angles: contains NaN"):
        quaternion.from_euler([0.0, np.nan, 0.0], "xyz")


def test_large_batches_span_several_blocks():
    count = 3 * BLOCK_ROWS + 17  # the conversions run block by block
    q = Rotation.random(count, random_state=4).as_quat()
    matrices = Rotation.from_quat(q).as_matrix()
    np.testing.assert_allclose(quaternion.to_rotation_matrix(q), matrices, atol=1e-12)
    assert_same_rotation(quaternion.from_rotation_matrix(matrices), q)
    vectors = np.random.default_rng(4).normal(size=(count, 3))
    np.testing.assert_allclose(quaternion.rotate(q, vectors), Rotation.from_quat(q).apply(vectors), atol=1e-12)
    broken = matrices.copy()
    broken[-1, 0, 0] = 1.5
    with pytest.raises(ValueError, match=r"matrix: expected orthonormal rotation matrices with det \+1"):
        quaternion.from_rotation_matrix(broken)
    broken[-1, 0, 0] = np.nan
    with pytest.raises(ValueError, match=r"matrix: contains NaN"):
        quaternion.from_rotation_matrix(broken)
    reflected = matrices.copy()
    reflected[BLOCK_ROWS + 1] *= -1
    with pytest.raises(ValueError, match=r"min det = -1"):
        quaternion.from_rotation_matrix(reflected)
    q[-1] *= 1.01
    with pytest.raises(ValueError, match=r"q: expected unit quaternions \(x, y, z, w\), found norm 1\.01"):
        quaternion.to_rotation_matrix(q)


def test_rotate_broadcasts_rotations_against_point_sets():
    q = Rotation.random(2, random_state=5).as_quat()
    vectors = np.random.default_rng(5).normal(size=(3, 3))
    result = quaternion.rotate(q[:, None, :], vectors)
    assert result.shape == (2, 3, 3)
    for index in range(2):
        np.testing.assert_allclose(result[index], Rotation.from_quat(q[index]).apply(vectors), atol=1e-12)
    np.testing.assert_allclose(quaternion.rotate(q, vectors[0]), Rotation.from_quat(q).apply(vectors[0]), atol=1e-12)
    assert quaternion.rotate(q[0], vectors[0]).shape == (3,)


@pytest.mark.parametrize("magnitude", [1e3, 1e200, 1e300])
def test_huge_rotation_vectors_give_the_reduced_rotation(magnitude):
    # The angle modulo 2*pi is what scipy computes from the same axis; both must be unit quaternions.
    q = quaternion.from_rotation_vector([magnitude, 0.0, 0.0])
    assert np.all(np.isfinite(q)) and np.isclose(np.linalg.norm(q), 1.0)
    reduced = np.mod(magnitude, 2 * np.pi)
    expected = Rotation.from_rotvec([reduced, 0.0, 0.0]).as_quat()
    assert min(np.abs(q - expected).max(), np.abs(q + expected).max()) < 1e-6


@pytest.mark.parametrize("t", [np.nan, np.inf, [0.5, np.nan]])
def test_slerp_rejects_non_finite_t(t):
    with pytest.raises(ValueError, match="t: expected finite"):
        quaternion.slerp([0, 0, 0, 1.0], [1.0, 0, 0, 0], t)
