"""COCO RLE encoder against pycocotools (the reference implementation)."""

from __future__ import annotations

import numpy as np
import pytest
from pycocotools import mask as mask_utils

from data_gen.coco import encode_rle
from evaluation.coco_masks import decode_rle
from paz6d.datasets.bop.writer import bbox_xywh


def masks():
    generator = np.random.default_rng(0)
    yield np.zeros((5, 7), dtype=bool)
    yield np.ones((4, 3), dtype=bool)
    corner = np.zeros((6, 6), dtype=bool)
    corner[0, 0] = True  # first pixel set: counts start with an empty background run
    yield corner
    last = np.zeros((3, 8), dtype=bool)
    last[-1, -1] = True
    yield last
    for _ in range(20):
        height, width = generator.integers(1, 40, size=2)
        yield generator.random((height, width)) < generator.uniform(0.05, 0.95)
    blob = np.zeros((48, 64), dtype=bool)
    rows, columns = np.mgrid[0:48, 0:64]
    blob[(rows - 20) ** 2 + (columns - 30) ** 2 < 150] = True
    yield blob


@pytest.mark.parametrize("mask", list(masks()), ids=lambda mask: f"{mask.shape}-{int(mask.sum())}")
def test_rle_matches_pycocotools(mask):
    rle = encode_rle(mask)
    assert rle["size"] == list(mask.shape)
    compressed = mask_utils.frPyObjects(rle, *mask.shape)
    reference = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    assert compressed["counts"] == reference["counts"]
    np.testing.assert_array_equal(mask_utils.decode(compressed).astype(bool), mask)
    np.testing.assert_array_equal(decode_rle(rle), mask)
    assert mask_utils.area(compressed) == mask.sum()
    if mask.any():
        np.testing.assert_array_equal(mask_utils.toBbox(compressed), bbox_xywh(mask))
    else:
        assert bbox_xywh(mask) == [-1, -1, -1, -1]


def test_bad_rle_input_is_rejected():
    with pytest.raises(ValueError, match="mask: expected shape"):
        encode_rle(np.zeros((2, 2, 2), dtype=bool))
    with pytest.raises(ValueError, match="RLE run lengths sum to 3, expected height\\*width = 4"):
        decode_rle({"counts": [1, 2], "size": [2, 2]})
