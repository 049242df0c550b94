"""Checks shared by the settings of every trainer that learns one object from a mesh or a BOP data set, and
the run options of the trainers that render one mesh (:class:`MeshTraining`).

Light: standard library only, so the ``paz6d train <method>`` parsers stay cheap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from paz6d.backend.paths import check_plain_name
from paz6d.cli_options import option
from paz6d.datasets.bop.units import MM_PER_M
from paz6d.training.settings import Settings, run_settings


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


@dataclass
class MeshTraining:
    """One run of a trainer that renders its views of one mesh (``paz6d train hrnet``, ``paz6d train
    probabilistic-keypoints``); each field but ``settings`` is a flag (see :mod:`paz6d.cli_options`). A
    subclass names its presets (:attr:`CONFIGS`) and redeclares ``config`` (their names as choices) and
    ``settings`` (their type)."""

    CONFIGS: ClassVar[dict[str, Settings]] = {}

    out: Path = option(help="run directory (re-run the command to resume)")
    mesh: Path = option(help="object mesh (PLY/OBJ/GLB); training crops are rendered from it")
    mesh_scale: float = option(1.0, "mesh file units to metres (BOP meshes are millimetres: 0.001)")
    config: str = option("quick", "network and schedule size")
    seed: int = option(0, "seed of every random choice (held-out renders use other seeds)")
    workers: int = option(2, "rendering worker processes (0: render in this process)")
    steps: int | None = option(None, "training steps (default: the config's)")
    progress: bool = option(True, "progress bars")
    settings: Settings | None = field(default=None)  # replaces the config's preset (e.g. a tiny network in tests)

    def __post_init__(self):
        self.out, self.mesh = Path(self.out), Path(self.mesh)
        self.mesh_scale = checked_mesh_scale(self.mesh, None, self.mesh_scale, self.seed, self.workers, None, None)
        self.model_config  # checks the preset and the flags

    @property
    def model_config(self) -> Settings:
        """``settings`` (default: the preset ``config``) with ``steps`` applied."""
        return run_settings(self.CONFIGS, self.config, self.settings, steps=self.steps)
