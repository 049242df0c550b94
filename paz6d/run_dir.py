"""The run-directory base: what every method's run directory shares.

A run directory is the folder that ``paz6d train <method>`` writes and that the method's pipeline
reads. Each method describes its own in a :class:`RunDir` subclass in ``paz6d/<method>/run_dir.py``
(its file names, the files that mark it, the files a pipeline needs, how messages name it, and the
readers of its method-specific files); this base owns the parts they share::

    RUN_DIR/config.json    the run's settings (a JSON object); most methods also record the training
                           mesh there (``mesh_path`` and ``mesh_scale``, mesh units to metres)
    RUN_DIR/metrics.json   the training summary (a JSON object)
    RUN_DIR/model.keras    the network (loaded in Keras safe mode by the method)

The readers and writers here are class methods taking the run directory (a ``str`` or ``Path``), called on
the method's class (``AAERunDir.read_config(run_dir)``); a method's ``run_dir`` module keeps as plain functions
only the readers and writers of its own files. :class:`DescribedRunDir` is the base of a run described by one JSON
file besides the network, :class:`CropRunDir` that of a keypoint network on box crops.
Every reader raises ``ValueError`` naming the file and what is missing or malformed.

Each file has one validator, run when the run directory is opened: :meth:`RunDir.validate` (a pipeline
opens the run: every file it needs, ``config.json`` through :meth:`RunDir.check_config`, then the
method's own files) and :func:`paz6d.run_dirs.prepare_run_output` (``paz6d train <method>`` opens its
``--out`` to resume: ``config.json`` and the trainer's files, :func:`paz6d.training.checkpoints.check_training_files`).

Example:
    >>> class TinyRunDir(RunDir):
    ...     KIND = "a tiny"
    ...     MARKER_FILES = ("tiny.json",)
    ...     REQUIRED_FILES = ("tiny.json",)
    >>> TinyRunDir.model_path("runs/tiny").name
    'model.keras'
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from paz6d.backend.checks import integer_field, number_field
from paz6d.backend.files import check_run_files, load_json_object, load_run_json, write_json_atomically
from paz6d.training.settings import Settings, recorded_settings


class RunDir:
    """One method's run directory: file names and the readers and writers every method shares.

    Subclasses set :attr:`KIND`, :attr:`MARKER_FILES` and :attr:`REQUIRED_FILES`, extend :meth:`validate`
    with the checks of their own files and implement :meth:`check_config` for the fields of their
    ``config.json``.
    """

    #: How messages name these run directories ("is DIR an AAE run directory?": ``"an AAE"``).
    KIND: ClassVar[str] = "a paz6d"
    #: Files that mark a directory as one of these run directories (see :func:`paz6d.methods.method_of`).
    MARKER_FILES: ClassVar[tuple[str, ...]] = ()
    #: Files without which the method's pipeline cannot run.
    REQUIRED_FILES: ClassVar[tuple[str, ...]] = ()
    CONFIG_FILE: ClassVar[str] = "config.json"
    METRICS_FILE: ClassVar[str] = "metrics.json"
    MODEL_FILE: ClassVar[str] = "model.keras"
    #: The ``config.json`` fields recording the training mesh and its scale to metres (``None``: no mesh).
    MESH_FIELDS: ClassVar[tuple[str, str] | None] = ("mesh_path", "mesh_scale")
    #: The method's typed settings, recorded as the ``"settings"`` object of ``config.json`` (``None``: none).
    SETTINGS: ClassVar[type[Settings] | None] = None

    # -- paths ----------------------------------------------------------------------------------
    @classmethod
    def path_of(cls, run_dir: str | Path, name: str) -> Path:
        """``run_dir / name`` for one of the run directory's file names."""
        return Path(run_dir) / name

    @classmethod
    def config_path(cls, run_dir: str | Path) -> Path:
        """The run's ``config.json``."""
        return Path(run_dir) / cls.CONFIG_FILE

    @classmethod
    def model_path(cls, run_dir: str | Path) -> Path:
        """Where the network is (or will be) saved."""
        return Path(run_dir) / cls.MODEL_FILE

    @classmethod
    def views_path(cls, run_dir: str | Path, name: str) -> Path:
        """The training cache ``views_<name>.npz`` (``train``, ``val``, ...)."""
        return Path(run_dir) / f"views_{name}.npz"

    # -- recognition and checks -----------------------------------------------------------------
    @classmethod
    def is_run_dir(cls, run_dir: str | Path) -> bool:
        """True when ``run_dir`` holds every one of :attr:`MARKER_FILES`."""
        return bool(cls.MARKER_FILES) and all((Path(run_dir) / name).is_file() for name in cls.MARKER_FILES)

    @classmethod
    def check_files(cls, run_dir: str | Path) -> Path:
        """``run_dir`` as a Path, checked to be a directory holding every one of :attr:`REQUIRED_FILES`.

        Raises:
            ValueError: not a directory, or the first missing file ("is DIR <KIND> run directory?").
        """
        return check_run_files(run_dir, cls.REQUIRED_FILES, cls.KIND)

    @classmethod
    def validate(cls, run_dir: str | Path) -> Any:
        """Opens ``run_dir`` for a pipeline: checks that it has every file the pipeline needs and that its
        ``config.json``, when it has one, passes :meth:`check_config`; returns ``run_dir`` as a Path.
        Subclasses call it first, then check their own files (and may return what they read)."""
        run_dir = cls.check_files(run_dir)
        cls.read_config(run_dir)
        return run_dir

    @classmethod
    def class_names(cls, run_dir: str | Path) -> tuple[str, ...] | None:
        """The class names a detector run outputs, read from its files; ``None`` for other methods."""
        return None

    # -- settings and metrics -------------------------------------------------------------------
    @classmethod
    def write_config(cls, run_dir: str | Path, config: dict[str, Any]) -> Path:
        """Writes ``config.json`` (creating ``run_dir``)."""
        Path(run_dir).mkdir(parents=True, exist_ok=True)
        return write_json_atomically(cls.config_path(run_dir), config, indent=2)

    @classmethod
    def check_config(cls, config: dict[str, Any], path: Path) -> dict[str, Any]:
        """The validator of ``config.json``: ``config`` (the file's JSON object) checked field by field;
        returns it. The base checks the recorded ``"settings"`` object, when the run has one, with
        :attr:`SETTINGS`' own checks; a method extends it for its other fields.

        Raises:
            ValueError: naming ``path``, the field and what was expected.
        """
        if cls.SETTINGS is not None and "settings" in config:
            recorded_settings(cls.SETTINGS, path, config)
        return config

    @classmethod
    def read_config(cls, run_dir: str | Path) -> dict[str, Any] | None:
        """The run's settings (checked by :meth:`check_config`), ``None`` when the run has none yet
        (``ValueError`` naming the file when it is not a JSON object or fails the check)."""
        path = cls.config_path(run_dir)
        return cls.check_config(load_json_object(path), path) if path.is_file() else None

    @classmethod
    def write_metrics(cls, run_dir: str | Path, metrics: dict[str, Any]) -> Path:
        """Writes the training summary ``metrics.json``."""
        return write_json_atomically(Path(run_dir) / cls.METRICS_FILE, metrics, indent=2)

    @classmethod
    def read_metrics(cls, run_dir: str | Path) -> dict[str, Any] | None:
        """The training summary of an earlier invocation, ``None`` when there is none (``ValueError``
        naming the file when it is not a JSON object)."""
        path = Path(run_dir) / cls.METRICS_FILE
        return load_json_object(path) if path.is_file() else None

    # -- the training mesh ----------------------------------------------------------------------
    @classmethod
    def training_mesh(cls, run_dir: str | Path) -> tuple[Path, float] | None:
        """``(mesh file, scale to metres)`` the run was trained on, from :attr:`MESH_FIELDS` of its
        ``config.json``; ``None`` when the method or the run records none (the file may be gone since)."""
        if cls.MESH_FIELDS is None:
            return None
        config = cls.read_config(run_dir)
        mesh_field, scale_field = cls.MESH_FIELDS
        if not config or not config.get(mesh_field):
            return None
        mesh, scale = config[mesh_field], config.get(scale_field, 1.0)
        where = Path(run_dir) / cls.CONFIG_FILE
        if not isinstance(mesh, str):
            raise ValueError(f"{where}: field {mesh_field!r} must be the path of a mesh, got {mesh!r:.60}")
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale < float("inf"):
            raise ValueError(f"{where}: field {scale_field!r} must be a positive number, got {scale!r:.60}")
        return Path(mesh), float(scale)

    @classmethod
    def surface_points(cls, run_dir: str | Path, count: int = 2000, seed: int = 0) -> np.ndarray:
        """``(count, 3)`` points (metres, model frame) sampled on the training mesh (for depth refinement).

        Raises:
            ValueError: the run records no mesh, or its file is gone (naming both).
        """
        from paz6d.backend.mesh import load_mesh, sample_points  # here: trimesh, only when a depth image is given

        found = cls.training_mesh(run_dir)
        if found is None or not found[0].is_file():
            field = "mesh_path" if cls.MESH_FIELDS is None else cls.MESH_FIELDS[0]
            raise ValueError(f"{cls.config_path(run_dir)}: {field} {None if found is None else str(found[0])!r} is "
                             f"not a file; depth refinement samples the object's surface from the mesh the run was "
                             f"trained on")
        return sample_points(load_mesh(found[0], found[1]), count, seed)


class DescribedRunDir(RunDir):
    """A run directory described by one JSON file besides the network: :attr:`DESCRIPTION_FILE` (what the
    pipeline needs besides the weights) marks it, it and ``model.keras`` are required, and :meth:`validate`
    returns the description.

    Subclasses set :attr:`DESCRIPTION_FILE` (:attr:`MARKER_FILES` and :attr:`REQUIRED_FILES` follow from it
    unless they set them) and provide :meth:`read_description`.
    """

    #: The JSON file describing the network (``detector.json``, ``classifier.json``, ...).
    DESCRIPTION_FILE: ClassVar[str]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Derives :attr:`MARKER_FILES` and :attr:`REQUIRED_FILES` of a class that sets :attr:`DESCRIPTION_FILE`
        from it, unless the class sets them itself."""
        super().__init_subclass__(**kwargs)
        if "DESCRIPTION_FILE" in vars(cls):
            if "MARKER_FILES" not in vars(cls):
                cls.MARKER_FILES = (cls.DESCRIPTION_FILE,)
            if "REQUIRED_FILES" not in vars(cls):
                cls.REQUIRED_FILES = (cls.DESCRIPTION_FILE, cls.MODEL_FILE)

    @classmethod
    def read_description(cls, run_dir: str | Path) -> dict[str, Any]:
        """:attr:`DESCRIPTION_FILE`, checked field by field (``ValueError`` naming the file and the field
        when it is missing or malformed)."""
        raise NotImplementedError(f"{cls.__name__} does not read its description file")

    @classmethod
    def validate(cls, run_dir: str | Path) -> dict[str, Any]:
        """:meth:`RunDir.validate` (the description and ``model.keras`` present, ``config.json`` checked), then
        the description (:meth:`read_description`); returns it."""
        return cls.read_description(super().validate(run_dir))


class CropRunDir(RunDir):
    """The run directory of a keypoint network on box crops: its ``config.json`` must hold the crop settings
    its pipeline reads, ``input_size`` (crop side, pixels), ``margin`` (crop side / longer box side) and
    ``downsample`` (crop pixels per output cell), and a keypoints file holds the 3D keypoints PnP uses.

    Subclasses set the class attributes of :class:`RunDir` and provide :meth:`read_keypoints`.
    """

    #: Keys of ``config.json`` that the pipeline reads.
    PIPELINE_CONFIG_KEYS: ClassVar[tuple[str, ...]] = ("input_size", "margin", "downsample")

    @classmethod
    def write_config(cls, run_dir: str | Path, config: dict[str, Any]) -> Path:
        """Writes ``config.json`` (creating ``run_dir``); ``config`` must hold the pipeline's keys."""
        missing = [key for key in cls.PIPELINE_CONFIG_KEYS if key not in config]
        if missing:
            raise ValueError(f"config: missing key(s) {missing} the pipeline needs")
        return super().write_config(run_dir, config)

    @classmethod
    def check_config(cls, config: dict[str, Any], path: Path) -> dict[str, Any]:
        """``config`` checked for its settings (:meth:`RunDir.check_config`), ``input_size``, ``margin`` and
        ``downsample``."""
        super().check_config(config, path)
        for name in ("input_size", "downsample"):
            integer_field(config, name, str(path), minimum=1)
        number_field(config, "margin", str(path), positive=True)
        return config

    @classmethod
    def read_config(cls, run_dir: str | Path) -> dict[str, Any]:
        """``config.json`` (required), checked by :meth:`check_config`."""
        path = cls.config_path(run_dir)
        return cls.check_config(load_run_json(path, cls.PIPELINE_CONFIG_KEYS, cls.KIND), path)

    @classmethod
    def read_keypoints(cls, run_dir: str | Path) -> tuple[np.ndarray, Any]:
        """``points_model (N, 3)`` metres (object frame) and what the method keeps with them, from the run's
        keypoints file (``ValueError`` naming the file when it is missing or malformed)."""
        raise NotImplementedError(f"{cls.__name__} does not read its keypoints file")

    @classmethod
    def validate(cls, run_dir: str | Path) -> Path:
        """:meth:`RunDir.validate`, then the run's keypoints file; returns ``run_dir`` as a Path."""
        run_dir = super().validate(run_dir)
        cls.read_keypoints(run_dir)
        return run_dir
