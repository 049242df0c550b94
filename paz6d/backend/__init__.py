"""Low-level numpy/OpenCV functions, vectorized over leading batch dimensions.

Submodules are imported explicitly (``from paz6d.backend import quaternion``) so that importing
one of them does not pull in the heavier ones (OpenCV, trimesh).
"""
