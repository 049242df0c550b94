"""Settings of one `paz6d generate` run, checked before any work starts."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from paz6d.backend.checks import is_whole_number
from paz6d.backend.paths import check_plain_name
from paz6d.cli_options import option
from renderers.platform import PLATFORMS
from renderers.antialias import ANTIALIAS_MODES

ROTATION_MODES = ("so3", "view-sphere")
#: floating: objects at independent distances and orientations (paz6d.synthesis.scene); tabletop:
#: upright on a textured table seen from above (paz6d.synthesis.tabletop).
SCENE_STYLES = ("floating", "tabletop")
#: How a tabletop scene's table looks, in the fingerprint: sets whose table was a vertex-coloured grid
#: (before the texture map) do not resume into sets with a textured one.
TABLE_LOOK = "texture-map"
DISTRACTOR_STYLES = ("primitive", "textured", "household")
RGB_FORMATS = ("png", "jpg")
#: Key of the input digests in a run's fingerprint (see :meth:`GenerationConfig.input_contents`).
CONTENTS_KEY = "input_contents"
#: Folder inside a generated data set holding the run's settings and per-image records.
STATE_FOLDER = ".paz6d-generate"
BACKENDS = ("local", "ray")  # where images are rendered: local processes or Ray actors
BACKGROUND_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
#: Largest image side (pixels): OpenGL render buffers of common drivers go no further.
MAX_IMAGE_SIDE = 16384
#: Largest number of annotated objects, distractors or lights in one image.
MAX_PER_IMAGE = 100
#: Largest camera distance (metres): keeps the geometry of the distance checks finite.
MAX_DISTANCE = 1e6
#: Largest side of the per-object crops (pixels).
MAX_CROP_SIZE = 2048
#: Largest data set (images): far beyond any BOP set, small enough to list its images.
MAX_IMAGES = 10_000_000
#: BOP image ids have six digits.
MAX_IMAGES_PER_SCENE = 1_000_000


def _file_digest(path: Path, name: str) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError as error:
        raise ValueError(f"{name}: cannot read {path} ({error.strerror or error})") from error


def _positive_int(value, name: str, maximum: int | None = None) -> int:
    if not is_whole_number(value) or value <= 0:
        raise ValueError(f"{name}: expected a positive integer, got {value!r}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name}: expected at most {maximum}, got {value!r}")
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
    """Everything that determines a generated data set; each field is also a ``paz6d generate`` flag
    (:mod:`paz6d.cli_options`: ``mesh_scale`` is ``--mesh-scale``, help text in the field).

    Lengths are metres unless a field says otherwise; BOP files on disk are millimetres. Image ``i``
    uses the seed ``SeedSequence([seed, i])``, so it does not depend on ``num_images``.
    """

    meshes: tuple[Path, ...] = option(
        help="mesh files (PLY/OBJ/GLB/GLTF), one per object. Object ids come from obj_XXXXXX file names "
             "when every file is named so, else 1, 2, ... in the given order", metavar="PATH")
    out: Path = option(help="output folder (BOP layout)")
    num_images: int = option(help="number of images")
    width: int = option(640, "image width (pixels)")
    height: int = option(480, "image height (pixels)")
    seed: int = option(0, "master seed (image i uses SeedSequence([seed, i]))")
    split: str = option("train", "BOP split folder name (train, val, test, ...)")
    mesh_scale: float = option(1.0, "mesh file units to metres (0.001 for BOP meshes in millimetres)")
    intrinsics: tuple[float, float, float, float] | None = option(
        None, "camera intrinsics in pixels (default fx = fy = 0.9 width, centre pixel)",
        metavar=("FX", "FY", "CX", "CY"))
    objects_per_image: tuple[int, int] = option((1, 3), "annotated objects per image", metavar=("MIN", "MAX"))
    distance: tuple[float, float] | None = option(
        None, "camera-to-object-centre distance range in metres (default: the largest mesh spans 15 %...60 % "
              "of the shorter image side)", metavar=("MIN", "MAX"))
    scene: str = option("floating", "floating: objects at independent distances and orientations; tabletop: "
                                    "objects upright on a photo-textured table seen from above (the camera's "
                                    "elevation above the table from --elevation-degrees within 15..85, its roll "
                                    "up to --inplane-degrees, at most 30; --rotation is not used)",
                        choices=SCENE_STYLES)
    rotation: str = option("so3", "object rotations: uniform (so3) or a viewpoint on a sphere plus an "
                                  "in-plane angle (view-sphere)", choices=ROTATION_MODES)
    inplane_degrees: float = option(180.0, "maximum absolute in-plane angle (degrees), view-sphere")
    elevation_degrees: tuple[float, float] = option((-90.0, 90.0), "viewpoint elevation range (degrees), "
                                                    "view-sphere", metavar=("MIN", "MAX"))
    distractors: int = option(2, "maximum number of unannotated distractor primitives per image")
    neutral_distractors: float = option(0.0, "share of primitive distractors coloured white to mid grey (like "
                                              "white cups, bowls and boxes in real clutter); the rest get random "
                                              "saturated colours")
    object_colored_distractors: float = option(0.0, "share of primitive distractors painted in a colour of the "
                                                    "annotated meshes (a random vertex colour, jittered like "
                                                    "the objects): the objects' colours on other shapes, so a "
                                                    "detector cannot tell objects by colour alone")
    occluder_probability: float = option(0.3, "chance that a primitive is put between the camera and an object")
    occluders: int = option(1, "occluder draws per image, each with --occluder-probability on a random object")
    cluster: float = option(0.0, "floating scenes: chance that an object or distractor is placed next to one "
                                 "already placed (image centres 0.2-0.9 of their summed projected radii apart), "
                                 "so that objects hide each other as in real clutter; 0 leaves data sets "
                                 "unchanged")
    distractor_style: str = option(
        "primitive", "primitive: boxes, cylinders, spheres, capsules in one random colour each; textured: as many "
                     "again of photo-textured boxes, cylinders, spheres, capsules, cones, tori "
                     "(paz6d.synthesis.mesh_distractors); household: as many again of bowls, mugs, cups, "
                     "bottles, plates and books, tinted like the primitives (paz6d.synthesis.household)",
        choices=DISTRACTOR_STYLES)
    backgrounds: Path | None = option(None, "folder of background images (default: procedural backgrounds)")
    light_count: tuple[int, int] = option((1, 3), "number of random lights", metavar=("MIN", "MAX"))
    color_jitter: float = option(0.2, "objects' base colour is multiplied by U(1 - j, 1 + j) per channel")
    roughness: tuple[float, float] | None = option(
        None, "random material roughness of every object and distractor per image, uniform in MIN..MAX (0: "
              "mirror-like highlights, 1: matte; default: none drawn, pyrender's 0.8 for vertex colours)",
        metavar=("MIN", "MAX"))
    metallic: tuple[float, float] | None = option(
        None, "random metallic factor likewise (0: plastic-like, 1: metal; default: none drawn, pyrender's 0.2)",
        metavar=("MIN", "MAX"))
    blur_probability: float = option(0.3, "chance of a Gaussian blur of the final image")
    noise_std: float = option(4.0, "maximum standard deviation (grey levels) of the Gaussian image noise, "
                                   "added to half of the images")
    depth_scale: float = option(0.1, "BOP depth scale: depth PNG value x depth_scale = millimetres")
    images_per_scene: int = option(1000, "images per <split>/<scene> folder")
    crop_size: int = option(0, "side in pixels of per-object crops written for autoencoder training (0: off)")
    symmetries: Path | None = option(
        None, "JSON file {obj_id: {symmetries_discrete: [...], symmetries_continuous: [...]}} copied into "
              "models_info.json (BOP units: mm)")
    rgb_format: str = option("png", "rgb images: lossless png or jpg (quality 95, like BOP PBR sets; faster)",
                             choices=RGB_FORMATS)
    antialias: str = option(
        "edges", "edges: one single-sample pass with softened object outlines; msaa: 4x multisampled colour, "
                 "~2x slower; none: binary outlines (see renderers.Renderer)", choices=ANTIALIAS_MODES)
    platform: str | None = option(None, "OpenGL platform of the renderers (default: auto)", choices=PLATFORMS)

    def __post_init__(self):
        meshes = tuple(Path(path) for path in self.meshes)
        if not meshes:
            raise ValueError("meshes: expected at least one mesh file")
        object.__setattr__(self, "meshes", meshes)
        object.__setattr__(self, "out", Path(self.out))
        _positive_int(self.num_images, "num_images", MAX_IMAGES)
        _positive_int(self.width, "width", MAX_IMAGE_SIDE)
        _positive_int(self.height, "height", MAX_IMAGE_SIDE)
        _positive_int(self.images_per_scene, "images_per_scene", MAX_IMAGES_PER_SCENE)
        if not is_whole_number(self.seed) or self.seed < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {self.seed!r}")
        check_plain_name(self.split, "split")
        if not math.isfinite(self.mesh_scale) or self.mesh_scale <= 0:
            raise ValueError(f"mesh_scale: expected a positive number (file units to metres), got {self.mesh_scale}")
        if self.intrinsics is not None:
            fx, fy, cx, cy = self.intrinsics
            if not all(math.isfinite(v) for v in self.intrinsics) or fx <= 0 or fy <= 0:
                raise ValueError(f"intrinsics: expected finite (fx, fy, cx, cy) with fx, fy > 0, got {self.intrinsics}")
        low, high = _range(self.objects_per_image, "objects_per_image", minimum=1, maximum=MAX_PER_IMAGE)
        if not (is_whole_number(low) and is_whole_number(high)):
            raise ValueError(f"objects_per_image: expected integers, got {self.objects_per_image}")
        if self.distance is not None:
            _range(self.distance, "distance")
            if self.distance[0] <= 0:
                raise ValueError(f"distance: expected a positive range in metres, got {tuple(self.distance)}")
            if self.distance[1] > MAX_DISTANCE:
                raise ValueError(f"distance: expected at most {MAX_DISTANCE:g} m, got {tuple(self.distance)}")
        if not math.isfinite(self.depth_scale) or self.depth_scale <= 0:
            raise ValueError(f"depth_scale: expected a positive number (mm per PNG unit), got {self.depth_scale}")
        if self.rgb_format not in RGB_FORMATS:
            raise ValueError(f"rgb_format: expected one of {RGB_FORMATS}, got {self.rgb_format!r}")
        if self.antialias not in ANTIALIAS_MODES:
            raise ValueError(f"antialias: expected one of {ANTIALIAS_MODES}, got {self.antialias!r}")
        if self.scene not in SCENE_STYLES:
            raise ValueError(f"scene: expected one of {SCENE_STYLES}, got {self.scene!r}")
        if self.scene == "tabletop" and (self.elevation_degrees[1] < 15 or self.elevation_degrees[0] > 85):
            raise ValueError(f"elevation_degrees: a tabletop camera needs elevations within 15..85 degrees, "
                             f"got {tuple(self.elevation_degrees)}")
        if self.rotation not in ROTATION_MODES:
            raise ValueError(f"rotation: expected one of {ROTATION_MODES}, got {self.rotation!r}")
        if not 0 <= self.inplane_degrees <= 180:
            raise ValueError(f"inplane_degrees: expected 0..180, got {self.inplane_degrees}")
        _range(self.elevation_degrees, "elevation_degrees", -90.0, 90.0)
        if not is_whole_number(self.distractors) or not 0 <= self.distractors <= MAX_PER_IMAGE:
            raise ValueError(f"distractors: expected an integer in 0..{MAX_PER_IMAGE}, got {self.distractors!r}")
        _fraction(self.occluder_probability, "occluder_probability")
        if not is_whole_number(self.occluders) or not 0 <= self.occluders <= MAX_PER_IMAGE:
            raise ValueError(f"occluders: expected an integer in 0..{MAX_PER_IMAGE}, got {self.occluders!r}")
        if self.distractor_style not in DISTRACTOR_STYLES:
            raise ValueError(f"distractor_style: expected one of {DISTRACTOR_STYLES}, got {self.distractor_style!r}")
        _fraction(self.blur_probability, "blur_probability")
        low, high = _range(self.light_count, "light_count", minimum=0, maximum=MAX_PER_IMAGE)
        if not (is_whole_number(low) and is_whole_number(high)):
            raise ValueError(f"light_count: expected integers, got {self.light_count}")
        if not 0 <= self.cluster <= 1:
            raise ValueError(f"cluster: expected a chance in [0, 1], got {self.cluster}")
        if self.cluster > 0 and self.scene != "floating":
            raise ValueError(f"cluster: only for floating scenes (--scene floating), got --scene {self.scene}; "
                             "tabletop scenes place their objects on the table on their own")
        if not 0 <= self.neutral_distractors <= 1:
            raise ValueError(f"neutral_distractors: expected a share in [0, 1], got {self.neutral_distractors}")
        if not 0 <= self.object_colored_distractors <= 1:
            raise ValueError(f"object_colored_distractors: expected a share in [0, 1], got "
                             f"{self.object_colored_distractors}")
        if self.neutral_distractors + self.object_colored_distractors > 1:
            raise ValueError(f"neutral_distractors + object_colored_distractors: expected shares summing to at most "
                             f"1, got {self.neutral_distractors} + {self.object_colored_distractors}")
        for name in ("roughness", "metallic"):
            if getattr(self, name) is not None:
                _range(getattr(self, name), name, minimum=0.0, maximum=1.0)
        if not 0 <= self.color_jitter < 1:
            raise ValueError(f"color_jitter: expected 0 <= j < 1, got {self.color_jitter}")
        if not math.isfinite(self.noise_std) or self.noise_std < 0:
            raise ValueError(f"noise_std: expected a non-negative number of grey levels, got {self.noise_std}")
        if not is_whole_number(self.crop_size) or not 0 <= self.crop_size <= MAX_CROP_SIZE:
            raise ValueError(f"crop_size: expected 0 (off) or a pixel size up to {MAX_CROP_SIZE}, "
                             f"got {self.crop_size!r}")

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
        for name in ("out", "num_images", "platform"):
            data.pop(name)
        data["scale"] = data.pop("mesh_scale")  # the key data sets made before the field's rename hold
        if data["scene"] == "floating":
            data.pop("scene")  # data sets made before scene styles existed are floating ones
        else:
            data["table"] = TABLE_LOOK
        for name in ("neutral_distractors", "object_colored_distractors", "cluster", "roughness", "metallic"):
            if not data[name]:
                data.pop(name)  # nor do those made before these fields existed
        if data["occluders"] == 1 and data["distractor_style"] == "primitive":
            data.pop("occluders")  # nor do those made before these two fields existed
            data.pop("distractor_style")
        data["meshes"] = [str(path.resolve()) for path in self.meshes]
        for name in ("backgrounds", "symmetries"):
            data[name] = None if data[name] is None else str(Path(data[name]).resolve())
        data[CONTENTS_KEY] = self.input_contents()
        return json.loads(json.dumps(data))

    def input_contents(self) -> dict:
        """Digests of the input files (SHA-256 of each mesh and of the symmetries file; names and sizes
        of the background images): a resumed run compares these, not the paths, so a data set whose
        inputs moved with it (the demo keeps its mesh inside its output) still resumes."""
        backgrounds = None
        if self.backgrounds is not None:
            listing = hashlib.sha256()
            for path in list_backgrounds(self.backgrounds):
                listing.update(f"{path.relative_to(self.backgrounds)}\0{path.stat().st_size}\n".encode())
            backgrounds = listing.hexdigest()
        return {"meshes": [_file_digest(path, "meshes") for path in self.meshes], "backgrounds": backgrounds,
                "symmetries": None if self.symmetries is None else _file_digest(self.symmetries, "symmetries")}


@dataclass(frozen=True)
class GenerationRun:
    """How a ``paz6d generate`` run is executed (no influence on the images); each field is a flag.

    Checked here and again by :func:`data_gen.generator.generate`, whose keyword arguments these are.
    """

    workers: int = option(1, "worker processes (Ray actors with --backend ray)")
    backend: str = option("local", "local: processes on this machine; ray: Ray actors (needs the ray extra)",
                          choices=BACKENDS)
    ray_address: str | None = option(None, "Ray cluster address, e.g. ray://head:10001 (default: start a local Ray)")
    progress: bool = option(True, "progress bar on stderr")

    def __post_init__(self):
        _positive_int(self.workers, "workers")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend: expected one of {BACKENDS}, got {self.backend!r}")


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def capped_workers(workers: int, backend: str) -> tuple[int, str | None]:
    """``(workers to start, message)``: local workers beyond :func:`usable_cores` only compete for the
    same cores (each holds a renderer of ~280 MB), so they are capped there, with a message saying
    so (``None`` when nothing changed). Ray actors may live on other machines and are not capped."""
    cores = usable_cores()
    if backend != "local" or workers <= cores:
        return workers, None
    return cores, f"--workers {workers} capped at {cores}, the number of usable CPU cores"


def _symbolic_links_inside(output: Path) -> Iterator[Path]:
    """Symbolic links anywhere below ``output`` (not followed), as they are found."""
    for folder, folders, files in os.walk(output):
        for name in folders + files:
            if os.path.islink(os.path.join(folder, name)):
                yield Path(folder) / name


def check_output_writable(output: Path) -> None:
    """Raises ``ValueError`` unless ``output`` is (or can be made) a writable folder that is new, empty
    or an earlier ``paz6d generate`` output (holding :data:`STATE_FOLDER`), so nothing that is not
    ours is overwritten, and whose contents are real files and folders: a symbolic link inside it
    could make ``paz6d generate`` write outside the folder, so one is refused.

    Leaves nothing behind: creates and deletes a probe file in the folder, or in its nearest
    existing ancestor when the folder does not exist yet.
    """
    output = Path(output)
    if output.exists() and not output.is_dir():
        raise ValueError(f"out: {output} exists and is not a folder")
    if output.is_dir():
        if not (output / STATE_FOLDER).is_dir() and any(output.iterdir()):
            raise ValueError(f"out: {output} is a folder with other contents, not the output of paz6d generate "
                             f"(no {STATE_FOLDER}/); give a new or empty folder so nothing else is overwritten")
        link = next(_symbolic_links_inside(output), None)
        if link is not None:
            raise ValueError(f"out: {link} is a symbolic link inside {output}; paz6d generate writes only into "
                             "real folders inside --out, so remove the link or use another --out")
    existing = output
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"out: {existing} (an ancestor of {output}) is not a folder")
    try:  # os.access says yes to root even where writes fail (read-only mounts, /proc)
        handle, probe = tempfile.mkstemp(dir=existing, prefix=".paz6d-write-probe-")
    except OSError as error:
        raise ValueError(f"out: cannot write in {existing} ({error.strerror})") from error
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
