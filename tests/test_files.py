"""Crash-safe writers of paz6d.backend.files: complete files or none, no temporaries left behind."""

import csv
import os
import stat

import numpy as np
import pytest

from paz6d.backend.files import (TEMPORARY_PREFIX, atomic_output, finite_or_none, load_json, null_non_finite,
                                 read_input_bytes, save_npz_atomically, write_csv_atomically, write_json_atomically)


def leftovers(folder):
    return sorted(path.name for path in folder.iterdir() if path.name.startswith(TEMPORARY_PREFIX))


def test_npz_round_trip_replaces_an_older_file(tmp_path):
    path = tmp_path / "deep" / "views.npz"
    save_npz_atomically(path, a=np.arange(3))
    save_npz_atomically(path, a=np.arange(5.0), b=np.eye(2, dtype=np.uint8))
    with np.load(path) as data:
        assert sorted(data.files) == ["a", "b"]
        np.testing.assert_array_equal(data["a"], np.arange(5.0))
        assert data["b"].dtype == np.uint8
    assert leftovers(path.parent) == []


class Unconvertible:
    def __array__(self, dtype=None, copy=None):
        raise RuntimeError("disk full")


def test_failed_npz_write_keeps_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "views.npz"
    save_npz_atomically(path, a=np.arange(3))
    with pytest.raises(RuntimeError, match="disk full"):
        save_npz_atomically(path, a=np.zeros(4), b=Unconvertible())
    with np.load(path) as data:
        np.testing.assert_array_equal(data["a"], np.arange(3))
    assert leftovers(tmp_path) == []


def test_interrupted_block_writes_nothing(tmp_path):
    path = tmp_path / "out.bin"
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(path) as stream:
            stream.write(b"half")
            raise KeyboardInterrupt
    assert not path.exists() and leftovers(tmp_path) == []


def test_csv_round_trip(tmp_path):
    path = write_csv_atomically(tmp_path / "log.csv", ["step", "loss"], ([step, 0.5 * step] for step in range(3)))
    assert path.read_bytes().count(b"\r") == 0
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert rows == [{"step": str(step), "loss": str(0.5 * step)} for step in range(3)]


def test_unmeasured_values_become_null(tmp_path):
    report = {"speed": float("inf"), "errors": [np.float64("nan"), 0.25, -np.inf], "nested": ({"n": 3},),
              "ok": np.float32(0.5)}
    write_json_atomically(tmp_path / "report.json", null_non_finite(report))
    assert load_json(tmp_path / "report.json") == {"speed": None, "errors": [None, 0.25, None],
                                                   "nested": [{"n": 3}], "ok": 0.5}
    assert finite_or_none(float("nan")) is None and finite_or_none(None) is None
    assert finite_or_none(np.float32(1.23456), 2) == 1.23


def test_json_rejects_nan_without_writing(tmp_path):
    path = tmp_path / "metrics.json"
    write_json_atomically(path, {"recall": 0.7}, indent=2)
    with pytest.raises(ValueError):
        write_json_atomically(path, {"recall": float("nan")})
    assert load_json(path) == {"recall": 0.7}
    assert leftovers(tmp_path) == []


def test_outputs_respect_the_umask(tmp_path):
    previous = os.umask(0o022)
    try:
        write_json_atomically(tmp_path / "shared.json", {"a": 1})
        os.umask(0o077)
        write_json_atomically(tmp_path / "private.json", {"a": 1})
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "shared.json").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "private.json").stat().st_mode) == 0o600


@pytest.mark.parametrize("kind", ["symlink", "folder", "fifo"])
def test_non_regular_targets_are_refused_and_left_alone(tmp_path, kind):
    target = tmp_path / "out.json"
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    if kind == "symlink":
        target.symlink_to(victim)
    elif kind == "folder":
        target.mkdir()
    else:
        os.mkfifo(target)
    with pytest.raises(ValueError, match="refusing to replace"):
        write_json_atomically(target, {"a": 1})
    assert victim.read_text() == "keep me"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(TEMPORARY_PREFIX)]


def test_device_target_is_refused():
    with pytest.raises(ValueError, match="/dev/null: refusing to replace a device"):
        write_json_atomically("/dev/null", {"a": 1})


def test_file_in_place_of_a_folder_is_a_clear_error(tmp_path):
    (tmp_path / "blocker").write_text("")
    with pytest.raises(ValueError, match="blocker"):
        write_json_atomically(tmp_path / "blocker" / "out.json", {"a": 1})


def test_load_run_json_names_the_file_and_the_run_directory(tmp_path):
    from paz6d.backend.files import load_run_json

    path = tmp_path / "run" / "thing.json"
    with pytest.raises(ValueError, match=r"thing.json: file not found \(is .*run a toy run directory\?\)"):
        load_run_json(path, ("a",), "a toy")
    path.parent.mkdir()
    path.write_text("{")
    with pytest.raises(ValueError, match=r"thing.json: invalid JSON"):
        load_run_json(path, ("a",), "a toy")
    with pytest.raises(ValueError, match=r"thing.json: corrupt toy description \(.*thing.json: invalid JSON"):
        load_run_json(path, ("a",), "a toy", description="toy description")
    path.write_text("[1]")
    with pytest.raises(ValueError, match=r"thing.json: expected a JSON object, got list"):
        load_run_json(path, ("a",), "a toy", description="toy description")
    path.write_text('{"a": 1}')
    with pytest.raises(ValueError, match=r"thing.json: missing field\(s\) \['b'\]"):
        load_run_json(path, ("a", "b"), "a toy")
    assert load_run_json(path, ("a",), "a toy") == {"a": 1}


def test_input_files_that_cannot_be_read_are_named_with_what_they_should_be(tmp_path):
    from paz6d.backend.image import image_size_from_header
    from paz6d.datasets.openimages import read_boxes

    readers = {"image file": image_size_from_header, "Open Images box CSV": lambda path: read_boxes(path, {}),
               "training log": lambda path: read_input_bytes(path, "training log")}
    for what, read in readers.items():
        with pytest.raises(ValueError, match=f"^{tmp_path / 'gone'}: {what} not found"):
            read(tmp_path / "gone")
        article = "an" if what[0] in "iO" else "a"
        with pytest.raises(ValueError, match=f"^{tmp_path}: expected {article} {what}, found a folder"):
            read(tmp_path)
