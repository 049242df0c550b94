"""The one way paz6d imports TensorFlow.

TensorFlow loads its bundled LLVM with ``RTLD_GLOBAL``; Mesa's llvmpipe (used by OSMesa and
surfaceless EGL) then resolves LLVM symbols against TF's copy and crashes (SIGSEGV). Blocking
``tensorflow.python.pywrap_dlopen_global_flags`` makes TF load its libraries with
``RTLD_LOCAL``, which keeps the two LLVMs apart. This must run before anything imports
TensorFlow (keras included); it is harmless afterwards but then cannot help.
"""

from __future__ import annotations

import os
import sys
import zipfile
from pathlib import Path
from types import ModuleType

_FLAGS_MODULE = "tensorflow.python.pywrap_dlopen_global_flags"


def import_tensorflow(threads: int | None = None) -> ModuleType:
    """Imports TensorFlow with RTLD_LOCAL semantics and returns the module (idempotent).

    Args:
        threads: CPU threads TensorFlow's operations may use (intra- and inter-op pools); None leaves
            TensorFlow's default (every core). Only the first call in a process that runs no operation before
            it can set them.

    Raises:
        RuntimeError: ``threads`` given after TensorFlow started running operations with other settings.
    """
    if "tensorflow" not in sys.modules:
        sys.modules.setdefault(_FLAGS_MODULE, None)
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
        os.environ.setdefault("KERAS_BACKEND", "tensorflow")
        if threads is not None:
            os.environ["OMP_NUM_THREADS"] = str(int(threads))
    import tensorflow

    if threads is not None:
        threading = tensorflow.config.threading
        if (threading.get_intra_op_parallelism_threads(), threading.get_inter_op_parallelism_threads()) != (threads,
                                                                                                           threads):
            try:
                threading.set_intra_op_parallelism_threads(int(threads))
                threading.set_inter_op_parallelism_threads(int(threads))
            except RuntimeError as error:
                raise RuntimeError(f"threads: TensorFlow already runs with its thread pools set up; limit it to "
                                   f"{threads} before it runs anything ({error})") from error
    return tensorflow


def import_keras() -> ModuleType:
    """Imports Keras 3 (TensorFlow backend) after :func:`import_tensorflow`."""
    import_tensorflow()
    import keras

    return keras


def load_keras_model(path: str | Path, error: type[ValueError] = ValueError, *,
                     outputs: tuple[tuple[str, ...], ...] | None = None, kind: str = "a model"):
    """Loads a native ``.keras`` model in safe mode (no Lambda layers, no pickled code), uncompiled.

    Args:
        outputs: the accepted sets of output names (a model with dict outputs); ``None``: any outputs.
        kind: how the error names the expected model (``"a KeypointNet"``).

    Raises:
        error: (a ``ValueError`` subclass) the file is missing, not a ``.keras`` archive, not a model
            Keras can rebuild, or a model with other outputs than ``outputs``; the message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: file not found")
    if not zipfile.is_zipfile(path):
        raise error(f"{path}: not a readable .keras model archive (corrupt or wrong file)")
    keras = import_keras()
    try:
        model = keras.saving.load_model(path, safe_mode=True, compile=False)
    except Exception as cause:  # Keras raises many types for damaged archives
        raise error(f"{path}: not a readable .keras model ({type(cause).__name__}: {cause})") from cause
    if outputs is not None and output_names(model) not in [set(names) for names in outputs]:
        expected = " or ".join(str(sorted(names)) for names in outputs)
        raise error(f"{path}: expected {kind} with outputs {expected}, got {sorted(output_names(model))}")
    return model


def output_names(model) -> set[str]:
    """Names of a Keras model's outputs when they are a dict (an empty set otherwise)."""
    return set(model.output.keys()) if isinstance(model.output, dict) else set()


def compiled_inference(model, output: str | None = None):
    """``model`` compiled for inference: ``images (B, H, W, C) float32 -> outputs`` (``outputs[output]``
    with ``output``), one ``tf.function`` trace for any batch size (``H``, ``W``, ``C``: the model's input;
    a model with free ``H``, ``W`` takes any); several times faster than eager calls."""
    tf = import_tensorflow()
    height, width, channels = model.input_shape[1:4]

    @tf.function(input_signature=[tf.TensorSpec((None, height, width, channels), tf.float32)], reduce_retracing=True)
    def infer(images):
        outputs = model(images, training=False)
        return outputs if output is None else outputs[output]

    return infer
