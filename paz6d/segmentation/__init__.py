"""Instance segmentation: a crop-then-segment mask head (Mask R-CNN's mask branch on square crops around
detection boxes), trained on ``paz6d generate`` data sets (``paz6d train segmentation``)."""

from __future__ import annotations

from paz6d.method import Method, NetworkSpec
from paz6d.segmentation.run_dir import SegmentationRunDir, read_model


def load_pipeline(run_dir, threshold: float | None = None):
    """The run's :class:`~paz6d.segmentation.pipeline.SegmentInstances` (imports TensorFlow)."""
    from paz6d.segmentation.pipeline import SegmentInstances

    return SegmentInstances(run_dir, threshold)


def load_network(run_dir):
    """The run's U-Net followed by a sigmoid (crops in 0..255 -> mask probabilities), what the ``predict`` step
    of ``SegmentInstances`` computes (imports TensorFlow)."""
    from paz6d.backend.tensorflow_guard import import_keras

    keras = import_keras()
    model, _ = read_model(run_dir)
    return keras.Model(model.input, keras.layers.Activation("sigmoid")(model.output), name="segmenter")


#: The mask head's record in :mod:`paz6d.methods`.
METHOD = Method("segmentation", "segmentation", SegmentationRunDir, load_pipeline, task="segmentation",
                options=("threshold",), network=NetworkSpec(load_network, (0.0, 255.0)))
