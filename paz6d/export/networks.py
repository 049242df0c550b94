"""The network a pipeline runs, per method, as one Keras model to export.

Each method's pipeline calls its network through one named step (``predict``, or ``encode`` for the
AAE); :func:`network_of` builds, from a run directory, the Keras model whose outputs are exactly
what that step's network function returns (:func:`paz6d.<method>.model.inference_function`): the
AAE's encoder, HRNet's heatmaps, the segmenter's sigmoid probabilities, the other networks whole.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from paz6d.run_dirs import RUN_DIR_MODULES, method_of

#: Files of a ``paz6d train emotion`` run directory (no ``run_dir`` module of its own).
EMOTION_FILES = ("model.keras", "classes.json")
#: Every method whose network exports.
METHODS = (*RUN_DIR_MODULES, "emotion")
#: Input value range per method (what its pipeline feeds the network): random test inputs are drawn in it.
INPUT_RANGES = {"aae": (0.0, 1.0), "keypointnet": (0.0, 255.0), "probabilistic-keypoints": (0.0, 255.0),
                "hrnet": (0.0, 255.0), "segmentation": (0.0, 255.0), "ssd": (-2.5, 2.5), "stn": (0.0, 1.0),
                "emotion": (-1.0, 1.0)}
#: Name of the pipeline step that runs the network (``None``: its pipeline has no such step).
STEP_NAMES = {"aae": "encode", "emotion": None}


@dataclass(frozen=True)
class Network:
    """A run's network as its pipeline runs it.

    Attributes:
        method: the method (a key of :data:`INPUT_RANGES`).
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


def run_method(run_dir: str | Path) -> str:
    """The method whose training wrote ``run_dir`` (:func:`paz6d.run_dirs.method_of`, or ``"emotion"``
    for a folder with ``model.keras`` and ``classes.json`` only).

    Raises:
        ValueError: not a run directory of any method (the message names the marker files).
    """
    try:
        return method_of(run_dir)
    except ValueError as error:
        if all((Path(run_dir) / name).is_file() for name in EMOTION_FILES):
            return "emotion"
        raise ValueError(f"--run: {error}; or emotion: {' + '.join(EMOTION_FILES)}") from None


def _loaded(run_dir: Path, method: str):
    """``(model, input_size or None)``: the run's trained Keras model as its ``run_dir`` module reads it."""
    if method == "emotion":
        from paz6d.backend.tensorflow_guard import load_keras_model

        return load_keras_model(run_dir / EMOTION_FILES[0]), None
    loaded = RUN_DIR_MODULES[method].read_model(run_dir)
    if method == "ssd":
        model, detector = loaded
        return model, int(detector["priors"]["input_size"])
    return (loaded[0] if isinstance(loaded, tuple) else loaded), None


def network_of(run_dir: str | Path) -> Network:
    """The network of a run directory of any method in :data:`METHODS` (imports TensorFlow).

    Raises:
        ValueError: not a run directory, or its model is missing or unreadable (naming the file).
    """
    from paz6d.backend.tensorflow_guard import import_keras

    keras = import_keras()
    run_dir = Path(run_dir)
    method = run_method(run_dir)
    model, input_size = _loaded(run_dir, method)
    if method == "aae":
        from paz6d.aae.model import encoder_of

        model = encoder_of(model)
    elif method == "hrnet":
        from paz6d.hrnet.model import OUTPUT_NAME

        model = keras.Model(model.input, model.output[OUTPUT_NAME], name="hrnet_heatmaps")
    elif method == "segmentation":
        model = keras.Model(model.input, keras.layers.Activation("sigmoid")(model.output), name="segmenter")
    shape = tuple(input_size if side is None else int(side) for side in model.input_shape[1:])
    return Network(method, float32_copy(model), shape, INPUT_RANGES[method], STEP_NAMES.get(method, "predict"))


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
