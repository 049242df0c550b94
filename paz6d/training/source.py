"""Checks shared by the settings of every trainer that learns one object from a mesh or a BOP data set.

Light: standard library only, so the ``paz6d train <method>`` parsers stay cheap.
"""

from __future__ import annotations

import math
from pathlib import Path

from paz6d.backend.paths import check_plain_name
from paz6d.datasets.bop.units import MM_PER_M


def checked_mesh_scale(mesh: Path | None, dataset: Path | None, mesh_scale: float | None, seed: int, workers: int,
                       object_id: int | None, split: str | None) -> float:
    """Validates one object's training source and returns its mesh scale (metres per mesh unit).

    Exactly one of ``mesh`` and ``dataset`` is given; ``mesh_scale`` defaults to 1 for a mesh and to
    0.001 for a data set (BOP meshes are millimetres). ``seed`` and ``workers`` are non-negative,
    ``object_id`` is a BOP id (>= 1) and ``split`` a plain folder name.

    Raises:
        ValueError: naming the setting and what was expected.
    """
    if (mesh is None) == (dataset is None):
        raise ValueError("mesh: expected exactly one of mesh and dataset")
    if mesh_scale is None:
        mesh_scale = 1.0 if dataset is None else 1.0 / MM_PER_M
    if not math.isfinite(mesh_scale) or mesh_scale <= 0:
        raise ValueError(f"mesh_scale: expected a positive factor to metres, got {mesh_scale}")
    if seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed}")
    if workers < 0:
        raise ValueError(f"workers: expected 0 (render in this process) or a number of processes, got {workers}")
    if object_id is not None and object_id < 1:
        raise ValueError(f"object_id: expected a BOP object id (a positive integer), got {object_id}")
    if split is not None:
        check_plain_name(split, "split")
    return float(mesh_scale)
