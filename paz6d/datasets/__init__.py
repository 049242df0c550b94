"""Data set readers that yield plain dataclasses with arrays in the project's conventions
(metres, OpenCV camera frame, uint8 RGB, pixel boxes ``x_min, y_min, x_max, y_max``).

* ``paz6d.datasets.bop``: the one BOP boundary (readers, writers, targets, results CSV; millimetre
  files converted once);
* ``voc``, ``coco``, ``openimages``, ``fer2013``, ``ferplus`` (docs/datasets.md) and ``ycb_video``,
  ``fat`` (docs/datasets_pose.md): ``load(root, split, ...)`` returns a lazy
  :class:`~paz6d.datasets.sample.SampleSequence` of :class:`~paz6d.datasets.sample.Sample`.

Nothing is imported here: each loader is imported by its module path.
"""
