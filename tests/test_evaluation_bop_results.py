"""BOP'19 results CSV (``paz6d.datasets.bop.results``): parsing, units, round trip and every kind of
bad row (with its line number)."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.datasets.bop.results import HEADER, read_pose_results, write_pose_results

R_TEXT = " ".join(map(str, np.eye(3).ravel()))
GOOD = f"2,3,5,0.5,{R_TEXT},1 2 1000,-1"


def write_lines(path, *rows, header=",".join(HEADER)):
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_round_trip_keeps_every_value(tmp_path):
    generator = np.random.default_rng(0)
    rotations = Rotation.random(5, random_state=2).as_matrix()
    translations = generator.normal(0, 300, (5, 3))
    scores = generator.random(5)
    path = write_pose_results(tmp_path / "r.csv", [1, 1, 2, 2, 3], [0, 4, 7, 7, 9], [5, 6, 5, 1, 12], scores,
                              rotations, translations, [0.5, 0.5, -1, -1, 2.0], units="mm")
    results = read_pose_results(path, units="mm")
    assert len(results) == 5 and results.skipped == () and results.units == "mm"
    np.testing.assert_array_equal(results.rotations, rotations)
    np.testing.assert_array_equal(results.translations, translations)
    np.testing.assert_array_equal(results.scores, scores)
    np.testing.assert_array_equal(results.obj_ids, [5, 6, 5, 1, 12])
    np.testing.assert_array_equal(results.line_numbers, [2, 3, 4, 5, 6])
    np.testing.assert_array_equal(results.T_model2cam[:, :3, 3], translations)


def test_metres_are_written_as_millimetres_and_read_back(tmp_path):
    translations_m = np.array([[0.0123, -0.2, 1.5], [0.1, 0.0, 0.75]])
    path = write_pose_results(tmp_path / "r.csv", [1, 1], [0, 1], [5, 5], [1.0, 0.5], np.tile(np.eye(3), (2, 1, 1)),
                              translations_m)
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    np.testing.assert_array_equal([[float(v) for v in row["t"].split()] for row in rows], translations_m * 1000.0)
    np.testing.assert_array_equal(read_pose_results(path, units="mm").translations, translations_m * 1000.0)
    in_metres = read_pose_results(path)
    assert in_metres.units == "m"
    np.testing.assert_allclose(in_metres.translations, translations_m, rtol=1e-15)
    with pytest.raises(ValueError, match="units: expected one of \\('m', 'mm'\\), got 'cm'"):
        read_pose_results(path, units="cm")


def test_lmo_results_file_parses_like_the_csv_module(shared_data):
    path = shared_data / "bop_lmo" / "results" / "results_lmo-test.csv"
    results = read_pose_results(path, units="mm")
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    assert len(results) == len(rows) == 1427
    index = 700
    np.testing.assert_array_equal(results.rotations[index].ravel(), [float(v) for v in rows[index]["R"].split()])
    np.testing.assert_array_equal(results.translations[index], [float(v) for v in rows[index]["t"].split()])
    assert results.scores[index] == float(rows[index]["score"])
    assert set(results.obj_ids.tolist()) == {1, 5, 6, 8, 9, 10, 11, 12}


BAD_ROWS = [
    ("2,3,5,0.5,1 0 0 0 1 0 0 0 1,1 2 3", "expected 7 comma-separated fields"),
    ("2,x,5,0.5,1 0 0 0 1 0 0 0 1,1 2 3,-1", "'im_id': expected a non-negative integer"),
    ("2,3,-5,0.5,1 0 0 0 1 0 0 0 1,1 2 3,-1", "'obj_id': expected a non-negative integer"),
    ("2,3,5,nan,1 0 0 0 1 0 0 0 1,1 2 3,-1", "'score': contains NaN"),
    ("2,3,5,0.5,1 0 0 0 1 0 0 0,1 2 3,-1", "'R': expected 9 numbers"),
    ("2,3,5,0.5,1 0 0 0 nan 0 0 0 1,1 2 3,-1", "'R': contains NaN"),
    ("2,3,5,0.5,1 0 0 0 1.2 0 0 0 1,1 2 3,-1", "'R': not a rotation matrix"),
    ("2,3,5,0.5,1 0 0 0 1 0 0 0 -1,1 2 3,-1", "'R': not a rotation matrix"),
    ("2,3,5,0.5,1 0 0 0 1 0 0 0 1,1 2 inf,-1", "'t': contains NaN or infinite"),
    ("2,3,5,0.5,1 0 0 0 1 0 0 0 1,1 2 three,-1", "'t': not a number"),
    ("2,3,5,0.5,1 0 0 0 1 0 0 0 1,1 2 3,soon", "'time': not a number"),
]


@pytest.mark.parametrize("row, message", BAD_ROWS)
def test_bad_row_names_file_and_line(tmp_path, row, message):
    path = write_lines(tmp_path / "r.csv", GOOD, GOOD, row, GOOD)
    with pytest.raises(ValueError, match=re.escape(f"{path}:4: ") + ".*" + re.escape(message)):
        read_pose_results(path)
    skipped = read_pose_results(path, skip_invalid=True)
    assert len(skipped) == 3 and [line for line, _ in skipped.skipped] == [4]
    assert message in skipped.skipped[0][1]
    np.testing.assert_array_equal(skipped.line_numbers, [2, 3, 5])


def test_unknown_objects_and_images(tmp_path):
    path = write_lines(tmp_path / "r.csv", GOOD, GOOD.replace("2,3,5,", "2,3,7,"), GOOD.replace("2,3,5,", "2,99,5,"))
    with pytest.raises(ValueError, match=re.escape(f"{path}:3: unknown object id 7")):
        read_pose_results(path, object_ids={5}, image_ids={(2, 3)})
    with pytest.raises(ValueError, match=re.escape(f"{path}:4: unknown image: scene 2, image 99")):
        read_pose_results(path, object_ids={5, 7}, image_ids={(2, 3)})
    results = read_pose_results(path, object_ids={5}, image_ids={(2, 3)}, skip_invalid=True)
    assert len(results) == 1 and [line for line, _ in results.skipped] == [3, 4]


def test_header_empty_file_and_blank_lines(tmp_path):
    with pytest.raises(ValueError, match=re.escape(f"{tmp_path / 'missing.csv'}: results file not found")):
        read_pose_results(tmp_path / "missing.csv")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(ValueError, match=":1: expected the header .* an empty file"):
        read_pose_results(empty, skip_invalid=True)
    wrong = write_lines(tmp_path / "wrong.csv", GOOD, header="scene_id,im_id,obj_id,score,R,t")
    with pytest.raises(ValueError, match=":1: expected the header scene_id,im_id,obj_id,score,R,t,time"):
        read_pose_results(wrong)
    blank = write_lines(tmp_path / "blank.csv", GOOD, "", GOOD, "")
    results = read_pose_results(blank)
    np.testing.assert_array_equal(results.line_numbers, [2, 4])


def test_rounded_rotations_within_tolerance_are_accepted(tmp_path):
    R = np.round(Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix(), 3)
    row = f"2,3,5,0.5,{' '.join(map(str, R.ravel()))},1 2 3,-1"
    path = write_lines(tmp_path / "r.csv", row)
    np.testing.assert_array_equal(read_pose_results(path).rotations[0], R)
    with pytest.raises(ValueError, match=":2: field 'R': not a rotation"):
        read_pose_results(path, rotation_tolerance=1e-6)
