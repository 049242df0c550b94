"""Eigenfaces (PCA) and Fisherfaces (PCA + LDA) face recognition in numpy.

Images are equal-size grey ``uint8`` arrays ``(H, W)``; each is flattened to a vector of
``D = H * W`` grey levels. :class:`EigenFaces` finds the principal components of the centred
training vectors with an SVD and recognises a face as the label of the nearest training face in
the projected "face space" (Turk & Pentland 1991). :class:`FisherFaces` first reduces to
``N - C`` principal components and then finds the ``C - 1`` directions that best separate the
``C`` classes (Belhumeur et al. 1997). Both save to ``.npz`` without pickling.

Example:
    >>> model = EigenFaces(n_components=40).fit(train_images, train_labels)
    >>> predicted = model.predict(test_images)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.linalg

from paz6d.backend.files import save_figure_atomically, save_npz_atomically

FORMAT_VERSION = 1
SNAPSHOT_RELATIVE_SINGULAR_VALUE = 1e-6


def as_face_stack(images, name: str = "images", image_shape: tuple[int, int] | None = None) -> np.ndarray:
    """Validates equal-size grey ``uint8`` images and returns them as ``(N, H, W)`` uint8.

    Args:
        images: a sequence of ``(H, W)`` arrays or one ``(N, H, W)`` array.
        name: argument name used in error messages.
        image_shape: required ``(H, W)``, e.g. the shape a model was trained on.
    Raises:
        ValueError: empty input, colour images, unequal sizes, a dtype other than uint8 or a
            shape other than ``image_shape``.
    """
    if isinstance(images, np.ndarray):
        if images.ndim not in (2, 3) or (images.ndim == 3 and images.shape[-1] in (3, 4)):
            raise ValueError(f"{name}: expected grey images as (N, H, W) uint8 (or one (H, W) image), got an array "
                             f"of shape {images.shape}; convert colour images with "
                             "cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)")
        arrays = list(images) if images.ndim == 3 else [images]
    else:
        arrays = [np.asarray(image) for image in images]
    if not arrays:
        raise ValueError(f"{name}: expected at least one image, got none")
    for index, image in enumerate(arrays):
        if image.ndim != 2:
            raise ValueError(f"{name}[{index}]: expected a grey (H, W) image, got shape {image.shape}; "
                             "convert colour images with cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)")
        if image.dtype != np.uint8:
            raise ValueError(f"{name}[{index}]: expected dtype uint8 grey levels, got {image.dtype}")
        if image.size == 0:
            raise ValueError(f"{name}[{index}]: image is empty (shape {image.shape})")
        if image.shape != arrays[0].shape:
            raise ValueError(f"{name}: expected images of equal size, got {arrays[0].shape} and "
                             f"{image.shape} (index {index})")
    stack = np.stack(arrays)
    if image_shape is not None and stack.shape[1:] != tuple(image_shape):
        raise ValueError(f"{name}: expected images of shape {tuple(image_shape)} (the training size), "
                         f"got {stack.shape[1:]}")
    return stack


def _as_labels(labels, count: int) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.ndim != 1 or len(labels) != count:
        raise ValueError(f"labels: expected {count} labels of shape ({count},), got shape {labels.shape}")
    if labels.dtype.kind not in "iuU":
        raise ValueError(f"labels: expected integer or string labels, got dtype {labels.dtype}")
    return labels


def _check_count(n_components, maximum: int, what: str) -> int:
    if n_components is None:
        return maximum
    if isinstance(n_components, bool) or not isinstance(n_components, (int, np.integer)) or n_components < 1:
        raise ValueError(f"n_components: expected a positive integer or None, got {n_components!r}")
    if n_components > maximum:
        raise ValueError(f"n_components: at most {maximum} {what} exist for this training set, "
                         f"got {n_components}")
    return int(n_components)


def principal_components(data: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PCA of ``(N, D)`` samples from the SVD ``X = U S V^T`` of the centred data ``X``.

    With fewer samples than dimensions (face images) ``U`` and ``S`` come from the ``N x N`` Gram
    matrix ``X X^T = U S^2 U^T`` and ``V = X^T U S^-1`` (Turk & Pentland's "snapshot" method):
    the same decomposition, faster than LAPACK's SVD of the ``D x N`` matrix (the fit against OpenCV's:
    ``benchmarks/eigenfaces.py``), and far
    less sensitive to BLAS thread oversubscription on a busy machine. Directions whose singular
    value is below ``1e-6`` of the largest (rank deficiency) fall back to the direct SVD.

    Returns:
        ``mean (D,)``, ``components (count, D)`` (orthonormal rows, by decreasing variance) and
        ``variances (count,)`` (eigenvalues of the sample covariance, divisor ``N - 1``).
    """
    mean = data.mean(axis=0)
    centred = data - mean
    divisor = max(len(data) - 1, 1)
    if len(data) < data.shape[1]:
        squared, left_vectors = np.linalg.eigh(centred @ centred.T)
        squared, left_vectors = squared[::-1][:count], left_vectors[:, ::-1][:, :count]
        if squared[-1] > SNAPSHOT_RELATIVE_SINGULAR_VALUE ** 2 * squared[0]:
            components = (centred.T @ left_vectors / np.sqrt(squared)).T
            return mean, components, squared / divisor
    left_vectors, singular_values, _ = np.linalg.svd(centred.T, full_matrices=False)
    return mean, left_vectors[:, :count].T, singular_values[:count] ** 2 / divisor


class _SubspaceRecognizer:
    """Shared parts of a linear-subspace nearest-neighbour face recogniser.

    Subclasses set ``mean_ (D,)``, ``components_ (k, D)`` in :meth:`fit` and call
    :meth:`_store_training`.
    """

    kind = ""

    def __init__(self, n_components: int | None = None):
        if n_components is not None:
            _check_count(n_components, np.iinfo(np.int64).max, "components")
        self.n_components = n_components
        self.mean_: np.ndarray | None = None
        self.components_: np.ndarray | None = None
        self.image_shape: tuple[int, int] | None = None
        self.train_projections_: np.ndarray | None = None
        self.train_labels_: np.ndarray | None = None

    def _require_fitted(self) -> None:
        if self.components_ is None:
            raise ValueError(f"{type(self).__name__}: call fit(images, labels) or load(path) first")

    def _vectors(self, images, name: str = "images") -> np.ndarray:
        self._require_fitted()
        stack = as_face_stack(images, name, self.image_shape)
        return stack.reshape(len(stack), -1).astype(np.float64)

    def _store_training(self, vectors: np.ndarray, labels: np.ndarray) -> None:
        self.train_projections_ = (vectors - self.mean_) @ self.components_.T
        self.train_labels_ = labels

    def project(self, images) -> np.ndarray:
        """Coordinates ``(N, k)`` of the images in the learned subspace."""
        return (self._vectors(images) - self.mean_) @ self.components_.T

    def nearest(self, images) -> tuple[np.ndarray, np.ndarray]:
        """Label ``(N,)`` of the nearest training face and its Euclidean distance ``(N,)`` in the subspace."""
        projections = self.project(images)
        squared = (np.sum(projections ** 2, axis=1)[:, None] - 2.0 * projections @ self.train_projections_.T
                   + np.sum(self.train_projections_ ** 2, axis=1)[None, :])
        index = np.argmin(squared, axis=1)
        distances = np.sqrt(np.maximum(squared[np.arange(len(index)), index], 0.0))
        return self.train_labels_[index], distances

    def predict(self, images) -> np.ndarray:
        """Label ``(N,)`` of the nearest training face in the subspace (1-NN, L2)."""
        return self.nearest(images)[0]

    def save(self, path) -> Path:
        """Writes the model to an ``.npz`` file (no pickled objects) and returns its path."""
        self._require_fitted()
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"path: expected a file name ending in .npz, got {path}")
        return save_npz_atomically(path, kind=np.array(self.kind), format_version=np.array(FORMAT_VERSION),
                                   n_components=np.array(-1 if self.n_components is None else self.n_components),
                                   image_shape=np.array(self.image_shape), **self._arrays())

    def _arrays(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "components": self.components_,
                "train_projections": self.train_projections_, "train_labels": self.train_labels_}

    def _restore(self, data) -> None:
        self.mean_ = data["mean"]
        self.components_ = data["components"]
        self.train_projections_ = data["train_projections"]
        self.train_labels_ = data["train_labels"]

    @classmethod
    def load(cls, path):
        """Reads a model written by :meth:`save` (``allow_pickle=False``)."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"path: model file {path} does not exist")
        try:
            with np.load(path, allow_pickle=False) as data:
                kind = str(data["kind"])
                if kind != cls.kind:
                    raise ValueError(f"{path}: holds a {kind!r} model, expected {cls.kind!r}")
                if int(data["format_version"]) != FORMAT_VERSION:
                    raise ValueError(f"{path}: format_version {int(data['format_version'])}, "
                                     f"expected {FORMAT_VERSION}")
                count = int(data["n_components"])
                model = cls(None if count < 0 else count)
                model.image_shape = tuple(int(value) for value in data["image_shape"])
                model._restore(data)
        except KeyError as error:
            raise ValueError(f"{path}: not a paz6d {cls.kind} model (missing field {error})") from error
        return model


class EigenFaces(_SubspaceRecognizer):
    """Eigenfaces: PCA face space, 1-NN recognition, reconstruction and distance from face space.

    Args:
        n_components: number of principal components ``k`` kept; ``None`` keeps all ``N - 1``
            non-trivial ones (at most ``min(N - 1, D)``).

    Attributes (after ``fit``):
        mean_: ``(D,)`` mean face, grey levels.
        components_: ``(k, D)`` eigenfaces, orthonormal rows sorted by decreasing variance.
        variances_: ``(k,)`` variance (grey levels squared) along each eigenface.
    """

    kind = "eigenfaces"

    def __init__(self, n_components: int | None = None):
        super().__init__(n_components)
        self.variances_: np.ndarray | None = None

    def fit(self, images, labels) -> "EigenFaces":
        """Learns the face space from ``N >= 2`` images and their labels ``(N,)`` (int or str)."""
        stack = as_face_stack(images)
        if len(stack) < 2:
            raise ValueError(f"images: expected at least 2 training images, got {len(stack)}")
        labels = _as_labels(labels, len(stack))
        vectors = stack.reshape(len(stack), -1).astype(np.float64)
        count = _check_count(self.n_components, min(len(stack) - 1, vectors.shape[1]), "principal components")
        self.image_shape = stack.shape[1:]
        self.mean_, self.components_, self.variances_ = principal_components(vectors, count)
        self._store_training(vectors, labels)
        return self

    def reconstruct(self, images) -> np.ndarray:
        """Projection onto the face space and back: ``(N, H, W)`` float64 grey levels."""
        vectors = self._vectors(images)
        weights = (vectors - self.mean_) @ self.components_.T
        return (self.mean_ + weights @ self.components_).reshape((len(vectors),) + self.image_shape)

    def distance_from_face_space(self, images) -> np.ndarray:
        """Root-mean-square residual ``(N,)`` (grey levels per pixel) between images and their reconstructions.

        Faces like the training ones lie close to the face space; other images do not, so a
        threshold on this value tells "face" from "not a face".
        """
        vectors = self._vectors(images)
        reconstructions = self.reconstruct(images).reshape(len(vectors), -1)
        return np.sqrt(np.mean((vectors - reconstructions) ** 2, axis=1))

    def _arrays(self) -> dict[str, np.ndarray]:
        return {**super()._arrays(), "variances": self.variances_}

    def _restore(self, data) -> None:
        super()._restore(data)
        self.variances_ = data["variances"]


class FisherFaces(_SubspaceRecognizer):
    """Fisherfaces: PCA to ``N - C`` dimensions, then LDA to ``k <= C - 1`` discriminant directions.

    Args:
        n_components: number of discriminant directions ``k``; ``None`` keeps ``C - 1``.

    Attributes (after ``fit``):
        mean_: ``(D,)`` mean face, grey levels.
        components_: ``(k, D)`` fisherfaces: the combined PCA+LDA projection (unit-length LDA
            directions in PCA space, so rows have unit norm but are not mutually orthogonal).
        eigenvalues_: ``(k,)`` between/within class scatter ratios of the directions, decreasing.
    """

    kind = "fisherfaces"

    def __init__(self, n_components: int | None = None):
        super().__init__(n_components)
        self.eigenvalues_: np.ndarray | None = None

    def fit(self, images, labels) -> "FisherFaces":
        """Learns the discriminant subspace from images of ``C >= 2`` classes with more images than classes."""
        stack = as_face_stack(images)
        labels = _as_labels(labels, len(stack))
        classes = np.unique(labels)
        if len(classes) < 2 or len(stack) <= len(classes):
            raise ValueError(f"labels: FisherFaces needs at least 2 classes and more images than classes, "
                             f"got {len(stack)} images of {len(classes)} classes")
        vectors = stack.reshape(len(stack), -1).astype(np.float64)
        count = _check_count(self.n_components, len(classes) - 1, "discriminant directions")
        pca_count = min(len(stack) - len(classes), vectors.shape[1])
        mean, pca_components, _ = principal_components(vectors, pca_count)
        reduced = (vectors - mean) @ pca_components.T
        within = np.zeros((pca_count, pca_count))
        between = np.zeros((pca_count, pca_count))
        for label in classes:
            members = reduced[labels == label]
            class_mean = members.mean(axis=0)
            centred = members - class_mean
            within += centred.T @ centred
            between += len(members) * np.outer(class_mean, class_mean)
        eigenvalues, eigenvectors = scipy.linalg.eigh(between, within)
        order = np.argsort(eigenvalues)[::-1][:count]
        # eigh returns within-scatter-normalised directions, which overweight the directions the
        # training set happens to make tight; unit length (OpenCV's choice) generalises better.
        directions = eigenvectors[:, order] / np.linalg.norm(eigenvectors[:, order], axis=0)
        self.image_shape = stack.shape[1:]
        self.mean_ = mean
        self.components_ = directions.T @ pca_components
        self.eigenvalues_ = eigenvalues[order]
        self._store_training(vectors, labels)
        return self

    def _arrays(self) -> dict[str, np.ndarray]:
        return {**super()._arrays(), "eigenvalues": self.eigenvalues_}

    def _restore(self, data) -> None:
        super()._restore(data)
        self.eigenvalues_ = data["eigenvalues"]


def save_eigenface_grid(model: EigenFaces, path, count: int = 15, columns: int = 8) -> Path:
    """Writes a PNG grid: the mean face followed by the first ``count`` eigenfaces (contrast-stretched)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model._require_fitted()
    count = min(count, len(model.components_))
    panels = [("mean face", model.mean_)] + [(f"eigenface {index + 1}", model.components_[index])
                                             for index in range(count)]
    rows = -(-len(panels) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(1.6 * columns, 2.0 * rows), squeeze=False)
    for axis in axes.ravel():
        axis.axis("off")
    for axis, (title, vector) in zip(axes.ravel(), panels):
        axis.imshow(vector.reshape(model.image_shape), cmap="gray")
        axis.set_title(title, fontsize=8)
    figure.tight_layout()
    save_figure_atomically(figure, path)
    plt.close(figure)
    return Path(path)


def reconstruction_errors(model: EigenFaces, images, component_counts) -> np.ndarray:
    """RMS reconstruction error ``(len(component_counts),)`` (grey levels) using the first ``k`` eigenfaces."""
    vectors = model._vectors(images) - model.mean_
    errors = []
    for count in component_counts:
        count = _check_count(int(count), len(model.components_), "fitted components")
        basis = model.components_[:count]
        residual = vectors - (vectors @ basis.T) @ basis
        errors.append(np.sqrt(np.mean(residual ** 2)))
    return np.array(errors)


def save_reconstruction_error_plot(component_counts, error_series: dict[str, np.ndarray], path) -> Path:
    """Writes a PNG of RMS reconstruction error vs number of eigenfaces, one line per named series."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 4))
    for name, errors in error_series.items():
        axis.plot(component_counts, errors, marker="o", markersize=3, label=name)
    axis.set_xlabel("number of eigenfaces")
    axis.set_ylabel("RMS reconstruction error (grey levels)")
    axis.grid(True, alpha=0.3)
    axis.legend()
    figure.tight_layout()
    save_figure_atomically(figure, path)
    plt.close(figure)
    return Path(path)
