"""Data set readers that yield plain dataclasses with arrays in the project's conventions
(metres, OpenCV camera frame, uint8 RGB). ``paz6d.datasets.bop``: the one BOP boundary (readers,
writers, targets, results CSV; millimetre files converted once); ``paz6d.datasets.fer2013``: FER-2013."""
