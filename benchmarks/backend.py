"""Batched rotation conversions of paz6d.backend.quaternion against scipy's Rotation, same run.

Usage: ``.venv/bin/python benchmarks/backend.py [--count 1000000] [--repeats 7]``

Each operation runs ``repeats`` times alternating with its scipy counterpart; the best time of
each is reported (the least disturbed by other processes) with the ratio scipy / paz6d
(> 1 means paz6d is faster). paz6d's times include its input validation (unit norm,
orthonormality); scipy's include its own (normalization in ``from_quat``).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from paz6d.backend import quaternion


def best_times(ours: Callable[[], object], theirs: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Best wall time (s) of each callable over ``repeats`` alternating runs."""
    ours_best = theirs_best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        ours()
        ours_best = min(ours_best, time.perf_counter() - start)
        start = time.perf_counter()
        theirs()
        theirs_best = min(theirs_best, time.perf_counter() - start)
    return ours_best, theirs_best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000, help="rotations per batch")
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    q = Rotation.random(args.count, random_state=0).as_quat()
    matrices = Rotation.from_quat(q).as_matrix()
    points = np.random.default_rng(0).normal(size=(args.count, 3))
    cases = {
        "quaternion -> matrix": (lambda: quaternion.to_rotation_matrix(q),
                                 lambda: Rotation.from_quat(q).as_matrix()),
        "matrix -> quaternion": (lambda: quaternion.from_rotation_matrix(matrices),
                                 lambda: Rotation.from_matrix(matrices).as_quat()),
        "rotate points (one rotation each)": (lambda: quaternion.rotate(q, points),
                                              lambda: Rotation.from_quat(q).apply(points)),
    }
    print(f"{args.count:,} rotations, best of {args.repeats}")
    print(f"{'operation':36s} {'paz6d (s)':>10s} {'scipy (s)':>10s} {'scipy/paz6d':>12s}")
    for name, (ours, theirs) in cases.items():
        ours_time, theirs_time = best_times(ours, theirs, args.repeats)
        print(f"{name:36s} {ours_time:10.4f} {theirs_time:10.4f} {theirs_time / ours_time:11.2f}x")


if __name__ == "__main__":
    main()
