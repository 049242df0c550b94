"""paz6d: hierarchical perception for 6D object pose.

Layers: ``paz6d.backend`` (numpy/OpenCV functions) → ``paz6d.processors`` (composable steps) →
``paz6d.pipelines`` (image → messages). Importing paz6d never imports TensorFlow.
"""

__version__ = "0.1.0"
