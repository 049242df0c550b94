"""The AAE run directory: the only module that knows its file names and formats.

``paz6d train aae`` writes, and :class:`~paz6d.aae.pipeline.ImplicitPose6D`, the demo and
``paz6d estimate`` read::

    RUN_DIR/config.json    {"config": {... "crop_size", "padding" ...}, "mesh", "mesh_scale", "seed", "dataset",
                            "crop_box"}
    RUN_DIR/object.npz     hull_points (M, 3), surface_points (P, 3), diameter, vertices (V, 3); metres
    RUN_DIR/model.keras    the trained autoencoder (native Keras format, loaded in safe mode)
    RUN_DIR/codebook.npz   latent codes of every view x in-plane rotation (:class:`~paz6d.aae.codebook.Codebook`)
    RUN_DIR/summary.json   loss, throughput, timings
    RUN_DIR/views.npz      training cache: clean on-axis renderings on the view sphere
    RUN_DIR/pairs.npz      training cache (with --dataset): data set crops and their clean targets

Every reader raises ``ValueError`` naming the file and what is missing or malformed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from paz6d.aae.codebook import Codebook
from paz6d.aae.config import AAEConfig
from paz6d.aae.model import load_model
from paz6d.backend.checks import integer_field, number_field, short_repr
from paz6d.backend.files import load_json_object, load_npz, save_npz_atomically
from paz6d.datasets.bop.fields import BOX_FIELDS
from paz6d.run_dir import RunDir

OBJECT_FILE = "object.npz"
CODEBOOK_FILE = "codebook.npz"
VIEWS_FILE = "views.npz"
PAIRS_FILE = "pairs.npz"
CONFIG_KEYS = ("config", "mesh", "mesh_scale", "seed")
MODEL_CONFIG_KEYS = ("crop_size", "padding")
OBJECT_KEYS = ("hull_points", "surface_points", "diameter", "vertices")


def _required(path: Path) -> Path:
    if not path.is_file():
        raise ValueError(f"{path}: missing; is {path.parent} an AAE run directory (`paz6d train aae`)?")
    return path


class AAERunDir(RunDir):
    """A ``paz6d train aae`` run directory (files in the module docstring); its training summary is
    ``summary.json`` and its ``config.json`` names the mesh in ``mesh``."""

    KIND = "an AAE"
    MARKER_FILES = (RunDir.CONFIG_FILE, CODEBOOK_FILE)
    REQUIRED_FILES = (RunDir.CONFIG_FILE, OBJECT_FILE, RunDir.MODEL_FILE, CODEBOOK_FILE)
    METRICS_FILE = "summary.json"
    MESH_FIELDS = ("mesh", "mesh_scale")

    @classmethod
    def check_files(cls, run_dir: str | Path) -> Path:
        """``run_dir`` as a Path, checked to be a directory holding every one of :attr:`REQUIRED_FILES`."""
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise ValueError(f"run_dir: {run_dir} is not a directory")
        for name in cls.REQUIRED_FILES:
            _required(run_dir / name)
        return run_dir

    @classmethod
    def write_config(cls, run_dir: str | Path, config: dict[str, Any], mesh: str | Path, mesh_scale: float,
                     seed: int, dataset: str | Path | None, crop_box: str = "obj") -> Path:
        """Writes ``config.json`` (creating ``run_dir``).

        Args:
            config: the model/training settings (``AAEConfig.to_dict()``), with ``crop_size`` and ``padding``.
            mesh: the object's mesh; mesh_scale: mesh units to metres; seed: the run's seed;
            dataset: the BOP data set whose crops were training inputs, or None.
            crop_box: the box the data set's input crops were cut around (``"obj"`` or ``"visib"``).
        """
        missing = [key for key in MODEL_CONFIG_KEYS if key not in config]
        if missing:
            raise ValueError(f"config: missing key(s) {missing} the pipeline needs")
        return super().write_config(run_dir, {
            "config": dict(config), "mesh": str(Path(mesh).resolve()), "mesh_scale": mesh_scale, "seed": int(seed),
            "dataset": None if dataset is None else str(Path(dataset).resolve()), "crop_box": crop_box})

    @classmethod
    def check_config(cls, config: dict[str, Any], path: Path) -> dict[str, Any]:
        """``config.json`` checked: its keys, every model/training setting (:meth:`AAEConfig.from_dict
        <paz6d.aae.config.AAEConfig.from_dict>`), ``mesh_scale``, ``seed``, ``dataset`` and ``crop_box``."""
        missing = [key for key in CONFIG_KEYS if key not in config]
        if not missing and isinstance(config["config"], dict):
            missing = [f"config.{key}" for key in MODEL_CONFIG_KEYS if key not in config["config"]]
        elif not missing:
            missing = ["config (an object)"]
        if missing:
            raise ValueError(f"{path}: missing key(s) {missing} of an AAE run configuration")
        try:
            AAEConfig.from_dict(config["config"])
        except ValueError as error:
            raise ValueError(f"{path}: config: {error}") from None
        number_field(config, "mesh_scale", str(path), positive=True)
        integer_field(config, "seed", str(path))
        if config.get("dataset") is not None and not isinstance(config["dataset"], str):
            raise ValueError(f"{path}: field 'dataset' must be the path of a data set or null, got "
                             f"{short_repr(config['dataset'])}")
        if config.get("crop_box", "obj") not in BOX_FIELDS:
            raise ValueError(f"{path}: field 'crop_box' must be one of {sorted(BOX_FIELDS)}, got "
                             f"{short_repr(config['crop_box'])}")
        return config

    @classmethod
    def read_config(cls, run_dir: str | Path) -> dict[str, Any]:
        """The whole ``config.json`` (see :meth:`write_config`), checked by :meth:`check_config`."""
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise ValueError(f"run_dir: {run_dir} is not a directory")
        path = _required(cls.config_path(run_dir))
        return cls.check_config(load_json_object(path), path)

    @classmethod
    def validate(cls, run_dir: str | Path) -> Path:
        """Checks that ``run_dir`` has every file a pipeline needs and readable configuration, geometry and
        codebook.

        Returns:
            ``run_dir`` as a Path.
        """
        run_dir = super().validate(run_dir)
        read_object(run_dir)
        read_codebook(run_dir)
        return run_dir


def object_path(run_dir: str | Path) -> Path:
    """Where the object geometry is (or will be) saved."""
    return Path(run_dir) / OBJECT_FILE


def codebook_path(run_dir: str | Path) -> Path:
    """Where the codebook is (or will be) saved."""
    return Path(run_dir) / CODEBOOK_FILE


def views_path(run_dir: str | Path) -> Path:
    """The training cache of on-axis renderings."""
    return Path(run_dir) / VIEWS_FILE


def pairs_path(run_dir: str | Path) -> Path:
    """The training cache of data set crop pairs."""
    return Path(run_dir) / PAIRS_FILE


def write_object(run_dir: str | Path, hull_points, surface_points, diameter: float, vertices) -> Path:
    """Writes ``object.npz``: convex-hull vertices ``(M, 3)``, surface samples ``(P, 3)``, diameter and
    mesh vertices ``(V, 3)``, all metres."""
    return save_npz_atomically(Path(run_dir) / OBJECT_FILE, hull_points=np.asarray(hull_points, dtype=np.float64),
                               surface_points=np.asarray(surface_points, dtype=np.float64),
                               diameter=float(diameter), vertices=np.asarray(vertices, dtype=np.float64))


def read_object(run_dir: str | Path) -> dict[str, np.ndarray | float]:
    """``{"hull_points", "surface_points", "vertices"}`` ``(N, 3)`` arrays and ``"diameter"`` (metres)."""
    path = _required(Path(run_dir) / OBJECT_FILE)
    fields = load_npz(path, "object geometry")
    missing = [key for key in OBJECT_KEYS if key not in fields]
    if missing:
        raise ValueError(f"{path}: missing key(s) {missing} of the object geometry")
    for key in ("hull_points", "surface_points", "vertices"):
        if fields[key].ndim != 2 or fields[key].shape[1] != 3 or not np.all(np.isfinite(fields[key])):
            raise ValueError(f"{path}: {key}: expected finite (N, 3) metres, got shape {fields[key].shape}")
    return {**{key: fields[key] for key in ("hull_points", "surface_points", "vertices")},
            "diameter": float(fields["diameter"])}


def read_codebook(run_dir: str | Path) -> Codebook:
    """The run's :class:`~paz6d.aae.codebook.Codebook`."""
    return Codebook.load(_required(codebook_path(run_dir)))


def read_model(run_dir: str | Path):
    """The trained autoencoder (imports TensorFlow)."""
    return load_model(_required(AAERunDir.model_path(run_dir)))
