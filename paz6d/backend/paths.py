"""Checks of paths given by users, creating nothing: plain names (a split, a scene) that must not
reach outside their folder, and output files/folders that must not replace what is not ours.

Standard library only, so command-line settings can use it while the parser is built.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path


def _mode(path: Path, parent_is_file: str) -> int | None:
    """``lstat`` mode of ``path`` (``None`` when nothing is there); ``ValueError(parent_is_file)`` when a
    file stands where one of its folders should be."""
    try:
        return os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    except NotADirectoryError as error:
        raise ValueError(parent_is_file) from error


def _kind(mode: int) -> str:
    """What stands at a path, in words, from its ``lstat`` mode."""
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    return "a file" if stat.S_ISREG(mode) else "a device, FIFO or socket"


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (as a link or anything else)."""
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def check_output_file(path: str | Path, name: str | None = None) -> Path:
    """Checks, creating nothing, that ``path`` may receive an output file: only a missing path or an
    existing regular file may be (re)placed; a symbolic link, folder, device, FIFO or socket at
    ``path`` is refused, as is a file standing where one of its folders should be. Commands call it
    before their long work, so a bad output path fails at once.

    Raises:
        ValueError: naming ``name`` (the flag, when given) and ``path`` and what stands there.
    """
    path = Path(path)
    label = f"{name}: {path}" if name else str(path)
    mode = _mode(path, f"{label}: a parent of this output path is a file, not a folder")
    if mode is not None and not stat.S_ISREG(mode):
        raise ValueError(f"{label}: refusing to replace {_kind(mode)} with an output file; "
                         "give the path of a new or existing regular file")
    existing = _nearest_existing(path.parent)
    if not existing.is_dir():
        raise ValueError(f"{label}: cannot create its folder {path.parent} ({existing} is not a folder)")
    return path


def check_plain_name(value: str, name: str) -> str:
    """``value`` when it is a plain file or folder name (no separator, not ``.``/``..``/hidden, no NUL),
    as BOP split and scene names are; else ``ValueError`` naming ``name``. Keeps such names from
    reaching outside the folder they name something in."""
    if (not isinstance(value, str) or not value or value.startswith(".") or "/" in value or "\\" in value
            or "\0" in value or value != value.strip()):
        raise ValueError(f"{name}: expected a plain folder name (such as test or train_pbr), got {value!r:.80}")
    return value


def path_inside(root: str | Path, value: object, where: str) -> Path:
    """``root / value`` for a relative path ``value`` read from a data set or run directory (a file
    name in an annotation, an image-set id, a checkpoint pointer's ``"path"``), refused unless it
    stays inside ``root``: no absolute path, no ``..`` that climbs out, no empty name or NUL.
    The check is on the path as written (symbolic links that the data set's owner made are followed
    as usual).

    Args:
        root: the data set or run directory the path is relative to.
        value: the path as read from the file (must be a ``str``).
        where: the file, record and field it was read from, for the message
            (``"a.json: images[3].file_name"``).

    Raises:
        ValueError: ``"<where>: expected a relative path inside <root>, got '../x'"``.
    """
    if (not isinstance(value, str) or not value.strip() or "\0" in value or os.path.isabs(value)
            or os.path.normpath(value).split(os.sep)[0] == ".."):
        raise ValueError(f"{where}: expected a relative path inside {root}, got {value!r:.80}")
    return Path(root) / value


def check_output_folder(path: str | Path, name: str) -> Path:
    """``path`` when it may become (or is) an output folder: refused when something other than a
    folder stands there (a file, device, FIFO, or a symbolic link) or in place of one of its
    parents. Creates nothing.

    Raises:
        ValueError: naming ``name`` and ``path``.
    """
    path = Path(path)
    mode = _mode(path, f"{name}: {path}: a parent of this output folder is a file")
    if mode is not None and not stat.S_ISDIR(mode):
        raise ValueError(f"{name}: {path} is {_kind(mode)}, not a folder; give a new or existing folder")
    existing = _nearest_existing(path)
    if not existing.is_dir():
        raise ValueError(f"{name}: {path}: its parent {existing} is not a folder")
    return path


def dataset_layout(folder: str | Path) -> str | None:
    """The kind of data set whose files lie at the top of ``folder`` or that ``folder`` is part of
    (a BOP split or scene folder) (``"BOP"``, ``"COCO"``,
    ``"PASCAL VOC"``, ``"YCB-Video"``, ``"FAT/NDDS"``, ``"Open Images"``, ``"FER-2013"``), or ``None``.
    Looks at a few names only (two folder levels at most), so it is cheap on a large data set."""
    folder = Path(folder)
    if not folder.is_dir():
        return None

    def has(*names: str) -> bool:
        return any(True for name in names for _ in folder.glob(name))

    if has(".paz6d-generate", "camera*.json", "models/models_info.json", "models_eval", "scene_gt.json",
           "scene_camera.json", "*/scene_gt.json", "*/scene_camera.json", "*/*/scene_gt.json",
           "*/*/scene_camera.json"):
        return "BOP"
    if has("annotations/instances_*.json", "annotations/person_keypoints_*.json"):
        return "COCO"
    if (folder / "Annotations").is_dir() and has("JPEGImages", "ImageSets"):
        return "PASCAL VOC"
    if has("VOC20*/Annotations", "image_sets/classes.txt"):
        return "PASCAL VOC" if has("VOC20*/Annotations") else "YCB-Video"
    if has("_object_settings.json", "mixed/*/_object_settings.json", "single/*/*/_object_settings.json"):
        return "FAT/NDDS"
    if has("*-annotations-bbox.csv", "annotations/*-annotations-bbox.csv", "*class-descriptions*.csv"):
        return "Open Images"
    if has("fer2013.csv", "fer2013new.csv"):
        return "FER-2013"
    return None


def _inside(path: str, folder: str) -> bool:
    """True when the real path ``path`` is ``folder`` or lies below it (both from ``os.path.realpath``)."""
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def check_outputs_apart(outputs: dict[str, str | Path | None], inputs: dict[str, str | Path | None]) -> None:
    """Refuses an output path that is also an input or another output (``{flag: path}``; ``None``
    entries are ignored), so a mistyped flag cannot overwrite what the command reads or writes. An
    input that is a folder (a data set, a run directory, an image folder) covers the files in it: an
    output may create a new file there but not replace an existing one. Paths are compared after
    resolving symbolic links.

    Raises:
        ValueError: ``"--out: x.json is also --results; ..."`` or ``"--out: D/scene_gt.json is a file
        of --dataset D, which this command reads; ..."``.
    """
    seen: dict[str, str] = {}
    for name, path in {**inputs, **outputs}.items():
        if path is None:
            continue
        key = os.path.realpath(path)
        if key in seen and name in outputs:
            raise ValueError(f"{name}: {path} is also {seen[key]}; give each output its own path, apart from "
                             "the inputs")
        seen.setdefault(key, name)
    folders = {name: os.path.realpath(path) for name, path in inputs.items()
               if path is not None and os.path.isdir(path)}
    for name, path in outputs.items():
        if path is None or not os.path.lexists(path) or os.path.isdir(path):
            continue
        key = os.path.realpath(path)
        for input_name, folder in folders.items():
            if _inside(key, folder):
                raise ValueError(f"{name}: {path} is a file of {input_name} {inputs[input_name]}, which this "
                                 "command reads; give a new path (outside it or a new name)")


def check_outputs(files: dict[str, str | Path | None], inputs: dict[str, str | Path | None],
                  folders: dict[str, str | Path | None] | None = None) -> None:
    """The output rule of every command, checked before any work starts, creating nothing:

    * each output file (``files``, ``{flag: path}``) is new or an existing regular file
      (:func:`check_output_file`: never a symbolic link, folder, device or FIFO);
    * each output folder (``folders``) is new or an existing folder (:func:`check_output_folder`:
      never a symbolic link), and is not a data set (:func:`dataset_layout`);
    * no output is an input of the call (``inputs``: files and folders the command reads), a file or
      folder inside an input folder, or another output (:func:`check_outputs_apart`).

    Whether an existing output folder belongs to another method is the run directories' business
    (:func:`paz6d.run_dirs.check_run_output`). ``None`` paths are ignored.

    Raises:
        ValueError: naming the flag, the path and what is wrong.
    """
    folders = folders or {}
    for name, path in folders.items():
        if path is None:
            continue
        check_output_folder(path, name)
        kind = dataset_layout(path)
        if kind is not None:
            raise ValueError(f"{name}: {path} holds a {kind} data set; refusing to write into it; give a new folder")
    for name, path in files.items():
        if path is not None:
            check_output_file(path, name)
    check_outputs_apart({**files, **folders}, inputs)
