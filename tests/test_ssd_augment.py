"""SSD's box augmentations (paz6d.synthesis.box_augment) and the photographic backgrounds."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from paz6d.abstract import SequentialProcessor
from paz6d.synthesis.box_augment import (FILL, AnnotatedImage, Expand, Grayscale, PhotometricDistortion, RandomFlip,
                                         RandomSampleCrop, RandomScaleCrop, WhiteBalance, ssd_augmentation)
from paz6d.synthesis.photo_backgrounds import photo_collage, sample_photographs, write_backgrounds


def _sample() -> AnnotatedImage:
    """A textured image with two boxes drawn as solid patches of known colour."""
    image = np.random.default_rng(0).integers(0, 60, (90, 120, 3), dtype=np.uint8)
    image[10:40, 20:50] = (250, 10, 10)
    image[50:80, 70:110] = (10, 250, 10)
    return AnnotatedImage(image, np.array([[20, 10, 50, 40], [70, 50, 110, 80]], float), np.array([1, 2]))


def _patch(sample: AnnotatedImage, index: int) -> np.ndarray:
    x0, y0, x1, y1 = np.round(sample.boxes[index]).astype(int)
    return sample.image[y0:y1, x0:x1]


def test_flip_mirrors_image_and_boxes():
    sample = _sample()
    flipped = RandomFlip(probability=1.0, seed=0)(sample)
    np.testing.assert_array_equal(flipped.image, sample.image[:, ::-1])
    np.testing.assert_allclose(flipped.boxes, [[70, 10, 100, 40], [10, 50, 50, 80]])
    np.testing.assert_array_equal(_patch(flipped, 0), _patch(sample, 0)[:, ::-1])
    assert RandomFlip(probability=0.0, seed=0)(sample) is sample


def test_expand_moves_boxes_with_the_content():
    sample = _sample()
    expanded = Expand(max_ratio=3.0, probability=1.0, seed=3)(sample)
    assert expanded.image.shape[0] >= 90 and expanded.image.shape[1] >= 120
    assert expanded.image.shape[:2] != sample.image.shape[:2]
    for index in range(2):
        np.testing.assert_array_equal(_patch(expanded, index), _patch(sample, index))
    np.testing.assert_array_equal(expanded.class_ids, sample.class_ids)


def test_random_sample_crop_keeps_boxes_whose_centre_is_inside():
    sample = _sample()
    crop = RandomSampleCrop(min_ious=(0.0,), seed=0)
    for seed in range(20):
        crop.reseed(seed)
        out = crop(sample)
        assert len(out.boxes) >= 1
        assert np.all(out.boxes[:, :2] >= 0) and np.all(out.boxes[:, 2] <= out.image.shape[1])
        assert np.all(out.boxes[:, 3] <= out.image.shape[0])
        for index, class_id in enumerate(out.class_ids):
            colour = (250, 10, 10) if class_id == 1 else (10, 250, 10)
            assert np.all(_patch(out, index) == colour)  # clipped boxes still cover only their object
    assert RandomSampleCrop(min_ious=(None,), seed=0)(sample) is sample


def test_random_scale_crop_rescales_within_its_range_and_keeps_boxes_on_their_objects():
    sample = _sample()
    crop = RandomScaleCrop(64, scale=(0.6, 1.6), seed=0)
    widths = []
    for seed in range(30):
        crop.reseed(seed)
        out = crop(sample)
        assert out.image.shape == (64, 64, 3)
        assert np.all(out.boxes >= 0) and np.all(out.boxes <= 64)
        for index, class_id in enumerate(out.class_ids):
            x0, y0, x1, y1 = out.boxes[index]
            inner = out.image[int(np.ceil(y0)) + 1:int(y1) - 1, int(np.ceil(x0)) + 1:int(x1) - 1].astype(int)
            colour = (250, 10, 10) if class_id == 1 else (10, 250, 10)
            assert np.abs(inner - colour).max() <= 2  # (interpolated) object colour inside its box
            if x0 > 0 and x1 < 64 and class_id == 1:
                widths.append((x1 - x0) / 30)  # the red patch is 30 px wide
    assert 0.6 - 1e-9 <= min(widths) and max(widths) <= 1.6 + 1e-9 and max(widths) - min(widths) > 0.3
    small = RandomScaleCrop(256, scale=(1.0, 1.0), seed=0)(sample)  # 120 x 90 image on a 256 canvas
    assert small.image.shape == (256, 256, 3) and len(small.boxes) == 2
    assert np.sum(np.all(small.image == FILL, axis=-1)) == 256 * 256 - 120 * 90
    with pytest.raises(ValueError, match="scale: expected 0 < lower <= upper"):
        RandomScaleCrop(64, scale=(1.2, 0.8))


def test_photometric_distortion_changes_colours_only_and_is_seeded():
    sample = _sample()
    first = PhotometricDistortion(seed=5)(sample)
    second = PhotometricDistortion(seed=5)(sample)
    np.testing.assert_array_equal(first.image, second.image)
    np.testing.assert_array_equal(first.boxes, sample.boxes)
    changed = [not np.array_equal(PhotometricDistortion(seed=s)(sample).image, sample.image) for s in range(5)]
    assert any(changed)


def test_white_balance_tints_grey_with_reciprocal_red_and_blue_gains_in_range():
    grey = AnnotatedImage(np.full((6, 8, 3), 100, np.uint8), np.array([[1.0, 1.0, 5.0, 4.0]]), np.array([2]))
    balance = WhiteBalance(0.3, probability=1.0, seed=3)
    gains = []
    for _ in range(40):
        tinted = balance(grey)
        np.testing.assert_array_equal(tinted.boxes, grey.boxes)
        red, green, blue = tinted.image[0, 0].astype(float)
        assert green == 100 and (tinted.image == tinted.image[0, 0]).all()
        assert red * blue == pytest.approx(100 * 100, rel=0.02)  # t and 1 / t
        gains.append(red / 100)
    assert 1 / 1.3 - 0.01 <= min(gains) < 0.9 and 1.3 + 0.01 >= max(gains) > 1.1
    assert WhiteBalance(0.3, probability=0.0, seed=3)(grey) is grey
    with pytest.raises(ValueError, match="strength: expected a gain change >= 0"):
        WhiteBalance(-0.1)


def test_grayscale_replaces_every_channel_with_the_luminance():
    image = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    sample = AnnotatedImage(image, np.array([[1.0, 1.0, 5.0, 4.0]]), np.array([2]))
    grey = Grayscale(probability=1.0, seed=0)(sample)
    expected = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)  # OpenCV's BT.601 weights as the oracle
    for channel in range(3):
        np.testing.assert_allclose(grey.image[..., channel].astype(int), expected.astype(int), atol=1)
    np.testing.assert_array_equal(grey.boxes, sample.boxes)
    assert Grayscale(probability=0.0, seed=0)(sample) is sample
    changed = [Grayscale(probability=0.3, seed=seed)(sample) is not sample for seed in range(200)]
    assert 0.2 < np.mean(changed) < 0.4
    with pytest.raises(ValueError, match="probability: expected a share"):
        Grayscale(probability=1.5)


def test_ssd_augmentation_is_a_named_sequence_and_reproducible():
    chain = ssd_augmentation(seed=1)
    assert isinstance(chain, SequentialProcessor)
    assert chain.names == ["photometric", "expand", "crop", "flip"]
    assert ssd_augmentation(white_balance=0.2).names == ["photometric", "white_balance", "expand", "crop", "flip"]
    assert ssd_augmentation(grayscale=0.2).names == ["photometric", "grayscale", "expand", "crop", "flip"]
    again = ssd_augmentation(seed=1)
    for _ in range(3):
        a, b = chain(_sample()), again(_sample())
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.boxes, b.boxes)


def test_annotated_image_checks_its_fields():
    with pytest.raises(ValueError, match="class_ids: expected 1 ids"):
        AnnotatedImage(np.zeros((4, 4, 3), np.uint8), [[0, 0, 1, 1]], [1, 2])
    with pytest.raises(ValueError, match="image"):
        AnnotatedImage(np.zeros((4, 4), np.uint8), np.zeros((0, 4)), [])


def test_photo_collages_are_seeded_and_written(tmp_path):
    photographs = sample_photographs()
    assert len(photographs) >= 10 and all(p.dtype == np.uint8 and p.shape[2] == 3 for p in photographs)
    first = photo_collage(np.random.default_rng(0), photographs, 64, 48)
    np.testing.assert_array_equal(first, photo_collage(np.random.default_rng(0), photographs, 64, 48))
    assert first.shape == (48, 64, 3) and first.std() > 5
    paths = write_backgrounds(tmp_path / "backgrounds", 3, 64, 48, seed=2)
    assert [path.name for path in paths] == [f"background_0000{i}.jpg" for i in range(3)]
    with pytest.raises(ValueError, match="photographs"):
        photo_collage(np.random.default_rng(0), [], 64, 48)


def test_photo_collage_layout_sets_piece_count_and_size():
    flat = [np.zeros((60, 60, 3), np.uint8), np.full((60, 60, 3), 255, np.uint8)]  # every crop is one colour
    assert photo_collage(np.random.default_rng(0), flat, 200, 200, pieces=(0, 0)).std() == 0
    changed = []
    for seed in range(20):  # one piece of exactly 50 x 50 px: it changes at most 2,500 pixels
        collage = photo_collage(np.random.default_rng(seed), flat, 200, 200, pieces=(1, 1), piece_size=(0.25, 0.25))
        base = collage[0, 0] if (collage == collage[0, 0]).all(axis=2).mean() > 0.5 else collage[-1, -1]
        changed.append(int((collage != base).any(axis=2).sum()))
    assert max(changed) == 2500 and min(changed) == 0

    def edge_share(pieces, piece_size):  # share of pixels next to a piece border
        shares = []
        for seed in range(10):
            collage = photo_collage(np.random.default_rng(seed), flat, 200, 200, pieces, piece_size).astype(int)
            shares.append((np.abs(np.diff(collage, axis=1)).sum(axis=2) > 0).mean())
        return float(np.mean(shares))

    assert edge_share((30, 40), (0.03, 0.1)) > 2 * edge_share((2, 3), (0.4, 0.45))


@pytest.mark.parametrize("pieces, piece_size, field", [((5, 2), (0.1, 0.2), "pieces"), ((-1, 2), (0.1, 0.2), "pieces"),
                                                       ((1, 2), (0.0, 0.2), "piece_size"),
                                                       ((1, 2), (0.3, 0.2), "piece_size"),
                                                       ((1, 2), (0.1, 1.5), "piece_size")])
def test_photo_collage_layout_errors_name_the_field(tmp_path, pieces, piece_size, field):
    with pytest.raises(ValueError, match=field):
        write_backgrounds(tmp_path, 1, 32, 32, pieces=pieces, piece_size=piece_size)
    assert not list(tmp_path.iterdir())  # nothing written
