"""COCO binary masks in numpy: RLE strings, polygon rasterization and mask IoU.

Everything here reproduces the pixel-exact behaviour of the COCO mask API (``maskApi.c`` in
cocodataset/cocoapi) without calling it:

* Masks are stored column-major (Fortran order): pixel ``(y, x)`` has flat index ``x * H + y``.
  An RLE is a list of run lengths that alternate background/foreground and start with background.
* Compressed RLE strings use COCO's LEB128 variant: 5 data bits per character (offset 48), a
  continuation bit 0x20, sign extension from bit 0x10, and every count after the third stored as a
  difference to the count two places before.
* Polygons are rasterized like ``rleFrPoly``: vertices are scaled by 5 and rounded with
  ``(int)(5 * v + 0.5)``, edges are walked on the 5x grid, and a pixel column boundary is kept where
  the walk crosses the centre of a pixel column; the toggled rows are rounded up (``ceil``).
* IoU of a detection with a crowd region is ``intersection / area(detection)``.

Internally a set of masks is a :class:`MaskIntervals`: the foreground runs of every mask as
half-open intervals ``[start, end)`` of flat indices, stored in one CSR layout so that areas,
bounding boxes and intersections of many masks are computed with a handful of numpy calls.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

POLYGON_SCALE = 5.0  # rleFrPoly upsampling factor
_CHAR_OFFSET = 48  # compressed RLE characters are 48 + 6-bit group
_MAX_CHARS_PER_COUNT = 12  # 60 bits: far beyond any image size, safe in int64


@dataclass(frozen=True)
class MaskIntervals:
    """Foreground runs of ``N`` binary masks in column-major pixel order.

    Attributes:
        heights: (N,) int64 mask heights in pixels.
        widths: (N,) int64 mask widths in pixels.
        starts: (R,) int64 flat index ``x * H + y`` of the first pixel of each run.
        ends: (R,) int64 flat index one past the last pixel of each run (``ends > starts``).
        offsets: (N + 1,) int64; the runs of mask ``i`` are ``starts[offsets[i]:offsets[i + 1]]``,
            sorted and disjoint.
    """

    heights: np.ndarray
    widths: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.heights)

    def owners(self) -> np.ndarray:
        """(R,) int64 index of the mask each run belongs to."""
        return np.repeat(np.arange(len(self), dtype=np.int64), np.diff(self.offsets))

    def areas(self) -> np.ndarray:
        """(N,) int64 foreground pixel counts."""
        lengths = np.concatenate([[0], np.cumsum(self.ends - self.starts)])
        return lengths[self.offsets[1:]] - lengths[self.offsets[:-1]]

    def boxes(self) -> np.ndarray:
        """(N, 4) float64 tight boxes ``[x, y, w, h]`` (pixels), zeros for empty masks.

        Equals pycocotools ``toBbox``: a run that wraps from one column into the next spans the
        full image height.
        """
        boxes = np.zeros((len(self), 4))
        if len(self.starts) == 0:
            return boxes
        owner = self.owners()
        height = self.heights[owner]
        last = self.ends - 1
        x_first, y_first = np.divmod(self.starts, height)
        x_last, y_last = np.divmod(last, height)
        wraps = x_last > x_first
        y_first = np.where(wraps, 0, y_first)
        y_last = np.where(wraps, height - 1, y_last)
        present = np.diff(self.offsets) > 0
        firsts = self.offsets[:-1][present]
        x_min = np.minimum.reduceat(x_first, firsts)
        x_max = np.maximum.reduceat(x_last, firsts)
        y_min = np.minimum.reduceat(y_first, firsts)
        y_max = np.maximum.reduceat(y_last, firsts)
        boxes[present] = np.stack([x_min, y_min, x_max - x_min + 1, y_max - y_min + 1], axis=1)
        return boxes


def concatenated_ranges(firsts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(f, f + c)`` for every pair, vectorized."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    segment_starts = np.cumsum(counts) - counts
    return np.repeat(firsts - segment_starts, counts) + np.arange(total, dtype=np.int64)


def _segment_ids(counts: np.ndarray) -> np.ndarray:
    """(sum(counts),) index of the segment each element belongs to."""
    return np.repeat(np.arange(len(counts), dtype=np.int64), counts)


# ----------------------------------------------------------------------------------------------
# Compressed RLE strings
# ----------------------------------------------------------------------------------------------

def decode_counts_strings(strings: Sequence[str | bytes], source: str = "counts",
                          labels: Sequence[int] | None = None) -> list[np.ndarray]:
    """Decodes COCO compressed RLE strings into run-length arrays, all strings at once.

    Args:
        strings: compressed ``counts`` strings (``str`` or ASCII ``bytes``).
        source: name used in error messages (file or field).
        labels: entry numbers used in error messages (default ``0..N-1``).

    Returns:
        One (M_i,) int64 array of run lengths per string.

    Raises:
        ValueError: on characters outside ``'0'..'o'``, a truncated last value or negative counts.
    """
    counts, sizes = _decode_counts_flat(strings, source, labels)
    return np.split(counts, np.cumsum(sizes)[:-1])


def _decode_counts_flat(strings: Sequence[str | bytes], source: str,
                        labels: Sequence[int] | None) -> tuple[np.ndarray, np.ndarray]:
    """Decodes compressed RLE strings into all run lengths laid end to end.

    Args:
        strings: compressed ``counts`` strings (``str`` or ASCII ``bytes``).
        source: name used in error messages (file or field).
        labels: entry numbers used in error messages (default ``0..N-1``).

    Returns:
        (total,) int64 run lengths and (N,) number of runs per string.
    """
    def where(char_index: int) -> str:
        string = int(np.searchsorted(string_ends, char_index, side="right"))
        return f"{source}[{string if labels is None else labels[string]}]"

    try:
        encoded = [s.encode("ascii") if isinstance(s, str) else bytes(s) for s in strings]
    except UnicodeEncodeError as error:
        raise ValueError(f"{source}: compressed RLE counts must be ASCII strings") from error
    string_ends = np.cumsum(np.array([len(s) for s in encoded], dtype=np.int64))
    from evaluation import coco_kernels  # here: numba loads only when masks are decoded

    chars = np.frombuffer(b"".join(encoded), dtype=np.uint8)
    counts, per_string, error, at = coco_kernels.decode_rle_strings(chars, string_ends, _CHAR_OFFSET,
                                                                    _MAX_CHARS_PER_COUNT)
    messages = {coco_kernels.BAD_CHARACTER: "compressed RLE counts must use characters '0'..'o'",
                coco_kernels.TRUNCATED: "compressed RLE string ends inside a value (truncated counts)",
                coco_kernels.TOO_LONG: f"compressed RLE value longer than {_MAX_CHARS_PER_COUNT} characters",
                coco_kernels.NEGATIVE: "compressed RLE decodes to negative run lengths"}
    if error:
        raise ValueError(f"{where(at)}: {messages[error]}")
    return counts, per_string


def encode_counts_string(counts: np.ndarray) -> str:
    """Encodes run lengths as a COCO compressed RLE string (inverse of :func:`decode_counts_strings`).

    Args:
        counts: (M,) non-negative run lengths, background first.
    """
    counts = np.asarray(counts, dtype=np.int64)
    values = counts.copy()
    values[3:] -= counts[1:-2]
    characters = []
    active = np.ones(len(values), dtype=bool)
    while np.any(active):
        group = values & 0x1F
        values = values >> 5
        more = np.where((group & 0x10) != 0, values != -1, values != 0) & active
        characters.append(np.where(active, (group | np.where(more, 0x20, 0)) + _CHAR_OFFSET, -1))
        active = more
    grid = np.stack(characters, axis=1).ravel()
    return grid[grid >= 0].astype(np.uint8).tobytes().decode("ascii")


# ----------------------------------------------------------------------------------------------
# Conversions between run lengths, intervals and dense masks
# ----------------------------------------------------------------------------------------------

def intervals_from_counts(counts_list: Sequence[np.ndarray], heights: np.ndarray, widths: np.ndarray,
                          source: str = "segmentation", labels: Sequence[int] | None = None) -> MaskIntervals:
    """Builds :class:`MaskIntervals` from run-length arrays (background first).

    Args:
        counts_list: one (M_i,) array of non-negative run lengths per mask.
        heights, widths: (N,) mask sizes in pixels.
        source: name used in error messages.
        labels: entry numbers used in error messages (default ``0..N-1``).

    Raises:
        ValueError: if the run lengths of a mask do not sum to ``height * width``.
    """
    sizes = np.array([len(c) for c in counts_list], dtype=np.int64)
    flat = np.concatenate(counts_list).astype(np.int64) if len(counts_list) else np.zeros(0, np.int64)
    return _intervals_from_flat_counts(flat, sizes, heights, widths, source, labels)


def _intervals_from_flat_counts(flat: np.ndarray, sizes: np.ndarray, heights, widths, source: str,
                                labels: Sequence[int] | None) -> MaskIntervals:
    """:func:`intervals_from_counts` for run lengths laid end to end, ``sizes[i]`` runs per mask."""
    heights = np.asarray(heights, dtype=np.int64)
    widths = np.asarray(widths, dtype=np.int64)
    running = np.cumsum(flat)
    mask_end = np.cumsum(sizes)
    total_before = np.concatenate([[0], running])[mask_end - sizes]
    totals = np.concatenate([[0], running])[mask_end] - total_before
    bad = np.flatnonzero(totals != heights * widths)
    if len(bad):
        i = int(bad[0])
        label = i if labels is None else labels[i]
        raise ValueError(f"{source}[{label}]: RLE run lengths sum to {totals[i]}, expected height*width = "
                         f"{heights[i] * widths[i]} ({heights[i]}x{widths[i]})")
    owner = _segment_ids(sizes)
    local = np.arange(len(flat)) - (mask_end - sizes)[owner]
    foreground = np.flatnonzero((local % 2 == 1) & (flat > 0))  # odd runs are foreground
    owner = owner[foreground]
    ends = running[foreground] - total_before[owner]
    return _pack(heights, widths, ends - flat[foreground], ends, owner)


def _pack(heights: np.ndarray, widths: np.ndarray, starts: np.ndarray, ends: np.ndarray,
          owner: np.ndarray) -> MaskIntervals:
    """Wraps runs (already grouped by ascending ``owner``) into a :class:`MaskIntervals`."""
    offsets = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=len(heights)))]).astype(np.int64)
    return MaskIntervals(heights, widths, starts.astype(np.int64), ends.astype(np.int64), offsets)


def counts_from_intervals(masks: MaskIntervals, index: int) -> np.ndarray:
    """Canonical run lengths (background first, no empty runs except a leading one) of mask ``index``."""
    lo, hi = masks.offsets[index], masks.offsets[index + 1]
    starts, ends = masks.starts[lo:hi], masks.ends[lo:hi]
    total = int(masks.heights[index] * masks.widths[index])
    # merge touching runs so the output is canonical like rleEncode
    if len(starts) > 1:
        touching = starts[1:] == ends[:-1]
        keep_start = np.concatenate([[True], ~touching])
        keep_end = np.concatenate([~touching, [True]])
        starts, ends = starts[keep_start], ends[keep_end]
    edges = np.empty(2 * len(starts) + 2, dtype=np.int64)
    edges[0] = 0
    edges[1:-1:2] = starts
    edges[2:-1:2] = ends
    edges[-1] = total
    counts = np.diff(edges)
    if counts[-1] == 0 and len(counts) > 1:
        counts = counts[:-1]
    return counts


def intervals_from_mask(mask: np.ndarray) -> MaskIntervals:
    """Foreground runs of one ``(H, W)`` boolean mask."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask: expected a 2-D (H, W) array, got shape {mask.shape}")
    height, width = mask.shape
    flat = np.ascontiguousarray(mask.astype(bool).T).ravel()
    change = np.flatnonzero(np.diff(np.concatenate([[False], flat, [False]]).astype(np.int8)))
    starts, ends = change[0::2], change[1::2]
    return _pack(np.array([height]), np.array([width]), starts, ends, np.zeros(len(starts), dtype=np.int64))


def mask_from_intervals(masks: MaskIntervals, index: int) -> np.ndarray:
    """Dense ``(H, W)`` boolean mask number ``index``."""
    height, width = int(masks.heights[index]), int(masks.widths[index])
    lo, hi = masks.offsets[index], masks.offsets[index + 1]
    toggles = np.zeros(height * width + 1, dtype=np.int8)
    np.add.at(toggles, masks.starts[lo:hi], 1)
    np.add.at(toggles, masks.ends[lo:hi], -1)
    flat = np.cumsum(toggles[:-1]) > 0
    return flat.reshape(width, height).T


def encode_mask(mask: np.ndarray) -> dict:
    """Encodes an ``(H, W)`` boolean mask as a COCO compressed RLE ``{"size": [H, W], "counts": str}``."""
    masks = intervals_from_mask(mask)
    return {"size": [int(masks.heights[0]), int(masks.widths[0])],
            "counts": encode_counts_string(counts_from_intervals(masks, 0))}


def decode_rle(rle: dict) -> np.ndarray:
    """Decodes a COCO RLE dict (compressed or uncompressed ``counts``) into an ``(H, W)`` bool mask."""
    return mask_from_intervals(segmentations_to_intervals([rle], [None], [None], "rle"), 0)


# ----------------------------------------------------------------------------------------------
# Polygons
# ----------------------------------------------------------------------------------------------

def _parts_to_intervals(coordinates: np.ndarray, vertex_counts: np.ndarray, heights: np.ndarray,
                        widths: np.ndarray, part_owner: np.ndarray, n_masks: int) -> tuple:
    """Rasterizes polygon parts (:func:`evaluation.coco_kernels.polygon_runs`, rleFrPoly's walk) and
    unites the parts of each mask.

    Returns:
        (starts, ends, owner) runs sorted by owner then position.
    """
    if len(vertex_counts) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    from evaluation import coco_kernels  # here: numba loads only when polygons are rasterized

    # rleFrPoly's grid: C casts double -> int by truncation toward zero, as numpy's astype does
    scaled = (POLYGON_SCALE * coordinates + 0.5).astype(np.int64)
    part, starts, ends = coco_kernels.polygon_runs(
        np.ascontiguousarray(scaled[:, 0]), np.ascontiguousarray(scaled[:, 1]), np.asarray(vertex_counts, np.int64),
        np.asarray(heights, np.int64), np.asarray(widths, np.int64))
    owner = part_owner[part]  # parts are listed mask by mask, so runs stay grouped by owner
    shared = (np.bincount(part_owner, minlength=n_masks) > 1)[owner]
    if not np.any(shared):
        return starts, ends, owner
    # union of the parts of multi-part masks: sweep +1/-1 events per mask
    mask_stride = int((heights * widths).max()) + 2  # above every position, end included
    event_keys = np.concatenate([starts[shared], ends[shared]]) + np.tile(owner[shared], 2) * mask_stride
    event_delta = np.repeat(np.array([1, -1], dtype=np.int64), np.count_nonzero(shared))
    order = np.argsort(event_keys, kind="stable")
    event_keys, event_delta = event_keys[order], event_delta[order]
    distinct = np.concatenate([[True], event_keys[1:] != event_keys[:-1]])
    positions = event_keys[distinct]
    coverage = np.cumsum(np.add.reduceat(event_delta, np.flatnonzero(distinct)))
    previous = np.concatenate([[0], coverage[:-1]])
    union_starts = positions[(previous == 0) & (coverage > 0)]
    union_ends = positions[(previous > 0) & (coverage == 0)]
    union_owner = union_starts // mask_stride
    starts = np.concatenate([starts[~shared], union_starts - union_owner * mask_stride])
    ends = np.concatenate([ends[~shared], union_ends - union_owner * mask_stride])
    owner = np.concatenate([owner[~shared], union_owner])
    order = np.argsort(owner, kind="stable")
    return starts[order], ends[order], owner[order]


def segmentations_to_intervals(segmentations: Sequence, heights: Sequence, widths: Sequence,
                               source: str = "segmentation") -> MaskIntervals:
    """Converts COCO segmentations of any kind into :class:`MaskIntervals`.

    Args:
        segmentations: each a polygon list ``[[x0, y0, x1, y1, ...], ...]`` (parts are united), an
            uncompressed RLE ``{"size": [H, W], "counts": [int, ...]}`` or a compressed RLE
            ``{"size": [H, W], "counts": str}``. As in pycocotools, a polygon list whose first part
            has exactly 4 numbers is read as boxes ``[x, y, w, h]``.
        heights, widths: image size per entry (pixels); required for polygons, and when given
            for RLEs they must equal the RLE ``size``. ``None`` means "take it from the RLE".
        source: name used in error messages.

    Raises:
        ValueError: naming ``source`` and the entry index for malformed input.
    """
    n = len(segmentations)
    out_heights = np.zeros(n, dtype=np.int64)
    out_widths = np.zeros(n, dtype=np.int64)
    rle_index, rle_strings, rle_lists = [], [], []
    poly_coords, poly_vertices, poly_owner = [], [], []
    for i, segmentation in enumerate(segmentations):
        height, width = heights[i], widths[i]
        if isinstance(segmentation, dict):
            size = segmentation.get("size")
            counts = segmentation.get("counts")
            if (not isinstance(size, (list, tuple)) or len(size) != 2 or counts is None
                    or not all(isinstance(s, int) and s > 0 for s in size)):
                raise ValueError(f"{source}[{i}]: expected an RLE dict with 'size': [H, W] (positive "
                                 "integers) and 'counts' (string or list of integers)")
            if height is not None and (size[0] != height or size[1] != width):
                raise ValueError(f"{source}[{i}]: RLE size {list(size)} differs from the image size "
                                 f"[{height}, {width}]")
            out_heights[i], out_widths[i] = size
            rle_index.append(i)
            if isinstance(counts, (str, bytes)):
                rle_strings.append((len(rle_index) - 1, counts))
            elif isinstance(counts, list):
                rle_lists.append((len(rle_index) - 1, counts))
            else:
                raise ValueError(f"{source}[{i}]: RLE 'counts' must be a string or a list of integers")
            continue
        if not isinstance(segmentation, list) or height is None:
            raise ValueError(f"{source}[{i}]: expected a polygon list [[x0, y0, x1, y1, ...], ...] or an RLE "
                             "dict with 'size' and 'counts'")
        out_heights[i], out_widths[i] = height, width
        parts = segmentation
        if parts and not all(isinstance(p, list) for p in parts):
            raise ValueError(f"{source}[{i}]: polygon parts must be lists of numbers [x0, y0, x1, y1, ...]")
        if parts and len(parts[0]) == 4:
            if not all(len(p) == 4 for p in parts):
                raise ValueError(f"{source}[{i}]: first polygon part has 4 numbers (read as a box "
                                 "[x, y, w, h]), so every part must be a box")
            parts = [[x, y, x, y + h, x + w, y + h, x + w, y] for x, y, w, h in parts]
        elif parts and len(parts[0]) < 4:
            raise ValueError(f"{source}[{i}]: polygon needs at least 3 points (6 numbers), got "
                             f"{len(parts[0])} numbers")
        for part in parts:
            vertices = len(part) // 2
            if vertices == 0:
                continue
            poly_coords.append(part[:2 * vertices])
            poly_vertices.append(vertices)
            poly_owner.append(i)
    pieces = []
    if poly_vertices:
        flat = np.array(list(itertools.chain.from_iterable(poly_coords)), dtype=np.float64)
        if not np.all(np.isfinite(flat)):
            raise ValueError(f"{source}: polygon coordinates must be finite numbers")
        owner = np.array(poly_owner, dtype=np.int64)
        pieces.append(_parts_to_intervals(flat.reshape(-1, 2), np.array(poly_vertices, dtype=np.int64),
                                          out_heights[owner], out_widths[owner], owner, n))
    if rle_index:
        counts_list: list = [None] * len(rle_index)
        if rle_strings:
            decoded, sizes = _decode_counts_flat([s for _, s in rle_strings], source,
                                                 [rle_index[slot] for slot, _ in rle_strings])
            if not rle_lists:  # common case: every RLE compressed, keep the flat layout
                counts_list = []
            else:
                for (slot, _), counts in zip(rle_strings, np.split(decoded, np.cumsum(sizes)[:-1])):
                    counts_list[slot] = counts
        for slot, counts in rle_lists:
            try:
                array = np.asarray(counts, dtype=np.int64)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{source}[{rle_index[slot]}]: RLE 'counts' list must hold integers") from error
            if array.ndim != 1 or np.any(array < 0):
                raise ValueError(f"{source}[{rle_index[slot]}]: RLE 'counts' must be non-negative integers")
            counts_list[slot] = array
        index = np.array(rle_index, dtype=np.int64)
        if counts_list:
            rle = intervals_from_counts(counts_list, out_heights[index], out_widths[index], source, index)
        else:
            rle = _intervals_from_flat_counts(decoded, sizes, out_heights[index], out_widths[index], source, index)
        pieces.append((rle.starts, rle.ends, index[rle.owners()]))
    if not pieces:
        empty = np.zeros(0, dtype=np.int64)
        return _pack(out_heights, out_widths, empty, empty, empty)
    starts = np.concatenate([p[0] for p in pieces])
    ends = np.concatenate([p[1] for p in pieces])
    owner = np.concatenate([p[2] for p in pieces])
    order = np.argsort(owner, kind="stable")
    return _pack(out_heights, out_widths, starts[order], ends[order], owner[order])


# ----------------------------------------------------------------------------------------------
# IoU
# ----------------------------------------------------------------------------------------------

def _intersections_query(base: MaskIntervals, query: MaskIntervals, base_index: np.ndarray,
                         query_index: np.ndarray) -> np.ndarray:
    """Pixels shared by ``base[base_index[p]]`` and ``query[query_index[p]]`` for every pair ``p``.

    Walks the runs of the query mask and measures each run with the cumulative foreground count
    of the base mask (a searchsorted into all base runs laid end to end).
    """
    base_area = base.heights * base.widths
    key_offsets = np.concatenate([[0], np.cumsum(base_area + 1)[:-1]]).astype(np.int64)
    base_owner = base.owners()
    keyed_starts = base.starts + key_offsets[base_owner]
    keyed_ends = base.ends + key_offsets[base_owner]
    below = np.concatenate([[0], np.cumsum(base.ends - base.starts)])  # foreground before run i
    run_counts = query.offsets[query_index + 1] - query.offsets[query_index]
    runs = concatenated_ranges(query.offsets[query_index], run_counts)
    pair_of_run = _segment_ids(run_counts)
    shift = key_offsets[base_index][pair_of_run]

    def foreground_before(points: np.ndarray) -> np.ndarray:
        run = np.searchsorted(keyed_starts, points, side="right") - 1
        safe = np.maximum(run, 0)
        partial = np.minimum(points, keyed_ends[safe]) - keyed_starts[safe]
        return np.where(run >= 0, below[safe] + partial, 0)

    covered = foreground_before(query.ends[runs] + shift) - foreground_before(query.starts[runs] + shift)
    return np.bincount(pair_of_run, weights=covered, minlength=len(base_index)).astype(np.int64)


def pair_intersections(first: MaskIntervals, second: MaskIntervals, first_index: np.ndarray,
                       second_index: np.ndarray) -> np.ndarray:
    """(P,) int64 pixel counts of ``first[first_index[p]] & second[second_index[p]]``.

    Masks of a pair must have the same size. Each pair walks the mask with fewer runs.
    """
    first_index = np.asarray(first_index, dtype=np.int64)
    second_index = np.asarray(second_index, dtype=np.int64)
    result = np.zeros(len(first_index), dtype=np.int64)
    if len(first_index) == 0:
        return result
    first_runs = np.diff(first.offsets)[first_index]
    second_runs = np.diff(second.offsets)[second_index]
    walk_second = second_runs <= first_runs
    if np.any(walk_second):
        result[walk_second] = _intersections_query(first, second, first_index[walk_second],
                                                   second_index[walk_second])
    if np.any(~walk_second):
        result[~walk_second] = _intersections_query(second, first, second_index[~walk_second],
                                                    first_index[~walk_second])
    return result


def iou_from_intersections(intersection: np.ndarray, detection_area: np.ndarray, truth_area: np.ndarray,
                           truth_is_crowd: np.ndarray) -> np.ndarray:
    """IoU as pycocotools ``rleIou``: ``i / (a_d + a_g - i)``, or ``i / a_d`` against crowd regions."""
    intersection = np.asarray(intersection, dtype=np.float64)
    union = np.where(truth_is_crowd, detection_area, detection_area + truth_area - intersection)
    union = np.where(intersection == 0, 1.0, union)
    return intersection / union


def box_overlap_areas(first_boxes: np.ndarray, second_boxes: np.ndarray) -> np.ndarray:
    """(P,) intersection areas of paired ``[x, y, w, h]`` boxes (0 when disjoint)."""
    a, b = first_boxes, second_boxes
    width = np.minimum(a[:, 0] + a[:, 2], b[:, 0] + b[:, 2]) - np.maximum(a[:, 0], b[:, 0])
    height = np.minimum(a[:, 1] + a[:, 3], b[:, 1] + b[:, 3]) - np.maximum(a[:, 1], b[:, 1])
    return np.clip(width, 0, None) * np.clip(height, 0, None)


def box_iou_pairs(detection_boxes: np.ndarray, truth_boxes: np.ndarray, truth_is_crowd: np.ndarray) -> np.ndarray:
    """IoU of paired ``[x, y, w, h]`` boxes with pycocotools ``bbIou`` arithmetic.

    Args:
        detection_boxes: (P, 4) float64 ``[x, y, w, h]``.
        truth_boxes: (P, 4) float64 ``[x, y, w, h]``.
        truth_is_crowd: (P,) bool; crowd IoU is ``intersection / detection area``.
    """
    d, g = detection_boxes, truth_boxes
    width = np.minimum(d[:, 2] + d[:, 0], g[:, 2] + g[:, 0]) - np.maximum(d[:, 0], g[:, 0])
    height = np.minimum(d[:, 3] + d[:, 1], g[:, 3] + g[:, 1]) - np.maximum(d[:, 1], g[:, 1])
    overlap = (width > 0) & (height > 0)
    intersection = np.where(overlap, width * height, 0.0)
    detection_area = d[:, 2] * d[:, 3]
    union = np.where(truth_is_crowd, detection_area, detection_area + g[:, 2] * g[:, 3] - intersection)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(overlap, intersection / np.where(overlap, union, 1.0), 0.0)


def box_iou(detection_boxes, truth_boxes, truth_is_crowd=None) -> np.ndarray:
    """(D, G) IoU matrix of ``[x, y, w, h]`` boxes, equal to pycocotools ``maskUtils.iou`` on boxes.

    Args:
        detection_boxes: (D, 4) boxes ``[x, y, w, h]`` in pixels.
        truth_boxes: (G, 4) boxes ``[x, y, w, h]`` in pixels.
        truth_is_crowd: (G,) bool, default all False.
    """
    d = np.asarray(detection_boxes, dtype=np.float64).reshape(-1, 4)
    g = np.asarray(truth_boxes, dtype=np.float64).reshape(-1, 4)
    crowd = np.zeros(len(g), bool) if truth_is_crowd is None else np.asarray(truth_is_crowd, bool)
    if crowd.shape != (len(g),):
        raise ValueError(f"truth_is_crowd: expected shape ({len(g)},), got {crowd.shape}")
    di, gi = np.divmod(np.arange(len(d) * len(g)), len(g))
    return box_iou_pairs(d[di], g[gi], crowd[gi]).reshape(len(d), len(g))


def mask_iou(detections: MaskIntervals, truths: MaskIntervals, truth_is_crowd=None) -> np.ndarray:
    """(D, G) IoU matrix of masks, equal to pycocotools ``maskUtils.iou`` on RLEs of equal size.

    Raises:
        ValueError: if a detection and a ground-truth mask differ in size.
    """
    crowd = np.zeros(len(truths), bool) if truth_is_crowd is None else np.asarray(truth_is_crowd, bool)
    if crowd.shape != (len(truths),):
        raise ValueError(f"truth_is_crowd: expected shape ({len(truths)},), got {crowd.shape}")
    di, gi = np.divmod(np.arange(len(detections) * len(truths)), max(len(truths), 1))
    if np.any((detections.heights[di] != truths.heights[gi]) | (detections.widths[di] != truths.widths[gi])):
        raise ValueError("mask_iou: every detection mask must have the size of every ground-truth mask")
    intersection = pair_intersections(detections, truths, di, gi)
    iou = iou_from_intersections(intersection, detections.areas()[di], truths.areas()[gi], crowd[gi])
    return iou.reshape(len(detections), len(truths))
