"""`paz6d train emotion` on FER-2013 CSVs with FERPlus votes: majority labels, probability (soft)
labels through the batch sampler, and a tiny training run per label mode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from paz6d.cli import main
from paz6d.datasets.ferplus import FERPLUS_CLASSES
from paz6d.faces.emotion_train import BatchSampler, load_emotion_data

DATA = Path(__file__).parent / "data" / "datasets"
PIXELS = DATA / "fer2013" / "fer2013.csv"
VOTES = DATA / "ferplus" / "fer2013new.csv"


def test_majority_and_probability_labels_reach_the_trainer():
    majority = load_emotion_data(PIXELS, ferplus=VOTES)
    assert majority["class_names"] == FERPLUS_CLASSES
    assert majority["train"][1].tolist() == [1, 0] and majority["validation"][1].tolist() == [4]
    probability = load_emotion_data(PIXELS.parent, ferplus=VOTES, label_mode="probability")  # folder with fer2013.csv
    train_faces, train_targets = probability["train"]
    assert train_targets.shape == (2, 8) and probability["validation"][1].shape == (2, 8)
    np.testing.assert_allclose(train_targets[1], [6 / 9, 0, 0, 0, 3 / 9, 0, 0, 0])
    sampler = BatchSampler(train_faces, train_targets, 8, batch_size=2, seed=1)
    inputs, targets = sampler(0)
    assert inputs.shape == (2, 48, 48, 1) and targets.dtype == np.float32
    assert sorted(map(tuple, targets.round(6))) == sorted(map(tuple, train_targets.astype(np.float32).round(6)))
    plain = load_emotion_data(PIXELS.parent)  # FER-2013 labels, 7 classes
    assert plain["train"][1].tolist() == [3, 0, 1] and len(plain["class_names"]) == 7


def test_ferplus_needs_the_fer2013_csv(tmp_path):
    with pytest.raises(ValueError, match="is not a FER-2013 CSV file; --ferplus votes need"):
        load_emotion_data(tmp_path, ferplus=VOTES)
    assert main(["train", "emotion", "--data", str(PIXELS), "--ferplus", str(tmp_path / "none.csv"),
                 "--out", str(tmp_path / "run")]) == 2


@pytest.mark.slow
@pytest.mark.parametrize("label_mode", ["majority", "probability"])
def test_tiny_training_run_per_label_mode(tmp_path, label_mode):
    run_dir = tmp_path / "run"
    assert main(["train", "emotion", "--data", str(PIXELS), "--ferplus", str(VOTES), "--label-mode", label_mode,
                 "--out", str(run_dir), "--epochs", "2", "--batch-size", "2", "--input-size", "24",
                 "--validate-every", "0", "--no-progress", "--eager", "--no-augment"]) == 0
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["step"] == 2 and metrics["class_names"] == list(FERPLUS_CLASSES)
    assert metrics["validation_count"] == (1 if label_mode == "majority" else 2)
    assert np.isfinite(metrics["train_metrics"]["loss"])
