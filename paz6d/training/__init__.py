"""Trainers behind ``paz6d train``: a shared checkpoint/resume/logging loop and one module per model."""
