"""Faces: Haar cascade detection, eigen/fisherfaces, emotion (mini-Xception) and head pose."""
