"""numba kernels of the pose errors: the KD-tree of :class:`evaluation.point_tree.PointTree` (build,
leaf neighbour lists and the block search for ADI), the MSSD and MSPD maxima over points / minima
over symmetries, and the means of ADD and of the 2D projection error (one pass over the points per
estimate).

Tree layout (arrays indexed by node, root 0): ``start``/``end`` index the points of the node in
tree order, ``left``/``right`` are the children (-1 for a leaf), ``low``/``high`` the tight
``(nodes, 3)`` bounding box. Nodes split at the median of their widest axis. Leaves are numbered in
tree order (``leaf_of[node]``) and each has a list of the nearest leaves, sorted by box distance.
"""

from __future__ import annotations

import sys

import numpy as np

# numba's array-math module (loaded at the first compilation or cache load) checks for BLAS by
# importing scipy.linalg, 0.2 s of CPU; these kernels use no BLAS, so that check is answered "no"
# by hiding scipy.linalg.cython_blas while the module loads. The only effect is that numba code in
# this process implements np.correlate and np.convolve with a plain loop instead of BLAS dot
# (np.dot and numba's linalg functions import scipy themselves when compiled).
if "numba.np.arraymath" not in sys.modules and "scipy.linalg.cython_blas" not in sys.modules:
    sys.modules["scipy.linalg.cython_blas"] = None  # makes the import raise ImportError
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        del sys.modules["scipy.linalg.cython_blas"]
import numba  # noqa: E402

STACK_DEPTH = 128  # far above the depth of a median-split tree on any realistic point count
BLOCK = 32  # queries searched together (four AVX-512 / eight AVX2 registers of float64)
NEIGHBOUR_LEAVES = 128  # length of each leaf's list of nearest leaves (64: 40 % slower on LM-O, 128 as fast as all)
REACH_SLACK = 1e-9  # relative margin on the list cut-off (rounding of box distances and square roots)


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


@numba.njit(cache=True)
def leaf_neighbours(start, end, left, right, low, high):
    """The leaves in tree order and, for each, its nearest leaves.

    Returns:
        ``(leaf_of, leaf_start, leaf_end, leaf_low, leaf_high, neighbours, distances)``: ``(nodes,)``
        leaf number of each node (-1 for inner nodes); ``(L,)`` first and end point and ``(L, 3)``
        box of each leaf; ``(L, K)`` the ``K = min(L, NEIGHBOUR_LEAVES)`` leaves nearest to each leaf
        (box to box; the leaf itself first, every unlisted leaf at least as far as the last listed
        one) and ``(L, K)`` those distances, ascending. Found by a pruned depth-first search per leaf.
    """
    nodes = left.shape[0]
    leaf_nodes = np.flatnonzero(left < 0)
    leaves = leaf_nodes[np.argsort(start[leaf_nodes])]
    count = leaves.shape[0]
    leaf_of = np.full(nodes, -1, np.int64)
    leaf_of[leaves] = np.arange(count)
    kept = min(count, NEIGHBOUR_LEAVES)
    neighbours = np.empty((count, kept), np.int64)
    distances = np.empty((count, kept))
    stack = np.empty(STACK_DEPTH, np.int64)
    for i in range(count):
        home = leaves[i]
        found = 0
        stack[0], top = 0, 1
        while top > 0:
            top -= 1
            node = stack[top]
            gap = _node_gap_squared(low, high, home, node)
            if found == kept and gap >= distances[i, kept - 1]:
                continue
            if left[node] >= 0:  # the nearer child searched first
                near, far = left[node], right[node]
                if _node_gap_squared(low, high, home, far) < _node_gap_squared(low, high, home, near):
                    near, far = far, near
                stack[top], stack[top + 1] = far, near
                top += 2
                continue
            if node == home:
                gap = -1.0  # the leaf itself first
            slot = min(found, kept - 1)  # sorted insertion; the farthest drops out when full
            while slot > 0 and distances[i, slot - 1] > gap:
                distances[i, slot], neighbours[i, slot] = distances[i, slot - 1], neighbours[i, slot - 1]
                slot -= 1
            distances[i, slot], neighbours[i, slot] = gap, leaf_of[node]
            found = min(found + 1, kept)
        distances[i, 0] = 0.0
        for k in range(1, kept):
            distances[i, k] = np.sqrt(distances[i, k])
    return (leaf_of, start[leaves].copy(), end[leaves].copy(), low[leaves].copy(), high[leaves].copy(),
            neighbours, distances)


@numba.njit(cache=True, inline="always")
def _node_gap_squared(low, high, a, c):
    """Squared distance between the boxes of nodes ``a`` and ``c``."""
    dx = max(low[c, 0] - high[a, 0], low[a, 0] - high[c, 0], 0.0)
    dy = max(low[c, 1] - high[a, 1], low[a, 1] - high[c, 1], 0.0)
    dz = max(low[c, 2] - high[a, 2], low[a, 2] - high[c, 2], 0.0)
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True, inline="always")
def _box_distance_squared(x, y, z, low, high, node):
    """Squared distance from ``(x, y, z)`` to the box ``low[node]``-``high[node]`` (0 inside); written
    with ``max`` instead of branches (the branches are unpredictable)."""
    dx = max(low[node, 0] - x, x - high[node, 0], 0.0)
    dy = max(low[node, 1] - y, y - high[node, 1], 0.0)
    dz = max(low[node, 2] - z, z - high[node, 2], 0.0)
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True)
def _estimate_mean(A, b, e, px, py, pz, left, right, low, high, leaf_of, leaf_start, leaf_end, leaf_low, leaf_high,
                   neighbours, distances, qx, qy, qz, best, half, quarter, stack, stack_bounds):
    """Mean over the tree points ``(px, py, pz)`` (tree order) of the distance from ``A[e] x + b[e]``
    to the nearest tree point; ``qx .. stack_bounds`` are scratch arrays (:func:`_scratch`).

    The queries go ``BLOCK`` at a time in tree order, so a block is compact in space, and the
    square roots are summed in that order. A block starts from the leaf whose box is nearest to the
    block's centre ("home", found by descending the tree). A leaf holding the nearest point of a
    query lies within ``reach = sqrt(max best) + (largest distance from a query to home's box)`` of
    home's box (triangle inequality), so home's list of nearest leaves is walked in order of
    distance until the next one is out of reach; should the list end first, a depth-first search
    of the tree (nearer child first, pruned by box distance) visits the remaining candidates. A visited leaf is skipped
    when the queries' bounding box
    is at least ``max best`` from its box, or when no query is nearer to its box than to its best
    point so far; otherwise its points are scanned for all queries at once (the inner loops run
    over the queries and are vectorized). The minimum of the same float64 distances results
    whatever is pruned, so the means equal those of a brute-force search summed in tree order.

    The code is written out in one function: numba's inlining of helpers that take arrays leaves
    reference-count updates in the loops, which made the search several times slower.
    """
    count, leaves, listed = px.shape[0], neighbours.shape[0], neighbours.shape[1]
    total = 0.0
    for first in range(0, count, BLOCK):
        size = min(BLOCK, count - first)
        for j in range(BLOCK):
            n = first + j if j < size else first  # a short last block repeats its first query
            qx[j] = A[e, 0, 0] * px[n] + A[e, 0, 1] * py[n] + A[e, 0, 2] * pz[n] + b[e, 0]
            qy[j] = A[e, 1, 0] * px[n] + A[e, 1, 1] * py[n] + A[e, 1, 2] * pz[n] + b[e, 1]
            qz[j] = A[e, 2, 0] * px[n] + A[e, 2, 1] * py[n] + A[e, 2, 2] * pz[n] + b[e, 2]
            best[j] = np.inf
        x0, y0, z0 = qx[0], qy[0], qz[0]
        x1, y1, z1 = x0, y0, z0
        for j in range(1, BLOCK):
            x0, x1 = min(x0, qx[j]), max(x1, qx[j])
            y0, y1 = min(y0, qy[j]), max(y1, qy[j])
            z0, z1 = min(z0, qz[j]), max(z1, qz[j])
        cx, cy, cz = 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1)
        node = 0
        while left[node] >= 0:
            near, far = left[node], right[node]
            if _box_distance_squared(cx, cy, cz, low, high, far) < _box_distance_squared(cx, cy, cz, low, high, near):
                near = far
            node = near
        home = leaf_of[node]
        offset = 0.0
        for j in range(BLOCK):
            dx = max(leaf_low[home, 0] - qx[j], qx[j] - leaf_high[home, 0], 0.0)
            dy = max(leaf_low[home, 1] - qy[j], qy[j] - leaf_high[home, 1], 0.0)
            dz = max(leaf_low[home, 2] - qz[j], qz[j] - leaf_high[home, 2], 0.0)
            offset = max(offset, dx * dx + dy * dy + dz * dz)
        offset = np.sqrt(offset)
        largest = np.inf
        top = 0
        step = 0  # 0: home; 1 .. listed - 1: home's list; listed + k: leaf k of all
        while True:
            if step == 0:
                leaf = home
            elif step < listed:
                reach = (np.sqrt(largest) + offset) * (1.0 + REACH_SLACK)
                if distances[home, step] > reach:
                    break
                if step == 1 and listed < leaves and distances[home, listed - 1] <= reach:
                    step = listed  # the list cannot cover the reach (a block far from the object): search the tree
                    continue
                leaf = neighbours[home, step]
            else:
                if step == listed:
                    reach = (np.sqrt(largest) + offset) * (1.0 + REACH_SLACK)
                    if listed == leaves or distances[home, listed - 1] > reach:
                        break  # every leaf was listed, or the unlisted ones are out of reach
                    stack[0], stack_bounds[0], top = 0, 0.0, 1
                leaf = -1
                while top > 0 and leaf < 0:  # the next leaf of a depth-first search, nearer child first
                    top -= 1
                    node = stack[top]
                    if stack_bounds[top] >= largest:
                        continue
                    if left[node] < 0:
                        leaf = leaf_of[node]
                        continue
                    near, far = left[node], right[node]
                    dx = max(low[near, 0] - x1, x0 - high[near, 0], 0.0)
                    dy = max(low[near, 1] - y1, y0 - high[near, 1], 0.0)
                    dz = max(low[near, 2] - z1, z0 - high[near, 2], 0.0)
                    near_bound = dx * dx + dy * dy + dz * dz
                    dx = max(low[far, 0] - x1, x0 - high[far, 0], 0.0)
                    dy = max(low[far, 1] - y1, y0 - high[far, 1], 0.0)
                    dz = max(low[far, 2] - z1, z0 - high[far, 2], 0.0)
                    far_bound = dx * dx + dy * dy + dz * dz
                    if far_bound < near_bound:
                        near, far, near_bound, far_bound = far, near, far_bound, near_bound
                    if far_bound < largest:
                        stack[top], stack_bounds[top] = far, far_bound
                        top += 1
                    if near_bound < largest:
                        stack[top], stack_bounds[top] = near, near_bound
                        top += 1
                if leaf < 0:
                    break
            step += 1
            lx, ly, lz = leaf_low[leaf, 0], leaf_low[leaf, 1], leaf_low[leaf, 2]
            hx, hy, hz = leaf_high[leaf, 0], leaf_high[leaf, 1], leaf_high[leaf, 2]
            dx, dy, dz = max(lx - x1, x0 - hx, 0.0), max(ly - y1, y0 - hy, 0.0), max(lz - z1, z0 - hz, 0.0)
            if dx * dx + dy * dy + dz * dz >= largest:
                continue
            needed = False
            for j in range(BLOCK):
                dx = max(lx - qx[j], qx[j] - hx, 0.0)
                dy = max(ly - qy[j], qy[j] - hy, 0.0)
                dz = max(lz - qz[j], qz[j] - hz, 0.0)
                needed |= dx * dx + dy * dy + dz * dz < best[j]
            if not needed:
                continue
            for p in range(leaf_start[leaf], leaf_end[leaf]):
                x, y, z = px[p], py[p], pz[p]
                for j in range(BLOCK):
                    distance = (x - qx[j]) ** 2 + (y - qy[j]) ** 2 + (z - qz[j]) ** 2
                    best[j] = distance if distance < best[j] else best[j]
            for j in range(BLOCK // 2):  # largest = max(best): two vectorized halvings, then 8 values
                half[j] = best[j] if best[j] > best[j + BLOCK // 2] else best[j + BLOCK // 2]
            for j in range(BLOCK // 4):
                quarter[j] = half[j] if half[j] > half[j + BLOCK // 4] else half[j + BLOCK // 4]
            largest = quarter[0]
            for j in range(1, BLOCK // 4):
                largest = max(largest, quarter[j])
        for j in range(size):
            total += np.sqrt(best[j])
    return total / count


@numba.njit(cache=True)
def _scratch():
    """Scratch arrays of :func:`_estimate_mean`: queries ``qx, qy, qz`` and their ``best`` squared
    distances (``BLOCK``), ``half`` and ``quarter`` of ``BLOCK`` for the maximum, a node stack and its bounds."""
    return (np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK // 2),
            np.empty(BLOCK // 4), np.empty(STACK_DEPTH, np.int64), np.empty(STACK_DEPTH))


@numba.njit(cache=True)
def mean_nearest_distances(A, b, px, py, pz, left, right, low, high, leaf_of, leaf_start, leaf_end, leaf_low,
                           leaf_high, neighbours, distances):
    """``(E,)`` mean over the tree points of the distance from ``A[e] x + b[e]`` to the nearest tree
    point, one thread (see :func:`_estimate_mean`)."""
    means = np.empty(A.shape[0])
    qx, qy, qz, best, half, quarter, stack, stack_bounds = _scratch()
    for e in range(A.shape[0]):
        means[e] = _estimate_mean(A, b, e, px, py, pz, left, right, low, high, leaf_of, leaf_start, leaf_end,
                                  leaf_low, leaf_high, neighbours, distances, qx, qy, qz, best, half, quarter,
                                  stack, stack_bounds)
    return means


@numba.njit(cache=True, parallel=True)
def mean_nearest_distances_parallel(A, b, px, py, pz, left, right, low, high, leaf_of, leaf_start, leaf_end,
                                    leaf_low, leaf_high, neighbours, distances):
    """:func:`mean_nearest_distances` with the estimates spread over numba's threads (same values)."""
    means = np.empty(A.shape[0])
    for e in numba.prange(A.shape[0]):
        qx, qy, qz, best, half, quarter, stack, stack_bounds = _scratch()
        means[e] = _estimate_mean(A, b, e, px, py, pz, left, right, low, high, leaf_of, leaf_start, leaf_end,
                                  leaf_low, leaf_high, neighbours, distances, qx, qy, qz, best, half, quarter,
                                  stack, stack_bounds)
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
                x = (A[e, s, 0, 0] * points[n, 0] + A[e, s, 0, 1] * points[n, 1] + A[e, s, 0, 2] * points[n, 2]
                     + b[e, s, 0])
                y = (A[e, s, 1, 0] * points[n, 0] + A[e, s, 1, 1] * points[n, 1] + A[e, s, 1, 2] * points[n, 2]
                     + b[e, s, 1])
                z = (A[e, s, 2, 0] * points[n, 0] + A[e, s, 2, 1] * points[n, 1] + A[e, s, 2, 2] * points[n, 2]
                     + b[e, s, 2])
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
    px, py, pz = points[:, 0].copy(), points[:, 1].copy(), points[:, 2].copy()
    distances = np.empty(count)
    for e in range(estimates):
        for n in range(count):  # vectorized ...
            x = A[e, 0, 0] * px[n] + A[e, 0, 1] * py[n] + A[e, 0, 2] * pz[n] + b[e, 0]
            y = A[e, 1, 0] * px[n] + A[e, 1, 1] * py[n] + A[e, 1, 2] * pz[n] + b[e, 1]
            z = A[e, 2, 0] * px[n] + A[e, 2, 1] * py[n] + A[e, 2, 2] * pz[n] + b[e, 2]
            distances[n] = np.sqrt(x * x + y * y + z * z)
        total = 0.0
        for n in range(count):  # ... and summed in point order
            total += distances[n]
        result[e] = total / count
    return result


@numba.njit(cache=True, error_model="numpy")
def mean_pixel_distances(M_est, m_est, M_gt, m_gt, points):
    """``(E,)``: mean over ``points`` of the pixel distance between ``(M_est, m_est)`` and
    ``(M_gt, m_gt)`` (``K R`` and ``K t`` of the two poses): the 2D projection error; NaN where a
    point lies on a camera plane."""
    estimates, count = M_est.shape[0], points.shape[0]
    result = np.empty(estimates)
    x, y, z = points[:, 0].copy(), points[:, 1].copy(), points[:, 2].copy()
    distances = np.empty(count)
    for e in range(estimates):
        for n in range(count):  # vectorized (divisions and roots in SIMD registers) ...
            u_est, v_est = _pixel(M_est, m_est, e, x[n], y[n], z[n])
            u_gt, v_gt = _pixel(M_gt, m_gt, e, x[n], y[n], z[n])
            distances[n] = np.sqrt((u_est - u_gt) ** 2 + (v_est - v_gt) ** 2)
        total = 0.0
        for n in range(count):  # ... and summed in point order, as before
            total += distances[n]
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
