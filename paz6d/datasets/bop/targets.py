"""BOP'19 estimation targets (``test_targets_bop19.json``): a list of
``{scene_id, im_id, obj_id, inst_count}``, one entry per object of an image."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from paz6d.backend.files import load_json, write_json_atomically

TARGETS_FILE = "test_targets_bop19.json"
#: BOP'19 estimation targets are the instances at least this visible.
TARGET_MIN_VISIBLE_FRACTION = 0.1


@dataclass(frozen=True)
class Target:
    """One BOP'19 estimation target: ``inst_count`` instances of ``obj_id`` in an image."""

    scene_id: int
    im_id: int
    obj_id: int
    inst_count: int


def read_targets(path: str | Path) -> list[Target]:
    """Reads a targets file (``test_targets_bop19.json``), in file order.

    Raises:
        ValueError: naming the file and entry: a missing, negative or non-integer field, a zero
            ``inst_count``, or the same ``(scene_id, im_id, obj_id)`` listed twice (its instances
            would be counted twice and recalls could exceed 1).
    """
    path = Path(path)
    data = load_json(path)
    if not isinstance(data, list):
        raise ValueError(f"{path}: expected a list of targets")
    if not data:
        raise ValueError(f"{path}: holds no targets (expected [{{scene_id, im_id, obj_id, inst_count}}, ...])")
    targets, first_index = [], {}
    for index, entry in enumerate(data):
        values = []
        for name in ("scene_id", "im_id", "obj_id", "inst_count"):
            value = entry.get(name) if isinstance(entry, dict) else None
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{path}: target {index}: field {name!r} must be a non-negative integer, "
                                 f"got {value!r}")
            values.append(value)
        if values[3] == 0:
            raise ValueError(f"{path}: target {index}: field 'inst_count' must be positive")
        key = tuple(values[:3])
        if key in first_index:
            raise ValueError(f"{path}: target {index} repeats target {first_index[key]}: scene {key[0]}, "
                             f"image {key[1]}, object {key[2]} (list each (scene_id, im_id, obj_id) once, "
                             "with inst_count instances)")
        first_index[key] = index
        targets.append(Target(*values))
    return targets


def targets_from_gt(scene_id: int, im_id: int, obj_ids, visib_fracts,
                    min_visible: float = TARGET_MIN_VISIBLE_FRACTION) -> list[Target]:
    """BOP'19 targets of one image: per object (ascending id), the count of its instances with
    ``visib_fract >= min_visible``; objects without such an instance are no target."""
    counts: dict[int, int] = {}
    for obj_id, fraction in zip(obj_ids, visib_fracts):
        if fraction >= min_visible:
            counts[int(obj_id)] = counts.get(int(obj_id), 0) + 1
    return [Target(scene_id, im_id, obj_id, count) for obj_id, count in sorted(counts.items())]


def write_targets(path: str | Path, targets: list[Target]) -> Path:
    """Writes ``targets`` as a BOP targets JSON list (atomically)."""
    return write_json_atomically(path, [asdict(target) for target in targets])
