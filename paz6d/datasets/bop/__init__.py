"""The BOP boundary: every BOP file the project reads or writes goes through this package.

Units are chosen once, here. BOP files store millimetres; every reader and writer takes
``units="m"`` (the default: the library works in metres, see ``docs/conventions.md``) or
``units="mm"`` and converts exactly once, when the file is read or written
(:mod:`~paz6d.datasets.bop.units` holds the one constant, :data:`MM_PER_M`). Consumers:

* the library (training data, ``paz6d estimate``, ``paz6d generate``) works in metres:
  :class:`BOPDataset` returns metres, ``write_pose_results(..., units="m")`` and the
  :mod:`~paz6d.datasets.bop.writer` functions take metres;
* BOP evaluation (``evaluation.bop_data``, ``evaluation.bop``) works in millimetres, as the BOP
  toolkit does and as BOP's thresholds are stated (MSSD/ADD as fractions of a diameter in mm,
  VSD's tolerance delta in mm, MSPD in px): it reads ground truth, models, ``models_info.json``
  and results with ``units="mm"``, so those values arrive exactly as stored (no conversion).

Modules:

* :mod:`~paz6d.datasets.bop.units`: :data:`MM_PER_M` and the two converters.
* :mod:`~paz6d.datasets.bop.camera`: ``camera.json`` (:func:`load_camera` → ``Camera``) and
  ``scene_camera.json``.
* :mod:`~paz6d.datasets.bop.scene`: ``scene_gt.json``, ``scene_gt_info.json``, depth and masks.
* :mod:`~paz6d.datasets.bop.models`: model meshes and ``models_info.json``.
* :mod:`~paz6d.datasets.bop.targets`: ``test_targets_bop19.json``.
* :mod:`~paz6d.datasets.bop.results`: BOP'19 results CSV (reader and writer).
* :mod:`~paz6d.datasets.bop.reader`: :class:`BOPDataset` / :class:`BOPScene` samples in metres, and
  :func:`load`: a split as the :class:`~paz6d.datasets.sample.Sample` interface the other loaders share.
* :mod:`~paz6d.datasets.bop.writer`: ``camera.json``, models and the scene JSON entries.

Importing the package loads none of its modules: each name below is imported from its module on
first use, so that reading ``units`` or ``results`` never loads the mesh reader (trimesh) or OpenCV.
"""

from __future__ import annotations

from paz6d.backend.lazy_exports import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "camera": ("SceneCamera", "load_camera", "load_scene_camera"),
    "models": ("ModelInfo", "load_model", "load_models_info", "model_path"),
    "reader": ("BOPDataset", "BOPObject", "BOPSample", "BOPScene", "load"),
    "results": ("PoseResults", "read_pose_results", "write_pose_results"),
    "scene": ("GroundTruthPose", "load_scene_gt", "load_scene_gt_info"),
    "targets": ("Target", "read_targets", "write_targets"),
    "units": ("MM_PER_M",),
})
