"""Model builders and classical models.

Keras models live in their own modules and load TensorFlow when imported:
``paz6d.models.aae``, ``paz6d.models.keypointnet``, ``paz6d.models.xception`` (and the AAE's
``paz6d.models.codebook``). The numpy-only eigen/fisherfaces are exported here.
"""

from paz6d.models.eigenfaces import EigenFaces, FisherFaces

__all__ = ["EigenFaces", "FisherFaces"]
