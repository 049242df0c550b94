"""The network a run's pipeline runs, as one Keras model to export.

Each method's record says where its runs keep that network (:class:`paz6d.method.NetworkSpec`):
:func:`network_of` finds the method that wrote a run directory in the registry
(:func:`paz6d.methods.method_of`) and loads, through its record, the Keras model whose outputs are exactly
what the pipeline's network step receives. Nothing here names a method.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from paz6d.method import Method
from paz6d.methods import method_of, methods


@dataclass(frozen=True)
class Network:
    """A run's network as its pipeline runs it.

    Attributes:
        method: the name of the method that wrote the run.
        model: Keras model, ``(B, *input_shape) float32 -> array or dict of arrays``.
        input_shape: one input's shape without the batch axis (free sides of a detector that takes any
            image size set to its training input size).
        input_range: the values its pipeline feeds it, ``(low, high)``.
        step: the name of the pipeline step that runs it, or ``None``.
    """

    method: str
    model: Any
    input_shape: tuple[int, ...]
    input_range: tuple[float, float]
    step: str | None


def exporting_methods() -> tuple[Method, ...]:
    """The registered methods whose runs hold a network to export."""
    return tuple(method for method in methods() if method.network is not None)


def run_method(run_dir: str | Path) -> Method:
    """The method whose training wrote ``run_dir`` (:func:`paz6d.methods.method_of`), one whose runs hold a
    network to export.

    Raises:
        ValueError: naming ``--run``: not a run directory of any method (naming the marker files), or one of
            a method without a network.
    """
    try:
        method = method_of(run_dir)
    except ValueError as error:
        raise ValueError(f"--run: {error}") from None
    if method.network is None:
        names = ", ".join(other.name for other in exporting_methods())
        raise ValueError(f"--run: {run_dir} is {method.run_dir.KIND} run directory, whose method has no network to "
                         f"export (methods that have one: {names})")
    return method


def network_of(run_dir: str | Path) -> Network:
    """The network of a run directory of any method in :func:`exporting_methods` (imports TensorFlow).

    Raises:
        ValueError: not such a run directory, or its model is missing or unreadable (naming the file).
    """
    run_dir = Path(run_dir)
    method = run_method(run_dir)
    spec = method.network
    model = spec.load(run_dir)
    side = None if spec.input_size is None else int(spec.input_size(run_dir))
    shape = tuple(side if size is None else int(size) for size in model.input_shape[1:])
    if None in shape:
        raise ValueError(f"{method.name}: the network of {run_dir} takes inputs of any size {model.input_shape}, but "
                         "the method's NetworkSpec gives no input_size to check it at")
    return Network(method.name, float32_copy(model), shape, spec.input_range, spec.step)


def float32_copy(model):
    """``model`` when every layer computes in float32, else a copy of it whose layers all compute in float32,
    with the same weights. A network trained with bfloat16 compute (the AAE's ``precision``) exports this way:
    TFLite has no bfloat16 kernels, and the copy's outputs differ from the bfloat16 network's only by its
    rounding."""
    from paz6d.backend.tensorflow_guard import import_keras

    if all(getattr(layer, "compute_dtype", "float32") == "float32" for layer in model.layers):
        return model

    def as_float32(layer):
        return layer.__class__.from_config({**layer.get_config(), "dtype": "float32"})

    copy = import_keras().models.clone_model(model, clone_function=as_float32)
    copy.set_weights(model.get_weights())
    return copy
