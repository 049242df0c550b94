"""Orientation charts: which of the two equivalent poses of a 2-fold symmetric object the keypoints follow.

An object with a 2-fold symmetry ``S`` (a 180° rotation about an axis ``n``, plus a small translation,
as in BOP's ``symmetries_discrete``) looks the same in pose ``T`` and in pose ``T @ S``, so ordered
keypoints cannot be learned from the views alone: the pair losses of discovery would ask for both. The
KeypointNet paper breaks such symmetries with an *orientation network* whose binary output is fed to
the keypoint network. Here that idea is made exact for a 2-fold symmetry:

- ``a`` is a unit vector of the object frame perpendicular to ``n`` (:func:`chart_axis`), so the
  symmetry flips it: ``R_S a = -a``. In the camera frame the pose ``T`` carries it to ``d = R a`` and
  the equivalent pose to ``-d``.
- A *chart* ``c`` in {0, 1, 2} (camera x, y or z) picks, of the two poses, the one with ``d_c >= 0``
  (:func:`canonical_poses`). That choice is continuous in the pose wherever ``|d_c|`` is not small.
- The orientation network predicts the chart ``argmax_c |d_c|`` (:func:`chart_targets`), which is
  the same for both poses (it depends on ``|d|`` only), so it can be learned from the image; there
  ``|d_c| >= 1/sqrt(3)``. The keypoint network gets the chart as input and predicts the keypoints of
  the pose that chart picks, a continuous function of the image for each chart.

Training feeds the true chart, or now and then another chart that is still safe (``|d_c|`` at least
:data:`SAFE_COMPONENT`), so that a wrong prediction near the border between two charts still yields
keypoints of one consistent pose. At inference the network uses its own predicted chart, and every
pose-dependent step (lifting, validation) takes the pose that chart picks.

Numpy only (the network side is in :mod:`paz6d.keypointnet.model`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

#: A chart is offered in training when the axis' component along it is at least this large.
SAFE_COMPONENT = 0.35
CHARTS = 3


def _half_turn_problem(symmetries: np.ndarray) -> str | None:
    """Why ``symmetries (S, 4, 4)`` is not exactly one half turn, or ``None`` when it is."""
    if len(symmetries) != 1:
        return f"the orientation network handles exactly one discrete symmetry (a half turn), got {len(symmetries)}"
    angle = np.degrees(np.arccos(np.clip((np.trace(symmetries[0][:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
    if abs(angle - 180.0) > 5.0:
        return (f"the orientation network needs a half-turn symmetry (180 degrees), "
                f"got a rotation of {angle:.1f} degrees")
    return None


def is_single_half_turn(symmetries: np.ndarray) -> bool:
    """Whether ``symmetries (S, 4, 4)`` (e.g. a BOP object's ``symmetries_discrete``) is exactly one half
    turn, i.e. whether the orientation network applies."""
    return _half_turn_problem(np.asarray(symmetries, np.float64).reshape(-1, 4, 4)) is None


def half_turn_symmetry(symmetries: np.ndarray, where: str) -> np.ndarray:
    """The one 2-fold symmetry ``(4, 4)`` of ``symmetries (S, 4, 4)``.

    Raises:
        ValueError: naming ``where``, when there is not exactly one symmetry or it is not a half turn.
    """
    symmetries = np.asarray(symmetries, np.float64).reshape(-1, 4, 4)
    problem = _half_turn_problem(symmetries)
    if problem is not None:
        raise ValueError(f"{where}: {problem}")
    return symmetries[0]


def mesh_symmetry(mesh_path: str | Path, mesh_scale: float) -> np.ndarray:
    """The half-turn symmetry ``(4, 4)`` of a BOP model ``obj_XXXXXX.ply`` from the ``models_info.json``
    beside it; its translation (millimetres in the file, as the model) times ``mesh_scale`` (the mesh's
    file units to metres), so metres.

    Raises:
        ValueError: naming the file, when the mesh is not a BOP model, there is no models_info.json, or
            the object has no single half-turn symmetry.
    """
    from paz6d.datasets.bop.models import MODELS_INFO, load_models_info

    mesh_path = Path(mesh_path)
    info_path = mesh_path.parent / MODELS_INFO
    stem = mesh_path.stem
    if not (stem.startswith("obj_") and stem[4:].isdigit()):
        raise ValueError(f"{mesh_path}: the orientation network reads the symmetry from models_info.json, so the "
                         f"mesh must be a BOP model named obj_XXXXXX.ply")
    if not info_path.is_file():
        raise ValueError(f"{info_path}: not found; the orientation network needs the object's symmetries_discrete")
    info = load_models_info(info_path, "mm").get(int(stem[4:]))
    if info is None:
        raise ValueError(f"{info_path}: no entry for object {int(stem[4:])}")
    symmetry = half_turn_symmetry(info.symmetries_discrete, f"{info_path}: object {int(stem[4:])}").copy()
    symmetry[:3, 3] *= float(mesh_scale)
    return symmetry


def chart_axis(symmetry: np.ndarray) -> np.ndarray:
    """A unit vector ``a (3,)`` of the object frame perpendicular to the half turn's axis (so that the
    symmetry's rotation maps it to about ``-a``)."""
    rotation = np.asarray(symmetry, np.float64)[:3, :3]
    # The axis n of a half turn: R = 2 n n^T - I, so R + I = 2 n n^T; its largest column is along n.
    plus = rotation + np.eye(3)
    n = plus[:, np.argmax(np.linalg.norm(plus, axis=0))]
    n = n / np.linalg.norm(n)
    helper = np.eye(3)[np.argmin(np.abs(n))]
    a = np.cross(n, helper)
    return a / np.linalg.norm(a)


def axis_in_camera(T_model2cam: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``d = R a``: ``(V, 3)`` for poses ``(V, 4, 4)``."""
    return np.einsum("vij,j->vi", np.asarray(T_model2cam, np.float64)[:, :3, :3], np.asarray(axis, np.float64))


def chart_targets(T_model2cam: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The chart each pose belongs to, ``argmax_c |d_c|``: ``(V,)`` ints in 0..2 (the same for ``T`` and
    ``T @ S``)."""
    return np.argmax(np.abs(axis_in_camera(T_model2cam, axis)), axis=1)


def canonical_poses(T_model2cam: np.ndarray, charts: np.ndarray, symmetry: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Of each pose ``T`` and its equivalent ``T @ S``, the one whose axis component along its chart is
    ``>= 0``: ``(V, 4, 4)``, same dtype as the input."""
    T = np.asarray(T_model2cam)
    d = axis_in_camera(T, axis)
    flip = d[np.arange(len(T)), np.asarray(charts, int)] < 0
    result = T.copy()
    result[flip] = (T[flip].astype(np.float64) @ np.asarray(symmetry, np.float64)).astype(T.dtype)
    return result


def training_charts(T_model2cam: np.ndarray, axis: np.ndarray, rng: np.random.Generator,
                    other_probability: float) -> np.ndarray:
    """Charts fed to the network in training: the true chart, or with ``other_probability`` a random
    other chart whose axis component is at least :data:`SAFE_COMPONENT` (when there is one)."""
    d = np.abs(axis_in_camera(T_model2cam, axis))
    charts = np.argmax(d, axis=1)
    for view in np.flatnonzero(rng.random(len(charts)) < other_probability):
        safe = [c for c in range(CHARTS) if c != charts[view] and d[view, c] >= SAFE_COMPONENT]
        if safe:
            charts[view] = safe[rng.integers(0, len(safe))]
    return charts


def one_hot(charts: np.ndarray) -> np.ndarray:
    """``(V, 3)`` float32 one-hot rows of chart indices."""
    return np.eye(CHARTS, dtype=np.float32)[np.asarray(charts, int)]


@dataclass(frozen=True)
class ChartSymmetry:
    """A half-turn symmetry ``(4, 4)`` (metres, checked) and its chart axis (:func:`chart_axis`)."""

    symmetry: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "symmetry", half_turn_symmetry(self.symmetry, "symmetry"))

    @cached_property
    def axis(self) -> np.ndarray:
        return chart_axis(self.symmetry)

    def for_outputs(self, T_model2cam: np.ndarray, outputs: dict) -> np.ndarray:
        """The poses ``(V, 4, 4)`` that the network's predicted charts (``outputs["chart"]``) pick."""
        return canonical_poses(T_model2cam, np.argmax(np.asarray(outputs["chart"]), axis=1), self.symmetry, self.axis)

    def to_dict(self) -> dict:
        return {"symmetry": self.symmetry.tolist(), "axis": self.axis.tolist()}
