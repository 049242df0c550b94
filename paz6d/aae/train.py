"""``paz6d train aae``: train an Augmented Autoencoder for one object and build its orientation codebook.

Stages, each resumable from what is already in the run directory (its files and formats:
:mod:`paz6d.aae.run_dir`): the settings (a re-run reuses them; --steps may extend training), the
object geometry, clean on-axis renderings on the view sphere (rendered in worker processes), with
--dataset the data set's crops and their clean targets, the Trainer's checkpoints, logs and samples,
the trained autoencoder, its codebook and a summary.

``paz6d.aae.pipeline.ImplicitPose6D(RUN_DIR, camera)`` loads the result.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from paz6d.aae import run_dir as run_files
from paz6d.aae.augment import Augmentation
from paz6d.backend.files import save_npz_atomically
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors, option
from paz6d.datasets.bop.units import MM_PER_M
from renderers.platform import PLATFORMS



@dataclass(frozen=True)
class AAEConfig:
    """Model, data and schedule of an AAE training run.

    Attributes:
        crop_size: side of the square model input (pixels).
        latent_size: length of the latent code.
        filters: encoder channels per strided convolution (the decoder mirrors them).
        kernel_size: convolution kernel size.
        batch_norm: batch normalisation after every convolution (not in the paper; trains faster).
        padding: crop side / longest side of the object box.
        render_size: side of the on-axis renderings the crops are cut from.
        views: view-sphere directions rendered (training views and codebook share them).
        in_plane: in-plane rotations per view in the codebook (codebook size = views * in_plane).
        steps: optimisation steps.
        batch_size: samples per step.
        learning_rate: Adam learning rate.
        bootstrap_fraction: fraction of largest pixel errors in the loss (1 = plain L2; paper 0.25).
        augmentation: input augmentation strengths.
        checkpoint_every / sample_every / log_every: Trainer intervals in steps.
    """

    crop_size: int = 64
    latent_size: int = 64
    filters: tuple[int, ...] = (32, 64, 64, 128)
    kernel_size: int = 5
    batch_norm: bool = False
    padding: float = 1.2
    render_size: int = 96
    views: int = 1000
    in_plane: int = 36
    steps: int = 3000
    batch_size: int = 32
    learning_rate: float = 1e-3
    bootstrap_fraction: float = 0.25
    augmentation: Augmentation = field(default_factory=Augmentation)
    checkpoint_every: int = 500
    sample_every: int = 500
    log_every: int = 25

    def to_dict(self) -> dict:
        data = asdict(self)
        data["filters"] = list(self.filters)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "AAEConfig":
        data = dict(data)
        unknown = set(data) - {f for f in cls.__dataclass_fields__}
        if unknown:
            raise ValueError(f"AAE config: unknown field(s) {sorted(unknown)}")
        augmentation = data.pop("augmentation", {})
        for key in ("occluder_size", "scale", "contrast", "saturation"):
            if key in augmentation:
                augmentation[key] = tuple(augmentation[key])
        return cls(filters=tuple(data.pop("filters", cls.filters)), augmentation=Augmentation(**augmentation), **data)

    @property
    def codebook_size(self) -> int:
        return self.views * self.in_plane


#: Sized for a 2-core CPU (the demo): 64x64 crops, batch normalisation (several times faster convergence),
#: latent 128, 1,000 views x 72 in-plane = 72,000-entry codebook, 5,000 steps (~10 minutes); small crop
#: shifts (the demo uses ground-truth boxes: measured, shifts of +-8 % doubled the rotation error at this
#: training length).
QUICK = AAEConfig(latent_size=128, batch_norm=True, in_plane=72, steps=5000,
                  augmentation=Augmentation(shift=0.03, scale=(0.95, 1.05)))
#: The paper's setting: 128x128 crops, latent 128, 30k iterations of 64, 2,562 x 36 = 92,232 codebook views.
FULL = AAEConfig(crop_size=128, latent_size=128, filters=(128, 256, 256, 512), render_size=192, views=2562,
                 in_plane=36, steps=30000, batch_size=64, learning_rate=2e-4, checkpoint_every=1000,
                 sample_every=2000, log_every=50)
CONFIGS = {"quick": QUICK, "full": FULL}


@dataclass(frozen=True)
class AAETraining:
    """One ``paz6d train aae`` run (each field is a flag, see :mod:`paz6d.cli_options`): the object,
    from a mesh or a BOP data set, the run directory, the config preset and how to run."""

    out: Path = option(help="run directory (re-run to resume)")
    mesh: Path | None = option(None, "mesh of the object (PLY/OBJ/GLB)", one_of="source")
    dataset: Path | None = option(None, "BOP data set (e.g. from `paz6d generate`): its models/obj_XXXXXX.ply "
                                        "(millimetres) is the object and its image crops are training inputs",
                                  one_of="source")
    object_id: int | None = option(None, "object of --dataset (default: the only one)")
    split: str = option("train", "split of --dataset to read")
    pair_fraction: float = option(0.5, "with --dataset: share of training samples taken from its crops "
                                       "(the rest: rendered views)")
    config: str = option("quick", "quick: 64x64, minutes on a 2-core CPU; full: the paper's 128x128, 30k steps, "
                                  "92,232-view codebook (hours on a CPU)", choices=tuple(sorted(CONFIGS)))
    steps: int | None = option(None, "training steps (default: the config's)")
    seed: int = option(0, "seed of the model initialisation and of the data stream")
    mesh_scale: float | None = option(None, "mesh units to metres (default: 1 with --mesh, 0.001 with --dataset, "
                                            "whose meshes are BOP millimetres)")
    workers: int = option(2, "rendering processes (0: render in this process)")
    platform: str | None = option(None, "OpenGL platform of the renderers (default: auto)", choices=PLATFORMS)
    progress: bool = option(True, "progress bars")

    def __post_init__(self):
        if (self.mesh is None) == (self.dataset is None):
            raise ValueError("mesh: expected exactly one of mesh and dataset")
        if self.config not in CONFIGS:
            raise ValueError(f"config: expected one of {sorted(CONFIGS)}, got {self.config!r}")
        if self.steps is not None and self.steps <= 0:
            raise ValueError(f"steps: expected a positive number of steps, got {self.steps}")
        if self.mesh_scale is None:
            object.__setattr__(self, "mesh_scale", 1.0 if self.dataset is None else 1.0 / MM_PER_M)
        if not np.isfinite(self.mesh_scale) or self.mesh_scale <= 0:
            raise ValueError(f"mesh_scale: expected a positive factor to metres, got {self.mesh_scale}")

    @property
    def model_config(self) -> AAEConfig:
        """The preset :attr:`config` with :attr:`steps` applied."""
        preset = CONFIGS[self.config]
        return preset if self.steps is None else replace(preset, steps=self.steps)


def _prepare_run(run_dir: Path, mesh_path: Path, mesh_scale: float, config: AAEConfig, seed: int,
                 dataset: Path | None) -> tuple[AAEConfig, int]:
    """Writes ``config.json`` for a new run, or reads the stored one (only ``steps`` may change)."""
    path = run_files.config_path(run_dir)
    if path.exists():
        stored = run_files.read_config(run_dir)
        try:
            stored_config = AAEConfig.from_dict(stored["config"])
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"{path}: unreadable AAE run configuration ({error})") from error
        if Path(stored["mesh"]).resolve() != mesh_path.resolve() or stored["mesh_scale"] != mesh_scale:
            raise ValueError(f"{path}: this run directory was trained on {stored['mesh']} (scale "
                             f"{stored['mesh_scale']}); use another --out for {mesh_path}")
        wanted = None if dataset is None else str(dataset.resolve())
        if stored.get("dataset") != wanted:
            raise ValueError(f"{path}: this run directory was trained with --dataset {stored.get('dataset')}; "
                             f"use another --out for --dataset {wanted}")
        config, seed = replace(stored_config, steps=config.steps), int(stored["seed"])
    run_files.write_config(run_dir, config.to_dict(), mesh_path, mesh_scale, seed, dataset)
    return config, seed


def _object_geometry(run_dir: Path, mesh_path: Path, mesh_scale: float, seed: int) -> dict:
    if not run_files.object_path(run_dir).exists():
        from paz6d.backend.mesh import diameter, load_mesh, sample_points

        mesh = load_mesh(mesh_path, mesh_scale)
        hull = np.asarray(mesh.convex_hull.vertices)
        run_files.write_object(run_dir, hull, sample_points(mesh, 2000, seed), diameter(hull),
                               np.asarray(mesh.vertices))
    return run_files.read_object(run_dir)


def _views(run_dir: Path, mesh_path: Path, mesh_scale: float, config: AAEConfig, geometry, workers: int,
           platform: str | None, progress: bool) -> dict:
    from paz6d.aae.codebook import fibonacci_sphere, look_at_rotations
    from paz6d.aae.views import render_views

    path = run_files.views_path(run_dir)
    rotations = look_at_rotations(fibonacci_sphere(config.views))
    if path.exists():
        with np.load(path) as data:
            if data["rgb"].shape[:2] == (config.views, config.render_size) and np.allclose(data["rotations"], rotations):
                return {key: data[key] for key in data.files}
    rgb, alpha = render_views(mesh_path, mesh_scale, rotations, geometry, workers=workers, platform=platform,
                              progress=progress)
    save_npz_atomically(path, rgb=rgb, alpha=alpha, rotations=rotations, K=geometry.K, distance=geometry.distance)
    return {"rgb": rgb, "alpha": alpha, "rotations": rotations, "K": geometry.K, "distance": geometry.distance}


def _sample_callback(sampler, count: int = 8):
    """Draws ``count`` fixed validation samples: augmented input / reconstruction / clean target rows."""
    from paz6d.aae.model import to_model_input

    rng = np.random.default_rng(123456)
    pairs = [sampler.sample(rng) for _ in range(count)]
    inputs = np.stack([pair[0] for pair in pairs])
    targets = np.stack([pair[1] for pair in pairs])

    def draw(model, step: int, path: Path) -> None:
        from paz6d.backend.image import save_image

        reconstructions = np.asarray(model(to_model_input(inputs), training=False))
        reconstructions = np.clip(np.rint(reconstructions * 255), 0, 255).astype(np.uint8)
        rows = [np.concatenate(list(images), axis=1) for images in (inputs, reconstructions, targets)]
        save_image(path, np.concatenate(rows, axis=0))

    return draw


def measure_loader(sampler, batch_size: int, batches: int = 4) -> float:
    """Samples per second of one thread making training batches (seeds unused by training)."""
    started = time.perf_counter()
    for index in range(batches):
        sampler.batch(10**12 + index, batch_size)
    return batches * batch_size / (time.perf_counter() - started)


def _pairs(run_dir: Path, dataset: Path, obj_id: int, split: str, mesh_path: Path, mesh_scale: float,
           config: AAEConfig, workers: int, platform: str | None, progress: bool):
    from paz6d.aae.dataset import CropPairs, dataset_pairs

    path = run_files.pairs_path(run_dir)
    if path.exists():
        with np.load(path) as data:
            if data["inputs"].shape[1] == config.crop_size:
                return CropPairs(data["inputs"], data["targets"], data["poses"])
    pairs = dataset_pairs(dataset, obj_id, mesh_path, mesh_scale, config.crop_size, config.padding, split, workers,
                          platform, progress)
    save_npz_atomically(path, inputs=pairs.inputs, targets=pairs.targets, poses=pairs.poses)
    return pairs


def train_aae(mesh_path: str | Path, run_dir: str | Path, config: AAEConfig = QUICK, mesh_scale: float = 1.0,
              seed: int = 0, workers: int = 2, platform: str | None = None, progress: bool = True,
              dataset: str | Path | None = None, object_id: int = 1, split: str = "train",
              pair_fraction: float = 0.5) -> dict:
    """Trains an AAE on renderings of ``mesh_path`` and writes a run directory ``ImplicitPose6D`` loads.

    Args:
        mesh_path: the object's mesh.
        run_dir: output folder (re-running resumes it).
        config: :data:`QUICK`, :data:`FULL` or a custom :class:`AAEConfig`.
        mesh_scale: factor from mesh units to metres (0.001 for BOP meshes in millimetres).
        seed: seed of the model initialisation and of the data stream.
        workers: rendering processes (0: render in this process).
        platform: OpenGL platform of the renderers (``"egl"``, ``"osmesa"`` or None = auto).
        dataset: optional BOP data set whose crops of ``object_id`` (``split``) become a share
            ``pair_fraction`` of the training inputs, with clean rendered targets (the rest are rendered views).

    Returns:
        The summary written to ``summary.json``.
    """
    from paz6d.backend.tensorflow_guard import import_keras

    keras = import_keras()
    from paz6d.aae.model import build_autoencoder, encoder_of, load_model, reconstruction_loss, save_model
    from paz6d.aae.augment import ViewSampler
    from paz6d.aae.build_codebook import build_codebook
    from paz6d.aae.views import ViewGeometry
    from paz6d.training.trainer import Trainer

    timings = {}
    started = time.perf_counter()
    mesh_path, run_dir = Path(mesh_path), Path(run_dir)
    if not mesh_path.is_file():
        raise ValueError(f"--mesh: {mesh_path}: mesh file not found")
    dataset = None if dataset is None else Path(dataset)
    config, seed = _prepare_run(run_dir, mesh_path, mesh_scale, config, seed, dataset)
    geometry_data = _object_geometry(run_dir, mesh_path, mesh_scale, seed)
    geometry = ViewGeometry.for_points(geometry_data["vertices"], config.render_size)
    views = _views(run_dir, mesh_path, mesh_scale, config, geometry, workers, platform, progress)
    timings["views_seconds"] = time.perf_counter() - started

    pairs = None
    if dataset is not None:
        pairs = _pairs(run_dir, dataset, object_id, split, mesh_path, mesh_scale, config, workers, platform,
                       progress)
    sampler = ViewSampler(views["rgb"], views["alpha"], geometry.K, config.crop_size, config.padding,
                          config.augmentation, seed=seed, pairs=pairs, pair_fraction=pair_fraction)
    loader_speed = measure_loader(sampler, config.batch_size)
    keras.utils.set_random_seed(seed)
    model = build_autoencoder(config.crop_size, config.latent_size, config.filters, config.kernel_size,
                              config.batch_norm)
    optimizer = keras.optimizers.Adam(config.learning_rate)

    def loss_fn(model, batch):
        inputs, targets = batch
        return reconstruction_loss(targets, model(inputs, training=True), config.bootstrap_fraction)

    trainer = Trainer(model, optimizer, loss_fn, lambda step: sampler.batch(step, config.batch_size), run_dir,
                      config.steps, checkpoint_every=config.checkpoint_every, log_every=config.log_every,
                      sample_every=config.sample_every, sample_callback=_sample_callback(sampler), progress=progress,
                      prefetch=4, prefetch_workers=1)
    tick = time.perf_counter()
    training = trainer.fit()
    timings["training_seconds"] = time.perf_counter() - tick
    model_path = run_files.model_path(run_dir)
    save_model(model, model_path)

    tick = time.perf_counter()
    encoder = encoder_of(load_model(model_path))  # the codebook is made by exactly what users load
    codebook = build_codebook(encoder, views["rgb"], views["alpha"], views["rotations"], geometry,
                              geometry_data["hull_points"], config.in_plane, config.crop_size, config.padding,
                              progress=progress)
    codebook.save(run_files.codebook_path(run_dir))
    timings["codebook_seconds"] = time.perf_counter() - tick
    timings["total_seconds"] = time.perf_counter() - started
    summary = {"steps": training.final_step, "resumed_from_step": training.start_step,
               "final_metrics": training.metrics, "loader_samples_per_second_one_thread": loader_speed,
               "model_samples_per_second": training.model_samples_per_second,
               "codebook_size": len(codebook), "dataset_pairs": 0 if pairs is None else len(pairs), **timings}
    run_files.write_summary(run_dir, summary)
    return summary


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train aae`` flags (the fields of :class:`AAETraining`)."""
    add_config_arguments(parser, AAETraining)


def _dataset_mesh(dataset: Path, object_id: int | None) -> tuple[Path, int]:
    models = sorted((dataset / "models").glob("obj_*.ply"))
    if not models:
        raise ValueError(f"--dataset: {dataset / 'models'} holds no obj_XXXXXX.ply meshes")
    if object_id is None:
        if len(models) > 1:
            raise ValueError(f"--dataset: {len(models)} objects in {dataset / 'models'}; choose one with --object-id")
        return models[0], int(models[0].stem.split("_")[1])
    path = dataset / "models" / f"obj_{object_id:06d}.ply"
    if not path.exists():
        raise ValueError(f"--object-id: {path} does not exist")
    return path, object_id


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d train aae``."""
    job = config_from_args(AAETraining, args)
    with flags_in_errors(AAETraining):
        mesh, object_id = (job.mesh, 1) if job.dataset is None else _dataset_mesh(job.dataset, job.object_id)
        summary = train_aae(mesh, job.out, job.model_config, job.mesh_scale, job.seed, job.workers, job.platform,
                            job.progress, dataset=job.dataset, object_id=object_id, split=job.split,
                            pair_fraction=job.pair_fraction)
    print(json.dumps(summary, indent=2))
    return 0
