"""HRNet-style 2D keypoint estimation: a multi-resolution network trained on renderings of a mesh with
projected farthest-point keypoints as Gaussian heatmap targets, and its ``(image, box) -> Keypoints2D``
pipeline (see docs/hrnet.md)."""
