"""BOP lengths: files store millimetres; a caller asks for metres (``"m"``, the library's unit) or
millimetres (``"mm"``, BOP evaluation's unit) once, when a file is read or written.

:data:`MM_PER_M` is the only millimetre constant of the project; the converters below are the
only places it multiplies. Converting to metres multiplies by ``1 / MM_PER_M`` (which is exactly
the double nearest 0.001), converting to millimetres multiplies by :data:`MM_PER_M`; asking for
millimetres from a millimetre file multiplies by 1, so those values come back bit-for-bit as stored.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

#: Millimetres per metre.
MM_PER_M = 1000.0
#: Largest value of a 16-bit depth PNG (depth = value x depth_scale millimetres).
DEPTH_PNG_MAX = 65535
#: Length units a BOP reader or writer can hand to its caller.
Units = Literal["m", "mm"]
UNITS = ("m", "mm")


def _checked(units: Units) -> Units:
    if units not in UNITS:
        raise ValueError(f"units: expected one of {UNITS}, got {units!r}")
    return units


def units_per_mm(units: Units) -> float:
    """Factor from BOP millimetres to ``units`` (``"m"``: ``1 / MM_PER_M``; ``"mm"``: 1).

    Raises:
        ValueError: ``units`` is neither ``"m"`` nor ``"mm"`` (all functions here check it).
    """
    return 1.0 / MM_PER_M if _checked(units) == "m" else 1.0


def mm_per_unit(units: Units) -> float:
    """Factor from ``units`` to BOP millimetres (``"m"``: :data:`MM_PER_M`; ``"mm"``: 1)."""
    return MM_PER_M if _checked(units) == "m" else 1.0


def lengths_from_mm(values, units: Units) -> np.ndarray:
    """BOP millimetres (any shape) to ``units``, as float64."""
    return np.asarray(values, dtype=np.float64) * units_per_mm(units)


def mm_from_lengths(values, units: Units) -> np.ndarray:
    """Lengths in ``units`` (any shape) to BOP millimetres, as float64."""
    return np.asarray(values, dtype=np.float64) * mm_per_unit(units)
