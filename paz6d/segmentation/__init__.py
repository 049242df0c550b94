"""Instance segmentation: a crop-then-segment mask head (Mask R-CNN's mask branch on square crops around
detection boxes), trained on ``paz6d generate`` data sets (``paz6d train segmentation``)."""

from __future__ import annotations

from paz6d.method import Method
from paz6d.segmentation.run_dir import SegmentationRunDir


def load_pipeline(run_dir, threshold: float | None = None):
    """The run's :class:`~paz6d.segmentation.pipeline.SegmentInstances` (imports TensorFlow)."""
    from paz6d.segmentation.pipeline import SegmentInstances

    return SegmentInstances(run_dir, threshold)


#: The mask head's record in :mod:`paz6d.methods`.
METHOD = Method("segmentation", "segmentation", SegmentationRunDir, load_pipeline, task="segmentation",
                options=("threshold",))
