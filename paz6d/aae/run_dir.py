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
from paz6d.aae.model import load_model
from paz6d.backend.checks import integer_field, number_field
from paz6d.backend.files import load_json_object, load_npz, save_npz_atomically, write_json_atomically

CONFIG_FILE = "config.json"
OBJECT_FILE = "object.npz"
MODEL_FILE = "model.keras"
CODEBOOK_FILE = "codebook.npz"
SUMMARY_FILE = "summary.json"
VIEWS_FILE = "views.npz"
PAIRS_FILE = "pairs.npz"
#: Files without which a run directory cannot estimate poses.
REQUIRED_FILES = (CONFIG_FILE, OBJECT_FILE, MODEL_FILE, CODEBOOK_FILE)
CONFIG_KEYS = ("config", "mesh", "mesh_scale", "seed")
MODEL_CONFIG_KEYS = ("crop_size", "padding")
OBJECT_KEYS = ("hull_points", "surface_points", "diameter", "vertices")
#: Files that mark a directory as an AAE run (see :func:`paz6d.run_dirs.method_of`).
MARKER_FILES = (CONFIG_FILE, CODEBOOK_FILE)



def _directory(run_dir: str | Path) -> Path:
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"run_dir: {run_dir} is not a directory")
    return run_dir


def _required(path: Path) -> Path:
    if not path.is_file():
        raise ValueError(f"{path}: missing; is {path.parent} an AAE run directory (`paz6d train aae`)?")
    return path


def object_path(run_dir: str | Path) -> Path:
    """Where the object geometry is (or will be) saved."""
    return Path(run_dir) / OBJECT_FILE


def config_path(run_dir: str | Path) -> Path:
    """Where the run configuration is (or will be) saved."""
    return Path(run_dir) / CONFIG_FILE


def model_path(run_dir: str | Path) -> Path:
    """Where the autoencoder is (or will be) saved."""
    return Path(run_dir) / MODEL_FILE


def codebook_path(run_dir: str | Path) -> Path:
    """Where the codebook is (or will be) saved."""
    return Path(run_dir) / CODEBOOK_FILE


def views_path(run_dir: str | Path) -> Path:
    """The training cache of on-axis renderings."""
    return Path(run_dir) / VIEWS_FILE


def pairs_path(run_dir: str | Path) -> Path:
    """The training cache of data set crop pairs."""
    return Path(run_dir) / PAIRS_FILE


def write_config(run_dir: str | Path, config: dict[str, Any], mesh: str | Path, mesh_scale: float, seed: int,
                 dataset: str | Path | None, crop_box: str = "obj") -> Path:
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
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return write_json_atomically(run_dir / CONFIG_FILE, {
        "config": dict(config), "mesh": str(Path(mesh).resolve()), "mesh_scale": mesh_scale, "seed": int(seed),
        "dataset": None if dataset is None else str(Path(dataset).resolve()), "crop_box": crop_box}, indent=2)


def read_config(run_dir: str | Path) -> dict[str, Any]:
    """The whole ``config.json`` (see :func:`write_config`), checked for the keys readers use."""
    path = _required(_directory(run_dir) / CONFIG_FILE)
    data = load_json_object(path)
    missing = [key for key in CONFIG_KEYS if key not in data]
    if not missing and isinstance(data["config"], dict):
        missing = [f"config.{key}" for key in MODEL_CONFIG_KEYS if key not in data["config"]]
    elif not missing:
        missing = ["config (an object)"]
    if missing:
        raise ValueError(f"{path}: missing key(s) {missing} of an AAE run configuration")
    integer_field(data["config"], "crop_size", f"{path}: config", minimum=1)
    number_field(data["config"], "padding", f"{path}: config", positive=True)
    number_field(data, "mesh_scale", str(path), positive=True)
    return data


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
    return load_model(_required(model_path(run_dir)))


def write_summary(run_dir: str | Path, summary: dict[str, Any]) -> Path:
    """Writes ``summary.json``."""
    return write_json_atomically(Path(run_dir) / SUMMARY_FILE, summary, indent=2)


def validate(run_dir: str | Path) -> Path:
    """Checks that ``run_dir`` has every file a pipeline needs and readable configuration and geometry.

    Returns:
        ``run_dir`` as a Path.
    """
    run_dir = _directory(run_dir)
    for name in REQUIRED_FILES:
        _required(run_dir / name)
    read_config(run_dir)
    read_object(run_dir)
    return run_dir
