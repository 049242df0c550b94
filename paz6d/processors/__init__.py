"""Reusable pipeline steps: :class:`~paz6d.abstract.Processor` classes over the backends, one module
per kind of step: ``image`` (loading, resizing, normalization; random augmentation is in
:mod:`paz6d.synthesis.augment`), ``crops`` (square crop around a box and back), ``boxes`` (formats, ``Box2D``),
``keypoints`` (``Keypoints2D``), ``pose`` (PnP, depth from a box, ``Pose6D``), ``predict`` (a model over
batches of crops).

Import the module you need (``from paz6d.processors.pose import SolvePnP``).
"""
