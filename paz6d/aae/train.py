"""Training for ``paz6d train aae`` (settings: :mod:`paz6d.aae.config`; flags and command:
:mod:`paz6d.aae.command`): train an Augmented Autoencoder for one object and build its orientation codebook.

Stages, each resumable from what is already in the run directory (its files and formats:
:mod:`paz6d.aae.run_dir`): the settings (a re-run reuses them; --steps may extend training), the
object geometry, clean on-axis renderings on the view sphere (rendered in worker processes), with
--dataset the data set's crops and their clean targets, the Trainer's checkpoints, logs and samples,
the trained autoencoder, its codebook and a summary.

``paz6d.aae.pipeline.ImplicitPose6D(RUN_DIR, camera)`` loads the result.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from paz6d.aae import run_dir as run_files
from paz6d.aae.codebook import fibonacci_sphere, look_at_rotations
from paz6d.aae.config import QUICK, AAEConfig, check_crop_box
from paz6d.aae.run_dir import AAERunDir
from paz6d.backend.files import read_cache, save_npz_atomically
from paz6d.training.precision import resolve_precision


def _prepare_run(run_dir: Path, mesh_path: Path, mesh_scale: float, config: AAEConfig, seed: int,
                 dataset: Path | None, crop_box: str) -> tuple[AAEConfig, int]:
    """Writes ``config.json`` for a new run (``precision`` resolved), or reads the stored one (only ``steps``
    may change)."""
    path = AAERunDir.config_path(run_dir)
    if path.exists():
        stored = AAERunDir.read_config(run_dir)  # every setting checked (AAERunDir.check_config)
        stored_config = AAEConfig.from_dict(stored["config"])
        if Path(stored["mesh"]).resolve() != mesh_path.resolve() or stored["mesh_scale"] != mesh_scale:
            raise ValueError(f"{path}: this run directory was trained on {stored['mesh']} (scale "
                             f"{stored['mesh_scale']}); use another --out for {mesh_path}")
        wanted = None if dataset is None else str(dataset.resolve())
        if stored.get("dataset") != wanted:
            raise ValueError(f"{path}: this run directory was trained with --dataset {stored.get('dataset')}; "
                             f"use another --out for --dataset {wanted}")
        if stored.get("crop_box", "obj") != crop_box:  # runs from before the option cut whole-object crops
            raise ValueError(f"{path}: this run directory's data set crops were cut around the "
                             f"{stored.get('crop_box', 'obj')!r} boxes; use another --out for --crop-box {crop_box}")
        config, seed = replace(stored_config, steps=config.steps), int(stored["seed"])
    else:
        config = replace(config, precision=resolve_precision(config.precision))
    AAERunDir.write_config(run_dir, config.to_dict(), mesh_path, mesh_scale, seed, dataset, crop_box)
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
    from paz6d.aae.views import render_views

    path = run_files.views_path(run_dir)
    rotations = look_at_rotations(fibonacci_sphere(config.views))
    cached = read_cache(path, ("rgb", "alpha", "rotations", "K", "distance"))
    if cached is not None and cached["rgb"].shape[:2] == (config.views, config.render_size) and \
            cached["rotations"].shape == rotations.shape and np.allclose(cached["rotations"], rotations):
        return cached
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
           config: AAEConfig, workers: int, platform: str | None, progress: bool, dataset_format: str = "bop",
           object_class: str | None = None, crop_box: str = "obj"):
    from paz6d.aae.dataset import CropPairs, dataset_pairs

    path = run_files.pairs_path(run_dir)
    cached = read_cache(path, ("inputs", "targets", "poses"))
    if cached is not None and cached["inputs"].ndim == 4 and cached["inputs"].shape[1] == config.crop_size:
        return CropPairs(cached["inputs"], cached["targets"], cached["poses"])
    pairs = dataset_pairs(dataset, obj_id, mesh_path, mesh_scale, config.crop_size, config.padding, split, workers,
                          platform, progress, dataset_format=dataset_format, object_class=object_class,
                          crop_box=crop_box)
    save_npz_atomically(path, inputs=pairs.inputs, targets=pairs.targets, poses=pairs.T_model2cam)
    return pairs


def learning_rate_at(config: AAEConfig, step: int) -> float:
    """Adam's rate for 0-based ``step``: ``learning_rate``, times ``lr_drop_factor`` for the last
    ``lr_drop_steps`` steps (``steps - lr_drop_steps`` on)."""
    dropped = config.lr_drop_steps and step >= config.steps - config.lr_drop_steps
    return config.learning_rate * (config.lr_drop_factor if dropped else 1.0)


def train_aae(mesh_path: str | Path, run_dir: str | Path, config: AAEConfig = QUICK, mesh_scale: float = 1.0,
              seed: int = 0, workers: int = 2, platform: str | None = None, progress: bool = True,
              dataset: str | Path | None = None, object_id: int = 1, split: str = "train",
              pair_fraction: float = 0.5, dataset_format: str = "bop", object_class: str | None = None,
              crop_box: str = "obj") -> dict:
    """Trains an AAE on renderings of ``mesh_path`` and writes a run directory ``ImplicitPose6D`` loads.

    Args:
        mesh_path: the object's mesh.
        run_dir: output folder (re-running resumes it).
        config: :data:`~paz6d.aae.config.QUICK`, :data:`~paz6d.aae.config.FULL` or a custom :class:`AAEConfig`.
        mesh_scale: factor from mesh units to metres (0.001 for BOP meshes in millimetres).
        seed: seed of the model initialisation and of the data stream.
        workers: rendering processes (0: render in this process).
        platform: OpenGL platform of the renderers (``"egl"``, ``"osmesa"`` or None = auto).
        dataset: optional data set whose crops of the object (``split``) become a share ``pair_fraction`` of
            the training inputs, with clean rendered targets (the rest are rendered views): BOP
            (``dataset_format="bop"``, object ``object_id``) or YCB-Video / FAT (``"ycb_video"``, ``"fat"``,
            object ``object_class``; see :mod:`paz6d.datasets.pose_crops`).
        crop_box: the box each data set crop is cut around: ``"obj"`` (the whole object's) or ``"visib"``
            (a BOP data set's visible-part box, as a detector sees a partly hidden object); the targets are
            always the whole object's view (:func:`paz6d.aae.dataset.dataset_pairs`).

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
    check_crop_box(crop_box, dataset_format)  # before the run directory records it
    config, seed = _prepare_run(run_dir, mesh_path, mesh_scale, config, seed, dataset, crop_box)
    geometry_data = _object_geometry(run_dir, mesh_path, mesh_scale, seed)
    geometry = ViewGeometry.for_points(geometry_data["vertices"], config.render_size)
    pairs, tick = None, time.perf_counter()
    if dataset is not None:  # before the views: a bad data set file fails before minutes of rendering
        pairs = _pairs(run_dir, dataset, object_id, split, mesh_path, mesh_scale, config, workers, platform,
                       progress, dataset_format, object_class, crop_box)
    timings["pairs_seconds"] = time.perf_counter() - tick
    views = _views(run_dir, mesh_path, mesh_scale, config, geometry, workers, platform, progress)
    timings["views_seconds"] = time.perf_counter() - started - timings["pairs_seconds"]
    sampler = ViewSampler(views["rgb"], views["alpha"], geometry.K, config.crop_size, config.padding,
                          config.augmentation, seed=seed, pairs=pairs, pair_fraction=pair_fraction)
    loader_speed = measure_loader(sampler, config.batch_size)
    keras.utils.set_random_seed(seed)
    model = build_autoencoder(config.crop_size, config.latent_size, config.filters, config.kernel_size,
                              config.batch_norm, config.precision, config.encoder_backbone)
    optimizer = keras.optimizers.Adam(config.learning_rate)

    def loss_fn(model, batch):
        inputs, targets = batch
        return reconstruction_loss(targets, model(inputs, training=True), config.bootstrap_fraction)

    trainer = Trainer(model, optimizer, loss_fn, lambda step: sampler.batch(step, config.batch_size), run_dir,
                      config.steps, checkpoint_every=config.checkpoint_every, log_every=config.log_every,
                      sample_every=config.sample_every, sample_callback=_sample_callback(sampler), progress=progress,
                      prefetch=4, prefetch_workers=1,
                      learning_rate=(lambda step: learning_rate_at(config, step)) if config.lr_drop_steps else None)
    tick = time.perf_counter()
    training = trainer.fit()
    timings["training_seconds"] = time.perf_counter() - tick
    model_path = AAERunDir.model_path(run_dir)
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
               "precision": config.precision, "codebook_size": len(codebook),
               "dataset_pairs": 0 if pairs is None else len(pairs), **timings}
    AAERunDir.write_metrics(run_dir, summary)
    return summary
