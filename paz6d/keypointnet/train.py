"""KeypointNet training: keypoints for one object, trained with the shared Trainer (the command
``paz6d train keypointnet`` is :mod:`paz6d.keypointnet.command`, its settings :mod:`paz6d.keypointnet.config`).

Two modes share the data, the network, the PnP pipeline and the evaluation:

- ``discovery`` (Suwajanakorn et al. 2018): pairs of views with known relative pose; the network
  finds ``N`` ordered keypoints by itself (multi-view consistency, relative pose, separation,
  silhouette and variance losses); the ``discovery`` preset adds a pair-angle curriculum and
  bootstrapping from the network's own keypoints lifted to 3D (:class:`AnchorSource`). Their final 3D
  positions in the object frame are lifted like the supervised ones (:func:`lift_run_keypoints`).
- ``supervised``: ``N`` keypoints chosen by farthest-point sampling on the mesh surface are
  projected into every view; the network learns them as heatmaps (cross-entropy to a Gaussian)
  plus their coordinates and depths. The 3D keypoints are known exactly.

With ``orientation_network`` (a half-turn symmetric object) both modes add the orientation network of
:mod:`paz6d.keypointnet.orientation`: batches carry the fed ``chart`` and the true ``chart_target``, their
poses are the ones the fed charts pick, and the chart-forcing twin of the network is what is trained.

The run directory (its files and formats: :mod:`paz6d.keypointnet.run_dir`) is what
:class:`paz6d.keypointnet.pipeline.KeypointPose6D` loads, plus the Trainer's checkpoints, ``log.csv``,
``tensorboard/`` and ``samples/``, the rendered views (training, validation, and crops of unseen whole
images, cut as at inference, from which the 3D keypoints are lifted) and the training metrics
(keypoint consistency on held-out views). Re-running the same command resumes.

TensorFlow and the renderer are loaded inside :func:`train_keypointnet`.
"""

from __future__ import annotations

import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from paz6d.backend import keypoints as keypoints_backend
from paz6d.backend.farthest_points import farthest_point_sampling
from paz6d.backend.files import finite_or_none, null_non_finite, read_cache, save_npz_atomically
from paz6d.backend.transform import apply, compose, invert
from paz6d.keypointnet import run_dir as run_files
from paz6d.keypointnet.config import (MAX_LIFTING_ERROR, ORIENTATION_WEIGHT, OTHER_CHART_PROBABILITY,
                                      SUPERVISED_WEIGHTS, KeypointConfig, KeypointTraining, anchors_due,
                                      pair_angle_at)
from paz6d.keypointnet.orientation import canonical_poses, chart_targets, one_hot, training_charts
from paz6d.keypointnet.run_dir import KeypointNetRunDir
from paz6d.processors.predict import predict_in_batches
from paz6d.training.precision import resolve_precision
from paz6d.training.settings import changed_settings, recorded_settings


# ------------------------------------------------------------------------------- run directory

#: Settings a resumed run may change: its length, and the compute dtype ("auto" resolves per machine).
RESUMABLE_CHANGES = ("steps", "precision")


def _prepare_run_dir(job: KeypointTraining, settings: KeypointConfig, object_diameter: float, sampling,
                     symmetry=None) -> dict:
    """Writes ``config.json`` or checks that an existing one describes the same run."""
    config = {"mode": job.mode, "config": job.config, "seed": job.seed, "mesh_path": str(Path(job.mesh).resolve()),
              "mesh_scale": job.mesh_scale, "diameter": object_diameter,
              "orientation": None if symmetry is None else symmetry.to_dict(),
              "input_size": settings.input_size, "margin": sampling.margin, "downsample": settings.downsample,
              "settings": settings.to_dict(), "sampling": sampling.to_dict()}
    job.out.mkdir(parents=True, exist_ok=True)
    path = KeypointNetRunDir.config_path(job.out)
    if path.exists():
        previous = KeypointNetRunDir.read_config(job.out)
        for key in ("mode", "config", "seed", "mesh_path", "mesh_scale", "input_size", "downsample", "orientation"):
            if previous.get(key) != config[key]:
                raise ValueError(f"{path}: this run directory holds a different run ({key}={previous.get(key)!r}, "
                                 f"now {config[key]!r}); choose another --out")
        earlier = recorded_settings(KeypointConfig, path, previous)
        fixed = [item.name for item in fields(settings) if item.name not in RESUMABLE_CHANGES]
        changed = changed_settings(earlier, settings, fixed)
        if changed:
            key = changed[0]
            raise ValueError(f"{path}: the {job.config!r} settings changed since this run started ({key}="
                             f"{getattr(earlier, key)!r}, now {getattr(settings, key)!r}); resuming would mix two "
                             f"trainings, choose another --out")
        if previous.get("sampling") != config["sampling"]:
            raise ValueError(f"{path}: the view sampling changed since this run started ({previous.get('sampling')!r}, "
                             f"now {config['sampling']!r}); resuming would mix two trainings, choose another --out")
        if earlier.steps != settings.steps:
            previous["settings"]["steps"] = settings.steps  # extending a run is allowed
            KeypointNetRunDir.write_config(job.out, previous)
        return previous
    KeypointNetRunDir.write_config(job.out, config)
    return config


# ------------------------------------------------------------------------------- losses

def _loss_function(mode: str, settings: KeypointConfig, object_diameter: float, keypoints_model: np.ndarray | None):
    """``loss_fn(model, batch) -> dict`` for the shared Trainer (TensorFlow imported here). With a
    ``chart`` in the batch, ``model`` is the chart-forcing network and the orientation network's
    cross-entropy against ``chart_target`` is added (weight :data:`ORIENTATION_WEIGHT`)."""
    from paz6d.keypointnet import model as kp

    tf = kp.tf

    def forward(model, batch):
        """The network's outputs and the orientation term (an empty dict without orientation)."""
        if "chart" not in batch:
            return model(batch["images"], training=True), {}
        outputs = model([batch["images"], batch["chart"]], training=True)
        cross_entropy = tf.keras.losses.sparse_categorical_crossentropy(batch["chart_target"], outputs["chart_logits"],
                                                                        from_logits=True)
        return outputs, {"orientation": tf.reduce_mean(cross_entropy)}

    def with_orientation(loss, terms, orientation):
        if orientation:
            loss = loss + ORIENTATION_WEIGHT * orientation["orientation"]
        return {"loss": loss, **terms, **orientation}

    size = float(settings.input_size)
    stride = settings.downsample
    grid = kp.cell_centres(int(size) // stride, int(size) // stride, stride)
    scale, offset = (terms.astype(np.float32) for terms in keypoints_backend.normalization((size, size)))
    to_unit = tf.constant([[scale[0], 0.0, offset[0]], [0.0, scale[1], offset[1]], [0.0, 0.0, 1.0]], tf.float32)

    def normalised(uv):  # pixels -> [-1, 1]
        return uv * scale + offset

    sigma = float(stride)  # one feature cell

    def targets_loss(outputs, points_model, K, T):
        """Heatmap cross-entropy + coordinates + depth code against 3D keypoints ``points_model`` (N, 3)."""
        points_cam = tf.einsum("bij,nj->bni", T[:, :3, :3], points_model) + T[:, None, :3, 3]
        target_uv = kp.project(points_cam, K)
        target_code = points_cam[..., 2] / (object_diameter * K[:, 0:1, 0] / size)
        heatmap = kp.heatmap_loss(outputs["probabilities"], kp.gaussian_heatmaps(target_uv, grid, sigma))
        coordinates = kp.coordinate_loss(normalised(outputs["uv"]), normalised(target_uv))
        depth = tf.reduce_mean(tf.abs(outputs["depth"] - target_code))
        return target_uv, {"heatmap": heatmap, "coordinates": coordinates, "depth": depth}

    def anchor_loss(outputs, anchors, K, T):
        _, terms = targets_loss(outputs, tf.cast(anchors, tf.float32), K, T)
        return tf.add_n([SUPERVISED_WEIGHTS[name] * value for name, value in terms.items()])

    if mode == "discovery":
        grid_unit = normalised(grid)

        def loss_fn(model, batch):
            outputs, orientation = forward(model, batch)
            K, T = batch["K"], batch["T_model2cam"]
            pairs = tf.shape(K)[0] // 2
            depth = kp.metres_from_depth_code(outputs["depth"], object_diameter, K, int(size))
            uv_unit = normalised(outputs["uv"])
            K_unit = tf.einsum("ij,bjk->bik", to_unit, K)
            T_a2b = tf.einsum("bij,bjk->bik", T[pairs:], kp.invert_transforms(T[:pairs]))
            consistency = kp.consistency_loss(uv_unit[:pairs], depth[:pairs], uv_unit[pairs:], depth[pairs:],
                                              K_unit[:pairs], K_unit[pairs:], T_a2b)
            points = kp.unproject(outputs["uv"], depth, K) / object_diameter
            pose = kp.relative_pose_loss(points[:pairs], points[pairs:], T_a2b[:, :3, :3])
            separation = kp.separation_loss(points, settings.separation_delta)
            silhouette = kp.silhouette_loss(outputs["probabilities"], batch["masks"])
            variance = kp.variance_loss(outputs["probabilities"], uv_unit, grid_unit)
            separation_image = kp.separation_loss(uv_unit, settings.separation_delta_image)
            terms = {"consistency": consistency, "pose": pose, "separation": separation,
                     "separation_image": separation_image, "silhouette": silhouette, "variance": variance}
            loss = tf.add_n([getattr(settings.discovery_weights, name) * value for name, value in terms.items()])
            if "anchors" in batch:  # bootstrapping: the network's own keypoints, lifted to 3D (_anchor_source)
                anchor = anchor_loss(outputs, batch["anchors"], K, T)
                loss = loss + batch["anchor_weight"] * anchor
                terms["anchor"] = anchor
            return with_orientation(loss, terms, orientation)

        return loss_fn

    points = tf.constant(keypoints_model, tf.float32)

    def pixel_error(uv, target_uv):
        return tf.reduce_mean(tf.norm(uv - target_uv, axis=-1))

    def supervised_loss(model, batch):
        outputs, orientation = forward(model, batch)
        target_uv, terms = targets_loss(outputs, points, batch["K"], batch["T_model2cam"])
        loss = tf.add_n([SUPERVISED_WEIGHTS[name] * value for name, value in terms.items()])
        return with_orientation(loss, {"pixel_error": pixel_error(outputs["uv"], target_uv), **terms}, orientation)

    return supervised_loss


# ------------------------------------------------------------------------------- evaluation on crops

def fixed_crops(views, seed: int, count: int | None = None):
    """Views composited over seeded random backgrounds without crop/colour jitter: ``images (V, S, S, 3)
    uint8``, ``K (V, 3, 3)``, ``T_model2cam (V, 4, 4)``."""
    from paz6d.keypointnet.views import Augmentation, augmented_view

    count = len(views) if count is None else min(count, len(views))
    plain = Augmentation(crop_scale=0.0, crop_shift=0.0, colour=False, background=True)
    images, intrinsics = [], []
    for index in range(count):
        picture, _, K = augmented_view(views, index, np.random.default_rng([seed, index]), plain)
        images.append(picture)
        intrinsics.append(K)
    return np.stack(images), np.stack(intrinsics), views.T_model2cam[:count]


def predict_crops(model, images: np.ndarray, batch_size: int = 32) -> dict[str, np.ndarray]:
    """Runs the model over ``(V, S, S, 3)`` crops in batches; numpy outputs."""
    from paz6d.keypointnet.model import inference_function

    return predict_in_batches(inference_function(model), images, batch_size)


def cross_view_errors(uv, depth, K, T_model2cam) -> np.ndarray:
    """Re-projection consistency ``(P, N)`` in pixels of consecutive view pairs ``(2i, 2i+1)``.

    Keypoint ``n`` of view A, lifted with its predicted depth (metres), moved by the true relative
    pose and projected into view B, against keypoint ``n`` predicted in view B (and B into A; the
    two distances are averaged).
    """
    from paz6d.backend.camera import project_points, unproject

    pairs = len(uv) // 2
    errors = np.zeros((pairs, uv.shape[1]))
    for pair in range(pairs):
        a, b = 2 * pair, 2 * pair + 1
        T_a2b = compose(T_model2cam[b], invert(T_model2cam[a]))
        a_in_b = project_points(apply(T_a2b, unproject(uv[a], depth[a], K[a])), K[b])
        b_in_a = project_points(apply(invert(T_a2b), unproject(uv[b], depth[b], K[b])), K[a])
        errors[pair] = 0.5 * (np.linalg.norm(a_in_b - uv[b], axis=1) + np.linalg.norm(b_in_a - uv[a], axis=1))
    return errors


def model_reprojection_errors(uv, K, T_model2cam, points_model, usable) -> np.ndarray:
    """``(V, N_usable)`` pixel distances between predicted keypoints and the 3D keypoints projected
    with the true pose."""
    from paz6d.backend.camera import transform_and_project

    if not np.any(usable):
        return np.zeros((len(uv), 0))
    return np.stack([np.linalg.norm(transform_and_project(points_model[usable], T_model2cam[v], K[v])
                                    - uv[v][usable], axis=1) for v in range(len(uv))])


# ------------------------------------------------------------------------------- samples

def _sample_drawer(model, images: np.ndarray, targets: np.ndarray | None):
    """``sample_callback(trained, step, path)`` drawing ``model``'s keypoints (filled) and targets (hollow);
    ``model`` is the inference network (``trained``, which the Trainer passes, may be its chart-forcing twin)."""

    def draw(trained, step, path):
        from paz6d.backend.draw import draw_keypoints, image_grid
        from paz6d.backend.image import save_image

        uv = np.asarray(model(images.astype(np.float32), training=False)["uv"])
        tiles = []
        for index, picture in enumerate(images.astype(np.uint8)):
            if targets is not None:
                picture = draw_keypoints(picture, targets[index], visible=[False] * len(targets[index]), radius=4)
            tiles.append(draw_keypoints(picture, uv[index], radius=3))
        save_image(path, image_grid(tiles, columns=4))

    return draw


# ------------------------------------------------------------------------------- training

def inference_crops(test, K, margin: float, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Crops of whole images made exactly as :class:`~paz6d.keypointnet.pipeline.KeypointPose6D`
    makes them (square window of ``margin`` × the box around the box, resampled to ``size``).

    Args:
        test: :class:`~paz6d.keypointnet.views.TestImages` (images, boxes, poses).
        K: ``(3, 3)`` intrinsics of the whole images.
    Returns:
        ``images (V, size, size, 3)`` uint8, their intrinsics ``(V, 3, 3)`` and ``T_model2cam (V, 4, 4)``.
    """
    from paz6d.backend.square_crop import crop_intrinsics, crop_square, square_window

    windows = [square_window(box, margin) for box in test.boxes]
    images = np.stack([crop_square(image, window, size) for image, window in zip(test.images, windows)])
    return images, np.stack([crop_intrinsics(K, window, size) for window in windows]), np.asarray(test.T_model2cam)


def _cached_lifting_crops(path: Path, render, K, margin: float, size: int):
    """:func:`inference_crops` of freshly rendered whole images, cached in ``path`` (``.npz``)."""
    cached = read_cache(path, ("images", "K", "T_model2cam"))
    if cached is not None:
        return cached["images"], cached["K"], cached["T_model2cam"]
    images, intrinsics, poses = inference_crops(render(), K, margin, size)
    save_npz_atomically(path, images=images, K=intrinsics, T_model2cam=poses)
    return images, intrinsics, poses


def lift_run_keypoints(model, crops, settings: KeypointConfig, object_diameter: float, out: Path,
                       targets: np.ndarray | None = None, symmetry=None) -> dict:
    """Writes ``out/keypoints.json``: the 3D keypoints (object frame, metres) that PnP will use.

    The trained network's keypoints on ``crops = (images, K, T_model2cam)`` (views with known
    poses) are lifted to 3D, by ``settings.lifting``:

    - ``"triangulate"``: 2D-only least-squares triangulation with outlier views dropped
      (:func:`~paz6d.keypointnet.keypoints.triangulate_keypoints`); systematic 2D biases of the
      network are absorbed into the 3D model, so they cancel in PnP;
    - ``"median"``: per-view 3D points from the predicted depths, median over views (the paper's
      lifting, :func:`~paz6d.keypointnet.keypoints.lift_keypoints`).

    Keypoints whose median re-projection error exceeds :data:`MAX_LIFTING_ERROR` × crop side are
    marked unusable.
    ``targets`` (supervised mode: the farthest-point keypoints) are stored alongside for reference.
    With ``symmetry`` (:class:`~paz6d.keypointnet.orientation.ChartSymmetry`) each view's pose is the one
    the network's predicted chart picks.
    """
    from paz6d.keypointnet.model import metres_from_depth_code
    from paz6d.keypointnet.keypoints import decode_keypoints, lift_keypoints, triangulate_keypoints

    method = settings.lifting
    images, K, T = crops
    outputs = predict_crops(model, images)
    if symmetry is not None:
        T = symmetry.for_outputs(T, outputs)
    uv = decode_keypoints(outputs, settings.downsample)
    if method == "median":
        depth = np.asarray(metres_from_depth_code(outputs["depth"], object_diameter, K, settings.input_size))
        points, _ = lift_keypoints(uv, depth, K, T)
    else:
        points, _ = triangulate_keypoints(uv, K, T)
    error = np.median(model_reprojection_errors(uv, K, T, points, np.ones(len(points), bool)), axis=0)
    usable = error <= MAX_LIFTING_ERROR * settings.input_size
    name = {"triangulate": "triangulated", "median": "lifted-median"}[method]
    run_files.write_keypoints(out, points, usable, name, error, targets)
    return {"lifting": name, "lifting_error_px": error.tolist(), "usable_keypoints": int(usable.sum())}


class AnchorSource:
    """Bootstrap anchors of discovery: the network's current keypoints on ``anchor_views`` training views
    (plain crops, known poses) lifted to 3D (object frame, metres; see :meth:`lift`), re-lifted every
    ``anchor_every`` steps from ``anchor_start`` on (:func:`~paz6d.keypointnet.config.anchors_due`).

    From then on every batch also trains the network to predict the projections of these anchors
    (heatmap, coordinates, depth, as the supervised mode does with its targets), which ties each
    keypoint to one 3D point over all views, not only over the two views of a pair.

    Args:
        model: the network being trained (read from the batch-preparing thread).
        views: the training :class:`~paz6d.keypointnet.views.ViewSet`; seed: of the crops' backgrounds.
    """

    def __init__(self, model, views, settings: KeypointConfig, seed: int, object_diameter: float, symmetry=None):
        self.model, self.views, self.settings, self.seed, self.symmetry = model, views, settings, seed, symmetry
        self.diameter = float(object_diameter)
        self.points: np.ndarray | None = None
        self.lifted_at: int | None = None
        self._crops = None
        self._infer = None

    def __call__(self, step: int) -> np.ndarray | None:
        """The anchors ``(N, 3)`` for ``step`` (lifting them first when due), or ``None`` before
        bootstrapping starts."""
        if anchors_due(step, self.lifted_at, self.settings):
            self.points = self.lift()
            self.lifted_at = step
        return self.points

    def lift(self) -> np.ndarray:
        """The network's keypoints on the anchor crops in 3D: ``(N, 3)`` metres, object frame.

        ``anchor_lifting`` ``"modes"`` (default): each view's keypoints at their predicted depths in the
        object frame, then per keypoint the place it lands most often, keypoints at least
        ``separation_delta`` diameters apart (:func:`~paz6d.keypointnet.keypoints.spread_modes`, density
        radius ``anchor_radius`` diameters); ``"triangulate"``: least-squares triangulation of the 2D
        keypoints (inconsistent keypoints triangulate near the object's centre: every anchor collapsed
        onto one point in the measured runs).
        """
        from paz6d.keypointnet.keypoints import decode_keypoints, per_view_points, spread_modes, triangulate_keypoints
        from paz6d.keypointnet.model import inference_function

        if self._crops is None:
            self._crops = fixed_crops(self.views, self.seed, self.settings.anchor_views)
            self._infer = inference_function(self.model)
        images, K, T = self._crops
        outputs = predict_in_batches(self._infer, images, 32)
        if self.symmetry is not None:
            T = self.symmetry.for_outputs(T, outputs)
        uv = decode_keypoints(outputs, self.settings.downsample)
        if self.settings.anchor_lifting == "triangulate":
            return triangulate_keypoints(uv, K, T)[0]
        depth = np.asarray(outputs["depth"], np.float64) * self.diameter * K[:, 0:1, 0] / self.settings.input_size
        return spread_modes(per_view_points(uv, depth, K, T), self.settings.anchor_radius * self.diameter,
                            self.settings.separation_delta * self.diameter)


def orientation_batch(T_model2cam: np.ndarray, symmetry, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """What a batch needs for the orientation network: ``chart (V, 3)`` one-hot charts fed to the network
    (:func:`~paz6d.keypointnet.orientation.training_charts`), ``chart_target (V,)`` the true charts, and
    ``T_model2cam`` replaced by the poses the fed charts pick."""
    charts = training_charts(T_model2cam, symmetry.axis, rng, OTHER_CHART_PROBABILITY)
    return {"chart": one_hot(charts), "chart_target": chart_targets(T_model2cam, symmetry.axis).astype(np.int32),
            "T_model2cam": canonical_poses(T_model2cam, charts, symmetry.symmetry, symmetry.axis)}


def supervised_keypoints(mesh, count: int, seed: int) -> np.ndarray:
    """``(count, 3)`` farthest-point samples (metres) of 5000 points drawn on the mesh surface."""
    from paz6d.backend.mesh import sample_points

    surface = sample_points(mesh, 5000, seed)
    return surface[farthest_point_sampling(surface, count)]


def train_keypointnet(job: KeypointTraining, views=None) -> dict:
    """Trains (or resumes) one KeypointNet run and writes everything ``KeypointPose6D`` needs.

    Args:
        job: what to train and where.
        views: optional pre-built :class:`~paz6d.keypointnet.views.ViewSet` (e.g. from a BOP set);
            by default views of ``job.mesh`` are rendered in worker processes.
    Returns:
        A summary dict (also written to ``job.out/metrics.json``): training time, final losses and,
        on held-out views (crop pixels, ``input_size`` wide): ``reprojection_px_median`` (detected
        keypoint vs its lifted 3D keypoint projected with the true pose) and ``cross_view_px_median``
        (a keypoint moved to the other view of a pair with its predicted depth and the true relative
        pose, vs the keypoint detected there, as in the consistency loss).
    """
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # before any renderer in this process (workers=0)
    from paz6d.backend.mesh import diameter, load_mesh
    from paz6d.keypointnet.keypoints import DECODERS, decode_keypoints, keypoint_spread
    from paz6d.keypointnet.views import ViewSampling, cached_views, render_test_images, render_views, training_batch
    from paz6d.synthesis.sampling import hull_points

    settings = job.model_config
    settings = settings.replace(precision=resolve_precision(settings.precision))
    started = time.perf_counter()
    mesh = load_mesh(job.mesh, job.mesh_scale)
    object_diameter = diameter(np.asarray(mesh.vertices))
    sampling = ViewSampling(input_size=settings.input_size, lighting=settings.lighting)
    symmetry = job.symmetry()
    _prepare_run_dir(job, settings, object_diameter, sampling, symmetry)
    out = job.out
    run_files.write_object(out, object_diameter, hull_points(np.asarray(mesh.vertices)))

    def render(count, seed):
        return lambda: render_views(job.mesh, count, seed, sampling, job.mesh_scale, job.workers,
                                    progress=job.progress)

    train_views = views if views is not None else cached_views(KeypointNetRunDir.views_path(out, "train"),
                                                                 render(settings.views, job.seed))
    validation_views = cached_views(KeypointNetRunDir.views_path(out, "val"),
                                    render(settings.validation_views, job.seed + 10_000))
    render_seconds = time.perf_counter() - started

    keypoints_model = None
    if job.mode == "supervised":
        keypoints_model = supervised_keypoints(mesh, settings.num_keypoints, job.seed)

    from paz6d.keypointnet import model as kp
    from paz6d.training.trainer import Trainer

    keras = kp.keras
    keras.utils.set_random_seed(job.seed)
    built = kp.build_keypointnet(settings.num_keypoints, settings.input_size, settings.filters, settings.downsample,
                                 settings.dilations, context_stride=settings.context_stride,
                                 compute_dtype=settings.precision, orientation=symmetry is not None,
                                 backbone=settings.backbone)
    model, trained = built if symmetry is not None else (built, built)  # trained: the chart-forcing twin
    schedule = keras.optimizers.schedules.CosineDecay(settings.learning_rate, settings.steps, alpha=0.05)
    ema = settings.ema_momentum
    optimizer = keras.optimizers.Adam(schedule, global_clipnorm=5.0, use_ema=ema is not None,
                                      ema_momentum=0.99 if ema is None else ema)
    pairs, downsample = settings.pairs, settings.downsample

    anchors = (AnchorSource(model, train_views, settings, job.seed + 3, object_diameter, symmetry)
               if job.mode == "discovery" else None)


    def make_batch(step: int):
        rng = np.random.default_rng([job.seed, 1, step])
        batch = training_batch(train_views, rng, pairs, downsample, settings.augmentation,
                               max_angle=pair_angle_at(step, settings))
        if symmetry is not None:
            batch.update(orientation_batch(batch["T_model2cam"], symmetry, rng))
        points = None if anchors is None else anchors(step)
        if points is not None:
            batch["anchors"] = points.astype(np.float32)
            batch["anchor_weight"] = np.float32(settings.anchor_weight)
        return batch

    sample_images, sample_K, sample_T = fixed_crops(validation_views, job.seed, 8)
    sample_targets = None
    if keypoints_model is not None:
        from paz6d.backend.camera import transform_and_project

        sample_targets = np.stack([transform_and_project(keypoints_model, T, K) for T, K in zip(sample_T, sample_K)])
    trainer = Trainer(trained, optimizer, _loss_function(job.mode, settings, object_diameter, keypoints_model),
                      make_batch, out, settings.steps, checkpoint_every=settings.checkpoint_every, log_every=10,
                      sample_every=settings.sample_every,
                      sample_callback=_sample_drawer(model, sample_images, sample_targets), progress=job.progress,
                      prefetch=1)
    training = trainer.fit()
    kp.save_keypointnet(model, KeypointNetRunDir.model_path(out))
    train_seconds = time.perf_counter() - started - render_seconds

    if views is None:  # rendered views: lift from unseen whole images cropped as at inference
        lifting_crops = _cached_lifting_crops(
            KeypointNetRunDir.views_path(out, "lift"),
            lambda: render_test_images(job.mesh, settings.lift_views, job.seed + 20_000, sampling,
                                       job.mesh_scale, job.workers, progress=job.progress),
            sampling.camera.K, sampling.margin, settings.input_size)
    else:  # crops cut from a data set's images: already made as at inference
        lifting_crops = fixed_crops(train_views, job.seed + 1, settings.lift_views)
    lifting = lift_run_keypoints(model, lifting_crops, settings, object_diameter, out, keypoints_model, symmetry)
    points_model, usable = KeypointNetRunDir.read_keypoints(out)

    images, K, T = fixed_crops(validation_views, job.seed + 2)
    outputs = predict_crops(model, images)
    chart_accuracy = None
    if symmetry is not None:
        chart_accuracy = float(np.mean(np.argmax(outputs["chart"], axis=1) == chart_targets(T, symmetry.axis)))
        T = symmetry.for_outputs(T, outputs)
    depth = np.asarray(kp.metres_from_depth_code(outputs["depth"], object_diameter, K, settings.input_size))
    summary = {"mode": job.mode, "config": job.config, "steps": training.final_step,
               "train_seconds": round(train_seconds, 1), "render_seconds": round(render_seconds, 1),
               "final_losses": training.metrics,
               "loader_samples_per_second": finite_or_none(training.loader_samples_per_second, 1),
               "model_samples_per_second": finite_or_none(training.model_samples_per_second, 1),
               **lifting, "validation_views": len(images), "input_size": settings.input_size,
               "chart_accuracy": chart_accuracy}
    for method in DECODERS:  # "local" is what KeypointPose6D uses by default
        uv = decode_keypoints(outputs, downsample, method)
        consistency = cross_view_errors(uv, depth, K, T)
        reprojection = model_reprojection_errors(uv, K, T, points_model, usable)
        suffix = "" if method == "local" else "_global"
        summary[f"cross_view_px_median{suffix}"] = float(np.median(consistency))
        summary[f"cross_view_px_mean{suffix}"] = float(np.mean(consistency))
        summary[f"reprojection_px_median{suffix}"] = float(np.median(reprojection)) if reprojection.size else None
    summary["spread_px_median"] = float(np.median(keypoint_spread(outputs["probabilities"], outputs["uv"], downsample)))
    summary = null_non_finite(summary)  # a keypoint that could not be lifted has no error: null
    KeypointNetRunDir.write_metrics(out, summary)
    return summary
