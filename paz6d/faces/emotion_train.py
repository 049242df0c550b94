"""Training for ``paz6d train emotion``: mini-Xception on FER-2013 data (CSV or image folders), with
augmentation. The settings are :class:`~paz6d.faces.emotion_config.EmotionTraining`; the command
(flags, run) is :mod:`paz6d.faces.emotion_command`.

Data (``--data``):

* a FER-2013 CSV (``emotion,pixels,Usage``): ``Training`` rows train, ``PublicTest`` rows validate
  (``PrivateTest`` is left for testing); without ``PublicTest`` rows a ``--val-fraction`` of the
  training rows is held out;
  (a folder holding ``fer2013.csv`` is read the same way);
* a FER-2013 CSV with ``--ferplus fer2013new.csv``: the FERPlus votes of its rows (eight classes,
  :mod:`paz6d.datasets.ferplus`) with ``--label-mode majority`` (one label per face) or
  ``probability`` (the vote distribution is the soft target of the cross-entropy); ``Training``
  rows train, ``PublicTest`` rows validate (scored against the most voted emotion);
* a folder ``DIR/<class>/<image>``: a seeded ``--val-fraction`` per class is held out; or
  ``DIR/train/<class>/...`` with ``DIR/test/<class>/...`` used for validation.

Training uses the shared :class:`~paz6d.training.trainer.Trainer` (checkpoints, resume, CSV and
TensorBoard logs). ``RUN_DIR`` receives ``model.keras`` and ``classes.json`` (what
:class:`paz6d.faces.emotion.DetectEmotion` loads), ``metrics.json`` (validation accuracy and
confusion matrix), ``confusion_matrix.png`` and, during training, ``validation.csv`` plus
``samples/step_*.png`` confusion matrices.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from paz6d.abstract import SequentialProcessor
from paz6d.abstract.processor import random_processors
from paz6d.backend.files import (save_figure_atomically, save_keras_model_atomically, write_json_atomically,
                                 write_text_atomically)
from paz6d.datasets import ferplus as ferplus_data
from paz6d.datasets.fer2013 import CSV_FILE, FER2013_CLASSES, load_fer2013_csv, load_image_folder
from paz6d.faces import emotion_run_dir as run_files
from paz6d.faces.emotion_config import EmotionTraining
from paz6d.faces.emotion_run_dir import EmotionRunDir
from paz6d.processors.image import ConvertColorSpace
from paz6d.synthesis.augment import RandomAffine, RandomBrightness, RandomContrast, RandomFlipLeftRight

VALIDATION_LOG = "validation.csv"


def _split_per_class(labels: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """Boolean validation mask holding out ``round(fraction * n_c)`` random samples of each class."""
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"val_fraction: expected a fraction in (0, 1), got {fraction}")
    rng = np.random.default_rng(seed)
    validation = np.zeros(len(labels), dtype=bool)
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        count = int(round(fraction * len(members)))
        validation[rng.permutation(members)[:count]] = True
    return validation


def _hard_labels(labels: np.ndarray) -> np.ndarray:
    """Class index per face: ``labels`` itself, or the arg-max of ``(N, C)`` soft targets."""
    return labels.argmax(axis=1) if labels.ndim == 2 else labels


def _ferplus_data(path: Path, votes: Path, label_mode: str, val_fraction: float, seed: int) -> tuple:
    """``(train, validation, class_names)`` of FERPlus votes on the FER-2013 CSV ``path``."""
    samples = ferplus_data.load(votes, None, fer2013_csv=path, label_mode=label_mode)
    if len(samples) == 0:
        raise ValueError(f"ferplus: {votes} keeps no face in label mode {label_mode!r}")
    faces = np.stack([sample.image for sample in samples])
    targets = np.stack([sample.extras["target"] for sample in samples])
    labels = targets if label_mode == "probability" else targets.argmax(axis=1)
    usage = np.array([sample.extras["usage"] for sample in samples])
    training, validation = usage == "Training", usage == "PublicTest"
    if not training.any():
        raise ValueError(f"ferplus: {votes} keeps no face with Usage 'Training'")
    if not validation.any():
        index = np.flatnonzero(training)
        held_out = index[_split_per_class(_hard_labels(labels[training]), val_fraction, seed)]
        validation[held_out], training[held_out] = True, False
    return (faces[training], labels[training]), (faces[validation], labels[validation]), ferplus_data.FERPLUS_CLASSES


def load_emotion_data(path, val_fraction: float = 0.1, seed: int = 0, ferplus: str | Path | None = None,
                      label_mode: str = "majority") -> dict:
    """Loads training and validation faces from a FER-2013 CSV (with optional FERPlus votes) or an
    image folder (see module doc).

    Args:
        path: FER-2013 CSV, folder holding ``fer2013.csv``, or image folder.
        val_fraction, seed: the held-out share when the data has no validation split.
        ferplus: FERPlus ``fer2013new.csv`` for the rows of the CSV.
        label_mode: FERPlus ``"majority"`` or ``"probability"``.
    Returns:
        dict with ``train`` and ``validation`` ``(faces (N, H, W) uint8, labels)`` where labels are
        ``(N,) int64`` class indices, or ``(N, C) float64`` vote distributions in FERPlus
        ``probability`` mode; and ``class_names``.
    """
    path = Path(path)
    if path.is_dir() and (path / CSV_FILE).is_file():
        path = path / CSV_FILE
    if ferplus is not None:
        if not path.is_file():
            raise ValueError(f"data: {path} is not a FER-2013 CSV file; --ferplus votes need the fer2013.csv "
                             "their rows refer to")
        train, valid, class_names = _ferplus_data(path, Path(ferplus), label_mode, val_fraction, seed)
    elif path.is_file():
        faces, labels, usage = load_fer2013_csv(path)
        class_names = FER2013_CLASSES
        training = usage == "Training"
        validation = usage == "PublicTest"
        if not training.any():
            raise ValueError(f"{path}: no rows with Usage 'Training'")
        if not validation.any():
            held_out = _split_per_class(labels[training], val_fraction, seed)
            index = np.flatnonzero(training)
            validation = np.zeros(len(labels), dtype=bool)
            validation[index[held_out]] = True
            training[index[held_out]] = False
        train, valid = (faces[training], labels[training]), (faces[validation], labels[validation])
    elif (path / "train").is_dir() and (path / "test").is_dir():
        train_faces, train_labels, class_names = load_image_folder(path / "train")
        test_faces, test_labels, _ = load_image_folder(path / "test", class_names)
        train, valid = (train_faces, train_labels), (test_faces, test_labels)
    elif path.is_dir():
        faces, labels, class_names = load_image_folder(path)
        held_out = _split_per_class(labels, val_fraction, seed)
        train, valid = (faces[~held_out], labels[~held_out]), (faces[held_out], labels[held_out])
    else:
        raise ValueError(f"data: {path} is neither a FER-2013 CSV file nor an image folder")
    if len(valid[0]) == 0 or len(train[0]) == 0:
        raise ValueError(f"data: {path} gives {len(train[0])} training and {len(valid[0])} validation faces; "
                         "both must be non-empty")
    return {"train": train, "validation": valid, "class_names": tuple(class_names)}


def build_augmentation(seed: int = 0) -> SequentialProcessor:
    """Grey-face augmentation: brightness, contrast, horizontal flip, rotation/zoom/shift (paper settings)."""
    return SequentialProcessor([
        ConvertColorSpace("GRAY", "RGB"), RandomBrightness(max_delta=32.0, seed=seed),
        RandomContrast(0.7, 1.3, seed=seed + 1), ConvertColorSpace("RGB", "GRAY"),
        RandomFlipLeftRight(seed=seed + 2),
        RandomAffine(max_rotation_degrees=10.0, max_zoom=0.1, max_shift=0.1, seed=seed + 3),
    ], name="emotion_augmentation")


def resize_faces(faces: np.ndarray, size: int) -> np.ndarray:
    """Resizes ``(N, H, W)`` uint8 faces to ``(N, size, size)`` (area when shrinking, linear when enlarging)."""
    import cv2

    if faces.shape[1:] == (size, size):
        return faces
    interpolation = cv2.INTER_AREA if faces.shape[1] > size else cv2.INTER_LINEAR
    return np.stack([cv2.resize(face, (size, size), interpolation=interpolation) for face in faces])


class BatchSampler:
    """``sampler(step) -> (inputs (B, S, S, 1) float32, targets (B, C) float32)``, deterministic in ``step``;
    targets are one-hot for ``(N,)`` class labels, or the rows of ``(N, C)`` soft labels.

    Each epoch visits the training faces in a seeded permutation; each sample's augmentation is
    reseeded from ``(seed, step, position)`` so a resumed run sees the same batches.
    """

    def __init__(self, faces: np.ndarray, labels: np.ndarray, num_classes: int, batch_size: int,
                 augmentation=None, seed: int = 0):
        if batch_size < 1:
            raise ValueError(f"batch_size: expected a positive integer, got {batch_size}")
        self.faces, self.labels = faces, labels
        self.num_classes, self.batch_size, self.seed = num_classes, batch_size, seed
        self.augmentation = augmentation
        self.random_steps = random_processors(augmentation) if augmentation is not None else []
        self.steps_per_epoch = max(1, len(faces) // batch_size)

    def __call__(self, step: int):
        from paz6d.faces.xception import preprocess_faces

        epoch, position = divmod(int(step), self.steps_per_epoch)
        order = np.random.default_rng([self.seed, epoch]).permutation(len(self.faces))
        index = order[position * self.batch_size:(position + 1) * self.batch_size]
        faces = self.faces[index]
        if self.augmentation is not None:
            augmented = []
            for offset, face in enumerate(faces):
                children = np.random.SeedSequence([self.seed, int(step), offset]).spawn(len(self.random_steps))
                for processor, child in zip(self.random_steps, children):
                    processor.reseed(child)
                augmented.append(self.augmentation(face))
            faces = np.stack(augmented)
        if self.labels.ndim == 2:  # soft targets (FERPlus vote distributions)
            targets = self.labels[index].astype(np.float32)
        else:
            targets = np.eye(self.num_classes, dtype=np.float32)[self.labels[index]]
        return preprocess_faces(faces), targets


def confusion_matrix(true_labels, predicted_labels, num_classes: int) -> np.ndarray:
    """``(C, C)`` int64 counts: row = true class, column = predicted class."""
    true_labels = np.asarray(true_labels, dtype=np.int64)
    predicted_labels = np.asarray(predicted_labels, dtype=np.int64)
    if true_labels.shape != predicted_labels.shape or true_labels.ndim != 1:
        raise ValueError(f"predicted_labels: expected shape {true_labels.shape} like true_labels, "
                         f"got {predicted_labels.shape}")
    for name, values in (("true_labels", true_labels), ("predicted_labels", predicted_labels)):
        if values.size and (values.min() < 0 or values.max() >= num_classes):
            raise ValueError(f"{name}: expected class indices in 0..{num_classes - 1}")
    return np.bincount(true_labels * num_classes + predicted_labels,
                       minlength=num_classes * num_classes).reshape(num_classes, num_classes)


def save_confusion_matrix_plot(matrix: np.ndarray, class_names, path, title: str = "") -> Path:
    """Writes a PNG of the confusion matrix (row-normalised colours, counts written in the cells)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    matrix = np.asarray(matrix)
    rates = matrix / np.maximum(matrix.sum(axis=1, keepdims=True), 1)
    figure, axis = plt.subplots(figsize=(6.4, 5.6))
    image = axis.imshow(rates, cmap="Blues", vmin=0.0, vmax=1.0)
    for row in range(len(matrix)):
        for column in range(len(matrix)):
            axis.text(column, row, str(matrix[row, column]), ha="center", va="center",
                      color="white" if rates[row, column] > 0.5 else "black", fontsize=9)
    axis.set_xticks(range(len(class_names)), class_names, rotation=45, ha="right")
    axis.set_yticks(range(len(class_names)), class_names)
    axis.set_xlabel("predicted")
    axis.set_ylabel("true")
    accuracy = np.trace(matrix) / max(matrix.sum(), 1)
    axis.set_title(f"{title} accuracy {accuracy:.1%} (n={matrix.sum()})".strip())
    figure.colorbar(image, ax=axis, fraction=0.046, label="fraction of true class")
    figure.tight_layout()
    save_figure_atomically(figure, path)
    plt.close(figure)
    return Path(path)


def predict_classes(model, inputs: np.ndarray, batch_size: int = 256) -> np.ndarray:
    """Arg-max class ``(N,)`` of a Keras classifier over preprocessed inputs ``(N, S, S, 1)``."""
    outputs = [np.asarray(model.predict_on_batch(inputs[start:start + batch_size]))
               for start in range(0, len(inputs), batch_size)]
    return np.concatenate(outputs).argmax(axis=1)


def _append_validation_row(run_dir: Path, step: int, accuracy: float) -> None:
    path = run_dir / VALIDATION_LOG
    rows = []
    if path.exists():
        with path.open(newline="") as handle:
            rows = [row for row in csv.DictReader(handle) if int(row["step"]) < step]
    rows.append({"step": step, "accuracy": f"{accuracy:.6f}"})
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=["step", "accuracy"])
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomically(path, text.getvalue())


def train_emotion(job: EmotionTraining) -> dict:
    """Trains (or resumes) ``job`` and writes ``model.keras``, ``classes.json``, ``metrics.json`` and
    ``confusion_matrix.png`` into ``job.out``; returns the metrics."""
    data = load_emotion_data(job.data, job.val_fraction, job.seed, job.ferplus, job.label_mode)  # before TF: fails fast
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.faces.xception import mini_xception, preprocess_faces
    from paz6d.training.trainer import Trainer

    keras = import_keras()
    keras.utils.set_random_seed(job.seed)
    class_names = data["class_names"]
    train_faces = resize_faces(data["train"][0], job.input_size)
    validation_faces = resize_faces(data["validation"][0], job.input_size)
    validation_inputs = preprocess_faces(validation_faces)
    validation_labels = _hard_labels(data["validation"][1])
    sampler = BatchSampler(train_faces, data["train"][1], len(class_names), job.batch_size,
                           build_augmentation(job.seed) if job.augment else None, job.seed)
    model = mini_xception((job.input_size, job.input_size, 1), len(class_names))
    optimizer = keras.optimizers.Adam(job.learning_rate)
    run_dir = Path(job.out)

    def loss_fn(model, batch):
        inputs, targets = batch
        probabilities = model(inputs, training=True)
        cross_entropy = keras.ops.mean(keras.losses.categorical_crossentropy(targets, probabilities))
        accuracy = keras.ops.mean(keras.ops.cast(
            keras.ops.equal(keras.ops.argmax(probabilities, axis=-1), keras.ops.argmax(targets, axis=-1)), "float32"))
        return {"loss": cross_entropy + keras.ops.sum(model.losses), "cross_entropy": cross_entropy,
                "accuracy": accuracy}

    def validate(model, step: int, png_path: Path) -> np.ndarray:
        matrix = confusion_matrix(validation_labels, predict_classes(model, validation_inputs), len(class_names))
        save_confusion_matrix_plot(matrix, class_names, png_path, title=f"validation, step {step}:")
        _append_validation_row(run_dir, step, float(np.trace(matrix) / matrix.sum()))
        return matrix

    trainer = Trainer(model, optimizer, loss_fn, data=sampler, run_dir=run_dir,
                      steps=job.epochs * sampler.steps_per_epoch, checkpoint_every=job.checkpoint_every,
                      log_every=min(10, sampler.steps_per_epoch), sample_every=max(job.validate_every, 0),
                      sample_callback=validate if job.validate_every > 0 else None,
                      progress=job.progress, compile_step=not job.eager)
    summary = trainer.fit()
    matrix = validate(model, summary.final_step, run_dir / run_files.CONFUSION_PNG)
    save_keras_model_atomically(model, EmotionRunDir.model_path(run_dir))
    write_json_atomically(run_dir / run_files.CLASSES_FILE, list(class_names))
    metrics = {"step": summary.final_step, "validation_accuracy": float(np.trace(matrix) / matrix.sum()),
               "validation_count": int(matrix.sum()), "confusion_matrix": matrix.tolist(),
               "class_names": list(class_names), "train_metrics": summary.metrics}
    write_json_atomically(run_dir / EmotionRunDir.METRICS_FILE, metrics, indent=2)
    print(f"emotion: step {summary.final_step}, validation accuracy {metrics['validation_accuracy']:.3f} "
          f"on {metrics['validation_count']} faces; model in {EmotionRunDir.model_path(run_dir)}")
    return metrics
