"""Timing helper shared by the inference benchmarks."""

from __future__ import annotations

import time

import numpy as np


def median_seconds(function, repeats: int) -> float:
    """Median seconds of ``repeats`` calls of ``function`` after one warm-up call."""
    function()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return float(np.median(times))
