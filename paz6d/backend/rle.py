"""COCO binary masks: RLE strings, polygon rasterization and run-length intervals, shared by the
COCO reader (:mod:`paz6d.datasets.coco`) and COCO scoring (:mod:`evaluation.coco_masks`).

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

Internally a set of masks is a :class:`MaskIntervals`: the foreground runs of every mask as
half-open intervals ``[start, end)`` of flat indices, stored in one CSR layout so that areas,
bounding boxes and intersections of many masks are computed with a handful of numpy calls. The
loops run in numba (:mod:`paz6d.backend.rle_kernels`, imported on first use).
"""

from __future__ import annotations

import itertools
import operator
from dataclasses import dataclass
from functools import cached_property
from typing import Sequence

import numpy as np

POLYGON_SCALE = 5.0  # rleFrPoly upsampling factor
_SIZE, _COUNTS = operator.itemgetter("size"), operator.itemgetter("counts")
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
        return self._areas_and_boxes[0]

    def boxes(self) -> np.ndarray:
        """(N, 4) float64 tight boxes ``[x, y, w, h]`` (pixels), zeros for empty masks.

        Equals pycocotools ``toBbox``: a run that wraps from one column into the next spans the
        full image height.
        """
        return self._areas_and_boxes[1]

    @cached_property
    def _areas_and_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        from paz6d.backend import rle_kernels  # here: numba loads only when masks are measured

        return rle_kernels.areas_and_boxes(self.heights, self.starts, self.ends, self.offsets)


def concatenated_ranges(firsts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(f, f + c)`` for every pair, vectorized."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    segment_starts = np.cumsum(counts) - counts
    return np.repeat(firsts - segment_starts, counts) + np.arange(total, dtype=np.int64)


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
    from paz6d.backend import rle_kernels  # here: numba loads only when masks are decoded

    chars, string_ends = _characters(strings, source)
    counts, per_string, error, at = rle_kernels.decode_rle_strings(chars, string_ends, _CHAR_OFFSET,
                                                                   _MAX_CHARS_PER_COUNT)
    if error:
        raise ValueError(_string_error_message(error, at, string_ends, source, labels))
    return counts, per_string


def _string_runs(strings: Sequence[str | bytes], heights: np.ndarray, widths: np.ndarray, source: str,
                 labels: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foreground runs ``(starts, ends, runs per string)`` of compressed RLE strings, decoded straight
    into runs; ``ValueError`` as :func:`_decode_counts_flat`, or naming the first string whose run
    lengths do not sum to ``height * width``."""
    from paz6d.backend import rle_kernels  # here: numba loads only when masks are decoded

    chars, string_ends = _characters(strings, source)
    starts, ends, runs, error, at, total = rle_kernels.rle_string_runs(
        chars, string_ends, _CHAR_OFFSET, _MAX_CHARS_PER_COUNT, heights * widths)
    if error == rle_kernels.WRONG_SUM:
        raise ValueError(f"{source}[{labels[at]}]: RLE run lengths sum to {total}, expected height*width = "
                         f"{heights[at] * widths[at]} ({heights[at]}x{widths[at]})")
    if error:
        raise ValueError(_string_error_message(error, at, string_ends, source, labels))
    return starts, ends, runs


def _characters(strings: Sequence[str | bytes], source: str) -> tuple[np.ndarray, np.ndarray]:
    """The strings' characters laid end to end (uint8) and where each string ends (exclusive)."""
    try:
        if set(map(type, strings)) <= {str}:
            text = "".join(strings).encode("ascii")
            lengths = np.fromiter(map(len, strings), dtype=np.int64, count=len(strings))
        else:
            encoded = [s.encode("ascii") if isinstance(s, str) else bytes(s) for s in strings]
            text = b"".join(encoded)
            lengths = np.array([len(s) for s in encoded], dtype=np.int64)
    except UnicodeEncodeError as error:
        raise ValueError(f"{source}: compressed RLE counts must be ASCII strings") from error
    return np.frombuffer(text, dtype=np.uint8), np.cumsum(lengths)


def _string_error_message(error: int, char_index: int, string_ends: np.ndarray, source: str,
                          labels: Sequence[int] | None) -> str:
    """Message for an error of :func:`paz6d.backend.rle_kernels.decode_rle_strings` at ``char_index``."""
    from paz6d.backend import rle_kernels

    messages = {rle_kernels.BAD_CHARACTER: "compressed RLE counts must use characters '0'..'o'",
                rle_kernels.TRUNCATED: "compressed RLE string ends inside a value (truncated counts)",
                rle_kernels.TOO_LONG: f"compressed RLE value longer than {_MAX_CHARS_PER_COUNT} characters",
                rle_kernels.NEGATIVE: "compressed RLE decodes to negative run lengths"}
    string = int(np.searchsorted(string_ends, char_index, side="right"))
    return f"{source}[{string if labels is None else labels[string]}]: {messages[error]}"


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
    heights = np.asarray(heights, dtype=np.int64)
    widths = np.asarray(widths, dtype=np.int64)
    sizes = np.array([len(c) for c in counts_list], dtype=np.int64)
    flat = np.concatenate(counts_list).astype(np.int64) if len(counts_list) else np.zeros(0, np.int64)
    starts, ends, runs = _runs_from_flat_counts(flat, sizes, heights, widths, source, labels)
    return _pack(heights, widths, starts, ends, runs)


def _runs_from_flat_counts(flat: np.ndarray, sizes: np.ndarray, heights: np.ndarray, widths: np.ndarray,
                           source: str, labels: Sequence[int] | None) -> tuple[np.ndarray, ...]:
    """Foreground runs ``(starts, ends, runs per mask)`` of run lengths laid end to end, ``sizes[i]``
    per mask; ``ValueError`` naming the first mask whose lengths do not sum to ``height * width``."""
    from paz6d.backend import rle_kernels  # here: numba loads only when masks are decoded

    starts, ends, runs, bad, total = rle_kernels.runs_from_counts(flat, sizes, heights * widths)
    if bad >= 0:
        label = bad if labels is None else labels[bad]
        raise ValueError(f"{source}[{label}]: RLE run lengths sum to {total}, expected height*width = "
                         f"{heights[bad] * widths[bad]} ({heights[bad]}x{widths[bad]})")
    return starts, ends, runs


def _pack(heights: np.ndarray, widths: np.ndarray, starts: np.ndarray, ends: np.ndarray,
          runs_per_mask: np.ndarray) -> MaskIntervals:
    """Wraps runs (mask by mask, ``runs_per_mask[i]`` each) into a :class:`MaskIntervals`."""
    offsets = np.zeros(len(heights) + 1, dtype=np.int64)
    np.cumsum(runs_per_mask, out=offsets[1:])
    return MaskIntervals(heights, widths, starts.astype(np.int64, copy=False), ends.astype(np.int64, copy=False),
                         offsets)


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
    return _pack(np.array([height]), np.array([width]), starts, ends, np.array([len(starts)]))


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
# Segmentations of any kind: RLE dicts and polygons
# ----------------------------------------------------------------------------------------------

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
    is_rle = np.fromiter(map(isinstance, segmentations, itertools.repeat(dict)), dtype=bool, count=n)
    groups = [np.flatnonzero(is_rle), np.flatnonzero(~is_rle)]
    rle_rows, polygon_rows = groups
    # every entry's structure is checked before anything is decoded, so the first bad entry is named
    rle = _rle_fields([segmentations[i] for i in rle_rows.tolist()], rle_rows, heights, widths)
    polygons = _polygon_fields([segmentations[i] for i in polygon_rows.tolist()], polygon_rows, heights, widths,
                               source)
    if rle is None or polygons is None:
        _raise_first_entry_error(segmentations, heights, widths, source)
    out_heights = np.zeros(n, dtype=np.int64)
    out_widths = np.zeros(n, dtype=np.int64)
    pieces = []
    if len(rle_rows):
        out_heights[rle_rows], out_widths[rle_rows] = rle[0][:, 0], rle[0][:, 1]
        pieces += _rle_runs(rle[1], rle_rows, out_heights[rle_rows], out_widths[rle_rows], source)
    if len(polygon_rows):
        out_heights[polygon_rows], out_widths[polygon_rows] = polygons[0], polygons[1]
        pieces.append((polygon_rows, *_polygon_runs(*polygons, source)))
    return _gather(out_heights, out_widths, pieces)


def _gather(heights: np.ndarray, widths: np.ndarray, pieces: list) -> MaskIntervals:
    """Joins runs made for groups of entries, ``(rows, starts, ends, runs per row)`` each, in entry order."""
    if len(pieces) == 1 and len(pieces[0][0]) == len(heights):  # one kind only: already in entry order
        return _pack(heights, widths, *pieces[0][1:])
    from paz6d.backend import rle_kernels  # here: numba loads only when masks are decoded

    runs_per_mask = np.zeros(len(heights), dtype=np.int64)
    for rows, _, _, runs in pieces:
        runs_per_mask[rows] = runs
    total = int(runs_per_mask.sum())
    masks = _pack(heights, widths, np.empty(total, np.int64), np.empty(total, np.int64), runs_per_mask)
    for rows, starts, ends, runs in pieces:
        rle_kernels.place_runs(rows, starts, ends, runs, masks.offsets, masks.starts, masks.ends)
    return masks


def _given_sizes(rows: np.ndarray, heights: Sequence, widths: Sequence) -> np.ndarray:
    """(k, 2) image sizes of ``rows``, -1 where not given."""
    if None not in heights and None not in widths:
        return np.stack([np.asarray(heights, dtype=np.int64)[rows], np.asarray(widths, dtype=np.int64)[rows]], axis=1)
    return np.array([[-1 if heights[i] is None else heights[i], -1 if widths[i] is None else widths[i]]
                     for i in rows.tolist()], dtype=np.int64).reshape(-1, 2)


def _rle_fields(entries: list, rows: np.ndarray, heights: Sequence, widths: Sequence) -> tuple | None:
    """``(sizes (k, 2), counts values)`` of RLE dicts, or ``None`` when one is malformed (sizes not
    two positive integers, sizes differing from the given image size, counts neither a string nor a list)."""
    if not entries:
        return np.zeros((0, 2), dtype=np.int64), []
    try:
        size_list = list(map(_SIZE, entries))
        counts = list(map(_COUNTS, entries))
        if not (set(map(type, size_list)) <= {list, tuple} and set(map(len, size_list)) == {2}
                and set(map(type, itertools.chain.from_iterable(size_list))) <= {int}):
            return None
        sizes = np.array(size_list, dtype=np.int64)
    except (KeyError, TypeError, ValueError, OverflowError):
        return None
    given = _given_sizes(rows, heights, widths)
    if np.any(sizes <= 0) or np.any((given >= 0) & (given != sizes)):
        return None
    if not all(map(isinstance, counts, itertools.repeat((str, bytes, list)))):
        return None
    return sizes, counts


def _rle_runs(counts: list, rows: np.ndarray, heights: np.ndarray, widths: np.ndarray, source: str) -> list:
    """Runs of RLE entries: one piece ``(rows, starts, ends, runs per row)`` for the compressed
    strings and one for the uncompressed lists."""
    pieces = []
    is_string = ~np.fromiter(map(isinstance, counts, itertools.repeat(list)), dtype=bool, count=len(counts))
    strings = np.flatnonzero(is_string)
    if len(strings):
        pieces.append((rows[strings], *_string_runs([counts[k] for k in strings.tolist()], heights[strings],
                                                    widths[strings], source, rows[strings].tolist())))
    lists = np.flatnonzero(~is_string)
    if len(lists):
        arrays = []
        for k in lists.tolist():
            try:
                array = np.asarray(counts[k], dtype=np.int64)
            except (TypeError, ValueError, OverflowError) as error:
                raise ValueError(f"{source}[{rows[k]}]: RLE 'counts' list must hold integers") from error
            if array.ndim != 1 or np.any(array < 0):
                raise ValueError(f"{source}[{rows[k]}]: RLE 'counts' must be non-negative integers")
            arrays.append(array)
        sizes = np.array([len(a) for a in arrays], dtype=np.int64)
        pieces.append((rows[lists], *_runs_from_flat_counts(np.concatenate(arrays), sizes, heights[lists],
                                                            widths[lists], source, rows[lists].tolist())))
    return pieces


def _polygon_fields(entries: list, rows: np.ndarray, heights: Sequence, widths: Sequence,
                    source: str) -> tuple | None:
    """``(heights, widths, parts, numbers per part, parts per entry)`` of polygon entries with boxes
    turned into 4-vertex polygons and empty parts dropped, or ``None`` when one is malformed (not a
    list of lists, no image size, a first part of fewer than 4 numbers, boxes mixed with polygons)."""
    if not set(map(type, entries)) <= {list}:
        return None
    sizes = _given_sizes(rows, heights, widths)
    if np.any(sizes < 0):
        return None
    parts = list(itertools.chain.from_iterable(entries))
    if not set(map(type, parts)) <= {list}:
        return None
    parts_per_entry = np.fromiter(map(len, entries), dtype=np.int64, count=len(entries))
    lengths = np.fromiter(map(len, parts), dtype=np.int64, count=len(parts))
    first_lengths = lengths[np.cumsum(parts_per_entry)[parts_per_entry > 0] - parts_per_entry[parts_per_entry > 0]]
    if np.any(first_lengths < 4):
        return None
    if np.any(first_lengths == 4):
        parts, parts_per_entry = _boxes_as_polygons(entries, source)
        if parts is None:
            return None
        lengths = np.fromiter(map(len, parts), dtype=np.int64, count=len(parts))
    empty = lengths < 2
    if np.any(empty):
        parts = [part for part, drop in zip(parts, empty.tolist()) if not drop]
        parts_per_entry -= np.bincount(np.repeat(np.arange(len(entries)), parts_per_entry)[empty],
                                       minlength=len(entries))
        lengths = lengths[~empty]
    return np.ascontiguousarray(sizes[:, 0]), np.ascontiguousarray(sizes[:, 1]), parts, lengths, parts_per_entry


def _boxes_as_polygons(entries: list, source: str) -> tuple:
    """Parts with each box entry (first part of 4 numbers ``[x, y, w, h]``) turned into rectangles, as
    pycocotools reads them; ``(None, None)`` when a box entry holds a part that is not a box."""
    parts, parts_per_entry = [], []
    for entry in entries:
        if entry and len(entry[0]) == 4:
            if not all(len(part) == 4 for part in entry):
                return None, None
            try:
                entry = [[x, y, x, y + h, x + w, y + h, x + w, y] for x, y, w, h in entry]
            except TypeError:
                raise ValueError(f"{source}: polygon coordinates must be finite numbers") from None
        parts += entry
        parts_per_entry.append(len(entry))
    return parts, np.array(parts_per_entry, dtype=np.int64)


def _polygon_runs(heights: np.ndarray, widths: np.ndarray, parts: list, lengths: np.ndarray,
                  parts_per_entry: np.ndarray, source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foreground runs ``(starts, ends, runs per entry)`` of polygon entries (``lengths``: numbers per
    part), rasterized as pycocotools does (:func:`paz6d.backend.rle_kernels.polygon_masks`)."""
    vertex_counts = lengths // 2
    if np.any(lengths % 2):  # an odd last number is ignored
        parts = [part[:2 * count] for part, count in zip(parts, vertex_counts.tolist())]
    try:
        flat = np.fromiter(itertools.chain.from_iterable(parts), dtype=np.float64, count=2 * int(vertex_counts.sum()))
    except (TypeError, ValueError):
        flat = None
    if flat is None or not np.all(np.isfinite(flat)):
        raise ValueError(f"{source}: polygon coordinates must be finite numbers")
    from paz6d.backend import rle_kernels  # here: numba loads only when polygons are rasterized

    # rleFrPoly's grid: C casts double -> int by truncation toward zero, as numpy's astype does
    scaled = (POLYGON_SCALE * flat + 0.5).astype(np.int64)
    return rle_kernels.polygon_masks(np.ascontiguousarray(scaled[0::2]), np.ascontiguousarray(scaled[1::2]),
                                     vertex_counts, parts_per_entry, heights, widths)


def _entry_error(index: int, segmentation, height, width, source: str) -> str | None:
    """Message for the structural problem of one segmentation, ``None`` if it has none."""
    where = f"{source}[{index}]"
    if isinstance(segmentation, dict):
        size, counts = segmentation.get("size"), segmentation.get("counts")
        if (not isinstance(size, (list, tuple)) or len(size) != 2 or counts is None
                or not all(type(s) is int and s > 0 for s in size)):
            return (f"{where}: expected an RLE dict with 'size': [H, W] (positive integers) and 'counts' "
                    "(string or list of integers)")
        if height is not None and (size[0] != height or size[1] != width):
            return f"{where}: RLE size {list(size)} differs from the image size [{height}, {width}]"
        if not isinstance(counts, (str, bytes, list)):
            return f"{where}: RLE 'counts' must be a string or a list of integers"
        return None
    if not isinstance(segmentation, list) or height is None:
        return (f"{where}: expected a polygon list [[x0, y0, x1, y1, ...], ...] or an RLE dict with 'size' "
                "and 'counts'")
    if segmentation and not all(isinstance(p, list) for p in segmentation):
        return f"{where}: polygon parts must be lists of numbers [x0, y0, x1, y1, ...]"
    if segmentation and len(segmentation[0]) == 4 and not all(len(p) == 4 for p in segmentation):
        return (f"{where}: first polygon part has 4 numbers (read as a box [x, y, w, h]), so every part "
                "must be a box")
    if segmentation and len(segmentation[0]) < 4:
        return f"{where}: polygon needs at least 3 points (6 numbers), got {len(segmentation[0])} numbers"
    return None


def _raise_first_entry_error(segmentations: Sequence, heights: Sequence, widths: Sequence, source: str):
    """Raises ``ValueError`` for the first malformed segmentation."""
    for i, segmentation in enumerate(segmentations):
        message = _entry_error(i, segmentation, heights[i], widths[i], source)
        if message:
            raise ValueError(message)
    raise ValueError(f"{source}: malformed segmentations (expected polygon lists or RLE dicts with 'size' "
                     "and 'counts')")
