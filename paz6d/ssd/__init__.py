"""SSD single-shot object detection (docs/ssd.md): ``model`` (SSD300/SSD512/light builders), ``loss``
(multibox), ``encoding`` (targets, decoding), ``dataset`` (COCO annotations of ``paz6d generate``),
``train`` (``paz6d train ssd``), ``run_dir`` (its files), ``pipeline`` (:class:`DetectSingleShot`) and
``detect`` (``paz6d detect``). Importing this package loads no TensorFlow."""

from __future__ import annotations

from paz6d.method import Method, NetworkSpec
from paz6d.ssd.run_dir import SSDRunDir, read_model


def load_pipeline(run_dir, score_threshold: float = 0.3, flip: bool = False, vote_iou: float | None = None):
    """The run's :class:`~paz6d.ssd.pipeline.DetectSingleShot` (imports TensorFlow)."""
    from paz6d.ssd.pipeline import DetectSingleShot

    return DetectSingleShot(run_dir, score_threshold=score_threshold, flip=flip, vote_iou=vote_iou)


def load_network(run_dir):
    """The run's whole network (normalised images -> ``(P, 4 + C)`` box offsets and class scores), the network
    of ``DetectSingleShot``'s ``predict`` step (imports TensorFlow)."""
    return read_model(run_dir)[0]


def training_input_size(run_dir) -> int:
    """The input side (pixels) the run's network was trained at (``detector.json``)."""
    return int(SSDRunDir.read_description(run_dir)["priors"]["input_size"])


#: The SSD's record in :mod:`paz6d.methods`: a detector built for any image size is exported with free sides
#: and checked at its training input size.
METHOD = Method("ssd", "SSD", SSDRunDir, load_pipeline, task="detection",
                options=("score_threshold", "flip", "vote_iou"),
                network=NetworkSpec(load_network, (-2.5, 2.5), input_size=training_input_size))
