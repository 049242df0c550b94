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
from types import ModuleType

_FLAGS_MODULE = "tensorflow.python.pywrap_dlopen_global_flags"


def import_tensorflow() -> ModuleType:
    """Imports TensorFlow with RTLD_LOCAL semantics and returns the module (idempotent)."""
    if "tensorflow" not in sys.modules:
        sys.modules.setdefault(_FLAGS_MODULE, None)
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
        os.environ.setdefault("KERAS_BACKEND", "tensorflow")
    import tensorflow

    return tensorflow


def import_keras() -> ModuleType:
    """Imports Keras 3 (TensorFlow backend) after :func:`import_tensorflow`."""
    import_tensorflow()
    import keras

    return keras
