"""FERPlus: ten crowd votes per FER-2013 face (``fer2013new.csv``), joined with the FER-2013 pixels.

``fer2013new.csv`` has the header
``Usage,Image name,neutral,happiness,surprise,sadness,anger,disgust,fear,contempt,unknown,NF`` and one
row per row of ``fer2013.csv``, in the same order (the join is by row; the ``Usage`` of both files
must agree row by row). Each row holds how many of the ten taggers chose each of the eight emotions
(:data:`FERPLUS_CLASSES`), ``unknown`` or ``NF`` (not a face); the ``Image name`` is empty for faces
FERPlus removed.

Label modes (following Barsoum et al., "Training deep networks for facial expression recognition
with crowd-sourced label distribution", 2016):

* votes of 1 are treated as outliers and set to 0 first (``drop_single_votes=True``, as the FERPlus
  reference code does);
* ``"majority"``: a face is kept when one column holds more than half of the remaining votes and that
  column is an emotion; its label is that emotion (one-hot target). Faces without such a majority
  (ties included) and faces where ``unknown`` or ``NF`` holds it are dropped;
* ``"probability"``: the target is the distribution of the remaining emotion votes (eight values
  summing to 1). Faces whose ``unknown`` + ``NF`` votes are at least half of the remaining votes, or
  that have no emotion vote left, are dropped. ``class_ids`` is the most voted emotion (first on ties).

Example:
    >>> train = load("FERPlus/fer2013new.csv", "train", fer2013_csv="fer2013/fer2013.csv")  # doctest: +SKIP
    >>> train[0].extras["target"]  # (8,) vote distribution or one-hot  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from paz6d.backend.files import read_input_text
from paz6d.datasets import fer2013
from paz6d.datasets.sample import Sample, SampleSequence

FERPLUS_CLASSES = ("neutral", "happiness", "surprise", "sadness", "anger", "disgust", "fear", "contempt")
VOTE_COLUMNS = FERPLUS_CLASSES + ("unknown", "NF")
#: Largest vote count accepted in one cell (FERPlus has ten taggers per face).
MAX_VOTES = 1000
CSV_COLUMNS = ("Usage", "Image name") + VOTE_COLUMNS
CSV_FILE = "fer2013new.csv"
LABEL_MODES = ("majority", "probability")


def read_votes(path: str | Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Reads ``fer2013new.csv``.

    Returns:
        ``votes (N, 10) int64`` in :data:`VOTE_COLUMNS` order, ``usage (N,) str`` and the image names.
    Raises:
        ValueError: a missing file or column, a row with a bad field; the message names the line and field.
    """
    path = Path(path)
    reader = csv.reader(io.StringIO(read_input_text(path, "FERPlus vote CSV"), newline=""))
    try:
        header = [cell.strip() for cell in next(reader, [])]
        if header[:len(CSV_COLUMNS)] != list(CSV_COLUMNS):
            raise ValueError(f"{path}: expected the FERPlus header {','.join(CSV_COLUMNS)}, got {','.join(header)!r}")
        votes, usage, names = [], [], []
        for line, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(row) < len(CSV_COLUMNS):
                raise ValueError(f"{path}, line {line}: expected {len(CSV_COLUMNS)} fields, got {len(row)}")
            counts = []
            for column, text in zip(VOTE_COLUMNS, row[2:len(CSV_COLUMNS)]):
                try:
                    value = int(text)
                except ValueError:
                    raise ValueError(f"{path}, line {line}, field {column}: expected a vote count (integer >= 0), "
                                     f"got {text!r}") from None
                if not 0 <= value <= MAX_VOTES:
                    raise ValueError(f"{path}, line {line}, field {column}: expected a vote count in 0..{MAX_VOTES}, "
                                     f"got {text!r:.40}")
                counts.append(value)
            votes.append(counts)
            usage.append(row[0].strip())
            names.append(row[1].strip())
    except csv.Error as error:
        raise ValueError(f"{path}, line {reader.line_num}: malformed CSV ({error})") from None
    if not votes:
        raise ValueError(f"{path}: no data rows")
    return np.array(votes, dtype=np.int64), np.array(usage), names


def targets_from_votes(votes: np.ndarray, label_mode: str = "majority",
                       drop_single_votes: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Training targets of FERPlus vote rows (rules in the module doc).

    Args:
        votes: ``(N, 10)`` counts in :data:`VOTE_COLUMNS` order.
        label_mode: ``"majority"`` or ``"probability"``.
        drop_single_votes: treat votes of 1 as outliers (set them to 0) first.
    Returns:
        ``keep (N,) bool`` and ``targets (N, 8) float64`` (rows of dropped faces are zeros).
    """
    if label_mode not in LABEL_MODES:
        raise ValueError(f"label_mode: expected one of {LABEL_MODES}, got {label_mode!r}")
    votes = np.asarray(votes, dtype=np.float64)
    if votes.ndim != 2 or votes.shape[1] != len(VOTE_COLUMNS):
        raise ValueError(f"votes: expected shape (N, {len(VOTE_COLUMNS)}), got {votes.shape}")
    if drop_single_votes:
        votes = np.where(votes <= 1, 0.0, votes)
    total = votes.sum(axis=1)
    emotions = votes[:, :len(FERPLUS_CLASSES)]
    emotion_total = emotions.sum(axis=1)
    targets = np.zeros_like(emotions)
    if label_mode == "majority":
        winner = votes.argmax(axis=1)
        keep = (votes.max(axis=1) > 0.5 * total) & (winner < len(FERPLUS_CLASSES)) & (total > 0)
        targets[np.flatnonzero(keep), winner[keep]] = 1.0
    else:
        keep = (emotion_total > 0) & (total - emotion_total < 0.5 * total)
        targets[keep] = emotions[keep] / emotion_total[keep, None]
    return keep, targets


def load(root_or_csv: str | Path, split: str | None = None, fer2013_csv: str | Path | None = None,
         label_mode: str = "majority", drop_single_votes: bool = True) -> SampleSequence:
    """FERPlus faces of one split as a :class:`SampleSequence` of inline ``(48, 48) uint8`` images.

    Args:
        root_or_csv: ``fer2013new.csv`` or the folder holding it.
        split: ``train``, ``val``, ``test`` (FER-2013 ``Usage`` ``Training``, ``PublicTest``,
            ``PrivateTest``) or ``None`` for all.
        fer2013_csv: the FER-2013 pixels (default: ``fer2013.csv`` next to ``fer2013new.csv``).
        label_mode: ``"majority"`` or ``"probability"`` (see the module doc); dropped faces are not in
            the sequence.
        drop_single_votes: treat single votes as outliers.
    Returns:
        Samples with ``class_ids (1,)`` indexing :data:`FERPLUS_CLASSES` and ``extras``: ``target``
        ``(8,)`` (one-hot or vote distribution), ``votes (10,)``, ``image_name``, ``usage``, ``row``.
    Raises:
        ValueError: missing files, row counts or ``Usage`` values that differ between the two files.
    """
    votes_path = Path(root_or_csv)
    if votes_path.is_dir():
        votes_path = votes_path / CSV_FILE
    pixels_path = Path(fer2013_csv) if fer2013_csv is not None else votes_path.parent / fer2013.CSV_FILE
    if not pixels_path.is_file():
        raise ValueError(f"fer2013_csv: FER-2013 pixel file {pixels_path} not found (FERPlus holds only votes; "
                         "pass the fer2013.csv its rows refer to)")
    usage_value = fer2013.usage_of_split(split)
    votes, usage, names = read_votes(votes_path)
    faces, _, fer_usage = fer2013.load_fer2013_csv(fer2013.csv_path(pixels_path))
    if len(faces) != len(votes):
        raise ValueError(f"{votes_path}: {len(votes)} vote rows but {pixels_path} has {len(faces)} faces; "
                         "FERPlus rows join FER-2013 rows one to one, in order")
    differ = np.flatnonzero(usage != fer_usage)
    if len(differ):
        row = int(differ[0])
        raise ValueError(f"{votes_path}, line {row + 2}, field Usage: {str(usage[row])!r} but line {row + 2} of "
                         f"{pixels_path} "
                         f"says {str(fer_usage[row])!r}; are the files from the same FER-2013 release?")
    keep, targets = targets_from_votes(votes, label_mode, drop_single_votes)
    if usage_value is not None:
        keep &= usage == usage_value
    rows = np.flatnonzero(keep)

    def read(position: int) -> Sample:
        row = int(rows[position])
        class_id = int(targets[row].argmax())
        return Sample(image=faces[row], boxes=np.zeros((0, 4)), class_ids=np.array([class_id], dtype=np.int64),
                      class_names=[FERPLUS_CLASSES[class_id]],
                      extras={"target": targets[row].copy(), "votes": votes[row].copy(), "image_name": names[row],
                              "usage": str(usage[row]), "row": row})

    return SampleSequence(len(rows), read, FERPLUS_CLASSES)
