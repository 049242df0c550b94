"""Eigenfaces/Fisherfaces training and recognition: paz6d (numpy) vs OpenCV's ``cv2.face`` recognizers.

Usage: ``python benchmarks/eigenfaces.py [--data ../shared/data/faces/orl] [--repeats 5] [--components 40]``.
ORL, 200 training and 200 test images (92x112). Each repeat times both sides back to back; the best
time of each is kept and the ratio OpenCV / paz6d printed (> 1: paz6d faster).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from paz6d.faces.eigenfaces import EigenFaces, FisherFaces

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "faces" / "orl"


def best_time(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--components", type=int, default=40)
    args = parser.parse_args()
    if not (args.data / "s1" / "1.pgm").is_file():
        raise SystemExit(f"ORL faces not found in {args.data}")
    faces = np.stack([cv2.imread(str(args.data / f"s{subject}" / f"{index}.pgm"), cv2.IMREAD_GRAYSCALE)
                      for subject in range(1, 41) for index in range(1, 11)])
    labels = np.repeat(np.arange(1, 41), 10).astype(np.int32)
    train = np.tile(np.arange(10) < 5, 40)
    train_faces, train_labels, test_faces = faces[train], labels[train], faces[~train]
    cases = (("Eigenfaces", lambda: EigenFaces(args.components),
              lambda: cv2.face.EigenFaceRecognizer_create(num_components=args.components)),
             ("Fisherfaces", lambda: FisherFaces(), lambda: cv2.face.FisherFaceRecognizer_create()))
    print("| method | step | paz6d [s] | OpenCV [s] | OpenCV / paz6d |")
    print("|---|---|---:|---:|---:|")
    for name, ours_factory, theirs_factory in cases:
        ours, theirs = ours_factory(), theirs_factory()
        fit_ours = best_time(lambda: ours.fit(train_faces, train_labels), args.repeats)
        fit_theirs = best_time(lambda: theirs.train(list(train_faces), train_labels), args.repeats)
        predict_ours = best_time(lambda: ours.predict(test_faces), args.repeats)
        predict_theirs = best_time(lambda: [theirs.predict(face) for face in test_faces], args.repeats)
        agreement = np.mean(ours.predict(test_faces) == np.array([theirs.predict(face)[0] for face in test_faces]))
        print(f"| {name} | fit 200 | {fit_ours:.3f} | {fit_theirs:.3f} | {fit_theirs / fit_ours:.2f}x |")
        print(f"| {name} | predict 200 | {predict_ours:.4f} | {predict_theirs:.4f} | "
              f"{predict_theirs / predict_ours:.2f}x |  (agreement {agreement:.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
