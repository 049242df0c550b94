"""Haar cascades on scikit-image's astronaut photograph (Eileen Collins, NASA, public domain)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import skimage.data

from paz6d.abstract import Box2D
from paz6d.faces.haar import HaarCascadeDetector, available_cascades, cascade_path, to_grey

# Hand-labelled on a 5x zoom of skimage.data.astronaut() (pixels, x right, y down).
PUPILS = np.array([[201.0, 101.0], [245.5, 103.0]])
MOUTH_CENTRE = np.array([224.0, 147.0])


@pytest.fixture(scope="module")
def astronaut() -> np.ndarray:
    return skimage.data.astronaut()


def contains(box: Box2D, point) -> bool:
    return box.x_min <= point[0] <= box.x_max and box.y_min <= point[1] <= box.y_max


def test_available_cascades_are_every_bundled_xml():
    names = available_cascades()
    bundled = sorted(path.stem for path in cascade_path("eye").parent.glob("haarcascade_*.xml"))
    assert names == [stem.removeprefix("haarcascade_") for stem in bundled]
    assert {"frontalface_default", "profileface", "eye", "smile", "fullbody", "frontalcatface"} <= set(names)


def test_every_bundled_cascade_loads_and_runs(astronaut):
    small = cv2.resize(astronaut, (128, 128), interpolation=cv2.INTER_AREA)
    for name in available_cascades():
        boxes = HaarCascadeDetector(name)(small)
        assert all(isinstance(box, Box2D) and box.class_name == name for box in boxes)


def test_exactly_one_frontal_face_on_the_astronaut(astronaut):
    for name in ("frontalface_default", "frontalface_alt", "frontalface_alt2"):
        boxes = HaarCascadeDetector(name)(astronaut)
        assert len(boxes) == 1, (name, boxes)
        face = boxes[0]
        assert all(contains(face, point) for point in (*PUPILS, MOUTH_CENTRE)), face
        assert 80 <= face.width <= 130 and face.width == face.height
        centre = np.array(face.center)
        assert np.linalg.norm(centre - [224.0, 115.0]) < 10.0, face
        assert face.score >= 1


def test_eye_cascade_finds_both_pupils(astronaut):
    eyes = HaarCascadeDetector("eye")(astronaut)
    assert len(eyes) == 2
    for pupil in PUPILS:
        assert sum(contains(eye, pupil) for eye in eyes) == 1


def test_grey_input_gives_the_colour_result(astronaut):
    detector = HaarCascadeDetector("frontalface_default")
    grey = cv2.cvtColor(astronaut, cv2.COLOR_RGB2GRAY)
    assert detector(grey) == detector(astronaut)


def test_size_limits_and_neighbour_threshold_filter(astronaut):
    assert HaarCascadeDetector("frontalface_default", min_size=(150, 150))(astronaut) == []
    assert HaarCascadeDetector("frontalface_default", max_size=(60, 60))(astronaut) == []
    loose = HaarCascadeDetector("frontalface_default", min_neighbors=0)(astronaut)
    assert len(loose) > 1  # raw, unmerged detections
    assert HaarCascadeDetector("frontalface_default", min_neighbors=200)(astronaut) == []


def test_cascade_given_as_xml_path(astronaut, tmp_path):
    copy = tmp_path / "my_face_cascade.xml"
    copy.write_bytes(cascade_path("frontalface_default").read_bytes())
    boxes = HaarCascadeDetector(copy)(astronaut)
    assert len(boxes) == 1 and boxes[0].class_name == "my_face_cascade"


def test_unknown_or_missing_cascade_names_the_available_ones(tmp_path):
    with pytest.raises(ValueError, match="available:.*frontalface_default.*smile"):
        HaarCascadeDetector("frontal_face")
    with pytest.raises(ValueError, match="does not exist; bundled cascades are .*eye"):
        HaarCascadeDetector(tmp_path / "absent.xml")
    broken = tmp_path / "broken.xml"
    broken.write_text("<opencv_storage></opencv_storage>")
    with pytest.raises(ValueError, match="not a valid OpenCV cascade"):
        HaarCascadeDetector(broken)


def test_bad_parameters_and_images_are_rejected(astronaut):
    with pytest.raises(ValueError, match="scale_factor"):
        HaarCascadeDetector(scale_factor=1.0)
    with pytest.raises(ValueError, match="min_size"):
        HaarCascadeDetector(min_size=(30,))
    with pytest.raises(ValueError, match="min_neighbors"):
        HaarCascadeDetector(min_neighbors=-1)
    detector = HaarCascadeDetector()
    with pytest.raises(ValueError, match="dtype float64"):
        detector(astronaut / 255.0)
    with pytest.raises(ValueError, match="alpha"):
        detector(np.dstack([astronaut, np.full(astronaut.shape[:2], 255, np.uint8)]))
    with pytest.raises(ValueError, match="squeeze"):
        detector(astronaut[..., :1])
    with pytest.raises(ValueError, match="non-empty"):
        detector(np.zeros((0, 0, 3), np.uint8))
    with pytest.raises(ValueError, match=r"\(H, W, 3\) or grey"):
        to_grey(np.zeros((2, 4, 4, 3), np.uint8))


def test_steps_can_be_replaced_inserted_and_removed_by_name(astronaut):
    from paz6d.abstract import KeyedStep
    from paz6d.faces.haar import RunCascade

    detector = HaarCascadeDetector("frontalface_default")
    assert detector.names == ["to_grey", "detect", "to_xyxy", "to_boxes2d", "sort"]
    [face] = detector(astronaut)
    # the eye cascade in place of the face cascade: the eyes, still named after the detector's class
    detector.replace("detect", KeyedStep(RunCascade(cascade_path("eye")), "grey", ("rectangles", "counts"), "detect"))
    eyes = detector(astronaut)
    assert len(eyes) == 2 and all(eye.class_name == "frontalface_default" for eye in eyes)
    detector.insert("sort", KeyedStep(lambda boxes: [box for box in boxes if box.x_min > 220], "boxes", "boxes",
                                      "right_half"))
    assert detector(astronaut) == [eye for eye in eyes if eye.x_min > 220]
    detector.remove("right_half")
    assert detector(astronaut) == eyes and face not in eyes
