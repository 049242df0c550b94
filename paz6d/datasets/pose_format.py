"""Which 6D-pose data set format a folder holds (BOP, YCB-Video, FAT), and each format's default split.

Light on purpose (standard library only): the ``paz6d train aae|keypointnet`` settings call it while the
command line is built; the readers themselves are :mod:`paz6d.datasets.bop`, :mod:`~paz6d.datasets.ycb_video`
and :mod:`~paz6d.datasets.fat`, and :mod:`paz6d.datasets.pose_crops` turns them into training records.
"""

from __future__ import annotations

from pathlib import Path

POSE_FORMATS = ("bop", "ycb_video", "fat")
#: ``split`` when none is given: BOP's (chosen by the trainer: train_pbr, else train), YCB-Video's
#: image set and FAT's folder.
DEFAULT_SPLITS = {"bop": None, "ycb_video": "train", "fat": "mixed"}


def detect_pose_format(root: str | Path) -> str:
    """``"ycb_video"`` for a folder with ``data/`` (or ``data_syn/``) and ``image_sets/``; ``"fat"`` for one
    with ``mixed/`` or ``single/``, or holding ``_object_settings.json`` itself; else ``"bop"`` (whose
    reader then names what is missing)."""
    root = Path(root)
    if (root / "image_sets").is_dir() and ((root / "data").is_dir() or (root / "data_syn").is_dir()):
        return "ycb_video"
    if (root / "mixed").is_dir() or (root / "single").is_dir() or (root / "_object_settings.json").is_file():
        return "fat"
    return "bop"


def check_pose_split(split: str, dataset_format: str) -> str:
    """``split`` when it is valid for ``dataset_format``: a plain folder / image-set name for BOP and
    YCB-Video, a relative folder path inside the data set for FAT (``mixed/kitchen_0``).

    Raises:
        ValueError: ``"split: expected ..."``.
    """
    if dataset_format not in POSE_FORMATS:
        raise ValueError(f"format: expected one of {POSE_FORMATS}, got {dataset_format!r}")
    if not isinstance(split, str) or not split or "\0" in split or split != split.strip():
        raise ValueError(f"split: expected a split name, got {split!r:.80}")
    if dataset_format == "fat":
        parts = Path(split).parts
        if Path(split).is_absolute() or ".." in parts or "\\" in split:
            raise ValueError(f"split: expected a folder inside the FAT data set (mixed, single, mixed/kitchen_0), "
                             f"got {split!r:.80}")
        return split
    if split.startswith(".") or "/" in split or "\\" in split:
        raise ValueError(f"split: expected a plain folder name (such as test or train_pbr), got {split!r:.80}")
    return split


def checked_pose_source(dataset: Path | None, dataset_format: str | None, dataset_mesh: Path | None,
                        mesh_scale: float | None, object_id: int | None, object_class: str | None,
                        split: str | None) -> tuple[str | None, float | None]:
    """Checks the data-set settings of a pose trainer and returns ``(format, mesh_scale)``: the format
    (detected when None; None without a data set) and the mesh scale to use (an explicit one; else 1 for
    a ``dataset_mesh`` or a YCB-Video model, metres; None for BOP's millimetre default).

    Raises:
        ValueError: naming the setting (``format:``, ``split:``, ``dataset_mesh:``, ``object_class:``,
            ``object_id:``) and what was expected.
    """
    if dataset is None:
        for name, value in (("format", dataset_format), ("dataset_mesh", dataset_mesh), ("object_class", object_class)):
            if value is not None:
                raise ValueError(f"{name}: only with --dataset")
        return None, mesh_scale
    dataset_format = detect_pose_format(dataset) if dataset_format is None else dataset_format
    if dataset_format not in POSE_FORMATS:
        raise ValueError(f"format: expected one of {POSE_FORMATS}, got {dataset_format!r}")
    if split is not None:
        check_pose_split(split, dataset_format)
    if dataset_format == "bop" and object_class is not None:
        raise ValueError("object_class: BOP data sets name their objects by --object-id")
    if dataset_format == "fat" and object_id is not None:
        raise ValueError("object_id: FAT classes have no ids; choose the object with --object-class")
    if dataset_format == "fat" and dataset_mesh is None:
        raise ValueError(f"dataset_mesh: FAT data sets ship no meshes; pass the object's YCB mesh (google_16k "
                         f"textured.obj, metres) with --dataset-mesh ({dataset})")
    if mesh_scale is None and (dataset_mesh is not None or dataset_format != "bop"):
        mesh_scale = 1.0
    return dataset_format, mesh_scale
