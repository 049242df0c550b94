"""Exact nearest-neighbour distances from rigidly moved copies of a point set (for ADD-S / ADI).

ADI asks, for every estimate, how far each model point under the ground-truth pose lies from the
nearest model point under the estimated pose. Rigid motions preserve distances, so the question
becomes: for the moved copy ``A x + b`` of every model point ``x`` (``A`` a rotation), how far is
the nearest model point? :class:`PointTree` answers it with a KD-tree built once per object and
searched by numba-compiled kernels:

* the queries go 32 at a time in the tree's point order, so each block is compact in space; a block
  starts from the leaf nearest its centre and walks that leaf's precomputed list of nearest leaves
  until the next one is provably out of reach, scanning a leaf for all 32 queries at once (the
  distances of one point to 32 queries are computed in SIMD registers) when its box is nearer to
  some query than that query's best point so far;
* the minimum of the same float64 distances is found whatever the pruning, and the square roots are
  summed in tree order, so the means do not depend on the search strategy or the thread count;
* estimates are spread over threads (``workers``), each estimate searched by one thread.

The kernels live in :mod:`evaluation.pose_error_kernels`, imported (and compiled, then cached on disk
by numba) on first use, so ``import evaluation`` stays light.
"""

from __future__ import annotations

import numpy as np

LEAF_SIZE = 32  # points per leaf; 16-64 perform alike on BOP models_eval meshes


class PointTree:
    """KD-tree on ``(N, 3)`` points for :meth:`mean_nearest_distance` (exact, float64)."""

    def __init__(self, points: np.ndarray, leaf_size: int = LEAF_SIZE):
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
            raise ValueError(f"points: expected a non-empty (N, 3) array, got shape {points.shape}")
        if not np.all(np.isfinite(points)):
            raise ValueError("points: expected finite coordinates, got NaN or inf")
        from evaluation import pose_error_kernels

        tree = pose_error_kernels.build_tree(np.ascontiguousarray(points), int(leaf_size))
        order, self._start, self._end, self._left, self._right, self._low, self._high = tree
        self._coords = tuple(np.ascontiguousarray(points[order, axis]) for axis in range(3))  # tree order
        self._leaves = pose_error_kernels.leaf_neighbours(self._start, self._end, self._left, self._right,
                                                          self._low, self._high)

    @property
    def n(self) -> int:
        """Number of points in the tree."""
        return len(self._coords[0])

    @property
    def points(self) -> np.ndarray:
        """``(N, 3)`` the points in tree order, the order in which the means sum the distances."""
        return np.stack(self._coords, axis=1)

    def mean_nearest_distance(self, A: np.ndarray, b: np.ndarray, workers: int = 1) -> np.ndarray:
        """``(E,)``: for each ``(A[e], b[e])`` the mean over the tree's points ``x`` of the distance
        from ``A[e] x + b[e]`` to the nearest tree point (unit of the points).

        Args:
            A: ``(E, 3, 3)`` rotations (distances are exact for any matrix; the search is fastest
                when ``A`` is close to a rotation and ``b`` small, i.e. for good estimates).
            b: ``(E, 3)`` translations.
            workers: threads (-1 = all cores numba may use).
        """
        A = np.ascontiguousarray(A, dtype=np.float64)
        b = np.ascontiguousarray(b, dtype=np.float64)
        if A.ndim != 3 or A.shape[1:] != (3, 3) or b.shape != (len(A), 3):
            raise ValueError(f"A, b: expected (E, 3, 3) and (E, 3), got {A.shape} and {b.shape}")
        if len(A) == 0:
            return np.empty(0)
        import numba

        from evaluation import pose_error_kernels

        available = numba.config.NUMBA_NUM_THREADS
        threads = available if workers == -1 else max(1, min(int(workers), available))
        arrays = (A, b, *self._coords, self._left, self._right, self._low, self._high, *self._leaves)
        if threads == 1:  # the serial kernel: loading numba's threading layer costs time too
            return pose_error_kernels.mean_nearest_distances(*arrays)
        previous = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            return pose_error_kernels.mean_nearest_distances_parallel(*arrays)
        finally:
            numba.set_num_threads(previous)
