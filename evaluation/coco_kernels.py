"""numba kernels of COCO mask evaluation: compressed RLE strings to run lengths, and polygon
boundaries (pycocotools' ``rleFrString`` and ``rleFrPoly``), written as the C code walks them so that
every run length is the same. Imported by :mod:`evaluation.coco_masks` on first use (numba compiles
them once and caches the machine code on disk).
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: error kinds of :func:`decode_rle_strings` (0: none)
BAD_CHARACTER, TRUNCATED, TOO_LONG, NEGATIVE = 1, 2, 3, 4


@numba.njit(cache=True)
def decode_rle_strings(chars, string_ends, offset, max_chars):
    """Run lengths of compressed RLE strings laid end to end in ``chars`` (uint8), string ``i``
    ending at ``string_ends[i]`` (exclusive).

    Returns:
        ``(counts (total,) int64, runs per string (N,) int64, error kind, character index)``; on an
        error the arrays are empty and the index is where the first error of that kind is (the
        checks run in the order of the kinds: characters, truncation, value length, sign).
    """
    total = chars.shape[0]
    strings = string_ends.shape[0]
    empty = np.zeros(0, np.int64)
    for i in range(total):
        if chars[i] < offset or chars[i] > offset + 63:
            return empty, empty, BAD_CHARACTER, i
    begin = 0
    for s in range(strings):
        end = string_ends[s]
        if end > begin and ((chars[end - 1] - offset) & 0x20) != 0:
            return empty, empty, TRUNCATED, end - 1
        begin = end
    # value lengths: report the first value of the largest length when it is too long
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
        return empty, empty, TOO_LONG, longest_at
    counts = np.empty(values_total, np.int64)
    last_char = np.empty(values_total, np.int64)
    per_string = np.zeros(strings, np.int64)
    m = 0
    begin = 0
    for s in range(strings):
        end = string_ends[s]
        p = begin
        first = m
        while p < end:
            x, k, more = 0, 0, True
            while more:
                c = np.int64(chars[p]) - offset
                x |= (c & 0x1F) << (5 * k)
                more = (c & 0x20) != 0
                p += 1
                k += 1
                if not more and (c & 0x10) != 0:
                    x |= np.int64(-1) << (5 * k)
            if m - first > 2:
                x += counts[m - 2]
            counts[m] = x
            last_char[m] = p - 1
            m += 1
        per_string[s] = m - first
        begin = end
    for i in range(values_total):
        if counts[i] < 0:
            return empty, empty, NEGATIVE, last_char[i]
    return counts, per_string, 0, -1


@numba.njit(cache=True)
def _walk(x, y, first, count, height, width, parts_index, out_part, out_flat, write_at):
    """Walks one polygon's edges on the 5x grid as rleFrPoly does and records every kept toggle
    (``x * height + y``) at ``write_at``; returns the new write position (counts only when
    ``out_part`` is empty)."""
    scale = 5.0
    have_previous, u_previous, v_previous = False, 0, 0
    for j in range(count):
        xs, ys = x[first + j], y[first + j]
        following = first + j + 1 if j + 1 < count else first
        xe, ye = x[following], y[following]
        dx, dy = abs(xe - xs), abs(ys - ye)
        flip = (dx >= dy and xs > xe) or (dx < dy and ys > ye)
        if flip:
            xs, xe = xe, xs
            ys, ye = ye, ys
        if dx >= dy:
            s = (ye - ys) / dx if dx > 0 else 0.0
            steps = dx
        else:
            s = (xe - xs) / dy
            steps = dy
        for d in range(steps + 1):
            t = steps - d if flip else d
            if dx >= dy:
                u = t + xs
                v = int(ys + s * t + 0.5)
            else:
                v = t + ys
                u = int(xs + s * t + 0.5)
            if have_previous and u != u_previous:
                xd = float(u if u < u_previous else u - 1)
                xd = (xd + 0.5) / scale - 0.5
                if math.floor(xd) == xd and xd >= 0 and xd <= width - 1:
                    yd = float(v if v < v_previous else v_previous)
                    yd = (yd + 0.5) / scale - 0.5
                    if yd < 0:
                        yd = 0.0
                    elif yd > height:
                        yd = float(height)
                    yd = math.ceil(yd)
                    if out_part.shape[0] > 0:
                        out_part[write_at] = parts_index
                        out_flat[write_at] = int(xd) * height + int(yd)
                    write_at += 1
            have_previous, u_previous, v_previous = True, u, v
    return write_at


@numba.njit(cache=True)
def polygon_runs(x, y, vertex_counts, heights, widths):
    """Foreground runs ``(part, start, end)`` (flat column-major pixel indices, ``end`` exclusive) of
    every polygon part, grouped by part in order, as rleFrPoly makes them: the kept toggles of the
    walk (:func:`_walk`) sorted, equal toggles cancelled in pairs, a toggle at ``H * W`` dropped and
    an odd count closed at ``H * W``. ``x``/``y`` are the vertices already on the 5x grid,
    ``(int)(5 * c + .5)``."""
    parts = vertex_counts.shape[0]
    none = np.zeros(0, np.int64)
    offsets = np.zeros(parts + 1, np.int64)
    first = 0
    for p in range(parts):
        offsets[p + 1] = _walk(x, y, first, vertex_counts[p], heights[p], widths[p], p, none, none, offsets[p])
        first += vertex_counts[p]
    owner = np.empty(offsets[parts], np.int64)
    toggles = np.empty(offsets[parts], np.int64)
    first = 0
    for p in range(parts):
        _walk(x, y, first, vertex_counts[p], heights[p], widths[p], p, owner, toggles, offsets[p])
        first += vertex_counts[p]
    out_part = np.empty(offsets[parts] // 2 + parts, np.int64)
    out_start = np.empty(offsets[parts] // 2 + parts, np.int64)
    out_end = np.empty(offsets[parts] // 2 + parts, np.int64)
    kept = np.empty(offsets[parts] + 1, np.int64)
    runs = 0
    for p in range(parts):
        area = heights[p] * widths[p]
        ordered = np.sort(toggles[offsets[p]:offsets[p + 1]])
        count, i = 0, 0
        while i < ordered.shape[0]:
            j = i
            while j < ordered.shape[0] and ordered[j] == ordered[i]:
                j += 1
            if (j - i) % 2 == 1 and ordered[i] < area:
                kept[count] = ordered[i]
                count += 1
            i = j
        if count % 2 == 1:
            kept[count] = area
            count += 1
        for k in range(0, count, 2):
            out_part[runs], out_start[runs], out_end[runs] = p, kept[k], kept[k + 1]
            runs += 1
    return out_part[:runs].copy(), out_start[:runs].copy(), out_end[:runs].copy()
