"""Data set readers that yield plain dataclasses with arrays in the project's conventions
(metres, OpenCV camera frame, uint8 RGB). ``paz6d.datasets.bop``: BOP-format data sets."""
