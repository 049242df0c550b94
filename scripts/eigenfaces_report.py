"""ORL face recognition with paz6d's Eigenfaces/Fisherfaces: accuracy vs components, agreement with OpenCV, plots.

Usage: ``python scripts/eigenfaces_report.py [--data ../shared/data/faces/orl] [--out docs/images] [--splits 10]``.
Writes ``eigenfaces_grid.png``, ``eigenfaces_reconstruction_error.png``, ``eigenfaces_accuracy.png`` and
``eigenfaces_metrics.json`` to ``--out`` and prints a Markdown table.

Protocol: for each seeded split, 5 random images of each of the 40 subjects train and the other 5 test;
the "fixed" split trains on images 1-5 and tests on 6-10.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from paz6d.faces.eigenfaces import (EigenFaces, FisherFaces, reconstruction_errors, save_eigenface_grid,
                                     save_reconstruction_error_plot)

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "faces" / "orl"
COMPONENTS = (5, 10, 20, 40, 80, 120, 160, 199)


def load_orl(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """``faces (400, 112, 92) uint8`` and subject labels ``(400,)`` from ``root/s<k>/<i>.pgm``."""
    if not (root / "s1" / "1.pgm").is_file():
        raise ValueError(f"data: {root} is not the ORL folder (expected s1/1.pgm ... s40/10.pgm)")
    faces = [cv2.imread(str(root / f"s{subject}" / f"{index}.pgm"), cv2.IMREAD_GRAYSCALE)
             for subject in range(1, 41) for index in range(1, 11)]
    return np.stack(faces), np.repeat(np.arange(1, 41), 10)


def split(seed: int | None) -> np.ndarray:
    """Training mask: 5 images per subject (random with ``seed``, or images 1-5 when ``seed`` is None)."""
    if seed is None:
        return np.tile(np.arange(10) < 5, 40)
    rng = np.random.default_rng(seed)
    mask = np.zeros(400, dtype=bool)
    for subject in range(40):
        mask[subject * 10 + rng.permutation(10)[:5]] = True
    return mask


def opencv_predictions(recognizer, train_faces, train_labels, test_faces) -> np.ndarray:
    recognizer.train(list(train_faces), train_labels.astype(np.int32))
    return np.array([recognizer.predict(face)[0] for face in test_faces])


def save_accuracy_plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 4))
    counts = [row["components"] for row in results["eigenfaces"]]
    mean = np.array([row["random_mean"] for row in results["eigenfaces"]])
    low = np.array([row["random_min"] for row in results["eigenfaces"]])
    high = np.array([row["random_max"] for row in results["eigenfaces"]])
    axis.fill_between(counts, low, high, alpha=0.25, label="eigenfaces, min-max over splits")
    axis.plot(counts, mean, marker="o", label="eigenfaces, mean of random splits")
    axis.plot(counts, [row["fixed"] for row in results["eigenfaces"]], marker="s", label="eigenfaces, images 1-5 train")
    fisher = results["fisherfaces"]
    axis.axhline(fisher["random_mean"], color="C3", linestyle="--",
                 label=f"fisherfaces (39 directions), mean {fisher['random_mean']:.3f}")
    axis.set_xscale("log")
    axis.set_xlabel("number of eigenfaces")
    axis.set_ylabel("recognition accuracy (ORL, 5 train / 5 test)")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    parser.add_argument("--splits", type=int, default=10, help="number of seeded random splits")
    args = parser.parse_args()
    faces, labels = load_orl(args.data)
    seeds = list(range(args.splits))
    results: dict = {"splits": args.splits, "eigenfaces": [], "fisherfaces": {}}
    for count in tqdm(COMPONENTS, desc="eigenfaces"):
        accuracies, agreements = [], []
        for seed in seeds + [None]:
            train = split(seed)
            model = EigenFaces(count).fit(faces[train], labels[train])
            predicted = model.predict(faces[~train])
            accuracies.append(float(np.mean(predicted == labels[~train])))
            if seed in (0, None):
                reference = opencv_predictions(cv2.face.EigenFaceRecognizer_create(num_components=count),
                                               faces[train], labels[train], faces[~train])
                agreements.append(float(np.mean(predicted == reference)))
        random = np.array(accuracies[:-1])
        results["eigenfaces"].append({"components": count, "random_mean": float(random.mean()),
                                      "random_min": float(random.min()), "random_max": float(random.max()),
                                      "fixed": accuracies[-1], "opencv_agreement": min(agreements)})
    fisher_accuracies, fisher_agreements = [], []
    for seed in tqdm(seeds + [None], desc="fisherfaces"):
        train = split(seed)
        predicted = FisherFaces().fit(faces[train], labels[train]).predict(faces[~train])
        fisher_accuracies.append(float(np.mean(predicted == labels[~train])))
        if seed in (0, None):
            reference = opencv_predictions(cv2.face.FisherFaceRecognizer_create(), faces[train], labels[train],
                                           faces[~train])
            fisher_agreements.append(float(np.mean(predicted == reference)))
    random = np.array(fisher_accuracies[:-1])
    results["fisherfaces"] = {"components": 39, "random_mean": float(random.mean()), "random_min": float(random.min()),
                              "random_max": float(random.max()), "fixed": fisher_accuracies[-1],
                              "opencv_agreement": min(fisher_agreements)}
    args.out.mkdir(parents=True, exist_ok=True)
    train = split(0)
    model = EigenFaces().fit(faces[train], labels[train])
    save_eigenface_grid(model, args.out / "eigenfaces_grid.png", count=15)
    counts = [1, 2, 5, 10, 20, 40, 80, 120, 160, 199]
    save_reconstruction_error_plot(counts, {"training faces": reconstruction_errors(model, faces[train], counts),
                                            "test faces (same people)": reconstruction_errors(model, faces[~train],
                                                                                              counts)},
                                   args.out / "eigenfaces_reconstruction_error.png")
    save_accuracy_plot(results, args.out / "eigenfaces_accuracy.png")
    temporary = args.out / "eigenfaces_metrics.json.tmp"
    temporary.write_text(json.dumps(results, indent=2) + "\n")
    os.replace(temporary, args.out / "eigenfaces_metrics.json")
    print(f"| components | mean of {args.splits} random splits | min | max | images 1-5 train "
          f"| agreement with OpenCV |")
    print("|---:|---:|---:|---:|---:|---:|")
    for row in results["eigenfaces"] + [dict(results["fisherfaces"], components="Fisherfaces (39)")]:
        print(f"| {row['components']} | {row['random_mean']:.3f} | {row['random_min']:.3f} | {row['random_max']:.3f} | "
              f"{row['fixed']:.3f} | {row['opencv_agreement']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
