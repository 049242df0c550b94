"""Exporting a Keras model (TensorFlow SavedModel, TFLite, ONNX) and running the exported files.

* ``saved_model``: Keras 3's ``model.export`` (a folder; signature ``serving_default``).
* ``tflite``: ``tf.lite.TFLiteConverter`` from that SavedModel (one ``.tflite`` file, float32).
* ``onnx``: ``tf2onnx`` from a ``tf.function`` of the model (one ``.onnx`` file), run by onnxruntime.

Each exported file runs through an :class:`ExportedModel`: a callable ``inputs (B, ...) float32 ->
array or dict of arrays`` with the Keras model's output structure, so it can stand wherever a pipeline
takes a network function (e.g. :class:`paz6d.processors.predict.Predict`).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from paz6d.abstract.processor import Processor
from paz6d.backend.files import write_bytes_atomically
from paz6d.backend.tensorflow_guard import import_tensorflow

FORMATS = ("saved_model", "tflite", "onnx")
#: What each format writes in the output folder.
FILE_NAMES = {"saved_model": "saved_model", "tflite": "model.tflite", "onnx": "model.onnx"}
#: ONNX opset written by :func:`export_onnx`.
ONNX_OPSET = 17
#: Metadata key of an exported ONNX file that lists the Keras output names in output order.
ONNX_OUTPUT_NAMES = "paz6d_output_names"
ONNX_PACKAGES = "tf2onnx onnx onnxruntime"


class ExportError(ValueError):
    """A format that cannot be written here, or an exported model that does not match the Keras model."""


def output_names(model) -> list[str] | None:
    """The sorted names of a Keras model's dict outputs (``None`` for a single output)."""
    return sorted(model.output) if isinstance(model.output, dict) else None


def export_saved_model(model, path: str | Path) -> Path:
    """Writes ``model`` as a TensorFlow SavedModel folder ``path`` (Keras 3 ``model.export``)."""
    model.export(str(path), format="tf_saved_model", verbose=False)
    return Path(path)


def export_tflite(saved_model: str | Path, path: str | Path) -> Path:
    """Converts a SavedModel folder to a float32 ``.tflite`` file ``path``."""
    tf = import_tensorflow()
    converter = tf.lite.TFLiteConverter.from_saved_model(str(saved_model))
    return write_bytes_atomically(path, converter.convert())


def onnx_modules():
    """``(tf2onnx, onnx)``; :class:`ExportError` when the converter cannot be imported here."""
    try:
        import onnx
        import tf2onnx
    except ImportError as error:  # also a converter built for another numpy / protobuf
        raise ExportError(f"--format onnx: the ONNX converter cannot be imported here ({error}); install "
                          f"{ONNX_PACKAGES} from PyPI (pyproject.toml pins the tested versions)") from error
    return tf2onnx, onnx


def export_onnx(model, path: str | Path) -> Path:
    """Converts ``model`` to an ONNX file ``path`` (opset :data:`ONNX_OPSET`; dict outputs in sorted
    name order, the names kept in the file's metadata).

    Raises:
        ExportError: ``tf2onnx`` or ``onnx`` is not importable, or the conversion fails.
    """
    tf2onnx, onnx = onnx_modules()
    tf = import_tensorflow()
    names = output_names(model)
    spec = (tf.TensorSpec((None, *model.input_shape[1:]), tf.float32, name="input"),)

    @tf.function(input_signature=spec)
    def network(inputs):
        outputs = model(inputs, training=False)
        return [outputs[name] for name in names] if names else outputs

    try:
        proto, _ = tf2onnx.convert.from_function(network, input_signature=spec, opset=ONNX_OPSET)
    except Exception as error:  # the converter raises many types for operations it does not know
        raise ExportError(f"--format onnx: tf2onnx could not convert the network ({type(error).__name__}: "
                          f"{error})") from error
    onnx.helper.set_model_props(proto, {ONNX_OUTPUT_NAMES: json.dumps(names)})
    return write_bytes_atomically(path, proto.SerializeToString())


def export(model, out: str | Path, format: str, work: str | Path) -> Path:
    """Exports ``model`` in ``format`` into folder ``out`` (:data:`FILE_NAMES`); ``work``: a folder for
    the SavedModel that the TFLite converter reads when ``saved_model`` is not also exported."""
    out = Path(out)
    if format == "saved_model":
        return export_saved_model(model, out / FILE_NAMES[format])
    if format == "tflite":
        saved = out / FILE_NAMES["saved_model"]
        if not saved.is_dir():
            saved = export_saved_model(model, Path(work) / FILE_NAMES["saved_model"])
        return export_tflite(saved, out / FILE_NAMES[format])
    if format == "onnx":
        return export_onnx(model, out / FILE_NAMES[format])
    raise ExportError(f"--format: unknown format {format!r}; expected one of {', '.join(FORMATS)}")


class ExportedModel(Processor):
    """An exported network as a function ``inputs (B, ...) float32 -> array (B, ...)`` or ``{name: array}``."""

    def call(self, inputs) -> np.ndarray | dict[str, np.ndarray]:
        return self.run(np.ascontiguousarray(inputs, dtype=np.float32))

    def run(self, inputs: np.ndarray) -> np.ndarray | dict[str, np.ndarray]:
        raise NotImplementedError


class SavedModelFunction(ExportedModel):
    """A SavedModel folder's ``serving_default`` signature."""

    def __init__(self, path: str | Path, name: str | None = None):
        super().__init__(name)
        tf = import_tensorflow()
        self.path = Path(path)
        if not (self.path / "saved_model.pb").is_file():
            raise ExportError(f"{self.path}: not a SavedModel folder (no saved_model.pb)")
        self.module = tf.saved_model.load(str(self.path))
        self.function = self.module.signatures["serving_default"]
        self.input_name = next(iter(self.function.structured_input_signature[1]))
        self.single = list(self.function.structured_outputs) == ["output_0"]

    def run(self, inputs: np.ndarray) -> np.ndarray | dict[str, np.ndarray]:
        outputs = {key: value.numpy() for key, value in self.function(**{self.input_name: inputs}).items()}
        return outputs["output_0"] if self.single else outputs


class TFLiteFunction(ExportedModel):
    """A ``.tflite`` file run by TensorFlow's TFLite interpreter (its ``serving_default`` signature;
    the batch size follows the inputs).

    Args:
        path: the file.
        threads: interpreter threads.
    """

    def __init__(self, path: str | Path, threads: int = 1, name: str | None = None):
        super().__init__(name)
        tf = import_tensorflow()
        self.path = Path(path)
        if not self.path.is_file():
            raise ExportError(f"{self.path}: TFLite file not found")
        with warnings.catch_warnings():  # tf.lite.Interpreter announces its move to the ai_edge_litert package
            warnings.simplefilter("ignore", UserWarning)
            try:
                self.interpreter = tf.lite.Interpreter(model_path=str(self.path), num_threads=int(threads))
            except ValueError as error:
                raise ExportError(f"{self.path}: not a readable TFLite model ({error})") from error
        signature = self.interpreter.get_signature_list()["serving_default"]
        self.input_name = signature["inputs"][0]
        self.single = signature["outputs"] == ["output_0"]
        self.runner = self.interpreter.get_signature_runner("serving_default")

    def run(self, inputs: np.ndarray) -> np.ndarray | dict[str, np.ndarray]:
        outputs = self.runner(**{self.input_name: inputs})
        if self.single:
            return np.array(outputs["output_0"])
        return {key: np.array(value) for key, value in outputs.items()}


class OnnxFunction(ExportedModel):
    """A ``.onnx`` file run by onnxruntime (CPU).

    Args:
        path: the file written by :func:`export_onnx`.
        threads: intra-op threads.
    """

    def __init__(self, path: str | Path, threads: int = 1, name: str | None = None):
        super().__init__(name)
        try:
            import onnxruntime
        except ImportError as error:
            raise ExportError(f"onnx: onnxruntime cannot be imported here ({error}); install {ONNX_PACKAGES}") \
                from error
        self.path = Path(path)
        if not self.path.is_file():
            raise ExportError(f"{self.path}: ONNX file not found")
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = int(threads)
        try:
            self.session = onnxruntime.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own exception types for unreadable files
            raise ExportError(f"{self.path}: not a readable ONNX model ({type(error).__name__}: {error})") from error
        self.input_name = self.session.get_inputs()[0].name
        metadata = self.session.get_modelmeta().custom_metadata_map
        self.names = json.loads(metadata.get(ONNX_OUTPUT_NAMES, "null"))

    def run(self, inputs: np.ndarray) -> np.ndarray | dict[str, np.ndarray]:
        outputs = self.session.run(None, {self.input_name: inputs})
        return dict(zip(self.names, outputs)) if self.names else outputs[0]


#: The runner of each format.
RUNNERS = {"saved_model": SavedModelFunction, "tflite": TFLiteFunction, "onnx": OnnxFunction}


def load_exported(path: str | Path, format: str, threads: int = 1) -> ExportedModel:
    """The :class:`ExportedModel` of an exported file or folder of ``format``."""
    if format not in RUNNERS:
        raise ExportError(f"format: unknown format {format!r}; expected one of {', '.join(FORMATS)}")
    return RUNNERS[format](path) if format == "saved_model" else RUNNERS[format](path, threads)
