"""paz6d.datasets.fer2013: `load` over the Kaggle CSV (splits, inline faces), the vectorised reader
equal to the row-by-row one, its fallback naming the bad line, and the 35,887-row speed target."""

from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np
import pytest

from paz6d.datasets import fer2013

FIXTURE = Path(__file__).parent / "data" / "datasets" / "fer2013"


def plain_parse(path: Path):
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    return ([np.array(row["pixels"].split(), dtype=np.uint8).reshape(48, 48) for row in rows],
            [int(row["emotion"]) for row in rows], [row["Usage"] for row in rows])


def test_load_splits_inline_faces():
    faces, labels, usage = plain_parse(FIXTURE / "fer2013.csv")
    everything = fer2013.load(FIXTURE)
    assert len(everything) == 6 and everything.class_names == list(fer2013.FER2013_CLASSES)
    for sample, face, label, use in zip(everything, faces, labels, usage):
        np.testing.assert_array_equal(sample.image, face)
        assert sample.image.dtype == np.uint8 and sample.boxes.shape == (0, 4)
        assert sample.class_ids.tolist() == [label] and sample.class_names == [fer2013.FER2013_CLASSES[label]]
        assert sample.extras["usage"] == use
    train = fer2013.load(FIXTURE / "fer2013.csv", "train")
    assert [s.extras["row"] for s in train] == [0, 1, 4]
    assert [s.extras["row"] for s in fer2013.load(FIXTURE, "val")] == [2, 5]
    assert [s.extras["row"] for s in fer2013.load(FIXTURE, "test")] == [3]
    assert len(fer2013.load(FIXTURE, "PublicTest")) == 2
    with pytest.raises(ValueError, match=r"split: expected one of \['train', 'val', 'test'\]"):
        fer2013.load(FIXTURE, "validation")


def test_vectorised_reader_equals_the_row_by_row_reader(tmp_path):
    text = (FIXTURE / "fer2013.csv").read_text()
    fast = fer2013._read_kaggle_layout(FIXTURE / "fer2013.csv")  # CRLF file: fast path
    assert fast is not None
    quoted = tmp_path / "quoted.csv"  # quotes send it to the csv module
    quoted.write_text("\n".join(line if i == 0 else line.replace(",", ',"', 1).replace(",", '",', 2).replace('",', ",",
                                                                                                             1)
                                for i, line in enumerate(text.splitlines())) + "\n")
    assert fer2013._read_kaggle_layout(quoted) is None
    slow = fer2013.load_fer2013_csv(quoted)
    for a, b in zip(fast, slow):
        np.testing.assert_array_equal(a, b)
    faces, labels, usage = plain_parse(FIXTURE / "fer2013.csv")
    np.testing.assert_array_equal(fast[0], np.stack(faces))


@pytest.mark.parametrize("row, message", [
    ("3," + " ".join(["1"] * 2303) + ",Training", "line 3: expected 2304 grey levels"),
    ("3," + " ".join(["1"] * 2303 + ["256"]) + ",Training", "line 3: expected 2304 grey levels in 0..255"),
    ("3," + " ".join(["1"] * 2303 + ["1x"]) + ",Training", "line 3: cannot parse emotion/pixels"),
    ("7," + " ".join(["1"] * 2304) + ",Training", "line 3: emotion 7 outside 0..6"),
])
def test_bad_rows_fall_back_and_name_the_line(tmp_path, row, message):
    good = "0," + " ".join(["5"] * 2304) + ",Training"
    path = tmp_path / "fer.csv"
    path.write_text(f"emotion,pixels,Usage\n{good}\n{row}\n")
    assert fer2013._read_kaggle_layout(path) is None
    with pytest.raises(ValueError, match=message):
        fer2013.load(path)


@pytest.mark.slow
def test_full_size_csv_loads_within_five_seconds(tmp_path):
    generator = np.random.default_rng(0)
    distinct = [" ".join(map(str, generator.integers(0, 256, 2304))) for _ in range(64)]
    usages = ("Training", "PublicTest", "PrivateTest")
    path = tmp_path / "fer2013.csv"
    with path.open("w") as handle:
        handle.write("emotion,pixels,Usage\n")
        handle.writelines(f"{row % 7},{distinct[row % 64]},{usages[row % 3]}\n" for row in range(35887))
    started, cpu_started = time.perf_counter(), time.process_time()
    samples = fer2013.load(path)
    seconds, cpu_seconds = time.perf_counter() - started, time.process_time() - cpu_started
    # CPU time: the target is the loader's work, not the waiting on a machine shared with other jobs
    assert len(samples) == 35887 and cpu_seconds <= 5.0, f"{cpu_seconds:.2f} s CPU ({seconds:.2f} s wall)"
    np.testing.assert_array_equal(samples[35886].image.ravel(), np.array(distinct[35886 % 64].split(), dtype=np.uint8))
    assert samples[100].class_ids.tolist() == [100 % 7] and samples[100].extras["usage"] == usages[100 % 3]
