"""Photographic backgrounds from the sample images that scikit-image ships (nothing is downloaded).

Real tabletop photos (LM-O, YCB) show the objects among many other things: cables, papers, boxes,
printed text. Procedural noise and stripes look nothing like that, so a detector trained on them
fires on real clutter. :func:`photo_collage` pastes random crops of scikit-image's bundled
photographs (astronaut, coffee, rocket, bricks, gravel, coins, text pages...) into one cluttered
picture; :func:`write_backgrounds` writes a folder of them for ``paz6d generate --backgrounds``.

Example::

    python -m paz6d.synthesis.photo_backgrounds out/backgrounds --count 200
    paz6d generate ... --backgrounds out/backgrounds
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from paz6d.backend.files import write_bytes_atomically
from paz6d.backend.image import encode_image
from paz6d.synthesis.backgrounds import crop_background

#: scikit-image sample images bundled with the wheel (``skimage.data.<name>()`` needs no download).
SAMPLE_NAMES = ("astronaut", "brick", "camera", "cell", "chelsea", "checkerboard", "clock", "coffee", "coins",
                "colorwheel", "grass", "gravel", "hubble_deep_field", "immunohistochemistry", "logo", "moon", "page",
                "retina", "rocket", "text")


def sample_photographs() -> list[np.ndarray]:
    """The bundled scikit-image samples of :data:`SAMPLE_NAMES` as ``uint8`` RGB ``(H, W, 3)`` arrays."""
    from skimage import data

    photographs = []
    for name in SAMPLE_NAMES:
        image = np.asarray(getattr(data, name)())
        if image.dtype != np.uint8:
            image = (255 * (image.astype(np.float64) / max(float(image.max()), 1e-9))).astype(np.uint8)
        if image.ndim == 2:
            image = np.repeat(image[..., None], 3, axis=2)
        photographs.append(np.ascontiguousarray(image[..., :3]))
    return photographs


def _random_crop(generator: np.random.Generator, photograph: np.ndarray, width: int, height: int) -> np.ndarray:
    """A crop of 20-100 % of the largest window (at most 4x the output size), mirrored half of the
    time, area-resized to ``(height, width, 3)``."""
    return crop_background(generator, photograph, width, height, scale=(0.2, 1.0), max_downscale=4.0,
                           interpolation=cv2.INTER_AREA)


#: Default number of pasted pieces (min, max) and their side as a share of the collage's side (min, max).
PIECES = (4, 16)
PIECE_SIZE = (0.05, 0.45)


def check_collage_layout(pieces: tuple[int, int], piece_size: tuple[float, float]) -> None:
    """Raises ``ValueError`` naming ``pieces``/``piece_size`` unless ``0 <= min <= max`` pieces and
    ``0 < min <= max <= 1`` for the side shares."""
    if len(pieces) != 2 or not 0 <= int(pieces[0]) <= int(pieces[1]):
        raise ValueError(f"pieces: expected (min, max) with 0 <= min <= max, got {tuple(pieces)}")
    if len(piece_size) != 2 or not 0 < float(piece_size[0]) <= float(piece_size[1]) <= 1:
        raise ValueError(f"piece_size: expected (min, max) shares of the side with 0 < min <= max <= 1, "
                         f"got {tuple(piece_size)}")


def photo_collage(generator: np.random.Generator, photographs: Sequence[np.ndarray], width: int, height: int,
                  pieces: tuple[int, int] = PIECES, piece_size: tuple[float, float] = PIECE_SIZE) -> np.ndarray:
    """``(height, width, 3)`` uint8: a crop of one photograph covered by ``pieces`` (min, max) rectangles,
    each a crop of a random photograph (``piece_size``: width and height each a uniform share of the
    image's, default 5-45 %), colour-scaled by 0.6-1.4 per channel.

    Many small pieces on a large collage (e.g. 20-60 pieces of 3-25 % on 1280 x 960) keep more fine
    detail once ``paz6d generate`` crops and shrinks it to the image size (``docs/ssd.md``).

    Args:
        generator: draws everything.
        photographs: ``uint8`` RGB images (e.g. :func:`sample_photographs`).
    """
    if not photographs:
        raise ValueError("photographs: expected at least one image")
    if int(width) < 1 or int(height) < 1:
        raise ValueError(f"width/height: expected positive pixel sizes, got {width}, {height}")
    check_collage_layout(pieces, piece_size)
    canvas = _random_crop(generator, photographs[int(generator.integers(len(photographs)))], width, height)
    for _ in range(int(generator.integers(pieces[0], pieces[1] + 1))):
        piece_width = max(2, int(generator.uniform(*piece_size) * width))
        piece_height = max(2, int(generator.uniform(*piece_size) * height))
        piece = _random_crop(generator, photographs[int(generator.integers(len(photographs)))], piece_width,
                             piece_height)
        piece = np.clip(piece * generator.uniform(0.6, 1.4, 3), 0, 255).astype(np.uint8)
        x = int(generator.integers(-piece_width // 2, width - piece_width // 2))
        y = int(generator.integers(-piece_height // 2, height - piece_height // 2))
        left, top = max(x, 0), max(y, 0)
        right, bottom = min(x + piece_width, width), min(y + piece_height, height)
        canvas[top:bottom, left:right] = piece[top - y:bottom - y, left - x:right - x]
    return canvas


def write_backgrounds(folder: str | Path, count: int, width: int = 640, height: int = 480, seed: int = 0,
                      pieces: tuple[int, int] = PIECES, piece_size: tuple[float, float] = PIECE_SIZE) -> list[Path]:
    """Writes ``count`` collages ``folder/background_XXXXX.jpg`` (collage ``i`` drawn from
    ``SeedSequence([seed, i])``, see :func:`photo_collage`); returns their paths."""
    if int(count) < 1:
        raise ValueError(f"count: expected a positive number of backgrounds, got {count}")
    check_collage_layout(pieces, piece_size)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    photographs = sample_photographs()
    paths = []
    for index in range(int(count)):
        collage = photo_collage(np.random.default_rng([seed, index]), photographs, width, height, pieces, piece_size)
        path = folder / f"background_{index:05d}.jpg"
        write_bytes_atomically(path, encode_image(collage, ".jpg", (cv2.IMWRITE_JPEG_QUALITY, 92)))
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``python -m paz6d.synthesis.photo_backgrounds OUT [--count N] [--width W] [--height H] [--seed S]
    [--pieces MIN MAX] [--piece-size MIN MAX]``."""
    parser = argparse.ArgumentParser(description="write photographic collage backgrounds for paz6d generate")
    parser.add_argument("out", type=Path, help="output folder")
    parser.add_argument("--count", type=int, default=200, help="number of backgrounds (default: 200)")
    parser.add_argument("--width", type=int, default=640, help="width in pixels (default: 640)")
    parser.add_argument("--height", type=int, default=480, help="height in pixels (default: 480)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default: 0)")
    parser.add_argument("--pieces", type=int, nargs=2, default=PIECES, metavar=("MIN", "MAX"),
                        help=f"pasted pieces per collage (default: {PIECES[0]} {PIECES[1]})")
    parser.add_argument("--piece-size", type=float, nargs=2, default=PIECE_SIZE, metavar=("MIN", "MAX"),
                        help=f"piece side as a share of the collage side (default: {PIECE_SIZE[0]} {PIECE_SIZE[1]})")
    args = parser.parse_args(argv)
    try:
        paths = write_backgrounds(args.out, args.count, args.width, args.height, args.seed, tuple(args.pieces),
                                  tuple(args.piece_size))
    except ValueError as error:
        parser.error(str(error))
    print(f"{len(paths)} backgrounds written to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
