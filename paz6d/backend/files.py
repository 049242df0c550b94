"""Crash-safe file output: a file appears complete (temporary name, then ``os.replace``) or not at all.

Every writer in paz6d (data sets, run directories, reports, plots) goes through these functions,
so a killed job never leaves a half-written file behind, only stale temporaries named
``TEMPORARY_PREFIX*`` that a resumed job may delete.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import numpy as np

TEMPORARY_PREFIX = ".paz6d-tmp-"


@contextmanager
def atomic_output(path: str | Path) -> Iterator[BinaryIO]:
    """A binary stream whose content appears at ``path`` (``os.replace``) only when the block ends
    without an exception; otherwise the temporary file in the same folder is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=TEMPORARY_PREFIX + path.name + ".")
    try:
        with os.fdopen(handle, "wb") as stream:
            yield stream
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_bytes_atomically(path: str | Path, data: bytes) -> Path:
    """Writes ``data`` to ``path`` through a temporary file in the same folder and ``os.replace``."""
    with atomic_output(path) as stream:
        stream.write(data)
    return Path(path)


def save_npz_atomically(path: str | Path, **arrays: Any) -> Path:
    """``np.savez(path, **arrays)`` atomically (uncompressed; no pickled objects needed to read it back)."""
    with atomic_output(path) as stream:
        np.savez(stream, **arrays)
    return Path(path)


def write_csv_atomically(path: str | Path, header, rows) -> Path:
    """Writes a CSV file (``header`` row, then ``rows``; LF line ends, UTF-8) atomically."""
    text = io.StringIO(newline="")
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return write_bytes_atomically(path, text.getvalue().encode("utf-8"))


def json_bytes(data: Any, indent: int | None = None) -> bytes:
    """Deterministic JSON encoding (key order as given; NaN/inf are rejected)."""
    text = json.dumps(data, allow_nan=False, indent=indent, separators=None if indent else (", ", ": "))
    return (text + "\n").encode() if indent else text.encode()


def load_json(path: str | Path) -> Any:
    """Parses a JSON file; ``ValueError`` naming the file when it is missing or malformed."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError as error:
        raise ValueError(f"{path}: file not found") from error
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: invalid JSON ({error})") from error


def write_json_atomically(path: str | Path, data: Any, indent: int | None = None) -> Path:
    """Writes ``data`` as JSON (``indent`` spaces, compact when None) atomically."""
    return write_bytes_atomically(path, json_bytes(data, indent))


def write_text_atomically(path: str | Path, text: str) -> Path:
    """Writes UTF-8 ``text`` atomically."""
    return write_bytes_atomically(path, text.encode("utf-8"))


def new_figure(width: float, height: float, dpi: int = 100):
    """A matplotlib ``Figure`` (``width × height`` inches) on the Agg canvas, without pyplot state."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def save_figure_atomically(figure, path: str | Path) -> Path:
    """Saves a matplotlib figure as PNG atomically and returns the path."""
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return write_bytes_atomically(path, buffer.getvalue())


def save_keras_model_atomically(model, path: str | Path) -> Path:
    """Saves a Keras model in the native ``.keras`` format through a temporary ``.keras`` file."""
    path = Path(path)
    if path.suffix != ".keras":
        raise ValueError(f"path: expected a file name ending in .keras, got {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(TEMPORARY_PREFIX + path.stem + ".keras")
    try:
        model.save(temporary)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path
