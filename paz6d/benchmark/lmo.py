"""``paz6d benchmark lmo``: synthetic training only, scored on the real LM-O frames.

From the 8 LM-O meshes (``<lmo>/models``) only:

1. ``backgrounds``: photographic collages of scikit-image's bundled sample photos
   (:mod:`paz6d.synthesis.photo_backgrounds`);
2. ``synthetic``: ``paz6d generate`` of floating multi-object scenes over those collages at LM-O's camera,
   distances and viewpoints (the settings of ``docs/ssd.md``'s commands);
3. ``detector``: ``paz6d train ssd`` (the light network on the settings' ``detector_backbone``: EfficientNet-Lite0
   pretrained on ImageNet in the quick sizes, its own body in the full ones) -> ``DIR/detector/``;
4. ``pose/obj_XXXXXX``: one pose model per object (AAE by default, KeypointNet with ``method="keypointnet"``
   or ``"keypointnet_robust"``, and per object with ``object_methods``) -> ``DIR/pose/obj_XXXXXX/``
   (KeypointNet: ``DIR/pose_<method>/obj_XXXXXX/``); the AAE also trains on crops of the synthetic scenes
   (real inter-object occlusion) besides its own rendered views;
5. ``estimate_gt`` / ``estimate_detections``: ``paz6d estimate`` on the real RGB frames with the ground-truth
   visible boxes and with the detector's boxes (which reads no ground truth; the detector also sees each frame's
   mirror image, ``paz6d estimate --flip``, ``docs/ssd.md``, and its boxes are voted, ``--vote-iou``; poses for
   each class's best detection, whose AAE searches around its box, ``--poses-per-class 1 --box-search``); in
   every condition the AAEs answer only with the training scenes' viewpoints widened by 15 degrees
   (:func:`viewpoints`); ``estimate_synthetic``: on held-out synthetic images of the training scenes' kind
   (``validation``, another seed), ground-truth visible boxes: what a user without real labels sees, to pick a
   method per object; ``estimate_synthetic_detections``: the same images with the detector's boxes (as on the
   real frames), what the boxes cost without the real photos;
6. ``evaluate_*``: ``paz6d evaluate bop`` (AR_MSSD, AR_MSPD, ADD(-S), per object) of each, and
   ``paz6d evaluate coco`` of the detections;
7. ``report``: ``DIR/report.json``, ``DIR/report.md`` (the table; once two methods were scored on an object,
   the method per object that the held-out synthetic images pick, :func:`method_pick`) and PNG overlays of the
   estimates on the real frames (``DIR/overlays/``).

The real frames' ground truth is read only to score and for the ground-truth-box condition. Every stage
is skipped when its output is complete (a ``DIR/stages/<stage>.json`` marker written after it, and the
trainers resume mid-run), so re-running the same command continues. TensorFlow is imported first
(:mod:`paz6d.backend.tensorflow_guard`); rendering happens in the spawn worker processes of the generator
and the trainers, as in ``paz6d demo``.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from paz6d.aae.config import check_crop_box
from paz6d.abstract import Box2D, Pose6D
from paz6d.backbones import check_backbone
from paz6d.backend.checks import is_whole_number
from paz6d.backend.files import load_json_object, write_json_atomically, write_text_atomically
from paz6d.backend.viewpoints import ViewpointRange
from paz6d.benchmark.parallel import run_in_processes, threads_per_job
from paz6d.cli import build_parser
from paz6d.datasets.bop import read_pose_results
from paz6d.datasets.bop.models import MODELS_INFO, load_models_info, model_meshes
from paz6d.datasets.bop.units import units_per_mm
from paz6d.estimate import estimate
from paz6d.keypointnet.config import CONFIGS as KEYPOINT_CONFIGS, KeypointTraining
from paz6d.keypointnet.orientation import is_single_half_turn
from paz6d.keypointnet.train import train_keypointnet
from paz6d.ssd.config import SSDTraining, check_input_size

#: Scale of the LM-O meshes (millimetres) to the library's metres.
MESH_SCALE = units_per_mm("m")
#: The LM-O data this repository's checkout shares (``../shared/data/bop_lmo``).
DEFAULT_LMO = Path(__file__).resolve().parents[3] / "shared" / "data" / "bop_lmo"
#: LM-O's camera (``camera.json`` of the BOP data set): fx, fy, cx, cy.
LMO_INTRINSICS = (572.4114, 573.57043, 325.2611, 242.04899)
#: Estimate conditions: real frames with ground-truth visible boxes, real frames with the detector's boxes, and
#: held-out synthetic images with ground-truth visible boxes and with the detector's boxes (their names in
#: report.json).
CONDITIONS = {"gt": "gt_visible_boxes", "detections": "detections", "synthetic": "synthetic_gt_visible_boxes",
              "synthetic_detections": "synthetic_detections"}
#: The detection score below which the scored conditions drop a detection: COCO AP ranks detections by score and
#: BOP scores each object's best estimates only, so a threshold can only drop detections that might match
#: (0.01, as detectors are commonly scored; `paz6d estimate`'s own default, 0.1, suits an application).
SCORED_DETECTION_THRESHOLD = 0.01
#: Box voting in the scored detection conditions (``paz6d estimate --vote-iou``): each detection's box is the
#: score-weighted mean of its class's boxes overlapping it by at least this IoU (chosen on the held-out synthetic
#: images: docs/experiments/2026-12-07-lmo-detector-box-voting.md).
SCORED_VOTE_IOU = 0.5
#: The conditions whose boxes come from the benchmark's detector.
DETECTOR_CONDITIONS = ("detections", "synthetic_detections")
#: Seed offset of the held-out synthetic images (image i of seed s + 1000 shares nothing with the training set's).
VALIDATION_SEED_OFFSET = 1000
#: The AAEs answer only with viewpoints of the training scenes' range widened by this much (degrees) on every side
#: (``paz6d estimate --elevation-degrees --inplane-degrees``): the camera is never below the table.
VIEWPOINT_MARGIN_DEGREES = 15.0


@dataclass(frozen=True)
class BenchmarkSettings:
    """Sizes of one benchmark (``quick`` or ``full``); times are for an idle 2-core CPU (``docs/real_photos.md``).

    Attributes:
        images: synthetic training images; backgrounds: photo collages.
        detector_steps / detector_input_size: SSD steps and input side in pixels (light network).
        detector_backbone: the light SSD's body: ``"efficientnet-lite0"`` (pretrained on ImageNet,
            ``docs/backbones.md``) or ``"none"`` (its own, trained from scratch).
        aae_steps / aae_views / aae_in_plane: AAE steps, view-sphere directions and codebook in-plane
            rotations per view.
        aae_lr_drop_steps: the last this many AAE steps train at a tenth of the learning rate.
        keypointnet_steps / keypointnet_views: KeypointNet steps and rendered training views.
        keypointnet_robust_steps / keypointnet_robust_views: the same for ``keypointnet_robust`` (None: the
            ``robust`` preset's own, 10,000 and 4,000).
        scene_crops: share of AAE training samples cut from the synthetic scenes (0: rendered views only).
        aae_crop_box: the box those scene crops are cut around: ``"obj"`` (the whole object's) or ``"visib"``
            (its visible part's, as the benchmark's boxes are at test time).
        validation_images: held-out synthetic images the pose models are also scored on.
        aae_encoder_backbone: the AAEs' encoder body (``AAEConfig.encoder_backbone``): ``"none"`` or
            ``"efficientnet-lite0"`` (pretrained, frozen).
        neutral_distractors: share of the synthetic images' distractor primitives coloured white to mid grey
            (hard negatives for the white objects: ``paz6d generate --neutral-distractors``).
        workers: rendering processes.
    """

    images: int
    backgrounds: int
    detector_steps: int
    aae_steps: int
    aae_in_plane: int
    keypointnet_steps: int
    keypointnet_views: int
    detector_input_size: int
    scene_crops: float = 0.5
    workers: int = 2
    aae_views: int = 1000
    aae_lr_drop_steps: int = 0
    keypointnet_robust_steps: int | None = None
    keypointnet_robust_views: int | None = None
    validation_images: int = 60
    aae_crop_box: str = "obj"
    detector_backbone: str = "none"
    neutral_distractors: float = 0.0
    aae_encoder_backbone: str = "none"

    def __post_init__(self):
        check_crop_box(self.aae_crop_box)
        check_backbone(self.aae_encoder_backbone, "aae_encoder_backbone")
        check_backbone(self.detector_backbone, "detector_backbone")
        try:
            check_input_size("light", self.detector_input_size)
        except ValueError as error:
            raise ValueError(f"detector_{error}") from None  # "detector_input_size: expected ..."
        share = self.neutral_distractors
        if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0 <= share <= 1:
            raise ValueError(f"neutral_distractors: expected a share in [0, 1], got {share!r:.40}")


#: Most AAE training steps a benchmark accepts (the full sizes train 5,000).
MAX_AAE_STEPS = 1_000_000

# The quick benchmark's detector sees the frames at 448 px (320 px trains in half the time and finds fewer
# objects); the detector and the AAEs' encoders build on the pretrained EfficientNet-Lite0; the AAEs train their
# last steps at a tenth of the rate, at no extra time; white and grey clutter neither helps nor hurts and is in the
# measured configuration. What each choice measured: docs/experiments/README.md (the LM-O entries).
QUICK = BenchmarkSettings(images=1500, backgrounds=200, detector_steps=1500, aae_steps=1000, aae_in_plane=36,
                          keypointnet_steps=1000, keypointnet_views=2000, detector_input_size=448,
                          aae_lr_drop_steps=200, detector_backbone="efficientnet-lite0",
                          aae_encoder_backbone="efficientnet-lite0", neutral_distractors=0.3)
# The full detector sees the frames at their own width, 640 px, with the light network's own body, and the AAEs keep
# their own encoders (the pretrained body is not measured at these sizes yet: --detector-backbone and
# --aae-encoder-backbone efficientnet-lite0) (docs/ssd.md, "Measured").
FULL = BenchmarkSettings(images=2500, backgrounds=300, detector_steps=1500, aae_steps=5000, aae_in_plane=72,
                         keypointnet_steps=5000, keypointnet_views=4000, detector_input_size=640,
                         aae_lr_drop_steps=500)


#: Fields of :class:`Benchmark` that replace the sizes' setting of the same name unless ``None``.
SETTINGS_OF_FLAGS = ("aae_crop_box", "detector_backbone", "detector_input_size", "neutral_distractors",
                     "aae_encoder_backbone")


@dataclass
class Benchmark:
    """One ``paz6d benchmark lmo`` run: where, which sizes and which pose method (``method`` for every object
    but those of ``object_methods``, ``{obj_id: method}``)."""

    out: Path
    lmo: Path = DEFAULT_LMO
    quick: bool = False
    method: str = "aae"
    progress: bool = True
    settings: BenchmarkSettings | None = None  # default: QUICK or FULL
    seed: int = 0
    objects: tuple[int, ...] = field(default=())  # default: every mesh in <lmo>/models
    aae_steps: int | None = None  # default: the settings'; a larger number on a finished run extends its AAEs
    aae_lr_drop_steps: int | None = None  # default: the settings'
    aae_crop_box: str | None = None  # default: the settings'
    detector_backbone: str | None = None  # default: the settings'
    detector_input_size: int | None = None  # default: the settings'
    neutral_distractors: float | None = None  # default: the settings'
    aae_encoder_backbone: str | None = None  # default: the settings'
    object_methods: dict[int, str] = field(default_factory=dict)
    jobs: int = 1  # pose models trained side by side, each in its own process

    def __post_init__(self):
        self.out, self.lmo = Path(self.out), Path(self.lmo)
        if not is_whole_number(self.jobs) or self.jobs < 1:
            raise ValueError(f"jobs: expected a positive number of processes, got {self.jobs!r}")
        if self.method not in METHODS:
            raise ValueError(f"method: expected one of {METHODS}, got {self.method!r}")
        for obj_id, method in self.object_methods.items():
            if method not in METHODS:
                raise ValueError(f"object_methods: object {obj_id}: expected one of {METHODS}, got {method!r}")
        if not is_whole_number(self.seed) or not 0 <= self.seed < 2 ** 32:
            raise ValueError(f"seed: expected a whole number in 0..2^32-1, got {self.seed!r:.40}")
        if self.settings is None:
            self.settings = QUICK if self.quick else FULL
        if self.aae_steps is not None:
            if not is_whole_number(self.aae_steps) or not 1 <= self.aae_steps <= MAX_AAE_STEPS:
                raise ValueError(f"aae_steps: expected a number of training steps in 1..{MAX_AAE_STEPS:,}, got "
                                 f"{self.aae_steps!r:.40}")
            steps, drop = int(self.aae_steps), self.settings.aae_lr_drop_steps
            if steps < self.settings.aae_steps:  # a shorter run keeps the sizes' drop as a share of its steps
                drop = drop * steps // self.settings.aae_steps
            self.settings = replace(self.settings, aae_steps=steps, aae_lr_drop_steps=drop)
        if self.aae_lr_drop_steps is not None:
            if not is_whole_number(self.aae_lr_drop_steps) or self.aae_lr_drop_steps < 0:
                raise ValueError(f"aae_lr_drop_steps: expected 0 or a number of steps, got {self.aae_lr_drop_steps!r}")
            self.settings = replace(self.settings, aae_lr_drop_steps=int(self.aae_lr_drop_steps))
        chosen = {name: getattr(self, name) for name in SETTINGS_OF_FLAGS if getattr(self, name) is not None}
        self.settings = replace(self.settings, **chosen)  # checked by BenchmarkSettings
        if self.settings.aae_lr_drop_steps > self.settings.aae_steps:
            raise ValueError(f"aae_lr_drop_steps: expected at most aae_steps ({self.settings.aae_steps}), got "
                             f"{self.settings.aae_lr_drop_steps}")
        models = self.lmo / "models"
        if not models.is_dir():
            raise ValueError(f"lmo: {models} not found (expected the LM-O BOP folder with models/ and test/)")
        if not (self.lmo / "test").is_dir():
            raise ValueError(f"lmo: {self.lmo / 'test'} not found "
                             "(expected the LM-O BOP folder with models/ and test/)")
        found = sorted(model_meshes(models))
        if not found:
            raise ValueError(f"lmo: {models} holds no obj_XXXXXX.ply meshes")
        if self.objects:
            missing = sorted(set(self.objects) - set(found))
            if missing:
                raise ValueError(f"objects: {missing} have no mesh in {models}")
        else:
            self.objects = tuple(found)
        unknown = sorted(set(self.object_methods) - set(self.objects))
        if unknown:
            raise ValueError(f"object_methods: objects {unknown} are not benchmarked (objects: {list(self.objects)})")
        self.object_methods = {int(obj_id): method for obj_id, method in sorted(self.object_methods.items())
                               if method != self.method}

    # -- paths ----------------------------------------------------------------------------------
    def mesh(self, obj_id: int) -> Path:
        return self.lmo / "models" / f"obj_{obj_id:06d}.ply"

    def method_of(self, obj_id: int) -> str:
        return self.object_methods.get(obj_id, self.method)

    @property
    def label(self) -> str:
        """Name of this combination of pose models in results, reports and overlays: the method, then
        ``+<method>@<obj_id>`` per object that differs (e.g. ``aae+keypointnet_robust@8``)."""
        return self.method + "".join(f"+{method}@{obj_id}" for obj_id, method in self.object_methods.items())

    def pose_root(self, method: str) -> Path:
        return self.out / POSE_MODELS[method].folder

    def pose_dir(self, obj_id: int) -> Path:
        return self.pose_root(self.method_of(obj_id)) / f"obj_{obj_id:06d}"

    def result(self, condition: str, suffix: str) -> Path:
        """``DIR/results/<label>_<condition><suffix>`` (condition: a key of :data:`CONDITIONS`)."""
        return self.out / "results" / f"{self.label}_{condition}{suffix}"

    def marker(self, stage: str) -> Path:
        return self.out / "stages" / f"{stage.replace('/', '_')}.json"

    def scoring_stage(self, step: str, condition: str | None = None) -> str:
        """Name of a scoring stage of this label: ``estimate_<label>_<condition>``, ``evaluate_<label>_<condition>``
        or ``detector_ap_<label>``."""
        return f"{step}_{self.label}" + ("" if condition is None else f"_{condition}")


# ------------------------------------------------------------------------------------------ stages
def _stage_backgrounds(job: Benchmark) -> dict:
    from paz6d.synthesis.photo_backgrounds import write_backgrounds

    return {"files": len(write_backgrounds(job.out / "backgrounds", job.settings.backgrounds, seed=job.seed))}


def generation_config(job: Benchmark):
    """The ``paz6d generate`` settings of the synthetic training set (``docs/ssd.md``, "Commands")."""
    from data_gen.config import GenerationConfig

    return GenerationConfig(meshes=tuple(job.mesh(obj_id) for obj_id in job.objects), out=job.out / "synthetic",
                            num_images=job.settings.images, seed=job.seed, mesh_scale=MESH_SCALE,
                            intrinsics=LMO_INTRINSICS, rotation="view-sphere", elevation_degrees=(15.0, 80.0),
                            inplane_degrees=30.0,
                            objects_per_image=(min(4, len(job.objects)), min(8, len(job.objects))),
                            distance=(0.75, 1.35), distractors=8, occluder_probability=0.3,
                            neutral_distractors=job.settings.neutral_distractors,
                            backgrounds=job.out / "backgrounds", rgb_format="jpg")


def viewpoints(job: Benchmark) -> ViewpointRange:
    """The viewpoints the AAEs may answer with: the synthetic scenes' elevations and in-plane angles widened by
    :data:`VIEWPOINT_MARGIN_DEGREES` (a prior that comes from the generator's settings, not from the real frames)."""
    config = generation_config(job)
    return ViewpointRange(config.elevation_degrees, config.inplane_degrees).widened(VIEWPOINT_MARGIN_DEGREES)


def _stage_synthetic(job: Benchmark) -> dict:
    from data_gen.generator import generate

    summary = generate(generation_config(job), workers=job.settings.workers, show_progress=job.progress)
    return {"images": job.settings.images, "summary": str(summary)[:500]}


def _stage_validation(job: Benchmark) -> dict:
    from data_gen.generator import generate

    config = replace(generation_config(job), out=job.out / "validation", num_images=job.settings.validation_images,
                     seed=job.seed + VALIDATION_SEED_OFFSET)
    summary = generate(config, workers=job.settings.workers, show_progress=job.progress)
    return {"images": job.settings.validation_images, "summary": str(summary)[:500]}


def _stage_detector(job: Benchmark) -> dict:
    from paz6d.ssd.train import train_ssd

    return train_ssd(SSDTraining(dataset=job.out / "synthetic", out=job.out / "detector",
                                 steps=job.settings.detector_steps, input_size=job.settings.detector_input_size,
                                 backbone=job.settings.detector_backbone, seed=job.seed, progress=job.progress))


def _train_aae(job: Benchmark, obj_id: int) -> dict:
    """Trains the AAE of one object (``DIR/pose/obj_XXXXXX``) at the benchmark's sizes."""
    from paz6d.aae.config import QUICK as AAE_QUICK, Augmentation
    from paz6d.aae.train import train_aae

    # paper-sized crop shifts/scales: the boxes come from a detector or from visible parts
    config = replace(AAE_QUICK, steps=job.settings.aae_steps, in_plane=job.settings.aae_in_plane,
                     views=job.settings.aae_views, lr_drop_steps=job.settings.aae_lr_drop_steps,
                     augmentation=Augmentation(), encoder_backbone=job.settings.aae_encoder_backbone)
    crops = job.settings.scene_crops > 0
    return train_aae(job.mesh(obj_id), job.pose_dir(obj_id), config, mesh_scale=MESH_SCALE, seed=job.seed,
                     workers=job.settings.workers, progress=job.progress,
                     dataset=job.out / "synthetic" if crops else None, object_id=obj_id,
                     pair_fraction=job.settings.scene_crops if crops else 0.5,
                     crop_box=job.settings.aae_crop_box)


def _train_keypointnet(job: Benchmark, obj_id: int, preset: str, steps: int | None, views: int | None) -> dict:
    """Trains the KeypointNet of one object with a preset, ``steps`` and rendered ``views`` (None: the preset's);
    objects with one half-turn symmetry (LM-O's eggbox and glue) get the orientation network."""
    symmetries = load_models_info(job.mesh(obj_id).parent / MODELS_INFO)[obj_id].symmetries_discrete
    return train_keypointnet(KeypointTraining(
        job.pose_dir(obj_id), job.mesh(obj_id), mesh_scale=MESH_SCALE, config=preset, seed=job.seed,
        workers=job.settings.workers, steps=steps, progress=job.progress,
        settings=None if views is None else KEYPOINT_CONFIGS[preset].replace(views=views),
        orientation_network=is_single_half_turn(symmetries)))


@dataclass(frozen=True)
class PoseModel:
    """A pose model the benchmark trains per object.

    Attributes:
        method: the registered method (:mod:`paz6d.methods`) whose run directories it writes.
        folder: ``DIR/<folder>/obj_XXXXXX``.
        train: ``(job, obj_id) -> training summary``.
        steps_setting: the :class:`BenchmarkSettings` field that sets its training length (a larger
            ``aae_steps`` on a finished run resumes the models it sets, see :func:`_extends_aae`).
    """

    method: str
    folder: str
    train: Callable[[Benchmark, int], dict]
    steps_setting: str


#: ``--method`` value -> its pose model: the AAE, KeypointNet's quick preset at the benchmark's length, and its
#: ``robust`` preset (photo backgrounds, its own length): the one that does more than fail on the driller
#: (docs/real_photos.md).
POSE_MODELS = {
    "aae": PoseModel("aae", "pose", _train_aae, "aae_steps"),
    "keypointnet": PoseModel("keypointnet", "pose_keypointnet", lambda job, obj_id: _train_keypointnet(
        job, obj_id, "quick", job.settings.keypointnet_steps, job.settings.keypointnet_views), "keypointnet_steps"),
    "keypointnet_robust": PoseModel("keypointnet", "pose_keypointnet_robust", lambda job, obj_id: _train_keypointnet(
        job, obj_id, "robust", job.settings.keypointnet_robust_steps, job.settings.keypointnet_robust_views),
        "keypointnet_robust_steps"),
}
#: The ``--method`` values.
METHODS = tuple(POSE_MODELS)


def _stage_pose(job: Benchmark, obj_id: int) -> dict:
    return POSE_MODELS[job.method_of(obj_id)].train(job, obj_id)


def _scored_split(job: Benchmark, condition: str) -> list[str]:
    """``--dataset DIR --split SPLIT`` of the images a condition is scored on."""
    if condition.startswith("synthetic"):
        return ["--dataset", str(job.out / "validation"), "--split", "train"]
    return ["--dataset", str(job.lmo), "--split", "test"]


def _targets(job: Benchmark, condition: str) -> Path:
    """The BOP'19 targets a condition is scored on. The held-out synthetic images have no targets file, so their
    detections are scored on the targets written with their ground-truth boxes (visible fraction >= 0.1)."""
    return job.result("synthetic" if condition == "synthetic_detections" else condition, "_targets.json")


def _estimate_args(job: Benchmark, condition: str) -> list[str]:
    argv = ["estimate", *[f"--run={obj_id}={job.pose_dir(obj_id)}" for obj_id in job.objects],
            *_scored_split(job, condition), "--out", str(job.result(condition, ".csv"))]
    prior = viewpoints(job)
    (low, high), inplane = prior.elevation_degrees, prior.inplane_degrees
    argv += ["--elevation-degrees", f"{low:g}", f"{high:g}", "--inplane-degrees", f"{inplane:g}"]
    if condition != "synthetic_detections":
        argv += ["--targets-out", str(_targets(job, condition))]
    if condition not in DETECTOR_CONDITIONS:
        argv += ["--box", "visib"]
    else:
        # LM-O shows each object once: BOP scores each object's best estimate, so only the best detection per class
        # needs a pose, and that makes the AAEs' box search cheap enough to run on every frame (docs/real_photos.md)
        argv += ["--detector", str(job.out / "detector"), "--flip", "--poses-per-class", "1", "--box-search",
                 "--score-threshold", f"{SCORED_DETECTION_THRESHOLD:g}", "--vote-iou", f"{SCORED_VOTE_IOU:g}",
                 "--detections-out", str(job.result(condition, "_detections.json"))]
    return argv + ([] if job.progress else ["--no-progress"])


def _run_command(argv: list[str]) -> dict | int:
    """A ``paz6d`` command run in this process (its function, not a shell); errors propagate."""

    args = build_parser().parse_args(argv)
    if argv[0] == "estimate":

        return estimate(args)
    return args._run(args)


def _stage_estimate(job: Benchmark, condition: str) -> dict:
    argv = _estimate_args(job, condition)
    return {"command": argv, **_run_command(argv)}


def _forget_stale_scores(job: Benchmark) -> list[str]:
    """Marks undone the estimate stages whose recorded ``paz6d estimate`` command differs from today's (flags
    added since the folder was scored, e.g. the viewpoint prior; markers from before commands were recorded), with
    their scores and, for the detections, the detector's AP; returns their names. The models are kept."""
    stale = []
    for condition in CONDITIONS:
        name = job.scoring_stage("estimate", condition)
        marker = job.marker(name)
        if marker.is_file() and (load_json_object(marker).get("summary") or {}).get("command") != \
                _estimate_args(job, condition):
            stale.append(name)
            for undone in (name, job.scoring_stage("evaluate", condition),
                           *((job.scoring_stage("detector_ap"),) if condition == "detections" else ())):
                job.marker(undone).unlink(missing_ok=True)
    return stale


def _stage_evaluate(job: Benchmark, condition: str) -> dict:
    scores = job.result(condition, "_scores.json")
    _run_command(["evaluate", "bop", *_scored_split(job, condition),
                  "--results", str(job.result(condition, ".csv")),
                  "--targets", str(_targets(job, condition)), "--metrics", "mssd,mspd,add",
                  "--out", str(scores), "--plots", str(job.out / "results" / f"{job.label}_{condition}_plots")]
                 + ([] if job.progress else ["--no-progress"]))
    return {"scores": str(scores)}


def _stage_detection_ap(job: Benchmark) -> dict:
    from paz6d.datasets.bop.coco_ground_truth import bop_split_to_coco

    truth = job.out / "results" / "coco_ground_truth.json"
    write_json_atomically(truth, bop_split_to_coco(job.lmo, "test"))  # scoring only
    scores = job.out / "results" / "detector_coco.json"
    _run_command(["evaluate", "coco", "--gt", str(truth), "--results", str(job.result("detections",
                                                                                       "_detections.json")),
                  "--out", str(scores)])
    return {"scores": str(scores)}


def stages(job: Benchmark) -> list[tuple[str, Callable[[], dict], list[Path]]]:
    """``(name, run, outputs)`` of every stage in order; a stage is done when its marker and outputs exist."""
    found = [("backgrounds", lambda: _stage_backgrounds(job), [job.out / "backgrounds"]),
             ("synthetic", lambda: _stage_synthetic(job), [job.out / "synthetic" / "camera.json"]),
             ("validation", lambda: _stage_validation(job), [job.out / "validation" / "camera.json"]),
             ("detector", lambda: _stage_detector(job), [job.out / "detector" / "model.keras"])]
    for obj_id in job.objects:
        found.append((f"{job.pose_dir(obj_id).parent.name}/obj_{obj_id:06d}",
                      lambda obj_id=obj_id: _stage_pose(job, obj_id), [job.pose_dir(obj_id)]))
    for condition in CONDITIONS:
        found.append((job.scoring_stage("estimate", condition), lambda c=condition: _stage_estimate(job, c),
                      [job.result(condition, ".csv")]))
        found.append((job.scoring_stage("evaluate", condition), lambda c=condition: _stage_evaluate(job, c),
                      [job.result(condition, "_scores.json")]))
    found.append((job.scoring_stage("detector_ap"), lambda: _stage_detection_ap(job),
                  [job.out / "results" / "detector_coco.json"]))
    return found


def stage_done(job: Benchmark, name: str, outputs: list[Path]) -> bool:
    """Whether a stage finished: its marker file and every output exist."""
    return job.marker(name).is_file() and all(path.exists() for path in outputs)


#: settings newer than some benchmark folders, with the value the versions before them used
_EARLIER_SETTINGS = {"aae_lr_drop_steps": 0, "keypointnet_robust_steps": None, "keypointnet_robust_views": None,
                     "validation_images": 60, "aae_crop_box": "obj", "detector_backbone": "none",
                     "neutral_distractors": 0.0, "aae_encoder_backbone": "none"}


def _check_settings(job: Benchmark) -> None:
    """Records the benchmark's settings in ``DIR/benchmark.json``; a re-run with other sizes is refused."""
    path = job.out / "benchmark.json"
    current = {"quick": job.quick, "settings": asdict(job.settings), "seed": job.seed,
               "objects": list(job.objects), "lmo": str(job.lmo.resolve())}
    if path.is_file():
        stored = load_json_object(path)
        if isinstance(stored.get("settings"), dict):
            stored["settings"] = {**_EARLIER_SETTINGS, **stored["settings"]}
        if _extends_aae(job, stored, current):
            write_json_atomically(path, current, indent=2)
            return
        differing = sorted(key for key in current if stored.get(key) != current[key])
        if "settings" in differing and isinstance(stored.get("settings"), dict):  # name the settings inside
            earlier = stored["settings"]
            differing.remove("settings")
            differing += [f"settings.{name} ({earlier.get(name)!r} there, {value!r} now)"
                          for name, value in current["settings"].items() if earlier.get(name) != value]
        if differing:
            raise ValueError(f"out: {job.out} holds a benchmark with other settings ({', '.join(differing)} differ; "
                             f"see {path}); use another --out or the same flags")
    else:
        write_json_atomically(path, current, indent=2)


def _extends_aae(job: Benchmark, stored: dict, current: dict) -> bool:
    """Whether ``current`` differs from the ``stored`` settings in a larger ``aae_steps`` only. If so, the
    AAE stages and the AAE estimates and scores are marked undone, so that the next run resumes each AAE to
    the new number of steps and scores it again (the data and the detector stay).

    Raises:
        ValueError: a smaller ``aae_steps`` than the stored one (trained AAEs cannot be shortened).
    """
    stored_settings = dict(stored.get("settings") or {})
    stored_steps = stored_settings.pop("aae_steps", None)
    current_settings = dict(current["settings"])
    steps = current_settings.pop("aae_steps")
    same_otherwise = all(stored.get(key) == current[key] for key in current if key != "settings")
    if not same_otherwise or stored_steps is None:
        return False
    if steps < stored_steps:  # checked first: a shorter run also shortens the sizes' drop
        raise ValueError(f"aae_steps: {job.out} holds AAEs trained for {stored_steps} steps; expected at least "
                         f"that many (a run resumes its AAEs, it cannot shorten them), got {steps}")
    if stored_settings != current_settings or steps == stored_steps:
        return False
    for method in _resumed_by_aae_steps(POSE_MODELS):
        for name, _, _ in stages(replace(job, method=method, object_methods={})):
            if name.startswith("pose/"):
                job.marker(name).unlink(missing_ok=True)
    for marker in (job.out / "stages").glob("*.json"):  # the scores of every combination with an AAE in it
        if marker.stem.startswith(("estimate_", "evaluate_")) and _has_aae(marker.stem):
            marker.unlink()
    _forget_report_rows(job, [label for label in _report(job).get("methods", {}) if _has_aae(label)])
    return True


def _resumed_by_aae_steps(names) -> list[str]:
    """The pose models among ``names`` whose training length ``aae_steps`` sets."""
    return [name for name in names if name in POSE_MODELS and POSE_MODELS[name].steps_setting == "aae_steps"]


def _has_aae(name: str) -> bool:
    """Whether a label (``aae+keypointnet_robust@8``) or a stage marker's name uses a pose model that
    ``aae_steps`` sets."""
    return bool(_resumed_by_aae_steps(re.split(r"[_+@]", name)))


def _report(job: Benchmark) -> dict:
    path = job.out / "report.json"
    return load_json_object(path) if path.is_file() else {}


def _forget_report_rows(job: Benchmark, labels: list[str]) -> None:
    """Removes these labels' scores from ``report.json``: their models changed, so the rows (and the method pick
    made from them) would be stale until the labels are scored again."""
    report = _report(job)
    if not any(label in report.get("methods", {}) for label in labels):
        return
    for key in ("methods", "object_methods", "not_estimated", "overlays"):
        report[key] = {label: value for label, value in report.get(key, {}).items() if label not in labels}
    write_json_atomically(job.out / "report.json", report, indent=2)


def trains_a_pose_model(name: str) -> bool:
    """Whether a stage trains a pose model: those run side by side with ``jobs`` > 1. The detector trains alone
    on every core before them, so it is the same model as without ``jobs`` (docs/real_photos.md)."""
    return name.startswith("pose")


def _run_stage(job: Benchmark, name: str, function: Callable[[], dict]) -> float:
    """Runs one stage and writes its marker (seconds and summary); returns the seconds."""
    print(f"[benchmark lmo] {name} ...", flush=True)
    started = time.perf_counter()
    summary = function()
    seconds = time.perf_counter() - started
    write_json_atomically(job.marker(name), {"stage": name, "seconds": seconds, "summary": _json_safe(summary)},
                          indent=2)
    print(f"[benchmark lmo] {name}: {seconds / 60:.1f} min", flush=True)
    return seconds


def _stage_in_own_process(job: Benchmark, name: str, threads: int) -> None:
    """Runs stage ``name`` in this (spawned) process, TensorFlow limited to ``threads`` CPU threads."""
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow(threads=threads)
    function = next(function for stage, function, _ in stages(job) if stage == name)
    _run_stage(job, name, function)


def _run_side_by_side(job: Benchmark, names: list[str]) -> None:
    """Runs these stages in ``job.jobs`` processes at once, the CPU cores shared out between them."""
    threads = threads_per_job(job.jobs)
    print(f"[benchmark lmo] {len(names)} pose models, {job.jobs} at a time ({threads} CPU thread(s) each)",
          flush=True)
    run_in_processes([(name, _stage_in_own_process, (job, name, threads)) for name in names], job.jobs)


def run_benchmark(job: Benchmark, only: tuple[str, ...] | None = None) -> dict:
    """Runs (or resumes) every stage, then writes the report; returns ``report.json``'s content.

    With ``job.jobs`` > 1 the unfinished pose models train side by side in their own processes once the data
    and the detector exist, ``job.jobs`` at a time.

    Args:
        only: run just the stages whose name starts with one of these (tests, partial runs).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # first: anything rendered in this process is then safe next to TensorFlow
    job.out.mkdir(parents=True, exist_ok=True)
    _check_settings(job)
    for name in _forget_stale_scores(job):
        print(f"[benchmark lmo] {name}: scored with another command, scored again", flush=True)
    started = time.perf_counter()
    selected = [stage for stage in stages(job) if only is None or stage[0].startswith(only)]
    side_by_side = [name for name, _, outputs in selected
                    if trains_a_pose_model(name) and not stage_done(job, name, outputs)]
    if job.jobs == 1 or len(side_by_side) < 2:
        side_by_side = []
    timings: dict[str, float] = {}
    for name, function, outputs in selected:
        if side_by_side and name == side_by_side[0]:
            _run_side_by_side(job, side_by_side)
        if stage_done(job, name, outputs):
            if name not in side_by_side:
                print(f"[benchmark lmo] {name}: done (skipped)", flush=True)
            timings[name] = float(load_json_object(job.marker(name)).get("seconds", 0.0))
            continue
        timings[name] = _run_stage(job, name, function)
    if only is not None:
        return {"timings": timings}
    return write_report(job, timings, wall_seconds=time.perf_counter() - started)


def _json_safe(value):
    try:
        json.dumps(value)
        return value
    except (TypeError, ValueError):
        return str(value)[:2000]


# ------------------------------------------------------------------------------------------ report
def _scores(path: Path) -> dict | None:
    return load_json_object(path) if path.is_file() else None


def _mean_ar(summary: dict | None) -> float | None:
    if not summary or summary.get("AR_MSSD") is None or summary.get("AR_MSPD") is None:
        return None
    return 0.5 * (summary["AR_MSSD"] + summary["AR_MSPD"])


def _cell(value: float | None) -> str:
    """A score in a Markdown table: three decimals, ``-`` when missing."""
    return "-" if value is None else f"{value:.3f}"


def score_table(report: dict) -> str:
    """The Markdown table of ``report.json``: per object and over all, per method and condition."""
    lines = ["| method | boxes | object | instances | AR_MSSD | AR_MSPD | mean | ADD(-S) |",
             "|---|---|---|---:|---:|---:|---:|---:|"]
    for method, conditions in sorted(report["methods"].items()):
        for condition, summary in conditions.items():
            if summary is None:
                continue
            for obj_id, entry in sorted(summary.get("per_object", {}).items(), key=lambda item: int(item[0])):
                lines.append(f"| {method} | {condition} | {int(obj_id)} | {entry.get('instances', '-')} | "
                             f"{_cell(entry.get('AR_MSSD'))} | {_cell(entry.get('AR_MSPD'))} | "
                             f"{_cell(_mean_ar(entry))} | {_cell(entry.get('ADD(-S)_recall'))} |")
            lines.append(f"| {method} | {condition} | **all** | {summary.get('counts', {}).get('gt_instances', '-')} | "
                         f"{_cell(summary.get('AR_MSSD'))} | {_cell(summary.get('AR_MSPD'))} | "
                         f"**{_cell(_mean_ar(summary))}** | {_cell(summary.get('ADD(-S)_recall'))} |")
    return "\n".join(lines) + "\n"


def method_pick(report: dict) -> dict | None:
    """Per object, the pose method whose model scores best on the held-out synthetic images (mean of AR_MSSD
    and AR_MSPD, ties to the first method name): a choice made without real labels. Also what that mix
    scores on the real frames, pooled over the objects' instances as ``paz6d evaluate bop`` pools them
    (exactly what ``--object-method`` runs of the mix report, since each object's estimates come from its
    own model). A model scored under several labels counts with the label scored last (``report.json`` keeps the
    labels in scoring order).

    Returns:
        ``None`` when no object has two methods scored on the synthetic images; else ``{"methods": {obj_id:
        method}, "validation": {obj_id: {method: mean}}, "method": the most common pick, "object_methods":
        {obj_id: method} (the other picks), "real": {condition: {"AR_MSSD", "AR_MSPD", "mean",
        "per_object": {obj_id: mean}} or None when an object lacks it}}``.
    """
    found = {}  # (condition, obj_id, method) -> that object's scores, from the label scored last
    for label, methods_of in reversed(list(report.get("object_methods", {}).items())):
        scores = report.get("methods", {}).get(label) or {}
        for condition in CONDITIONS.values():
            per_object = (scores.get(condition) or {}).get("per_object", {})
            for obj_id, method in methods_of.items():
                if _mean_ar(per_object.get(obj_id)) is not None:
                    found.setdefault((condition, obj_id, method), per_object[obj_id])
    validation = {}
    for (condition, obj_id, method), entry in found.items():
        if condition == CONDITIONS["synthetic"]:
            validation.setdefault(obj_id, {})[method] = _mean_ar(entry)
    if not any(len(methods) > 1 for methods in validation.values()):
        return None
    picks = {obj_id: max(sorted(validation[obj_id]), key=lambda method: validation[obj_id][method])
             for obj_id in sorted(validation, key=int)}
    names = sorted(picks.values())
    base = max(names, key=names.count)
    real = {}
    for condition in ("gt", "detections"):
        entries = {obj_id: found.get((CONDITIONS[condition], obj_id, method)) for obj_id, method in picks.items()}
        if any(entry is None for entry in entries.values()):
            real[CONDITIONS[condition]] = None
            continue
        instances = sum(entry["instances"] for entry in entries.values())
        pooled = {key: sum(entry["instances"] * entry[key] for entry in entries.values()) / instances
                  for key in ("AR_MSSD", "AR_MSPD")}
        real[CONDITIONS[condition]] = {**pooled, "mean": _mean_ar(pooled),
                                       "per_object": {obj_id: _mean_ar(entry) for obj_id, entry in entries.items()}}
    return {"methods": picks, "validation": validation, "method": base,
            "object_methods": {obj_id: method for obj_id, method in picks.items() if method != base}, "real": real}


def method_pick_notes(pick: dict | None) -> str:
    """Markdown section of :func:`method_pick` (empty without a choice to make)."""
    if pick is None:
        return ""

    def cell(summary, obj_id=None):
        return _cell(None if summary is None else summary["mean"] if obj_id is None else summary["per_object"][obj_id])

    gt, detections = pick["real"][CONDITIONS["gt"]], pick["real"][CONDITIONS["detections"]]
    lines = ["", "## Method per object, picked on the held-out synthetic images", "",
             "| object | held-out synthetic: mean of AR_MSSD and AR_MSPD per method | pick | real, visible boxes | "
             "real, detections |", "|---|---|---|---:|---:|"]
    for obj_id, method in pick["methods"].items():
        scores = ", ".join(f"{name} {value:.3f}" for name, value in sorted(pick["validation"][obj_id].items()))
        lines.append(f"| {int(obj_id)} | {scores} | {method} | {cell(gt, obj_id)} | {cell(detections, obj_id)} |")
    lines.append(f"| **all** | | | **{cell(gt)}** | **{cell(detections)}** |")
    options = "".join(f" --object-method {int(obj_id)}={method}" for obj_id, method in pick["object_methods"].items())
    lines += ["", f"The pick runs as `paz6d benchmark lmo --method {pick['method']}{options}` (same folder)."]
    return "\n".join(lines) + "\n"


def _not_estimated(job: Benchmark) -> dict[str, str]:
    """``{obj_id: reason}`` of the objects whose pose model could not estimate (from the estimate stages)."""
    found = {}
    for condition in CONDITIONS:
        marker = job.marker(job.scoring_stage("estimate", condition))
        if marker.is_file():
            found.update((load_json_object(marker).get("summary") or {}).get("unusable", {}))
    return found


def not_estimated_notes(report: dict) -> str:
    """Markdown lines naming the objects scored as misses because their pose model could not estimate."""
    lines = [f"- {method}, object {int(obj_id)}: not estimated, scored as misses ({reason})"
             for method, objects in sorted(report.get("not_estimated", {}).items())
             for obj_id, reason in sorted(objects.items(), key=lambda item: int(item[0]))]
    return ("\n" + "\n".join(lines) + "\n") if lines else ""


def _overlays(job: Benchmark, condition: str) -> list[Path]:
    """One PNG per real frame with the estimates' model outlines and axes, and a grid of all frames."""
    import cv2

    from paz6d.backend.draw import image_grid
    from paz6d.backend.image import load_image, save_image
    from paz6d.backend.mesh import load_mesh
    from paz6d.datasets.bop.camera import load_scene_camera
    from paz6d.datasets.bop.scene import find_image
    from paz6d.detect_and_estimate import draw_estimates

    results_path = job.result(condition, ".csv")
    if not results_path.is_file():
        return []
    results = read_pose_results(results_path, units="m")
    meshes = {}
    for obj_id in job.objects:
        mesh = load_mesh(job.mesh(obj_id), MESH_SCALE)
        meshes[f"obj_{obj_id:06d}"] = (np.asarray(mesh.vertices), np.asarray(mesh.faces))
    boxes = {}
    detections = job.result(condition, "_detections.json")
    if condition == "detections" and detections.is_file():
        for entry in json.loads(detections.read_text()):
            if entry["score"] >= 0.1:
                x, y, w, h = entry["bbox"]
                boxes.setdefault(entry["image_id"], []).append(Box2D(x, y, x + w, y + h, entry["score"],
                                                                     f"obj_{entry['category_id']:06d}"))
    folder = job.out / "overlays" / f"{job.label}_{condition}"
    written, tiles = [], []
    for scene in sorted((job.lmo / "test").iterdir()):
        if not scene.name.isdigit():
            continue
        cameras = load_scene_camera(scene / "scene_camera.json")
        for im_id, camera in sorted(cameras.items()):
            path = find_image(scene / "rgb", im_id)
            if path is None:
                continue
            image = load_image(path)
            rows = np.nonzero((results.scene_ids == int(scene.name)) & (results.im_ids == im_id))[0]
            poses = [Pose6D.from_matrix(results.T_model2cam[row], f"obj_{int(results.obj_ids[row]):06d}",
                                        float(results.scores[row])) for row in rows]
            image_id = int(scene.name) * 1_000_000 + im_id
            canvas = draw_estimates(image, poses, camera.K, meshes, boxes.get(image_id, []))
            out = folder / f"{int(scene.name):06d}_{im_id:06d}.png"
            out.parent.mkdir(parents=True, exist_ok=True)
            written.append(save_image(out, canvas))
            tiles.append(cv2.resize(canvas, (320, 240), interpolation=cv2.INTER_AREA))
    if tiles:
        written.append(save_image(job.out / "overlays" / f"{job.label}_{condition}.png", image_grid(tiles, 4)))
    return written


def _wall_note(report: dict) -> str:
    """`` (this run: N min of wall time, pose models J at a time)`` when they trained side by side."""
    if report["jobs"] == 1 or report["run_wall_minutes"] is None:
        return ""
    return (f" (this run: {report['run_wall_minutes']:.1f} min of wall time, pose models {report['jobs']} at "
            f"a time; stages run side by side overlap)")


def _scored_last(rows: dict, label: str, value) -> dict:
    """``rows`` with ``label``'s entry replaced by ``value`` and moved last (the report keeps scoring order)."""
    return {**{other: row for other, row in rows.items() if other != label}, label: value}


def write_report(job: Benchmark, timings: dict[str, float], wall_seconds: float | None = None) -> dict:
    """``DIR/report.json`` (settings, timings, scores of every method run so far, in scoring order),
    ``DIR/report.md`` and the overlays of this method.

    Args:
        timings: seconds of each stage (trainings run side by side overlap).
        wall_seconds: this run's wall time (stages skipped as done count 0).
    """
    path = job.out / "report.json"
    report = _report(job)
    scores = {name: _scores(job.result(condition, "_scores.json")) for condition, name in CONDITIONS.items()}
    for summary in scores.values():
        if summary is not None:
            summary["mean_AR_MSSD_AR_MSPD"] = _mean_ar(summary)
    methods_of = {str(obj_id): job.method_of(obj_id) for obj_id in job.objects}
    all_timings = {**report.get("timings_seconds", {}), **timings}
    detector = _scores(job.out / "results" / "detector_coco.json")
    overlays = {condition: [str(p) for p in _overlays(job, condition)] for condition in ("gt", "detections")}
    report = {"benchmark": "lmo", "quick": job.quick, "settings": asdict(job.settings), "objects": list(job.objects),
              "lmo": str(job.lmo), "methods": _scored_last(report.get("methods", {}), job.label, scores),
              "object_methods": _scored_last(report.get("object_methods", {}), job.label, methods_of),
              "not_estimated": _scored_last(report.get("not_estimated", {}), job.label, _not_estimated(job)),
              "detector_coco": detector, "timings_seconds": all_timings,
              "total_minutes": sum(all_timings.values()) / 60,
              "run_wall_minutes": None if wall_seconds is None else wall_seconds / 60, "jobs": job.jobs,
              "overlays": _scored_last(report.get("overlays", {}), job.label, overlays)}
    report["method_pick"] = method_pick(report)
    write_json_atomically(path, report, indent=2)
    table = score_table(report) + not_estimated_notes(report) + method_pick_notes(report["method_pick"])
    header = (f"# paz6d benchmark lmo ({'quick' if job.quick else 'full'})\n\n"
              f"Synthetic training only; {len(job.objects)} LM-O objects; scored on the real RGB frames of "
              f"{job.lmo} with `paz6d evaluate bop`; `detections`: the benchmark's detector, which also sees each "
              f"frame's mirror image, whose boxes are voted, and whose best box per object is searched around by its "
              f"AAE (`paz6d estimate --flip --vote-iou {SCORED_VOTE_IOU:g} --poses-per-class 1 --box-search`); in "
              f"every condition the AAEs answer only with views of "
              f"{viewpoints(job).describe()} (the training scenes' range widened by {VIEWPOINT_MARGIN_DEGREES:g}); "
              f"`synthetic_gt_visible_boxes`: the same models on "
              f"{job.settings.validation_images} held-out synthetic images (what a user without real labels can "
              f"measure, to pick a method per object), and `synthetic_detections` with the detector's boxes on "
              f"them. Total stage time {report['total_minutes']:.1f} min"
              f"{_wall_note(report)}.\n\n")
    write_text_atomically(job.out / "report.md", header + table)
    print(table)
    return report
