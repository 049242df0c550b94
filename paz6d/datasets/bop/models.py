"""BOP object models: ``models[_eval]/obj_XXXXXX.ply`` meshes and ``models_info.json``
(millimetre files; lengths come back in the units the caller asks for)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from paz6d.backend.mesh import load_mesh, load_ply_vertices
from paz6d.datasets.bop.fields import entries_by_id, number_field, required_field
from paz6d.datasets.bop.scene import nearest_rotation
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


def parse_symmetries(entry: dict, where: str, units: Units = "m") -> tuple[np.ndarray, list]:
    """The symmetry fields of a ``models_info.json`` entry (millimetre offsets), checked.

    Returns:
        ``(discrete, continuous)``: ``(S, 4, 4)`` transforms (translations in ``units``) whose
        rotation parts are (rounded) rotations, and ``[(axis (3,), offset (3,) in units), ...]``
        with non-zero axes.

    Raises:
        ValueError: ``"<where>, symmetries_discrete[i]: ..."`` and the like.
    """
    discrete_values = entry.get("symmetries_discrete", [])
    if not isinstance(discrete_values, list):
        raise ValueError(f"{where}: field 'symmetries_discrete' must be a list of 16-number transforms")
    discrete = []
    for index, values in enumerate(discrete_values):
        inner = f"{where}, symmetries_discrete[{index}]"
        T = required_field({"symmetries_discrete": values}, "symmetries_discrete", inner, 16).reshape(4, 4)
        nearest_rotation(T[:3, :3], inner)
        if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-6:
            raise ValueError(f"{inner}: the last row of a 4x4 transform must be 0 0 0 1, got {T[3].tolist()}")
        T[:3, 3] = lengths_from_mm(T[:3, 3], units)
        discrete.append(T)
    continuous_values = entry.get("symmetries_continuous", [])
    if not isinstance(continuous_values, list):
        raise ValueError(f"{where}: field 'symmetries_continuous' must be a list of {{axis, offset}} objects")
    continuous = []
    for index, symmetry in enumerate(continuous_values):
        inner = f"{where}, symmetries_continuous[{index}]"
        axis = required_field(symmetry, "axis", inner, 3)
        if not np.linalg.norm(axis) > 0:
            raise ValueError(f"{inner}: field 'axis' must be a non-zero vector, got {axis.tolist()}")
        continuous.append((axis, lengths_from_mm(required_field(symmetry, "offset", inner, 3), units)))
    return np.array(discrete).reshape(-1, 4, 4), continuous


def load_models_info(path: str | Path, units: Units = "m") -> dict[int, ModelInfo]:
    """``models_info.json`` → ``{obj_id: ModelInfo}`` with lengths in ``units`` (``"m"`` or ``"mm"``).

    Raises:
        ValueError: naming the file, object and field: a missing or non-positive diameter, a
            malformed box or symmetry.
    """
    path = Path(path)
    result = {}
    for obj_id, entry in entries_by_id(path, "object").items():
        where = f"{path}: object {obj_id}"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected an object with diameter (and min_x.., symmetries)")
        diameter = float(lengths_from_mm(number_field(entry, "diameter", where, positive=True), units))
        minimum = size = None
        if "min_x" in entry:
            minimum = lengths_from_mm([required_field(entry, f"min_{axis}", where, 1)[0] for axis in "xyz"], units)
            size = lengths_from_mm([required_field(entry, f"size_{axis}", where, 1)[0] for axis in "xyz"], units)
        discrete, continuous = parse_symmetries(entry, where, units)
        result[obj_id] = ModelInfo(diameter, minimum, size, discrete, continuous)
    return result


def model_meshes(models_folder: str | Path) -> dict[int, Path]:
    """``{obj_id: path}`` of the ``obj_XXXXXX.ply`` meshes in a BOP ``models`` folder, by id.

    Raises:
        ValueError: a mesh named ``obj_*.ply`` whose rest is no object id (``obj_abc.ply``), naming it.
    """
    found = {}
    for path in sorted(Path(models_folder).glob("obj_*.ply")):
        digits = path.stem[len("obj_"):]
        if not (digits.isascii() and digits.isdigit()):
            raise ValueError(f"{path}: expected a mesh named obj_<object id>.ply (such as obj_000001.ply)")
        found[int(digits)] = path
    return found


def model_path(models_folder: str | Path, obj_id: int) -> Path:
    """``<models_folder>/obj_XXXXXX.ply``."""
    return Path(models_folder) / f"obj_{obj_id:06d}.ply"


def load_model(models_folder: str | Path, obj_id: int, units: Units = "m"):
    """The PLY model of ``obj_id`` as a ``trimesh.Trimesh`` with vertices in ``units`` (colours kept)."""
    return load_mesh(model_path(models_folder, obj_id), scale=units_per_mm(units))


def load_model_points(models_folder: str | Path, obj_id: int, units: Units = "m") -> np.ndarray:
    """The ``(N, 3)`` vertices of ``obj_id``'s PLY model in ``units``, without building a mesh: the
    vertices of ``load_model(...)`` in the same order (bit for bit in ``"mm"``, as stored); see
    :func:`paz6d.backend.mesh.load_ply_vertices`."""
    return load_ply_vertices(model_path(models_folder, obj_id)) * units_per_mm(units)
