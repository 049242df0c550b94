"""PointTree (the ADI search) against brute-force nearest neighbours written here."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from evaluation.point_tree import PointTree


def brute_force_means(points: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    means = []
    for rotation, translation in zip(A, b):
        queries = points @ rotation.T + translation
        squared = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=-1)
        means.append(np.sqrt(squared.min(axis=1)).mean())
    return np.array(means)


def surface_points(count: int, seed: int) -> np.ndarray:
    """Points on an ellipsoid surface with some clumps, mm-sized like a BOP model."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = directions * np.array([60.0, 35.0, 20.0])
    points[: count // 5] = points[0] + rng.normal(scale=0.5, size=(count // 5, 3))  # a dense clump
    return points


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31), count=st.integers(1, 400), leaf_size=st.integers(1, 40),
       shift=st.floats(0.0, 500.0))
def test_mean_nearest_distance_equals_brute_force(seed, count, leaf_size, shift):
    rng = np.random.default_rng(seed)
    points = surface_points(count, seed)
    A = Rotation.random(6, random_state=seed).as_matrix()
    A[0] = np.eye(3)
    b = rng.normal(size=(6, 3)) * np.array([0.0, 1.0, 10.0, 50.0, shift, shift])[:, None]
    got = PointTree(points, leaf_size=leaf_size).mean_nearest_distance(A, b)
    np.testing.assert_allclose(got, brute_force_means(points, A, b), rtol=1e-12, atol=1e-9)


def sequential_brute_force_means(tree: PointTree, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The means as the kernel defines them, by brute force: queries ``A x + b`` evaluated term by
    term, squared distances ``dx² + dy² + dz²`` in that order, square roots summed one by one in tree
    order, divided by N."""
    points = tree.points
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    means = []
    for rotation, translation in zip(A, b):
        queries = [rotation[row, 0] * x + rotation[row, 1] * y + rotation[row, 2] * z + translation[row]
                   for row in range(3)]
        squared = ((x[None, :] - queries[0][:, None]) ** 2 + (y[None, :] - queries[1][:, None]) ** 2
                   + (z[None, :] - queries[2][:, None]) ** 2)
        means.append(np.add.accumulate(np.sqrt(squared.min(axis=1)))[-1] / len(points))
    return np.array(means)


@pytest.mark.parametrize("leaf_size", [1, 3, 32])
def test_mean_nearest_distance_is_bit_identical_to_brute_force(leaf_size):
    """Every pruning path (home leaf, neighbour list, tree search when the list cannot cover the
    reach: leaf size 1 gives 1,200 leaves for lists of 128) finds the same minima bit for bit."""
    rng = np.random.default_rng(7)
    points = surface_points(1200, 7)
    A = Rotation.random(8, random_state=8).as_matrix()
    A[0] = np.eye(3)
    b = rng.normal(size=(8, 3)) * np.array([0.0, 0.5, 3.0, 10.0, 40.0, 150.0, 1000.0, 5000.0])[:, None]
    tree = PointTree(points, leaf_size=leaf_size)
    np.testing.assert_array_equal(tree.mean_nearest_distance(A, b), sequential_brute_force_means(tree, A, b))
    assert sorted(map(tuple, tree.points)) == sorted(map(tuple, points))


def test_identity_gives_zero_and_duplicates_are_handled():
    points = np.repeat(surface_points(50, 1), 3, axis=0)  # every point three times
    tree = PointTree(points, leaf_size=4)
    assert tree.n == 150
    assert tree.mean_nearest_distance(np.eye(3)[None], np.zeros((1, 3)))[0] == 0.0


def test_result_does_not_depend_on_thread_count():
    points = surface_points(2000, 3)
    A = Rotation.random(40, random_state=4).as_matrix()
    b = np.random.default_rng(5).normal(scale=20.0, size=(40, 3))
    tree = PointTree(points)
    one = tree.mean_nearest_distance(A, b, workers=1)
    np.testing.assert_array_equal(tree.mean_nearest_distance(A, b, workers=-1), one)
    np.testing.assert_array_equal(tree.mean_nearest_distance(A, b, workers=2), one)


def test_empty_batch_and_bad_input():
    tree = PointTree(surface_points(10, 0))
    assert tree.mean_nearest_distance(np.empty((0, 3, 3)), np.empty((0, 3))).shape == (0,)
    with pytest.raises(ValueError, match=r"points: expected a non-empty \(N, 3\)"):
        PointTree(np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"points: expected a non-empty \(N, 3\)"):
        PointTree(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="finite"):
        PointTree(np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match=r"A, b: expected \(E, 3, 3\) and \(E, 3\)"):
        tree.mean_nearest_distance(np.eye(3)[None], np.zeros((2, 3)))
