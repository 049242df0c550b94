"""numba kernels of COCO masks: compressed RLE strings to run lengths, and polygon boundaries
(pycocotools' ``rleFrString`` and ``rleFrPoly``), written as the C code walks them so that every run
length is the same; run areas, boxes and pairwise intersections. Imported by :mod:`paz6d.backend.rle`
and :mod:`evaluation.coco_masks` on first use (numba compiles them once and caches the machine code
on disk).
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: error kinds of :func:`decode_rle_strings` and :func:`rle_string_runs` (0: none)
BAD_CHARACTER, TRUNCATED, TOO_LONG, NEGATIVE, WRONG_SUM = 1, 2, 3, 4, 5


@numba.njit(cache=True)
def _string_errors(chars, string_ends, offset, max_chars):
    """Checks of compressed RLE strings that come before decoding, in this order: characters,
    truncation, value length (the first value of the largest length is reported when too long).

    Returns:
        ``(error kind, character index, number of values)``.
    """
    total = chars.shape[0]
    for i in range(total):
        if chars[i] < offset or chars[i] > offset + 63:
            return BAD_CHARACTER, i, 0
    begin = 0
    for s in range(string_ends.shape[0]):
        end = string_ends[s]
        if end > begin and ((chars[end - 1] - offset) & 0x20) != 0:
            return TRUNCATED, end - 1, 0
        begin = end
    longest, longest_at, digits = 0, -1, 0
    values_total = 0
    for i in range(total):
        digits += 1
        if ((chars[i] - offset) & 0x20) == 0:
            if digits > longest:
                longest, longest_at = digits, i
            digits = 0
            values_total += 1
    if longest > max_chars:
        return TOO_LONG, longest_at, 0
    return 0, -1, values_total


@numba.njit(cache=True)
def _next_value(chars, p, offset):
    """The value starting at ``chars[p]`` (5 bits per character, continuation bit 0x20, sign from
    bit 0x10 of the last character) and the index after it."""
    x, k, more = 0, 0, True
    while more:
        c = np.int64(chars[p]) - offset
        x |= (c & 0x1F) << (5 * k)
        more = (c & 0x20) != 0
        p += 1
        k += 1
        if not more and (c & 0x10) != 0:
            x |= np.int64(-1) << (5 * k)
    return x, p


@numba.njit(cache=True)
def decode_rle_strings(chars, string_ends, offset, max_chars):
    """Run lengths of compressed RLE strings laid end to end in ``chars`` (uint8), string ``i``
    ending at ``string_ends[i]`` (exclusive); every value after a string's third is a difference to
    the one two places before.

    Returns:
        ``(counts (total,) int64, runs per string (N,) int64, error kind, character index)``; on an
        error the arrays are empty and the index is where the first error of that kind is (the
        checks run in the order of the kinds: characters, truncation, value length, sign).
    """
    empty = np.zeros(0, np.int64)
    error, at, values_total = _string_errors(chars, string_ends, offset, max_chars)
    if error:
        return empty, empty, error, at
    counts = np.empty(values_total, np.int64)
    per_string = np.zeros(string_ends.shape[0], np.int64)
    m, p = 0, 0
    for s in range(string_ends.shape[0]):
        first = m
        while p < string_ends[s]:
            x, p = _next_value(chars, p, offset)
            if m - first > 2:
                x += counts[m - 2]
            if x < 0:
                return empty, empty, NEGATIVE, p - 1
            counts[m] = x
            m += 1
        per_string[s] = m - first
    return counts, per_string, 0, -1


@numba.njit(cache=True)
def rle_string_runs(chars, string_ends, offset, max_chars, areas):
    """Foreground runs of compressed RLE strings (as :func:`decode_rle_strings` reads them), without
    keeping the run lengths.

    Returns:
        ``(starts, ends, runs per string, error kind, where, total)``: flat runs, ``end`` exclusive,
        string by string, empty runs dropped. On an error the arrays are empty; ``where`` is the
        character index for the kinds of :func:`decode_rle_strings`, or for ``WRONG_SUM`` (checked
        after all of them) the first string whose lengths do not add up to its area, ``total``
        being what they add up to.
    """
    empty = np.zeros(0, np.int64)
    strings = string_ends.shape[0]
    error, at, values_total = _string_errors(chars, string_ends, offset, max_chars)
    if error:
        return empty, empty, empty, error, at, 0
    starts = np.empty(values_total // 2, np.int64)
    ends = np.empty(values_total // 2, np.int64)
    runs = np.zeros(strings, np.int64)
    wrong, wrong_total = -1, 0
    at, p = 0, 0
    for s in range(strings):
        first, k, position = at, 0, 0
        two_back, one_back = 0, 0
        while p < string_ends[s]:
            x, p = _next_value(chars, p, offset)
            if k > 2:
                x += two_back
            if x < 0:
                return empty, empty, empty, NEGATIVE, p - 1, 0
            if k % 2 == 1 and x > 0:
                starts[at], ends[at] = position, position + x
                at += 1
            position += x
            two_back, one_back = one_back, x
            k += 1
        runs[s] = at - first
        if position != areas[s] and wrong < 0:
            wrong, wrong_total = s, position
    if wrong >= 0:
        return empty, empty, empty, WRONG_SUM, wrong, wrong_total
    return starts[:at], ends[:at], runs, 0, -1, 0


@numba.njit(cache=True)
def _row(v, height):
    """rleFrPoly's row of a boundary point ``v`` on the 5x grid: back to pixels, clamped, rounded up."""
    yd = (float(v) + 0.5) / 5.0 - 0.5
    if yd < 0:
        yd = 0.0
    elif yd > height:
        yd = float(height)
    return int(math.ceil(yd))


@numba.njit(cache=True)
def _edge_point(xs, ys, s, t, shallow):
    """Point ``t`` of an edge walk on the 5x grid, as rleFrPoly computes it (C truncation)."""
    if shallow:
        return t + xs, int(ys + s * t + 0.5)
    return int(xs + s * t + 0.5), t + ys


@numba.njit(cache=True)
def _pair_toggle(u_previous, v_previous, u, v, height, width):
    """rleFrPoly's toggle for two consecutive boundary points, or -1 when it keeps none."""
    if u == u_previous:
        return -1
    xd = float(u if u < u_previous else u - 1)
    xd = (xd + 0.5) / 5.0 - 0.5
    if math.floor(xd) != xd or xd < 0 or xd > width - 1:
        return -1
    return int(xd) * height + _row(min(v, v_previous), height)


@numba.njit(cache=True)
def _shallow_toggles(xs, ys, s, steps, height, last_column, out, at):
    """Toggles between points ``t`` and ``t + 1`` of a shallow edge (``u = xs + t``): only where the
    smaller ``u`` is ``5 * column + 2`` (the pixel column centres) is one kept, so only those are visited."""
    low = max(0, 2 - xs)
    high = min(steps - 1, 5 * last_column + 2 - xs)
    if low > high:
        return at
    t = low + (2 - (xs + low)) % 5
    while t <= high:
        v_here = int(ys + s * t + 0.5)
        v_next = int(ys + s * (t + 1) + 0.5)
        out[at] = ((xs + t - 2) // 5) * height + _row(min(v_here, v_next), height)
        at += 1
        t += 5
    return at


@numba.njit(cache=True)
def _steep_toggles(xs, ys, s, steps, height, last_column, out, at):
    """Toggles between points ``t`` and ``t + 1`` of a steep edge (``v = ys + t``, ``u`` monotone in
    ``t`` and changing by at most 1 per step): for every column centre ``m = 5 * column + 2`` that ``u``
    passes, the step where it does is found from the line equation and corrected on the exact
    rounding, instead of visiting every step."""
    if s == 0.0:
        return at
    u_first = int(xs + s * 0 + 0.5)
    u_last = int(xs + s * steps + 0.5)
    rising = s > 0
    m = max(u_first if rising else u_last, 2)
    top = min((u_last if rising else u_first) - 1, 5 * last_column + 2)
    m += (2 - m) % 5
    while m <= top:
        # first t with u(t) >= m + 1 (rising) or u(t) <= m (falling); u(0) is on the other side
        estimate = (m + 0.5 - xs) / s
        t = 1 if estimate < 1 else (steps if estimate > steps else int(math.ceil(estimate)))
        if rising:
            while t > 1 and int(xs + s * (t - 1) + 0.5) >= m + 1:
                t -= 1
            while int(xs + s * t + 0.5) < m + 1:
                t += 1
        else:
            while t > 1 and int(xs + s * (t - 1) + 0.5) <= m:
                t -= 1
            while int(xs + s * t + 0.5) > m:
                t += 1
        out[at] = ((m - 2) // 5) * height + _row(ys + t - 1, height)
        at += 1
        m += 5
    return at


@numba.njit(cache=True)
def _toggle_bound(x, first, count):
    """Upper bound of the toggles :func:`_boundary_toggles` records for one polygon."""
    total = 0
    for j in range(count):
        following = first + j + 1 if j + 1 < count else first
        total += abs(x[following] - x[first + j]) // 5 + 3
    return total


@numba.njit(cache=True)
def _boundary_toggles(x, y, first, count, height, width, out, at):
    """Records at ``out[at:]`` the toggles (``column * height + row``) of one polygon's boundary as
    rleFrPoly's walk over its edges on the 5x grid keeps them; returns the new end.

    The toggle set of a walk does not depend on its direction: it comes from the unordered pairs of
    consecutive points, the pairs ``(t, t + 1)`` inside each edge and the pair joining an edge's last
    point to the next edge's first one."""
    have_previous, u_previous, v_previous = False, 0, 0
    for j in range(count):
        xs, ys = x[first + j], y[first + j]
        following = first + j + 1 if j + 1 < count else first
        xe, ye = x[following], y[following]
        dx, dy = abs(xe - xs), abs(ys - ye)
        shallow = dx >= dy
        flip = (shallow and xs > xe) or (not shallow and ys > ye)
        if flip:
            xs, xe = xe, xs
            ys, ye = ye, ys
        if shallow:
            s = (ye - ys) / dx if dx > 0 else 0.0
            steps = dx
        else:
            s = (xe - xs) / dy
            steps = dy
        start = steps if flip else 0  # the walk begins at the edge's original first vertex
        u, v = _edge_point(xs, ys, s, start, shallow)
        if have_previous:
            toggle = _pair_toggle(u_previous, v_previous, u, v, height, width)
            if toggle >= 0:
                out[at] = toggle
                at += 1
        if shallow:
            at = _shallow_toggles(xs, ys, s, steps, height, width - 1, out, at)
        else:
            at = _steep_toggles(xs, ys, s, steps, height, width - 1, out, at)
        u_previous, v_previous = _edge_point(xs, ys, s, steps - start, shallow)
        have_previous = True
    return at


@numba.njit(cache=True)
def _sort_toggles(toggles, height, scratch):
    """Sorts one polygon's toggles in place: a counting sort by column (``toggle // height``), then
    an insertion sort that only reorders inside a column (a boundary crosses each column a few
    times). ``scratch`` holds at least ``2 * len(toggles) + 2`` values."""
    n = toggles.shape[0]
    if n < 2:
        return
    low, high = toggles.min() // height, toggles.max() // height
    columns = high - low + 1
    if columns > n:  # sparse columns (very thin or far-apart parts): a plain sort is as good
        toggles.sort()
        return
    placed, starts = scratch[:n], scratch[n:n + columns + 1]
    starts[:] = 0
    for k in range(n):
        starts[toggles[k] // height - low + 1] += 1
    for c in range(columns):
        starts[c + 1] += starts[c]
    for k in range(n):
        c = toggles[k] // height - low
        placed[starts[c]] = toggles[k]
        starts[c] += 1
    for k in range(n):
        value = placed[k]
        j = k
        while j > 0 and toggles[j - 1] > value:
            toggles[j] = toggles[j - 1]
            j -= 1
        toggles[j] = value


@numba.njit(cache=True)
def _runs_from_toggles(toggles, area, starts, ends, at):
    """Writes the runs of one polygon's sorted toggles at ``starts/ends[at:]`` as rleFrPoly encodes
    them: equal toggles cancel in pairs, a toggle at ``area`` is dropped and an odd count is closed
    at ``area``. Returns the new end."""
    pending = -1
    i = 0
    while i < toggles.shape[0]:
        j = i
        while j < toggles.shape[0] and toggles[j] == toggles[i]:
            j += 1
        if (j - i) % 2 == 1 and toggles[i] < area:
            if pending < 0:
                pending = toggles[i]
            else:
                starts[at], ends[at] = pending, toggles[i]
                at += 1
                pending = -1
        i = j
    if pending >= 0:
        starts[at], ends[at] = pending, area
        at += 1
    return at


@numba.njit(cache=True)
def _unite_runs(starts, ends, first, stop):
    """Unites the runs ``first..stop-1`` (several sorted, disjoint lists) in place into one sorted
    list, joining overlapping and touching runs; returns its new end."""
    order = np.argsort(starts[first:stop], kind="mergesort")
    begin = starts[first:stop][order]
    finish = ends[first:stop][order]
    at = first
    current_start, current_end = begin[0], finish[0]
    for k in range(1, order.shape[0]):
        if begin[k] <= current_end:
            current_end = max(current_end, finish[k])
        else:
            starts[at], ends[at] = current_start, current_end
            at += 1
            current_start, current_end = begin[k], finish[k]
    starts[at], ends[at] = current_start, current_end
    return at + 1


@numba.njit(cache=True)
def polygon_masks(x, y, vertex_counts, parts_per_mask, heights, widths):
    """Foreground runs of polygon masks as pycocotools makes them (``rleFrPoly`` per part, then the
    parts united as ``rleMerge`` does).

    Args:
        x, y: vertices of all parts laid end to end, already on the 5x grid, ``(int)(5 * c + .5)``.
        vertex_counts: (P,) vertices per part; parts are listed mask by mask.
        parts_per_mask: (N,) parts of each mask.
        heights, widths: (N,) mask sizes.

    Returns:
        ``(starts, ends, runs per mask)``: flat column-major runs, ``end`` exclusive, mask by mask.
    """
    n_parts = vertex_counts.shape[0]
    first_vertex = np.zeros(n_parts + 1, np.int64)
    bounds = np.zeros(n_parts, np.int64)
    for p in range(n_parts):
        first_vertex[p + 1] = first_vertex[p] + vertex_counts[p]
        bounds[p] = _toggle_bound(x, first_vertex[p], vertex_counts[p])
    largest = bounds.max() if n_parts else 0
    toggles = np.empty(largest, np.int64)
    scratch = np.empty(2 * largest + 2, np.int64)
    run_bound = 0
    for p in range(n_parts):
        run_bound += bounds[p] // 2 + 1
    starts = np.empty(run_bound, np.int64)
    ends = np.empty(run_bound, np.int64)
    runs_per_mask = np.zeros(parts_per_mask.shape[0], np.int64)
    at, p = 0, 0
    for i in range(parts_per_mask.shape[0]):
        first = at
        for _ in range(parts_per_mask[i]):
            found = _boundary_toggles(x, y, first_vertex[p], vertex_counts[p], heights[i], widths[i], toggles, 0)
            _sort_toggles(toggles[:found], heights[i], scratch)
            at = _runs_from_toggles(toggles[:found], heights[i] * widths[i], starts, ends, at)
            p += 1
        if parts_per_mask[i] > 1 and at - first > 1:
            at = _unite_runs(starts, ends, first, at)
        runs_per_mask[i] = at - first
    return starts[:at], ends[:at], runs_per_mask


@numba.njit(cache=True)
def place_runs(rows, starts, ends, runs, offsets, out_starts, out_ends):
    """Copies the runs of masks ``rows`` (laid end to end, ``runs[k]`` of mask ``rows[k]``) to where
    ``offsets`` puts each mask in ``out_starts``/``out_ends``."""
    read = 0
    for k in range(rows.shape[0]):
        write = offsets[rows[k]]
        for r in range(runs[k]):
            out_starts[write + r] = starts[read + r]
            out_ends[write + r] = ends[read + r]
        read += runs[k]


@numba.njit(cache=True)
def runs_from_counts(counts, runs_per_mask, areas):
    """Foreground runs of masks given as run lengths (background first) laid end to end.

    Returns:
        ``(starts, ends, runs per mask, bad mask, its total)``: flat runs, ``end`` exclusive, mask
        by mask, empty runs dropped; ``bad mask`` is the first mask whose lengths do not sum to its
        area (-1 when all do).
    """
    n = runs_per_mask.shape[0]
    starts = np.empty(counts.shape[0] // 2, np.int64)
    ends = np.empty(counts.shape[0] // 2, np.int64)
    foreground_runs = np.zeros(n, np.int64)
    read, at = 0, 0
    for i in range(n):
        position, first = 0, at
        for k in range(runs_per_mask[i]):
            length = counts[read + k]
            if k % 2 == 1 and length > 0:
                starts[at], ends[at] = position, position + length
                at += 1
            position += length
        read += runs_per_mask[i]
        if position != areas[i]:
            return starts[:0], ends[:0], foreground_runs, i, position
        foreground_runs[i] = at - first
    return starts[:at], ends[:at], foreground_runs, -1, 0


@numba.njit(cache=True)
def areas_and_boxes(heights, starts, ends, offsets):
    """(N,) foreground pixel counts and (N, 4) boxes ``[x, y, w, h]`` of masks given as runs (zeros
    for empty masks); a run that wraps into the next column spans the full height, as in toBbox."""
    n = heights.shape[0]
    areas = np.zeros(n, np.int64)
    boxes = np.zeros((n, 4))
    for i in range(n):
        first, stop = offsets[i], offsets[i + 1]
        if stop == first:
            continue
        height = heights[i]
        area = 0
        for r in range(first, stop):
            area += ends[r] - starts[r]
        # runs are sorted: the columns span from the first run's to the last run's; rows need every run
        # until one wraps into the next column (then they span the full height)
        x_min, x_max = starts[first] // height, (ends[stop - 1] - 1) // height
        y_min, y_max = height - 1, 0
        for r in range(first, stop):
            x_first = starts[r] // height
            y_first = starts[r] - x_first * height
            y_last = y_first + (ends[r] - 1 - starts[r])
            if y_last >= height:
                y_min, y_max = 0, height - 1
                break
            y_min, y_max = min(y_min, y_first), max(y_max, y_last)
        areas[i] = area
        boxes[i, 0], boxes[i, 1] = x_min, y_min
        boxes[i, 2], boxes[i, 3] = x_max - x_min + 1, y_max - y_min + 1
    return areas, boxes


@numba.njit(cache=True)
def pair_intersections(first_starts, first_ends, first_offsets, second_starts, second_ends, second_offsets,
                       first_index, second_index):
    """(P,) pixels shared by masks ``first_index[p]`` and ``second_index[p]`` (sorted disjoint runs of
    each), one merge walk over both run lists per pair."""
    pairs = first_index.shape[0]
    shared = np.zeros(pairs, np.int64)
    for p in range(pairs):
        i, i_stop = first_offsets[first_index[p]], first_offsets[first_index[p] + 1]
        j, j_stop = second_offsets[second_index[p]], second_offsets[second_index[p] + 1]
        total = 0
        while i < i_stop and j < j_stop:
            low = max(first_starts[i], second_starts[j])
            high = min(first_ends[i], second_ends[j])
            if high > low:
                total += high - low
            if first_ends[i] < second_ends[j]:
                i += 1
            else:
                j += 1
        shared[p] = total
    return shared
