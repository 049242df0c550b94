"""numba kernels of the pose errors: the KD-tree of :class:`evaluation.point_tree.PointTree` (build and
seeded search, for ADI), the MSSD and MSPD maxima over points / minima over symmetries, and the
means of ADD and of the 2D projection error (one pass over the points per estimate).

Tree layout (arrays indexed by node, root 0): ``start``/``end`` index the points of the node in
tree order, ``left``/``right`` are the children (-1 for a leaf), ``low``/``high`` the tight
``(nodes, 3)`` bounding box. Nodes split at the median of their widest axis.
"""

from __future__ import annotations

import numba
import numpy as np

STACK_DEPTH = 128  # far above the depth of a median-split tree on any realistic point count


@numba.njit(cache=True)
def build_tree(points, leaf_size):
    """``(order, start, end, left, right, low, high)`` for ``(N, 3)`` float64 ``points``."""
    count = points.shape[0]
    order = np.arange(count)
    capacity = 4 * (count // leaf_size + 1) + 1
    start = np.empty(capacity, np.int64)
    end = np.empty(capacity, np.int64)
    left = np.full(capacity, -1, np.int64)
    right = np.full(capacity, -1, np.int64)
    low = np.empty((capacity, 3))
    high = np.empty((capacity, 3))
    nodes = 1
    start[0], end[0] = 0, count
    pending = np.empty(capacity, np.int64)
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = pending[top]
        first, last = start[node], end[node]
        for axis in range(3):
            low[node, axis] = np.inf
            high[node, axis] = -np.inf
        for i in range(first, last):
            for axis in range(3):
                value = points[order[i], axis]
                low[node, axis] = min(low[node, axis], value)
                high[node, axis] = max(high[node, axis], value)
        if last - first <= leaf_size:
            continue
        widest = 0
        for axis in range(1, 3):
            if high[node, axis] - low[node, axis] > high[node, widest] - low[node, widest]:
                widest = axis
        members = order[first:last].copy()
        ranks = np.argsort(points[members, widest], kind="mergesort")
        order[first:last] = members[ranks]
        middle = first + (last - first) // 2
        left[node], right[node] = nodes, nodes + 1
        start[nodes], end[nodes] = first, middle
        start[nodes + 1], end[nodes + 1] = middle, last
        pending[top], pending[top + 1] = nodes, nodes + 1
        top += 2
        nodes += 2
    return order, start[:nodes], end[:nodes], left[:nodes], right[:nodes], low[:nodes].copy(), high[:nodes].copy()


@numba.njit(cache=True, inline="always")
def _box_distance_squared(x, y, z, low, high, node):
    """Squared distance from ``(x, y, z)`` to the bounding box of ``node`` (0 inside); written with
    ``max`` instead of branches (the branches are unpredictable and cost ~20 % of the ADI search)."""
    dx = max(low[node, 0] - x, x - high[node, 0], 0.0)
    dy = max(low[node, 1] - y, y - high[node, 1], 0.0)
    dz = max(low[node, 2] - z, z - high[node, 2], 0.0)
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, parallel=True)
def mean_nearest_distances(A, b, points, start, end, left, right, low, high):
    """``(E,)`` mean over ``points`` (tree order) of the distance from ``A[e] x + b[e]`` to the
    nearest of ``points``. Each query starts from the previous query's answer as an upper bound."""
    estimates, count = A.shape[0], points.shape[0]
    means = np.empty(estimates)
    for e in numba.prange(estimates):
        stack = np.empty(STACK_DEPTH, np.int64)
        bounds = np.empty(STACK_DEPTH)
        nearest, total = 0, 0.0
        for n in range(count):
            x = A[e, 0, 0] * points[n, 0] + A[e, 0, 1] * points[n, 1] + A[e, 0, 2] * points[n, 2] + b[e, 0]
            y = A[e, 1, 0] * points[n, 0] + A[e, 1, 1] * points[n, 1] + A[e, 1, 2] * points[n, 2] + b[e, 1]
            z = A[e, 2, 0] * points[n, 0] + A[e, 2, 1] * points[n, 1] + A[e, 2, 2] * points[n, 2] + b[e, 2]
            best = (points[nearest, 0] - x) ** 2 + (points[nearest, 1] - y) ** 2 + (points[nearest, 2] - z) ** 2
            own = (points[n, 0] - x) ** 2 + (points[n, 1] - y) ** 2 + (points[n, 2] - z) ** 2
            if own < best:
                best, nearest = own, n
            stack[0], bounds[0], top = 0, 0.0, 1
            while top > 0:
                top -= 1
                node = stack[top]
                if bounds[top] >= best:
                    continue
                if left[node] < 0:
                    for p in range(start[node], end[node]):  # branch-free: a select and a min per point
                        distance = (points[p, 0] - x) ** 2 + (points[p, 1] - y) ** 2 + (points[p, 2] - z) ** 2
                        nearest = p if distance < best else nearest
                        best = min(distance, best)
                    continue
                near, far = left[node], right[node]
                near_bound = _box_distance_squared(x, y, z, low, high, near)
                far_bound = _box_distance_squared(x, y, z, low, high, far)
                if far_bound < near_bound:
                    near, far, near_bound, far_bound = far, near, far_bound, near_bound
                if far_bound < best:  # pushed first, searched after the nearer child
                    stack[top], bounds[top] = far, far_bound
                    top += 1
                if near_bound < best:
                    stack[top], bounds[top] = near, near_bound
                    top += 1
            total += np.sqrt(best)
        means[e] = total / count
    return means


@numba.njit(cache=True)
def min_max_distances(A, b, points):
    """``(E,)``: ``min over s of max over n of |A[e, s] points[n] + b[e, s]|`` for ``A`` ``(E, S, 3, 3)``,
    ``b`` ``(E, S, 3)`` (MSSD over symmetries). A symmetry is abandoned as soon as its running maximum
    reaches the best one so far, which cannot change the result."""
    estimates, symmetries, count = A.shape[0], A.shape[1], points.shape[0]
    result = np.empty(estimates)
    for e in range(estimates):
        best = np.inf
        for s in range(symmetries):
            largest = 0.0
            for n in range(count):
                x = A[e, s, 0, 0] * points[n, 0] + A[e, s, 0, 1] * points[n, 1] + A[e, s, 0, 2] * points[n, 2] + b[e, s, 0]
                y = A[e, s, 1, 0] * points[n, 0] + A[e, s, 1, 1] * points[n, 1] + A[e, s, 1, 2] * points[n, 2] + b[e, s, 1]
                z = A[e, s, 2, 0] * points[n, 0] + A[e, s, 2, 1] * points[n, 1] + A[e, s, 2, 2] * points[n, 2] + b[e, s, 2]
                largest = max(largest, x * x + y * y + z * z)
                if largest >= best:
                    break
            best = min(best, largest)
        result[e] = np.sqrt(best)
    return result


@numba.njit(cache=True, inline="always")
def _pixel(M, m, e, x, y, z):
    """Pixel ``(u, v)`` of the point ``M[e] (x, y, z) + m[e]`` (homogeneous, divided by its z as BOP
    does: a point on the camera plane gives inf or NaN)."""
    hx = M[e, 0, 0] * x + M[e, 0, 1] * y + M[e, 0, 2] * z + m[e, 0]
    hy = M[e, 1, 0] * x + M[e, 1, 1] * y + M[e, 1, 2] * z + m[e, 1]
    hz = M[e, 2, 0] * x + M[e, 2, 1] * y + M[e, 2, 2] * z + m[e, 2]
    return hx / hz, hy / hz


@numba.njit(cache=True)
def mean_distances(A, b, points):
    """``(E,)``: mean over ``points`` of ``|A[e] x + b[e]|`` (ADD with ``A = R_est - R_gt``,
    ``b = t_est - t_gt``)."""
    estimates, count = A.shape[0], points.shape[0]
    result = np.empty(estimates)
    for e in range(estimates):
        total = 0.0
        for n in range(count):
            x = A[e, 0, 0] * points[n, 0] + A[e, 0, 1] * points[n, 1] + A[e, 0, 2] * points[n, 2] + b[e, 0]
            y = A[e, 1, 0] * points[n, 0] + A[e, 1, 1] * points[n, 1] + A[e, 1, 2] * points[n, 2] + b[e, 1]
            z = A[e, 2, 0] * points[n, 0] + A[e, 2, 1] * points[n, 1] + A[e, 2, 2] * points[n, 2] + b[e, 2]
            total += np.sqrt(x * x + y * y + z * z)
        result[e] = total / count
    return result


@numba.njit(cache=True, error_model="numpy")
def mean_pixel_distances(M_est, m_est, M_gt, m_gt, points):
    """``(E,)``: mean over ``points`` of the pixel distance between ``(M_est, m_est)`` and
    ``(M_gt, m_gt)`` (``K R`` and ``K t`` of the two poses): the 2D projection error; NaN where a
    point lies on a camera plane."""
    estimates, count = M_est.shape[0], points.shape[0]
    result = np.empty(estimates)
    for e in range(estimates):
        total = 0.0
        for n in range(count):
            u_est, v_est = _pixel(M_est, m_est, e, points[n, 0], points[n, 1], points[n, 2])
            u_gt, v_gt = _pixel(M_gt, m_gt, e, points[n, 0], points[n, 1], points[n, 2])
            total += np.sqrt((u_est - u_gt) ** 2 + (v_est - v_gt) ** 2)
        result[e] = total / count
    return result


@numba.njit(cache=True, error_model="numpy")
def min_max_pixel_distances(M_est, m_est, M_sym, m_sym, points):
    """``(E,)``: min over symmetries ``s`` of the max over ``points`` of the pixel distance between
    ``(M_est[e], m_est[e])`` and ``(M_sym[e, s], m_sym[e, s])`` (MSPD); a symmetry with a point on a
    camera plane counts as infinite, and one is abandoned once its running maximum reaches the best."""
    estimates, symmetries, count = M_sym.shape[0], M_sym.shape[1], points.shape[0]
    result = np.empty(estimates)
    for e in range(estimates):
        best = np.inf
        for s in range(symmetries):
            largest = 0.0
            for n in range(count):
                u_est, v_est = _pixel(M_est, m_est, e, points[n, 0], points[n, 1], points[n, 2])
                u_sym, v_sym = _pixel(M_sym[e], m_sym[e], s, points[n, 0], points[n, 1], points[n, 2])
                distance = np.sqrt((u_est - u_sym) ** 2 + (v_est - v_sym) ** 2)
                if distance != distance:  # NaN: a point on a camera plane
                    distance = np.inf
                largest = max(largest, distance)
                if largest >= best:
                    break
            best = min(best, largest)
        result[e] = best
    return result
