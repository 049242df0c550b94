"""Everything that makes synthetic training images, shared by ``paz6d generate`` (:mod:`data_gen`)
and the trainers (:mod:`paz6d.aae`, :mod:`paz6d.keypointnet`).

* :mod:`~paz6d.synthesis.workers`: one pool of *spawn* render processes (a GL context each).
* :mod:`~paz6d.synthesis.sampling`: rotations, object placement in the image, convex hulls.
* :mod:`~paz6d.synthesis.scene`: one image's objects, distractors and occluders.
* :mod:`~paz6d.synthesis.lighting`: random lights.
* :mod:`~paz6d.synthesis.backgrounds`: procedural backgrounds and crops of background files.
* :mod:`~paz6d.synthesis.occluders`: distractor primitives and 2D occluder polygons.
* :mod:`~paz6d.synthesis.augment`: photometric and geometric augmentation as random processors.

Every random function takes the ``numpy.random.Generator`` it draws from, so an image (or a
sample) depends only on its own seed. Importing this package loads neither GL nor TensorFlow.
"""
