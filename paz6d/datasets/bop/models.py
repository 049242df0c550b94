"""BOP object models: ``models[_eval]/obj_XXXXXX.ply`` meshes and ``models_info.json``
(millimetre files; lengths come back in the units the caller asks for)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paz6d.backend.mesh import load_mesh
from paz6d.datasets.bop.fields import entries_by_id, required_field
from paz6d.datasets.bop.units import Units, lengths_from_mm, units_per_mm

MODELS_INFO = "models_info.json"


@dataclass(frozen=True)
class ModelInfo:
    """``models_info.json`` entry, lengths in the units asked for.

    Attributes:
        diameter: largest distance between two model points.
        minimum: ``(3,)`` corner of the model's axis-aligned box.
        size: ``(3,)`` box extent.
        symmetries_discrete: ``(S, 4, 4)`` symmetry transforms.
        symmetries_continuous: ``[(axis (3,), offset (3,)), ...]``.
    """

    diameter: float
    minimum: np.ndarray | None
    size: np.ndarray | None
    symmetries_discrete: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    symmetries_continuous: list = field(default_factory=list)


def load_models_info(path: str | Path, units: Units = "m") -> dict[int, ModelInfo]:
    """``models_info.json`` → ``{obj_id: ModelInfo}`` with lengths in ``units`` (``"m"`` or ``"mm"``)."""
    path = Path(path)
    result = {}
    for obj_id, entry in entries_by_id(path, "object").items():
        where = f"{path}: object {obj_id}"
        diameter = float(lengths_from_mm(required_field(entry, "diameter", where, 1)[0], units))
        minimum = size = None
        if "min_x" in entry:
            minimum = lengths_from_mm([required_field(entry, f"min_{axis}", where, 1)[0] for axis in "xyz"], units)
            size = lengths_from_mm([required_field(entry, f"size_{axis}", where, 1)[0] for axis in "xyz"], units)
        discrete = []
        for index, values in enumerate(entry.get("symmetries_discrete", [])):
            T = required_field({"value": values}, "value", f"{where}, symmetries_discrete[{index}]", 16).reshape(4, 4)
            T[:3, 3] = lengths_from_mm(T[:3, 3], units)
            discrete.append(T)
        continuous = []
        for index, symmetry in enumerate(entry.get("symmetries_continuous", [])):
            inner = f"{where}, symmetries_continuous[{index}]"
            continuous.append((required_field(symmetry, "axis", inner, 3),
                               lengths_from_mm(required_field(symmetry, "offset", inner, 3), units)))
        result[obj_id] = ModelInfo(diameter, minimum, size, np.array(discrete).reshape(-1, 4, 4), continuous)
    return result


def model_path(models_folder: str | Path, obj_id: int) -> Path:
    """``<models_folder>/obj_XXXXXX.ply``."""
    return Path(models_folder) / f"obj_{obj_id:06d}.ply"


def load_model(models_folder: str | Path, obj_id: int, units: Units = "m"):
    """The PLY model of ``obj_id`` as a ``trimesh.Trimesh`` with vertices in ``units`` (colours kept)."""
    return load_mesh(model_path(models_folder, obj_id), scale=units_per_mm(units))
