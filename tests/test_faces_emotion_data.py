"""FER-2013 loaders, grey-face augmentation, batch sampling and confusion matrices (no TensorFlow)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from paz6d.datasets.fer2013 import FER2013_CLASSES, load_fer2013_csv, load_image_folder
from paz6d.synthesis.augment import RandomAffine, similarity_matrix
from paz6d.faces.emotion_train import (_split_per_class, build_augmentation, confusion_matrix, load_emotion_data,
                                    save_confusion_matrix_plot)


def write_csv(path, rows, header="emotion,pixels,Usage"):
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def face_row(label: int, value: int, usage: str) -> str:
    return f"{label},{' '.join([str(value)] * 48 * 48)},{usage}"


@pytest.fixture(scope="module")
def fer_sample(shared_data):
    root = shared_data / "faces" / "fer2013_sample"
    if not root.is_dir():
        pytest.skip("FER-2013 sample not in shared data")
    return root


def test_csv_loader_reads_labels_pixels_and_usage(tmp_path):
    path = write_csv(tmp_path / "fer.csv", [face_row(3, 7, "Training"), face_row(6, 200, "PublicTest")])
    faces, labels, usage = load_fer2013_csv(path)
    assert faces.shape == (2, 48, 48) and faces.dtype == np.uint8
    assert faces[0].max() == faces[0].min() == 7 and faces[1][0, 0] == 200
    assert labels.tolist() == [3, 6] and usage.tolist() == ["Training", "PublicTest"]
    assert FER2013_CLASSES[3] == "happy" and FER2013_CLASSES[6] == "neutral"


def test_csv_loader_names_the_bad_line(tmp_path):
    with pytest.raises(ValueError, match="missing"):
        load_fer2013_csv(write_csv(tmp_path / "a.csv", ["1,2"], header="label,pixels"))
    with pytest.raises(ValueError, match="line 3: emotion 9"):
        load_fer2013_csv(write_csv(tmp_path / "b.csv", [face_row(1, 0, "Training"), face_row(9, 0, "Training")]))
    with pytest.raises(ValueError, match="line 2: expected 2304 grey levels"):
        load_fer2013_csv(write_csv(tmp_path / "c.csv", ["1,1 2 3,Training"]))
    with pytest.raises(ValueError, match="line 2: cannot parse"):
        load_fer2013_csv(write_csv(tmp_path / "d.csv", ["x,1 2 3,Training"]))
    with pytest.raises(ValueError, match="does not exist"):
        load_fer2013_csv(tmp_path / "absent.csv")


def test_image_folder_loader_on_the_fer_sample(fer_sample):
    faces, labels, class_names = load_image_folder(fer_sample)
    assert class_names == FER2013_CLASSES  # folder names recognised, FER label order kept
    assert faces.shape == (98, 48, 48) and faces.dtype == np.uint8
    assert np.bincount(labels).tolist() == [14] * 7
    first_happy = sorted((fer_sample / "happy").iterdir())[0]
    np.testing.assert_array_equal(faces[labels == 3][0], cv2.imread(str(first_happy), cv2.IMREAD_GRAYSCALE))


def test_image_folder_errors(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        load_image_folder(tmp_path / "absent")
    with pytest.raises(ValueError, match="one sub-folder"):
        load_image_folder(tmp_path)
    (tmp_path / "cats").mkdir()
    cv2.imwrite(str(tmp_path / "cats" / "a.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(tmp_path / "cats" / "b.png"), np.zeros((6, 8), np.uint8))
    with pytest.raises(ValueError, match="differs"):
        load_image_folder(tmp_path)
    faces, labels, names = load_image_folder(tmp_path, size=(4, 4))
    assert faces.shape == (2, 4, 4) and names == ("cats",)
    with pytest.raises(ValueError, match="not in class_names"):
        load_image_folder(tmp_path, class_names=("dogs",), size=(4, 4))


def test_emotion_data_splits(tmp_path, fer_sample):
    data = load_emotion_data(fer_sample, val_fraction=0.25, seed=1)
    assert len(data["validation"][0]) == 7 * 4 and len(data["train"][0]) == 7 * 10
    assert np.bincount(data["validation"][1]).tolist() == [4] * 7
    rows = [face_row(label, label, "Training") for label in range(7) for _ in range(4)]
    csv_only_training = load_emotion_data(write_csv(tmp_path / "t.csv", rows), val_fraction=0.25)
    assert len(csv_only_training["validation"][0]) == 7 and len(csv_only_training["train"][0]) == 21
    with_public = load_emotion_data(write_csv(tmp_path / "p.csv", rows + [face_row(2, 9, "PublicTest"),
                                                                          face_row(4, 9, "PrivateTest")]))
    assert with_public["validation"][1].tolist() == [2] and len(with_public["train"][0]) == 28
    with pytest.raises(ValueError, match="val_fraction"):
        _split_per_class(np.zeros(4, int), 1.5, 0)
    with pytest.raises(ValueError, match="neither"):
        load_emotion_data(tmp_path / "nothing")


def test_confusion_matrix_matches_counting_loop(tmp_path):
    rng = np.random.default_rng(0)
    true, predicted = rng.integers(0, 7, 200), rng.integers(0, 7, 200)
    expected = np.zeros((7, 7), int)
    for t, p in zip(true, predicted):
        expected[t, p] += 1
    np.testing.assert_array_equal(confusion_matrix(true, predicted, 7), expected)
    with pytest.raises(ValueError, match="predicted_labels"):
        confusion_matrix(true, predicted[:-1], 7)
    with pytest.raises(ValueError, match="0..6"):
        confusion_matrix(true, predicted + 1, 7)
    path = save_confusion_matrix_plot(expected, FER2013_CLASSES, tmp_path / "cm.png", title="random")
    assert cv2.imread(str(path)).shape == (560, 640, 3)


def test_random_affine_is_seeded_and_identity_without_range():
    face = np.random.default_rng(0).integers(0, 256, (48, 48), dtype=np.uint8)
    np.testing.assert_array_equal(RandomAffine(0.0, 0.0, 0.0, seed=0)(face), face)
    a, b = RandomAffine(seed=5)(face), RandomAffine(seed=5)(face)
    np.testing.assert_array_equal(a, b)
    assert a.shape == face.shape and a.dtype == np.uint8 and not np.array_equal(a, face)
    # a pure shift moves a bright pixel by the shift
    dot = np.zeros((20, 20), np.uint8)
    dot[5, 5] = 255
    moved = cv2.warpAffine(dot, similarity_matrix((9.5, 9.5), 0.0, 1.0, (3.0, 2.0)), (20, 20))
    assert np.unravel_index(moved.argmax(), moved.shape) == (7, 8)
    with pytest.raises(ValueError, match="max_zoom"):
        RandomAffine(max_zoom=1.5)
    with pytest.raises(ValueError, match="non-empty"):
        RandomAffine(seed=0)(np.zeros((0, 3), np.uint8))


def test_augmentation_keeps_grey_faces_and_is_reproducible():
    face = np.random.default_rng(1).integers(0, 256, (48, 48), dtype=np.uint8)
    first, second = build_augmentation(seed=3)(face), build_augmentation(seed=3)(face)
    assert first.shape == (48, 48) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, second)
    assert not np.array_equal(first, build_augmentation(seed=4)(face))


def test_train_emotion_command_reports_bad_data(tmp_path, capsys):
    from paz6d.cli import main

    assert main(["train", "emotion", "--data", str(tmp_path / "absent"), "--out", str(tmp_path / "run")]) == 2
    assert "neither a FER-2013 CSV file nor an image folder" in capsys.readouterr().err
    assert main(["train", "emotion", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--epochs", "0"]) == 2
    assert "--epochs" in capsys.readouterr().err
