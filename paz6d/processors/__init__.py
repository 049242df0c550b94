"""Thin :class:`~paz6d.abstract.Processor` classes over the backends, one module per backend:
``image`` (loading, resizing, PAZ photometric augmentation), ``boxes`` (formats, NMS, SSD
encoding), ``keypoints`` (normalization, flipping) and ``pose`` (PnP, projection, ``Pose6D``).

Import the module you need (``from paz6d.processors.image import RandomContrast``).
"""
