"""paz6d.backend.image: I/O, geometry, colour spaces (checked against scikit-image) and seeded
photometric augmentation."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest
from skimage import color

from paz6d.backend import image


@pytest.fixture
def picture() -> np.ndarray:
    """Smooth colourful RGB test image (gradients, so colour conversions are well defined)."""
    rows, cols = np.mgrid[0:48, 0:64]
    red = 40 + 3 * cols
    green = 30 + 4 * rows
    blue = 200 - 2 * cols - rows
    return np.clip(np.stack([red, green, blue], axis=-1), 0, 255).astype(np.uint8)


def test_load_returns_rgb_and_save_round_trips(tmp_path, picture):
    cv2.imwrite(str(tmp_path / "opencv.png"), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    np.testing.assert_array_equal(image.load_image(tmp_path / "opencv.png"), picture)
    saved = image.save_image(tmp_path / "nested" / "ours.png", picture)
    assert saved == tmp_path / "nested" / "ours.png"
    np.testing.assert_array_equal(cv2.imread(str(saved))[..., ::-1], picture)
    gray = image.load_image(saved, grayscale=True)
    assert gray.shape == (48, 64) and gray.dtype == np.uint8
    # ITU-R BT.601 luma; the PNG decoder converts to grey itself and truncates instead of rounding
    np.testing.assert_allclose(gray, picture @ [0.299, 0.587, 0.114], atol=1.01)
    jpeg = image.load_image(image.save_image(tmp_path / "lossy.jpg", picture))
    assert np.abs(jpeg.astype(int) - picture).mean() < 3.0


def test_save_masks_and_16_bit(tmp_path):
    mask = np.zeros((5, 6), bool)
    mask[1:3, 2:5] = True
    written = cv2.imread(str(image.save_image(tmp_path / "mask.png", mask)), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(written, mask.astype(np.uint8) * 255)
    depth = np.arange(30, dtype=np.uint16).reshape(5, 6) * 1000
    written = cv2.imread(str(image.save_image(tmp_path / "depth.png", depth)), cv2.IMREAD_UNCHANGED)
    assert written.dtype == np.uint16
    np.testing.assert_array_equal(written, depth)


def test_save_is_atomic(tmp_path, picture, monkeypatch):
    target = tmp_path / "picture.png"
    image.save_image(target, picture)
    before = target.read_bytes()

    def failing_replace(source, destination):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        image.save_image(target, 255 - picture)
    assert target.read_bytes() == before
    assert sorted(path.name for path in tmp_path.iterdir()) == ["picture.png"]  # no temporary left behind


def test_load_and_save_errors(tmp_path, picture):
    with pytest.raises(ValueError, match=r"missing.png: image file not found"):
        image.load_image(tmp_path / "missing.png")
    (tmp_path / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(200)))
    with pytest.raises(ValueError, match=r"corrupt.png: could not decode image"):
        image.load_image(tmp_path / "corrupt.png")
    (tmp_path / "empty.jpg").write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty.jpg: could not decode image"):
        image.load_image(tmp_path / "empty.jpg")
    with pytest.raises(ValueError, match=r"unsupported image suffix '.txt'"):
        image.save_image(tmp_path / "picture.txt", picture)
    with pytest.raises(ValueError, match=r"image: expected a uint8 image \(H, W, 3\), got dtype float64"):
        image.save_image(tmp_path / "float.png", picture / 255.0)
    with pytest.raises(ValueError, match=r"image: expected uint8 RGB \(H, W, 3\), uint8/uint16 \(H, W\) or bool"):
        image.save_image(tmp_path / "float.png", np.zeros((4, 4), np.float32))
    assert not (tmp_path / "float.png").exists()


def test_resize_matches_opencv_and_validates(picture):
    for name, flag in image.INTERPOLATIONS.items():
        np.testing.assert_array_equal(image.resize(picture, (20, 10), name),
                                      cv2.resize(picture, (20, 10), interpolation=flag))
    assert image.resize(picture[..., 0], (7, 9)).shape == (9, 7)
    with pytest.raises(ValueError, match=r"size: expected positive \(width, height\)"):
        image.resize(picture, (0, 10))
    with pytest.raises(ValueError, match="interpolation: expected one of"):
        image.resize(picture, (10, 10), "bilinear")


def test_crop_covers_the_pixels_touched_by_the_box(picture):
    np.testing.assert_array_equal(image.crop(picture, [2.0, 3.0, 10.0, 7.0]), picture[3:7, 2:10])
    np.testing.assert_array_equal(image.crop(picture, [2.5, 3.2, 9.1, 6.9]), picture[3:7, 2:10])
    np.testing.assert_array_equal(image.crop(picture, [-5, -5, 4, 2]), picture[0:2, 0:4])  # clipped
    cropped = image.crop(picture, [0, 0, 2, 2])
    cropped[...] = 0
    assert picture[0, 0].any()  # a copy, not a view
    with pytest.raises(ValueError, match=r"box: \[70, 0, 80, 5\] covers no pixel of a 64x48 image"):
        image.crop(picture, [70, 0, 80, 5])
    with pytest.raises(ValueError, match=r"box: expected shape \(\.\.\., 4\), got \(2,\)"):
        image.crop(picture, [1, 2])


def test_pad_to_square_and_flip(picture):
    padded, (offset_x, offset_y) = image.pad_to_square(picture, value=7)
    assert padded.shape == (64, 64, 3) and (offset_x, offset_y) == (0, 8)
    np.testing.assert_array_equal(padded[8:56], picture)
    assert np.all(padded[:8] == 7) and np.all(padded[56:] == 7)
    tall, (offset_x, offset_y) = image.pad_to_square(picture[:, :45, 0])
    assert tall.shape == (48, 48) and (offset_x, offset_y) == (1, 0)
    np.testing.assert_array_equal(tall[:, 1:46], picture[:, :45, 0])
    flipped = image.flip_left_right(picture)
    np.testing.assert_array_equal(flipped[:, 0], picture[:, 63])
    assert flipped.flags["C_CONTIGUOUS"]


def test_color_space_conversions_match_scikit_image(picture):
    hsv = image.convert_color_space(picture, "RGB", "HSV").astype(float)
    reference = color.rgb2hsv(picture)
    hue_error = np.abs(hsv[..., 0] - reference[..., 0] * 180)
    assert np.minimum(hue_error, 180 - hue_error).max() <= 1.0  # OpenCV stores hue / 2 in 8 bits
    np.testing.assert_allclose(hsv[..., 1:] / 255, reference[..., 1:], atol=1 / 255 + 1e-9)
    lab = image.convert_color_space(picture, "RGB", "LAB").astype(float)
    reference = color.rgb2lab(picture)
    np.testing.assert_allclose(lab[..., 0] * 100 / 255, reference[..., 0], atol=1.0)
    np.testing.assert_allclose(lab[..., 1:] - 128, reference[..., 1:], atol=1.5)  # 8-bit rounding + white point
    gray = image.convert_color_space(picture, "RGB", "GRAY")
    np.testing.assert_allclose(gray, picture @ [0.299, 0.587, 0.114], atol=0.51)
    np.testing.assert_array_equal(image.convert_color_space(picture, "RGB", "BGR"), picture[..., ::-1])
    back = image.convert_color_space(image.convert_color_space(picture, "RGB", "HSV"), "HSV", "RGB")
    assert np.abs(back.astype(int) - picture).max() <= 4
    via_rgb = image.convert_color_space(image.convert_color_space(picture, "RGB", "HSV"), "HSV", "LAB")
    assert np.abs(via_rgb.astype(int) - lab).max() <= 4
    assert image.convert_color_space(gray, "GRAY", "RGB").shape == picture.shape
    with pytest.raises(ValueError, match=r"target: expected one of \('RGB', 'BGR', 'HSV', 'LAB', 'GRAY'\), got 'XYZ'"):
        image.convert_color_space(picture, "RGB", "XYZ")
    with pytest.raises(ValueError, match=r"image: expected a non-empty uint8 image \(H, W, 3\), got shape \(48, 64\)"):
        image.convert_color_space(gray, "RGB", "HSV")


def test_normalize_and_denormalize(picture):
    values = image.normalize(picture, mean=[0.4, 0.5, 0.6], std=[0.2, 0.25, 0.3])
    assert values.dtype == np.float32
    np.testing.assert_allclose(values, (picture / 255 - [0.4, 0.5, 0.6]) / [0.2, 0.25, 0.3], atol=1e-5)
    np.testing.assert_array_equal(image.denormalize(values, [0.4, 0.5, 0.6], [0.2, 0.25, 0.3]), picture)
    np.testing.assert_allclose(image.normalize(picture), picture / 255, atol=1e-7)
    with pytest.raises(ValueError, match="std: expected positive values"):
        image.normalize(picture, std=[0.0, 1.0, 1.0])


def test_brightness_and_contrast_adjustments(picture):
    np.testing.assert_array_equal(image.adjust_brightness(picture, 20), np.clip(picture.astype(int) + 20, 0, 255))
    np.testing.assert_array_equal(image.adjust_brightness(picture, -300), np.zeros_like(picture))
    flat = (100 + picture // 8).astype(np.uint8)  # low contrast: nothing clips at factor 1.5
    mean = flat.reshape(-1, 3).mean(axis=0)
    stretched = image.adjust_contrast(flat, 1.5).astype(float)
    np.testing.assert_allclose(stretched, (flat - mean) * 1.5 + mean, atol=0.5)
    gray_mean = image.adjust_contrast(picture, 0.0)
    np.testing.assert_allclose(gray_mean[0, 0], picture.reshape(-1, 3).mean(axis=0), atol=0.5)


def test_saturation_and_hue_adjustments_match_scikit_image(picture):
    reference = color.rgb2hsv(picture)
    desaturated = color.rgb2hsv(image.adjust_saturation(picture, 0.5))
    np.testing.assert_allclose(desaturated[..., 1], reference[..., 1] * 0.5, atol=0.02)
    np.testing.assert_allclose(desaturated[..., 2], reference[..., 2], atol=0.01)
    gray = image.adjust_saturation(picture, 0.0)
    assert np.all(gray.max(axis=-1) - gray.min(axis=-1) <= 1)
    shifted = color.rgb2hsv(image.adjust_hue(picture, 40.0))
    vivid = (reference[..., 1] > 0.3) & (reference[..., 2] > 0.3)
    difference = np.mod(shifted[..., 0] - reference[..., 0] - 40 / 360 + 0.5, 1.0) - 0.5
    assert np.abs(difference[vivid]).max() < 3 / 360  # 2-degree hue quantization of 8-bit HSV
    np.testing.assert_allclose(shifted[..., 2][vivid], reference[..., 2][vivid], atol=0.02)
    full_turn = image.adjust_hue(picture, 360.0)
    assert np.abs(full_turn.astype(int) - picture).max() <= 4


@pytest.mark.parametrize("amount", [-250.0, -37.5, 0.0, 13.0, 0.45, 1.7, 400.0])
def test_colour_adjustments_equal_their_per_pixel_rules(picture, amount):
    """The 256-entry tables give exactly what the per-pixel float rules give."""
    import cv2

    values = picture.astype(np.float32)
    rule = lambda x: np.clip(np.rint(x), 0, 255).astype(np.uint8)  # noqa: E731
    np.testing.assert_array_equal(image.adjust_brightness(picture, amount), rule(values + np.float32(amount)))
    factor = abs(amount) % 3.0
    mean = picture.reshape(-1, 3).mean(axis=0).astype(np.float32)
    contrast = rule((values - mean) * np.float32(factor) + mean)
    assert np.abs(image.adjust_contrast(picture, factor).astype(int) - contrast).max() <= 1  # the mean's rounding
    hsv = cv2.cvtColor(picture, cv2.COLOR_RGB2HSV_FULL).astype(np.float32)
    hsv[..., 1] = np.clip(hsv[..., 1] * np.float32(factor), 0, 255)
    np.testing.assert_array_equal(image.adjust_saturation(picture, factor),
                                  cv2.cvtColor(rule(hsv), cv2.COLOR_HSV2RGB_FULL))
    hsv = cv2.cvtColor(picture, cv2.COLOR_RGB2HSV)
    hsv[..., 0] = np.mod(np.rint(hsv[..., 0].astype(np.float32) + np.float32(amount / 2.0)), 180).astype(np.uint8)
    np.testing.assert_array_equal(image.adjust_hue(picture, amount), cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB))


def test_gaussian_blur_matches_a_separable_reference(picture):
    size, sigma = 5, 1.3
    offsets = np.arange(size) - size // 2
    kernel = np.exp(-offsets ** 2 / (2 * sigma ** 2))
    kernel /= kernel.sum()
    padded = np.pad(picture.astype(float), ((2, 2), (2, 2), (0, 0)), mode="reflect")  # OpenCV BORDER_REFLECT_101
    rows = sum(weight * padded[index:index + 48] for index, weight in enumerate(kernel))
    expected = sum(weight * rows[:, index:index + 64] for index, weight in enumerate(kernel))
    blurred = image.gaussian_blur(picture, size, sigma)
    assert np.abs(blurred.astype(float) - expected).max() <= 1.0
    with pytest.raises(ValueError, match="kernel_size: expected an odd positive integer, got 4"):
        image.gaussian_blur(picture, 4)


def test_gaussian_noise_is_seeded_and_has_the_requested_spread():
    gray = np.full((200, 200, 3), 128, np.uint8)
    noisy = image.add_gaussian_noise(gray, 10.0, seed=3)
    np.testing.assert_array_equal(noisy, image.add_gaussian_noise(gray, 10.0, seed=3))
    difference = noisy.astype(float) - 128
    assert abs(difference.std() - 10.0) < 0.2 and abs(difference.mean()) < 0.2
    np.testing.assert_array_equal(image.add_gaussian_noise(gray, 0.0, seed=1), gray)
    with pytest.raises(ValueError, match="std: expected a non-negative standard deviation"):
        image.add_gaussian_noise(gray, -1.0)


@pytest.mark.parametrize("function, arguments", [
    (image.random_brightness, (32.0,)), (image.random_contrast, (0.5, 1.5)), (image.random_saturation, (0.5, 1.5)),
    (image.random_hue, (18.0,)), (image.random_gaussian_blur, ((3, 5, 7),)), (image.random_image_noise, (10.0,)),
])
def test_random_augmentations_are_reproducible_per_seed(picture, function, arguments):
    outputs = [function(picture, seed, *arguments) for seed in (0, 0, 1, 2, 3)]
    np.testing.assert_array_equal(outputs[0], outputs[1])
    assert any(not np.array_equal(outputs[0], output) for output in outputs[2:])
    generator = np.random.default_rng(0)
    np.testing.assert_array_equal(function(picture, generator, *arguments), outputs[0])


def test_random_parameters_stay_in_their_ranges():
    gray = np.full((4, 4, 3), 128, np.uint8)
    for seed in range(30):
        offset = int(image.random_brightness(gray, seed, max_delta=10.0)[0, 0, 0]) - 128
        assert -10 <= offset <= 10
        assert int(image.random_hue(np.array([[[255, 0, 0]]], np.uint8), seed, 10.0)[0, 0, 2]) <= 255 * 10 / 60 + 1
    with pytest.raises(ValueError, match=r"lower/upper: expected lower <= upper, got \(1.5, 0.5\)"):
        image.random_contrast(gray, 0, 1.5, 0.5)
    with pytest.raises(ValueError, match="kernel_sizes: expected at least one odd kernel size"):
        image.random_gaussian_blur(gray, 0, ())


def test_alpha_blend(picture):
    background = np.full_like(picture, 10)
    alpha = np.linspace(0, 1, 64)[None, :].repeat(48, axis=0)
    blended = image.alpha_blend(picture, alpha, background)
    np.testing.assert_allclose(blended, alpha[..., None] * picture + (1 - alpha[..., None]) * 10, atol=0.5)
    mask = alpha > 0.5
    np.testing.assert_array_equal(image.alpha_blend(picture, mask, background), np.where(mask[..., None], picture, 10))
    np.testing.assert_array_equal(image.alpha_blend(picture, mask.astype(np.uint8) * 255, background),
                                  np.where(mask[..., None], picture, 10))
    with pytest.raises(ValueError, match=r"alpha: expected values in \[0, 1\]"):
        image.alpha_blend(picture, alpha * 2, background)
    with pytest.raises(ValueError, match=r"alpha: expected shape \(48, 64\), got \(48, 63\)"):
        image.alpha_blend(picture, alpha[:, 1:], background)
    with pytest.raises(ValueError, match=r"background: expected shape \(48, 64, 3\) like foreground"):
        image.alpha_blend(picture, alpha, background[1:])


def test_alpha_blend_uint8_alpha_rounds_like_the_float_formula(picture):
    alpha = np.random.default_rng(1).integers(0, 256, picture.shape[:2], dtype=np.uint8)
    background = np.random.default_rng(2).integers(0, 256, picture.shape, dtype=np.uint8)
    expected = np.rint(alpha[..., None] / 255 * picture + (1 - alpha[..., None] / 255) * background)
    np.testing.assert_array_equal(image.alpha_blend(picture, alpha, background), expected)
    # Only the box of alpha > 0 is blended: outside it the result is the background, untouched.
    alpha[:10], alpha[:, :7] = 0, 0
    blended = image.alpha_blend(picture, alpha, background)
    np.testing.assert_array_equal(blended[:10], background[:10])
    np.testing.assert_array_equal(blended, np.rint(alpha[..., None] / 255 * picture
                                                   + (1 - alpha[..., None] / 255) * background))
    np.testing.assert_array_equal(image.alpha_blend(picture, np.zeros_like(alpha), background), background)


def test_encode_image_matches_the_saved_file_and_takes_encoder_parameters(tmp_path, picture):
    saved = image.save_image(tmp_path / "picture.png", picture)
    assert image.encode_image(picture) == saved.read_bytes()
    fast = image.encode_image(picture, ".png", [cv2.IMWRITE_PNG_COMPRESSION, 1])
    assert fast != saved.read_bytes()
    np.testing.assert_array_equal(cv2.imdecode(np.frombuffer(fast, np.uint8), cv2.IMREAD_COLOR)[..., ::-1], picture)
    mask = picture[..., 0] > 100
    decoded = cv2.imdecode(np.frombuffer(image.encode_image(mask), np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(decoded, mask.astype(np.uint8) * 255)


def test_nonzero_window_is_the_tight_box_grown_and_clipped():
    from paz6d.backend.image import nonzero_window

    mask = np.zeros((6, 8), dtype=np.uint8)
    mask[2, 3] = mask[4, 6] = 9
    assert nonzero_window(mask) == (slice(2, 5), slice(3, 7))
    assert nonzero_window(mask, margin=1) == (slice(1, 6), slice(2, 8))
    assert nonzero_window(mask, margin=3) == (slice(0, 6), slice(0, 8))
    assert nonzero_window(np.zeros((3, 3), bool)) is None


def test_mask_box_covers_the_nonzero_pixels():
    mask = np.zeros((6, 8), dtype=bool)
    mask[2, 3] = mask[4, 6] = True
    np.testing.assert_array_equal(image.mask_box(mask), [3.0, 2.0, 7.0, 5.0])
    assert image.mask_box(mask).dtype == np.float64
    assert image.mask_box(np.zeros((3, 3), np.uint8)) is None
