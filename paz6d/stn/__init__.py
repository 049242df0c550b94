"""Spatial transformer networks: a differentiable bilinear sampler, an affine localisation network and
a digit classifier with and without them (``paz6d train stn``; see docs/stn.md)."""
