"""Image I/O, geometry and photometric augmentation on ``uint8`` RGB ``(H, W, 3)`` arrays.

OpenCV's BGR order never leaks out: :func:`load_image` returns RGB and :func:`save_image` takes
RGB. Random augmentations take a ``seed`` or a ``numpy.random.Generator`` (passed through
``numpy.random.default_rng``, so a Generator is used as is and advanced).

Example:
    >>> import numpy as np
    >>> from paz6d.backend import image
    >>> picture = np.full((4, 6, 3), 100, np.uint8)
    >>> image.adjust_brightness(picture, 30)[0, 0].tolist()
    [130, 130, 130]
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

import cv2
import numpy as np

from paz6d.backend.checks import as_array
from paz6d.backend.files import input_file_errors, write_bytes_atomically

COLOR_SPACES = ("RGB", "BGR", "HSV", "LAB", "GRAY")
INTERPOLATIONS = {"nearest": cv2.INTER_NEAREST, "linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC,
                  "area": cv2.INTER_AREA, "lanczos": cv2.INTER_LANCZOS4}
_WRITABLE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp")
#: Largest image side :func:`load_image` decodes (pixels); a header claiming more is refused before decoding.
MAX_IMAGE_SIDE = 16384


def as_image(value, name: str = "image", channels: int | None = 3) -> np.ndarray:
    """Checks a ``uint8`` image of shape ``(H, W, channels)`` (``(H, W)`` when ``channels`` is None)."""
    image = np.asarray(value)
    expected = "(H, W)" if channels is None else f"(H, W, {channels})"
    if image.dtype != np.uint8:
        raise ValueError(f"{name}: expected a uint8 image {expected}, got dtype {image.dtype}")
    wanted_ndim = 2 if channels is None else 3
    if image.ndim != wanted_ndim or (channels is not None and image.shape[-1] != channels) or 0 in image.shape:
        raise ValueError(f"{name}: expected a non-empty uint8 image {expected}, got shape {image.shape}")
    return image


def _generator(seed) -> np.random.Generator:
    return np.random.default_rng(seed)


_JPEG_FRAMES = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _header_size(path: Path) -> tuple[int, int] | None:
    """``(width, height)`` from a PNG ``IHDR`` or JPEG ``SOF`` header; ``None`` for other files and for
    a JPEG without a frame header. ``OSError`` when the file cannot be read."""
    with path.open("rb") as handle:
        start = handle.read(24)
        if start[:8] == b"\x89PNG\r\n\x1a\n" and start[12:16] == b"IHDR":
            width, height = struct.unpack(">II", start[16:24])
            return int(width), int(height)
        if start[:2] != b"\xff\xd8":
            return None
        handle.seek(2)
        while True:
            marker = handle.read(2)
            while len(marker) == 2 and marker[1] == 0xFF:  # fill bytes
                marker = marker[1:] + handle.read(1)
            if len(marker) < 2 or marker[0] != 0xFF:
                return None
            if marker[1] in (0xD8, 0x01) or 0xD0 <= marker[1] <= 0xD7:
                continue
            length_bytes = handle.read(2)
            if len(length_bytes) < 2:
                return None
            length = struct.unpack(">H", length_bytes)[0]
            if marker[1] in _JPEG_FRAMES:
                frame = handle.read(5)
                if len(frame) < 5:
                    return None
                height, width = struct.unpack(">HH", frame[1:5])
                return int(width), int(height)
            handle.seek(length - 2, io.SEEK_CUR)


def image_size_from_header(path: str | Path) -> tuple[int, int]:
    """``(width, height)`` of an image from its PNG ``IHDR`` or JPEG ``SOF`` header (other formats:
    decoded with OpenCV). Raises ``ValueError`` naming the file when it cannot be read."""
    path = Path(path)
    with input_file_errors(path, "image file"):
        size = _header_size(path)
    if size is not None:
        return size
    with path.open("rb") as handle:
        if handle.read(2) == b"\xff\xd8":
            raise ValueError(f"{path}: JPEG file without a frame header (SOF marker); cannot read the image size")
    image = load_image(path)
    return image.shape[1], image.shape[0]


def load_image(path: str | Path, grayscale: bool = False) -> np.ndarray:
    """Reads an image file as ``uint8`` RGB ``(H, W, 3)`` (or ``(H, W)`` with ``grayscale``).

    16-bit files are scaled to 8 bits and an alpha channel is dropped (OpenCV ``IMREAD_COLOR``).

    Raises:
        ValueError: the file is missing, cannot be decoded as an image, or its PNG/JPEG header claims a
            side above :data:`MAX_IMAGE_SIDE` (refused before decoding).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: image file not found")
    try:
        size = _header_size(path)
    except OSError as error:
        raise ValueError(f"{path}: cannot read the image ({error.strerror or error})") from None
    if size is not None:
        width, height = size
        if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
            raise ValueError(f"{path}: the image header claims {width} x {height} pixels; expected sides of "
                             f"1..{MAX_IMAGE_SIDE} px")
    data = np.fromfile(path, dtype=np.uint8)
    flag = cv2.IMREAD_GRAYSCALE if grayscale else cv2.IMREAD_COLOR
    decoded = cv2.imdecode(data, flag) if data.size else None
    if decoded is None:
        raise ValueError(f"{path}: could not decode image (corrupt or unsupported format)")
    return decoded if grayscale else cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)


def encode_image(image, extension: str = ".png", parameters: list[int] | tuple[int, ...] = ()) -> bytes:
    """The bytes of an image file (``extension`` such as ``".png"`` or ``".jpg"``; OpenCV ``imwrite``
    ``parameters`` such as PNG compression).

    Accepts ``uint8`` RGB ``(H, W, 3)``, ``uint8``/``uint16`` single-channel ``(H, W)`` and ``bool``
    masks ``(H, W)`` (written as ``{0, 255}``).
    """
    array = np.asarray(image)
    if array.dtype == bool and array.ndim == 2:
        array = array.view(np.uint8) * np.uint8(255)
    if array.ndim == 3:
        array = cv2.cvtColor(as_image(array), cv2.COLOR_RGB2BGR)
    elif array.ndim != 2 or array.dtype not in (np.uint8, np.uint16) or 0 in array.shape:
        raise ValueError(f"image: expected uint8 RGB (H, W, 3), uint8/uint16 (H, W) or bool (H, W), "
                         f"got {array.dtype} {array.shape}")
    ok, encoded = cv2.imencode(extension, array, list(parameters))
    if not ok:
        raise ValueError(f"image: OpenCV could not encode a {array.dtype} {array.shape} array as {extension}")
    return encoded.tobytes()


def save_image(path: str | Path, image) -> Path:
    """Writes an image atomically (temporary file in the same folder, then ``os.replace``); the format
    follows the suffix (see :func:`encode_image` for the accepted arrays)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in _WRITABLE_SUFFIXES:
        raise ValueError(f"{path}: unsupported image suffix {path.suffix!r}; expected one of {_WRITABLE_SUFFIXES}")
    try:
        data = encode_image(image, suffix)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from error
    return write_bytes_atomically(path, data)


def resize(image, size: tuple[int, int], interpolation: str = "linear") -> np.ndarray:
    """Resizes to ``size = (width, height)`` pixels; ``interpolation`` is one of :data:`INTERPOLATIONS`."""
    image = np.asarray(image)
    if image.ndim not in (2, 3) or 0 in image.shape:
        raise ValueError(f"image: expected a non-empty (H, W) or (H, W, C) array, got shape {image.shape}")
    width, height = (int(value) for value in size)
    if width <= 0 or height <= 0:
        raise ValueError(f"size: expected positive (width, height), got {size}")
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {sorted(INTERPOLATIONS)}, got {interpolation!r}")
    return cv2.resize(image, (width, height), interpolation=INTERPOLATIONS[interpolation])


def pixel_slices_from_box(box, image_shape: tuple[int, ...]) -> tuple[slice, slice]:
    """Rows/columns slices of the pixels touched by ``xyxy`` ``box``, clipped to the image.

    With pixel ``i`` covering ``[i, i + 1)``, the box covers columns ``floor(x_min)`` to
    ``ceil(x_max) - 1``.
    """
    x_min, y_min, x_max, y_max = as_array(box, "box", (4,)).reshape(4)
    height, width = image_shape[:2]
    columns = slice(int(np.clip(np.floor(x_min), 0, width)), int(np.clip(np.ceil(x_max), 0, width)))
    rows = slice(int(np.clip(np.floor(y_min), 0, height)), int(np.clip(np.ceil(y_max), 0, height)))
    return rows, columns


def nonzero_window(mask: np.ndarray, margin: int = 0) -> tuple[slice, slice] | None:
    """``(rows, columns)`` slices of the tight box around the nonzero pixels of a 2D ``mask``, grown
    by ``margin`` pixels on each side and clipped to the mask; ``None`` when the mask is empty."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    columns = np.flatnonzero(mask.any(axis=0))
    height, width = mask.shape
    return (slice(max(int(rows[0]) - margin, 0), min(int(rows[-1]) + 1 + margin, height)),
            slice(max(int(columns[0]) - margin, 0), min(int(columns[-1]) + 1 + margin, width)))


def mask_box(mask: np.ndarray) -> np.ndarray | None:
    """``xyxy`` box ``(4,)`` float64 of the nonzero pixels of a 2D ``mask`` (pixel ``i`` covers
    ``[i, i + 1)``, so the box is ``(x_min, y_min, x_max + 1, y_max + 1)``); ``None`` when empty."""
    window = nonzero_window(mask)
    if window is None:
        return None
    rows, columns = window
    return np.array([columns.start, rows.start, columns.stop, rows.stop], dtype=np.float64)


def crop(image, box) -> np.ndarray:
    """Copies the pixels covered by ``xyxy`` ``box`` (clipped to the image).

    Raises:
        ValueError: the box does not cover any pixel of the image.
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3):
        raise ValueError(f"image: expected (H, W) or (H, W, C), got shape {image.shape}")
    rows, columns = pixel_slices_from_box(box, image.shape)
    if rows.stop <= rows.start or columns.stop <= columns.start:
        raise ValueError(f"box: {np.asarray(box).tolist()} covers no pixel of a "
                         f"{image.shape[1]}x{image.shape[0]} image")
    return image[rows, columns].copy()


def pad_to_square(image, value: int = 0) -> tuple[np.ndarray, tuple[int, int]]:
    """Pads the shorter side symmetrically (extra pixel at the end) to a square image.

    Returns:
        ``(padded, (offset_x, offset_y))``: a pixel ``(u, v)`` of the input is ``(u + offset_x,
        v + offset_y)`` in the output.
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or 0 in image.shape:
        raise ValueError(f"image: expected a non-empty (H, W) or (H, W, C) array, got shape {image.shape}")
    height, width = image.shape[:2]
    side = max(height, width)
    offset_x, offset_y = (side - width) // 2, (side - height) // 2
    padded = np.full((side, side) + image.shape[2:], value, dtype=image.dtype)
    padded[offset_y:offset_y + height, offset_x:offset_x + width] = image
    return padded, (offset_x, offset_y)


def flip_left_right(image) -> np.ndarray:
    """Mirrors an image horizontally (column ``i`` goes to ``W - 1 - i``)."""
    return np.ascontiguousarray(np.asarray(image)[:, ::-1])


def convert_color_space(image, source: str, target: str) -> np.ndarray:
    """Converts between ``"RGB"``, ``"BGR"``, ``"HSV"``, ``"LAB"`` and ``"GRAY"`` (OpenCV
    conventions: 8-bit HSV hue in ``[0, 180)``, ``GRAY`` is ``(H, W)``).
    """
    for argument, value in (("source", source), ("target", target)):
        if value not in COLOR_SPACES:
            raise ValueError(f"{argument}: expected one of {COLOR_SPACES}, got {value!r}")
    image = as_image(image, "image", None if source == "GRAY" else 3)
    if source == target:
        return image.copy()
    if "RGB" not in (source, target) and "BGR" not in (source, target):
        image = cv2.cvtColor(image, getattr(cv2, f"COLOR_{source}2RGB"))
        source = "RGB"
    return cv2.cvtColor(image, getattr(cv2, f"COLOR_{source}2{target}"))


def normalize(image, mean=None, std=None) -> np.ndarray:
    """``uint8`` image to ``float32``: ``(image / 255 - mean) / std`` (per channel when given)."""
    values = np.asarray(image, dtype=np.float32) / 255.0
    if mean is not None:
        values = values - np.asarray(mean, dtype=np.float32)
    if std is not None:
        std = np.asarray(std, dtype=np.float32)
        if np.any(std <= 0):
            raise ValueError(f"std: expected positive values, got {std.tolist()}")
        values = values / std
    return values


def denormalize(values, mean=None, std=None) -> np.ndarray:
    """Inverse of :func:`normalize`, rounded and clipped back to ``uint8``."""
    values = np.asarray(values, dtype=np.float32)
    if std is not None:
        values = values * np.asarray(std, dtype=np.float32)
    if mean is not None:
        values = values + np.asarray(mean, dtype=np.float32)
    return np.clip(np.rint(values * 255.0), 0, 255).astype(np.uint8)


def _to_uint8(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


_LEVELS = np.arange(256, dtype=np.float32)


def _apply_table(channel_or_image: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Maps every ``uint8`` value through ``table`` (256 entries, or ``(256, C)``: one column per channel);
    a per-value rule computed once instead of per pixel."""
    table = np.ascontiguousarray(table, dtype=np.uint8)
    return cv2.LUT(channel_or_image, table.reshape(1, 256, -1) if table.ndim == 2 else table)


def adjust_brightness(image, delta: float) -> np.ndarray:
    """Adds ``delta`` (intensity levels) to every channel, clipped to ``[0, 255]``."""
    return _apply_table(as_image(image), _to_uint8(_LEVELS + float(delta)))


def adjust_contrast(image, factor: float) -> np.ndarray:
    """Scales each channel's deviation from its mean by ``factor`` (``tf.image.adjust_contrast`` rule)."""
    image = as_image(image)
    mean = np.float32(cv2.mean(image)[:3])  # per channel, summed in float64
    return _apply_table(image, _to_uint8((_LEVELS[:, None] - mean) * np.float32(factor) + mean))


def adjust_saturation(image, factor: float) -> np.ndarray:
    """Multiplies the HSV saturation by ``factor`` (clipped)."""
    hsv = cv2.cvtColor(as_image(image), cv2.COLOR_RGB2HSV_FULL)
    hsv[..., 1] = _apply_table(np.ascontiguousarray(hsv[..., 1]), _to_uint8(_LEVELS * float(factor)))
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB_FULL)


def adjust_hue(image, delta_degrees: float) -> np.ndarray:
    """Rotates the hue by ``delta_degrees`` (wrapping around the colour circle)."""
    hsv = cv2.cvtColor(as_image(image), cv2.COLOR_RGB2HSV)
    hue = np.mod(np.rint(_LEVELS + float(delta_degrees) / 2.0), 180)  # 8-bit OpenCV hue is degrees / 2
    hsv[..., 0] = _apply_table(np.ascontiguousarray(hsv[..., 0]), hue)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def gaussian_blur(image, kernel_size: int, sigma: float = 0.0) -> np.ndarray:
    """Gaussian blur with an odd ``kernel_size``; ``sigma = 0`` derives it from the size (OpenCV rule)."""
    image = as_image(image)
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f"kernel_size: expected an odd positive integer, got {kernel_size}")
    return cv2.GaussianBlur(image, (kernel_size, kernel_size), sigma)


def add_gaussian_noise(image, std: float, seed: int | np.random.Generator | None = None) -> np.ndarray:
    """Adds zero-mean Gaussian noise of standard deviation ``std`` (intensity levels), clipped."""
    image = as_image(image)
    if std < 0:
        raise ValueError(f"std: expected a non-negative standard deviation, got {std}")
    noise = _generator(seed).normal(0.0, std, image.shape)
    return _to_uint8(image.astype(np.float32) + noise)


def _check_range(lower: float, upper: float, name: str) -> None:
    if not lower <= upper:
        raise ValueError(f"{name}: expected lower <= upper, got ({lower}, {upper})")


def random_brightness(image, seed=None, max_delta: float = 32.0) -> np.ndarray:
    """Adds a brightness offset drawn uniformly from ``[-max_delta, max_delta]``."""
    _check_range(-max_delta, max_delta, "max_delta")
    return adjust_brightness(image, _generator(seed).uniform(-max_delta, max_delta))


def random_contrast(image, seed=None, lower: float = 0.5, upper: float = 1.5) -> np.ndarray:
    """Contrast factor drawn uniformly from ``[lower, upper]`` (see :func:`adjust_contrast`)."""
    _check_range(lower, upper, "lower/upper")
    return adjust_contrast(image, _generator(seed).uniform(lower, upper))


def random_saturation(image, seed=None, lower: float = 0.5, upper: float = 1.5) -> np.ndarray:
    """Saturation factor drawn uniformly from ``[lower, upper]``."""
    _check_range(lower, upper, "lower/upper")
    return adjust_saturation(image, _generator(seed).uniform(lower, upper))


def random_hue(image, seed=None, max_delta_degrees: float = 18.0) -> np.ndarray:
    """Hue rotation drawn uniformly from ``[-max_delta_degrees, max_delta_degrees]``."""
    _check_range(-max_delta_degrees, max_delta_degrees, "max_delta_degrees")
    return adjust_hue(image, _generator(seed).uniform(-max_delta_degrees, max_delta_degrees))


def random_gaussian_blur(image, seed=None, kernel_sizes: tuple[int, ...] = (3, 5, 7)) -> np.ndarray:
    """Gaussian blur with a kernel size drawn from ``kernel_sizes``."""
    if len(kernel_sizes) == 0:
        raise ValueError("kernel_sizes: expected at least one odd kernel size")
    return gaussian_blur(image, int(_generator(seed).choice(kernel_sizes)))


def random_image_noise(image, seed=None, max_std: float = 10.0) -> np.ndarray:
    """Gaussian noise whose standard deviation is drawn uniformly from ``[0, max_std]``."""
    generator = _generator(seed)
    return add_gaussian_noise(image, generator.uniform(0.0, max_std), generator)


def alpha_blend(foreground, alpha, background) -> np.ndarray:
    """Composites ``foreground`` over ``background``: ``alpha * fg + (1 - alpha) * bg``.

    Args:
        foreground: ``uint8`` RGB ``(H, W, 3)``.
        alpha: ``(H, W)`` opacity, ``float`` in ``[0, 1]``, ``bool`` mask or ``uint8`` (255 = opaque).
        background: ``uint8`` RGB ``(H, W, 3)``.
    """
    foreground = as_image(foreground, "foreground")
    background = as_image(background, "background")
    if foreground.shape != background.shape:
        raise ValueError(f"background: expected shape {foreground.shape} like foreground, got {background.shape}")
    alpha = np.asarray(alpha)
    if alpha.shape != foreground.shape[:2]:
        raise ValueError(f"alpha: expected shape {foreground.shape[:2]}, got {alpha.shape}")
    if alpha.dtype == bool:
        return np.where(alpha[..., None], foreground, background)
    if alpha.dtype == np.uint8:
        # Exact integer form of round(fg * a / 255 + bg * (1 - a / 255)), computed only inside the box
        # of alpha > 0 (outside it the result is the background): several times faster for an object.
        image = background.copy()
        window = nonzero_window(alpha)
        if window is not None:
            weight = alpha[window].astype(np.uint16)[..., None]
            blended = (foreground[window].astype(np.uint16) * weight + background[window] * (255 - weight) + 127) // 255
            image[window] = blended.astype(np.uint8)
        return image
    weight = alpha.astype(np.float32)
    if not np.all((weight >= 0) & (weight <= 1)):
        raise ValueError("alpha: expected values in [0, 1] (or a uint8/bool mask)")
    weight = weight[..., None]
    return _to_uint8(weight * foreground + (1.0 - weight) * background)
