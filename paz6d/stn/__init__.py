"""Spatial transformer networks: a differentiable bilinear sampler, an affine localisation network and
a digit classifier with and without them (``paz6d train stn``; see docs/stn.md)."""

from __future__ import annotations

from paz6d.method import Method, NetworkSpec
from paz6d.stn.run_dir import STNRunDir, read_model


def load_pipeline(run_dir):
    """The run's :class:`~paz6d.stn.pipeline.ClassifyDigit` (imports TensorFlow)."""
    from paz6d.stn.pipeline import ClassifyDigit

    return ClassifyDigit(run_dir)


def load_network(run_dir):
    """The run's whole network (grey canvases in 0..1 -> ``logits``, ``probabilities``, ``theta``, ``crop``),
    the network of ``ClassifyDigit``'s ``predict`` step (imports TensorFlow)."""
    return read_model(run_dir)[0]


#: The spatial transformer's record in :mod:`paz6d.methods`.
METHOD = Method("stn", "spatial-transformer", STNRunDir, load_pipeline, task="classification", options=(),
                network=NetworkSpec(load_network, (0.0, 1.0)))
