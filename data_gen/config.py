"""Settings of one `paz6d generate` run, checked before any work starts."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from renderers.renderer import ANTIALIAS_MODES

ROTATION_MODES = ("so3", "view-sphere")
RGB_FORMATS = ("png", "jpg")
BACKGROUND_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or int(value) != value or value <= 0:
        raise ValueError(f"{name}: expected a positive integer, got {value!r}")
    return int(value)


def _range(value, name: str, minimum: float | None = None, maximum: float | None = None) -> tuple:
    low, high = value
    if not (math.isfinite(low) and math.isfinite(high)) or low > high:
        raise ValueError(f"{name}: expected a finite range with min <= max, got {tuple(value)}")
    if minimum is not None and low < minimum:
        raise ValueError(f"{name}: expected values >= {minimum}, got {tuple(value)}")
    if maximum is not None and high > maximum:
        raise ValueError(f"{name}: expected values <= {maximum}, got {tuple(value)}")
    return low, high


def _fraction(value: float, name: str) -> float:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name}: expected a probability in [0, 1], got {value}")
    return float(value)


@dataclass(frozen=True)
class GenerationConfig:
    """Everything that determines a generated data set (plus how to run it).

    Lengths are metres unless a field says otherwise; BOP files on disk are millimetres.

    Attributes:
        meshes: mesh files (PLY/OBJ/GLB/...); object ids come from ``obj_XXXXXX`` file names when
            every file is named so, else 1, 2, ... in the given order.
        output: output folder (BOP layout).
        num_images: number of images.
        width, height: image size in pixels.
        seed: master seed; image ``i`` uses ``SeedSequence([seed, i])``.
        split: BOP split folder name (``train``, ``val``, ``test``...).
        scale: factor from mesh file units to metres (0.001 for BOP meshes in mm).
        intrinsics: ``(fx, fy, cx, cy)`` pixels; default ``fx = fy = 0.9 * width``, centre pixel.
        objects_per_image: ``(min, max)`` annotated objects per image.
        distance: ``(min, max)`` camera-to-object-centre distance in metres; default from the
            largest mesh so that it spans 15 %...60 % of the shorter image side.
        rotation: ``"so3"`` (uniform) or ``"view-sphere"`` (viewpoint on a sphere + in-plane angle).
        inplane_degrees: maximum absolute in-plane rotation for ``view-sphere``.
        elevation_degrees: ``(min, max)`` viewpoint elevation for ``view-sphere``.
        distractors: maximum number of unannotated distractor primitives per image.
        occluder_probability: chance that a primitive is put between the camera and an object.
        backgrounds: folder of background images (procedural backgrounds when ``None``).
        light_count: ``(min, max)`` number of random lights.
        color_jitter: objects' base colour is multiplied by ``U(1 - j, 1 + j)`` per channel.
        blur_probability: chance of a Gaussian blur of the final image.
        noise_std: maximum standard deviation (grey levels) of the Gaussian image noise (added
            to half of the images).
        depth_scale: BOP depth scale: depth PNG value × ``depth_scale`` = millimetres.
        images_per_scene: images per ``<split>/<scene>`` folder.
        crop_size: side in pixels of per-object crops written for autoencoder training (0: off).
        symmetries: JSON file ``{obj_id: {"symmetries_discrete": [...], "symmetries_continuous": [...]}}``
            copied into ``models_info.json`` (BOP units: mm).
        rgb_format: ``"png"`` (lossless) or ``"jpg"`` (quality 95, as BOP's PBR sets; faster).
        antialias: ``"edges"`` (single-sample render with softened object outlines), ``"msaa"``
            (4× multisampled colour: ~2x slower on llvmpipe) or ``"none"``; see
            :class:`renderers.Renderer`.
        platform: OpenGL platform for the renderers (``egl``/``osmesa``/auto).
    """

    meshes: tuple[Path, ...]
    output: Path
    num_images: int
    width: int = 640
    height: int = 480
    seed: int = 0
    split: str = "train"
    scale: float = 1.0
    intrinsics: tuple[float, float, float, float] | None = None
    objects_per_image: tuple[int, int] = (1, 3)
    distance: tuple[float, float] | None = None
    rotation: str = "so3"
    inplane_degrees: float = 180.0
    elevation_degrees: tuple[float, float] = (-90.0, 90.0)
    distractors: int = 2
    occluder_probability: float = 0.3
    backgrounds: Path | None = None
    light_count: tuple[int, int] = (1, 3)
    color_jitter: float = 0.2
    blur_probability: float = 0.3
    noise_std: float = 4.0
    depth_scale: float = 0.1
    images_per_scene: int = 1000
    crop_size: int = 0
    symmetries: Path | None = None
    rgb_format: str = "png"
    antialias: str = "edges"
    platform: str | None = None

    def __post_init__(self):
        meshes = tuple(Path(path) for path in self.meshes)
        if not meshes:
            raise ValueError("meshes: expected at least one --mesh file")
        object.__setattr__(self, "meshes", meshes)
        object.__setattr__(self, "output", Path(self.output))
        for name in ("num_images", "width", "height", "images_per_scene"):
            _positive_int(getattr(self, name), name)
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {self.seed!r}")
        if not self.split or "/" in self.split or self.split.startswith("."):
            raise ValueError(f"split: expected a plain folder name, got {self.split!r}")
        if not math.isfinite(self.scale) or self.scale <= 0:
            raise ValueError(f"scale: expected a positive number (file units to metres), got {self.scale}")
        if self.intrinsics is not None:
            fx, fy, cx, cy = self.intrinsics
            if not all(math.isfinite(v) for v in self.intrinsics) or fx <= 0 or fy <= 0:
                raise ValueError(f"intrinsics: expected finite (fx, fy, cx, cy) with fx, fy > 0, got {self.intrinsics}")
        low, high = _range(self.objects_per_image, "objects_per_image", minimum=1)
        if int(low) != low or int(high) != high:
            raise ValueError(f"objects_per_image: expected integers, got {self.objects_per_image}")
        if self.distance is not None:
            _range(self.distance, "distance")
            if self.distance[0] <= 0:
                raise ValueError(f"distance: expected a positive range in metres, got {tuple(self.distance)}")
        if self.rgb_format not in RGB_FORMATS:
            raise ValueError(f"rgb_format: expected one of {RGB_FORMATS}, got {self.rgb_format!r}")
        if self.antialias not in ANTIALIAS_MODES:
            raise ValueError(f"antialias: expected one of {ANTIALIAS_MODES}, got {self.antialias!r}")
        if self.rotation not in ROTATION_MODES:
            raise ValueError(f"rotation: expected one of {ROTATION_MODES}, got {self.rotation!r}")
        if not 0 <= self.inplane_degrees <= 180:
            raise ValueError(f"inplane_degrees: expected 0..180, got {self.inplane_degrees}")
        _range(self.elevation_degrees, "elevation_degrees", -90.0, 90.0)
        if isinstance(self.distractors, bool) or int(self.distractors) != self.distractors or self.distractors < 0:
            raise ValueError(f"distractors: expected a non-negative integer, got {self.distractors!r}")
        _fraction(self.occluder_probability, "occluder_probability")
        _fraction(self.blur_probability, "blur_probability")
        low, high = _range(self.light_count, "light_count", minimum=0)
        if int(low) != low or int(high) != high:
            raise ValueError(f"light_count: expected integers, got {self.light_count}")
        if not 0 <= self.color_jitter < 1:
            raise ValueError(f"color_jitter: expected 0 <= j < 1, got {self.color_jitter}")
        if not math.isfinite(self.noise_std) or self.noise_std < 0:
            raise ValueError(f"noise_std: expected a non-negative number of grey levels, got {self.noise_std}")
        if not math.isfinite(self.depth_scale) or self.depth_scale <= 0:
            raise ValueError(f"depth_scale: expected a positive number (mm per PNG unit), got {self.depth_scale}")
        if isinstance(self.crop_size, bool) or int(self.crop_size) != self.crop_size or self.crop_size < 0:
            raise ValueError(f"crop_size: expected 0 (off) or a positive pixel size, got {self.crop_size!r}")

    @property
    def K(self) -> list[list[float]]:
        """``3×3`` intrinsics (pixels) as nested lists."""
        if self.intrinsics is None:
            fx = fy = 0.9 * self.width
            cx, cy = (self.width - 1) / 2, (self.height - 1) / 2
        else:
            fx, fy, cx, cy = self.intrinsics
        return [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]

    def fingerprint(self) -> dict:
        """The settings that determine image content: a resumed run must match them.

        ``num_images`` is left out on purpose: image ``i`` does not depend on it, so a finished
        set can be extended by re-running with a larger number.
        """
        data = dataclasses.asdict(self)
        for name in ("output", "num_images", "platform"):
            data.pop(name)
        data["meshes"] = [str(path.resolve()) for path in self.meshes]
        for name in ("backgrounds", "symmetries"):
            data[name] = None if data[name] is None else str(Path(data[name]).resolve())
        return json.loads(json.dumps(data))


def check_output_writable(output: Path) -> None:
    """Raises ``ValueError`` unless ``output`` is (or can be made) a writable folder.

    Leaves nothing behind: creates and deletes a probe file in the folder, or in its nearest
    existing ancestor when the folder does not exist yet.
    """
    output = Path(output)
    if output.exists() and not output.is_dir():
        raise ValueError(f"output: {output} exists and is not a folder")
    existing = output
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"output: {existing} (an ancestor of {output}) is not a folder")
    try:  # os.access says yes to root even where writes fail (read-only mounts, /proc)
        handle, probe = tempfile.mkstemp(dir=existing, prefix=".paz6d-write-probe-")
    except OSError as error:
        raise ValueError(f"output: cannot write in {existing} ({error.strerror})") from error
    os.close(handle)
    os.unlink(probe)


def list_backgrounds(folder: Path) -> list[Path]:
    """Sorted image files of a background folder; raises ``ValueError`` when there are none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"backgrounds: {folder} is not a folder")
    files = sorted(path for path in folder.rglob("*") if path.suffix.lower() in BACKGROUND_SUFFIXES and path.is_file())
    if not files:
        raise ValueError(f"backgrounds: no images ({', '.join(BACKGROUND_SUFFIXES)}) in {folder}")
    return files
