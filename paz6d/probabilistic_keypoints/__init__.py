"""Probabilistic keypoints: a 2D Gaussian (mean + Cholesky covariance) per KeypointNet keypoint, trained
with the negative log-likelihood, and covariance-weighted PnP (``paz6d train probabilistic-keypoints``;
see docs/probabilistic_keypoints.md)."""
