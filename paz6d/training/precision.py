"""Compute precision of a network body: float32, or bfloat16 on CPUs that compute it natively.

One place for the ``precision`` setting every trainer offers (``"auto"``, ``"float32"``, ``"bfloat16"``)
and for the Keras dtype policy a body's layers get from it. With ``"bfloat16"`` a body computes in
bfloat16 with float32 weights (Keras ``mixed_bfloat16``); the layers whose values are compared or
regressed finely (heads, codes, reconstructions) stay float32, as each builder documents.
"""

from __future__ import annotations

from pathlib import Path

from paz6d.backend.tensorflow_guard import import_tensorflow

#: Compute dtypes of a network body.
PRECISIONS = ("float32", "bfloat16")
#: Values of a ``precision`` setting: a compute dtype, or ``"auto"`` (:func:`resolve_precision`).
SETTINGS = ("auto",) + PRECISIONS


def native_bfloat16(cpuinfo: str | Path = "/proc/cpuinfo") -> bool:
    """Whether this CPU computes bfloat16 natively (``avx512_bf16`` or ``amx_bf16`` flags, Linux).

    Elsewhere TensorFlow emulates bfloat16 and a ``"bfloat16"`` model trains slower than float32.
    """
    try:
        flags = Path(cpuinfo).read_text()
    except OSError:
        return False
    return any(flag in flags.split() for flag in ("avx512_bf16", "amx_bf16"))


def check_setting(precision: str, name: str = "precision") -> str:
    """``precision`` unchanged if it is one of :data:`SETTINGS`.

    Raises:
        ValueError: anything else, naming the setting ``name``.
    """
    if precision not in SETTINGS:
        raise ValueError(f"{name}: expected 'auto' or one of {PRECISIONS}, got {precision!r}")
    return precision


def resolve_precision(precision: str) -> str:
    """``"float32"`` or ``"bfloat16"`` for a ``precision`` setting; ``"auto"`` is bfloat16 on CPUs that
    compute it natively (:func:`native_bfloat16`) when TensorFlow sees no GPU, else float32.

    Raises:
        ValueError: anything but ``"auto"`` or one of :data:`PRECISIONS`.
    """
    if precision == "auto":
        gpus = import_tensorflow().config.list_physical_devices("GPU")
        return "bfloat16" if native_bfloat16() and not gpus else "float32"
    return check_setting(precision)


def body_policy(compute_dtype: str) -> str:
    """The Keras dtype policy of a body's layers: ``"mixed_bfloat16"`` for ``"bfloat16"``, else ``"float32"``.

    Raises:
        ValueError: ``compute_dtype`` is not one of :data:`PRECISIONS`.
    """
    if compute_dtype not in PRECISIONS:
        raise ValueError(f"compute_dtype: expected one of {PRECISIONS}, got {compute_dtype!r}")
    return "mixed_bfloat16" if compute_dtype == "bfloat16" else "float32"
