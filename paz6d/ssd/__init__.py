"""SSD single-shot object detection (docs/ssd.md): ``model`` (SSD300/SSD512/light builders), ``loss``
(multibox), ``encoding`` (targets, decoding), ``dataset`` (COCO annotations of ``paz6d generate``),
``train`` (``paz6d train ssd``), ``run_dir`` (its files), ``pipeline`` (:class:`DetectSingleShot`) and
``detect`` (``paz6d detect``). Importing this package loads no TensorFlow."""

from __future__ import annotations

from paz6d.method import Method
from paz6d.ssd.run_dir import SSDRunDir


def load_pipeline(run_dir, score_threshold: float = 0.3, flip: bool = False):
    """The run's :class:`~paz6d.ssd.pipeline.DetectSingleShot` (imports TensorFlow)."""
    from paz6d.ssd.pipeline import DetectSingleShot

    return DetectSingleShot(run_dir, score_threshold=score_threshold, flip=flip)


#: The SSD's record in :mod:`paz6d.methods`.
METHOD = Method("ssd", "SSD", SSDRunDir, load_pipeline, task="detection", options=("score_threshold", "flip"))
