"""paz6d.datasets.ferplus: votes joined with FER-2013 pixels by row, majority and probability labels,
and errors naming the file, line and field."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from paz6d.datasets import fer2013, ferplus

FIXTURE = Path(__file__).parent / "data" / "datasets"
VOTES = FIXTURE / "ferplus" / "fer2013new.csv"
PIXELS = FIXTURE / "fer2013" / "fer2013.csv"


def test_majority_labels_drop_ties_unknown_and_non_faces():
    samples = ferplus.load(VOTES, fer2013_csv=PIXELS)
    assert samples.class_names == list(ferplus.FERPLUS_CLASSES)
    assert [s.extras["row"] for s in samples] == [0, 1, 5]  # tie (2), not a face (3), unknown (4) dropped
    assert [s.class_names[0] for s in samples] == ["happiness", "neutral", "anger"]
    faces = fer2013.load(PIXELS)
    for sample in samples:
        np.testing.assert_array_equal(sample.image, faces[sample.extras["row"]].image)
        assert sample.extras["target"].sum() == 1.0 and sample.extras["target"].argmax() == sample.class_ids[0]
    assert samples[1].extras["votes"].tolist() == [6, 0, 0, 1, 3, 0, 0, 0, 0, 0]
    assert samples[0].extras["image_name"] == "fer0000000.png" and samples[0].extras["usage"] == "Training"
    assert [s.extras["row"] for s in ferplus.load(VOTES, "train", fer2013_csv=PIXELS)] == [0, 1]
    assert [s.extras["row"] for s in ferplus.load(VOTES, "val", fer2013_csv=PIXELS)] == [5]


def test_probability_labels_are_vote_distributions():
    samples = ferplus.load(VOTES, fer2013_csv=PIXELS, label_mode="probability")
    assert [s.extras["row"] for s in samples] == [0, 1, 2, 5]
    np.testing.assert_allclose(samples[1].extras["target"], [6 / 9, 0, 0, 0, 3 / 9, 0, 0, 0])  # single vote dropped
    np.testing.assert_allclose(samples[2].extras["target"], [0.5, 0, 0.5, 0, 0, 0, 0, 0])
    assert samples[2].class_names == ["neutral"]  # first of the tied emotions
    with_singles = ferplus.load(VOTES, fer2013_csv=PIXELS, label_mode="probability", drop_single_votes=False)
    np.testing.assert_allclose(with_singles[1].extras["target"], [0.6, 0, 0, 0.1, 0.3, 0, 0, 0])
    keep, targets = ferplus.targets_from_votes(np.array([[0, 3, 3, 0, 0, 0, 0, 0, 4, 0]]), "probability")
    assert keep.tolist() == [True] and targets[0, 1] == 0.5
    keep, _ = ferplus.targets_from_votes(np.array([[0, 3, 0, 0, 0, 0, 0, 0, 2, 2]]), "probability")
    assert keep.tolist() == [False]  # unknown + not-a-face hold half the votes
    with pytest.raises(ValueError, match="label_mode: expected one of"):
        ferplus.targets_from_votes(np.zeros((1, 10)), "vote")


def test_folder_with_both_files(tmp_path):
    shutil.copy(VOTES, tmp_path / "fer2013new.csv")
    with pytest.raises(ValueError, match=r"fer2013_csv: FER-2013 pixel file .*fer2013\.csv not found"):
        ferplus.load(tmp_path)
    shutil.copy(PIXELS, tmp_path / "fer2013.csv")
    assert len(ferplus.load(tmp_path)) == 3


@pytest.mark.parametrize("edit, message", [
    (lambda lines: lines[:4], r"fer2013new\.csv: 2 vote rows but .*fer2013\.csv has 6 faces"),
    (lambda lines: lines[:2] + [lines[2].replace("Training", "PublicTest", 1)] + lines[3:],
     r"fer2013new\.csv, line 2, field Usage: 'PublicTest' but line 2 of .* says 'Training'"),
    (lambda lines: lines[:4] + [lines[4].replace(",4,0,0,0,0,0,2,0", ",4,0,0,x,0,0,2,0")] + lines[5:],
     r"fer2013new\.csv, line 4, field disgust: expected a vote count \(integer >= 0\), got 'x'"),
    (lambda lines: lines[:2] + [lines[2].replace(",10,", ",-1,")] + lines[3:],
     r"line 2, field happiness: expected a vote count in 0..1000, got .-1."),
    (lambda lines: lines[:1] + [lines[1].replace("contempt", "contempts")] + lines[2:], r"expected the FERPlus header"),
    (lambda lines: lines[:2] + ["Training,fer0000000.png,1,2"] + lines[3:], r"line 2: expected 12 fields, got 4"),
])
def test_malformed_vote_files_name_line_and_field(tmp_path, edit, message):
    lines = [""] + VOTES.read_text().splitlines()  # index = line number
    (tmp_path / "fer2013new.csv").write_text("\n".join(edit(lines)[1:]) + "\n")
    with pytest.raises(ValueError, match=message):
        ferplus.load(tmp_path / "fer2013new.csv", fer2013_csv=PIXELS)
