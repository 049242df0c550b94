"""The record of one method: what the commands and pipelines that use every method need to know of it.

Each method package exports one :class:`Method` as ``METHOD`` (``paz6d/aae/__init__.py`` etc.), and
:mod:`paz6d.methods` lists them. A record loads nothing heavy: its ``load_pipeline`` imports the
pipeline (and TensorFlow) only when called.

Example:
    >>> from paz6d.aae import METHOD
    >>> METHOD.name, METHOD.task, METHOD.run_dir.MARKER_FILES, METHOD.network.step
    ('aae', 'pose', ('config.json', 'codebook.npz'), 'encode')
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from paz6d.run_dir import RunDir

#: What a method's pipeline does: ``pose``: ``pipeline(image, box, *, camera=None, depth=None) -> Pose6D``;
#: ``detection``: ``pipeline(image) -> [Box2D]`` with class names; ``classification`` and ``segmentation``
#: (pipelines that ``paz6d estimate`` and ``DetectAndEstimatePose6D`` do not use).
TASKS = ("pose", "detection", "classification", "segmentation")


@dataclass(frozen=True)
class NetworkSpec:
    """Where a method's runs keep the network its pipeline runs, for ``paz6d export`` (:mod:`paz6d.export`).

    Args:
        load: ``(run_dir) -> Keras model`` whose outputs are exactly what the pipeline's network step
            receives (the AAE's encoder, HRNet's heatmaps, ...); imports TensorFlow when called; raises
            ``ValueError`` naming a missing or unreadable file.
        input_range: ``(low, high)``, the values the pipeline feeds the network (exports are checked on
            random inputs drawn in it).
        step: the name of the pipeline step that runs the network; ``None``: the pipeline calls the model
            itself.
        input_size: ``(run_dir) -> side`` (pixels) given to the free input sides of a network that takes
            any image size (checked at that size); ``None``: the network's input sides are fixed.
    """

    load: Callable[[Path], Any]
    input_range: tuple[float, float]
    step: str | None = "predict"
    input_size: Callable[[Path], int] | None = None

    def __post_init__(self):
        if not callable(self.load) or (self.input_size is not None and not callable(self.input_size)):
            raise ValueError("network: load and input_size: expected callables (run_dir) -> model, side")
        low, high = self.input_range
        if not low < high:
            raise ValueError(f"network: input_range: expected (low, high) with low < high, got {self.input_range}")


@dataclass(frozen=True)
class Method:
    """One method: its name, its run directories and how to load its pipeline from one.

    Args:
        name: as in ``paz6d train <name>`` (``"aae"``).
        label: how messages name the method (``"AAE"``).
        run_dir: its :class:`~paz6d.run_dir.RunDir` subclass.
        load_pipeline: ``(run_dir, **options) -> pipeline``; imports what it needs when called.
        task: one of :data:`TASKS`.
        options: the keyword options ``load_pipeline`` takes (``"camera"``, ``"class_name"``, ...);
            :meth:`load` passes only these, so that one set of options serves every method.
        aliases: other names accepted for it (``paz6d estimate --method keypoints``).
        network: where its runs keep the network its pipeline runs (what ``paz6d export`` writes);
            ``None``: its runs hold no network to export.
    """

    name: str
    label: str
    run_dir: type[RunDir]
    load_pipeline: Callable[..., Any]
    task: str = "pose"
    options: tuple[str, ...] = ("camera", "class_name")
    aliases: tuple[str, ...] = ()
    network: NetworkSpec | None = None

    def __post_init__(self):
        if not self.name or not isinstance(self.name, str):
            raise ValueError(f"name: expected a method name, got {self.name!r}")
        if self.task not in TASKS:
            raise ValueError(f"{self.name}: task: expected one of {TASKS}, got {self.task!r}")
        if not (isinstance(self.run_dir, type) and issubclass(self.run_dir, RunDir)):
            raise ValueError(f"{self.name}: run_dir: expected a RunDir subclass, got {self.run_dir!r}")
        if not self.run_dir.MARKER_FILES:
            raise ValueError(f"{self.name}: run_dir: {self.run_dir.__name__} names no MARKER_FILES")
        if not callable(self.load_pipeline):
            raise ValueError(f"{self.name}: load_pipeline: expected a callable (run_dir, **options) -> pipeline")
        if self.network is not None and not isinstance(self.network, NetworkSpec):
            raise ValueError(f"{self.name}: network: expected a paz6d.method.NetworkSpec, got {self.network!r:.60}")

    def load(self, run_dir: str | Path, **options) -> Any:
        """The pipeline of ``run_dir``, given those of ``options`` that this method takes (the others are
        other methods' options and are left out)."""
        return self.load_pipeline(run_dir, **{key: value for key, value in options.items() if key in self.options})
