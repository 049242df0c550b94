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
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import numpy as np

from paz6d.backend.paths import check_output_file

TEMPORARY_PREFIX = ".paz6d-tmp-"


def _current_umask() -> int:
    """The process umask, read without changing it where Linux shows it (no window in which
    other threads would create files with a zero umask)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def prepare_output_file(path: str | Path) -> Path:
    """Checks that ``path`` may receive an output file (:func:`check_output_file`) and creates its folder.

    Raises:
        ValueError: naming ``path`` and what stands there.
    """
    path = check_output_file(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as error:
        raise ValueError(f"{path}: cannot create its folder {path.parent} (a file stands in the way)") from error
    return path


@contextmanager
def atomic_output(path: str | Path) -> Iterator[BinaryIO]:
    """A binary stream whose content appears at ``path`` (``os.replace``) only when the block ends
    without an exception; otherwise the temporary file in the same folder is removed. The file
    gets the permissions of a newly created file (``0o666`` less the umask), as ``open`` would
    give it. See :func:`prepare_output_file` for the paths that are refused."""
    path = prepare_output_file(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=TEMPORARY_PREFIX + path.name + ".")
    try:
        with os.fdopen(handle, "wb") as stream:
            os.fchmod(stream.fileno(), 0o666 & ~_current_umask())
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


def finite_or_none(value: float | None, digits: int | None = None) -> float | None:
    """``float(value)`` (rounded to ``digits``), or ``None`` (JSON ``null``) for ``None``, NaN and ±inf,
    e.g. a median over misses or a throughput when nothing ran."""
    if value is None or not np.isfinite(value):
        return None
    return float(value) if digits is None else round(float(value), digits)


def null_non_finite(data: Any) -> Any:
    """``data`` with every NaN/±inf float (Python or NumPy, inside dicts, lists and tuples) replaced by
    ``None``: a report that may hold unmeasured values becomes valid JSON for :func:`json_bytes`."""
    if isinstance(data, dict):
        return {key: null_non_finite(value) for key, value in data.items()}
    if isinstance(data, (list, tuple)):
        return [null_non_finite(value) for value in data]
    if isinstance(data, (float, np.floating)):
        return finite_or_none(data)
    return data


#: Longest quoted excerpt of a parser's message about a bad input file (characters).
EXCERPT_LIMIT = 200


def _excerpt(text: str) -> str:
    return text if len(text) <= EXCERPT_LIMIT else text[:EXCERPT_LIMIT] + " ..."


@contextmanager
def input_file_errors(path: str | Path, what: str = "file") -> Iterator[None]:
    """Turns the ``OSError`` of opening or reading the input file ``path`` inside the block into a
    ``ValueError`` naming it and ``what`` it should be: missing, a folder, or unreadable."""
    try:
        yield
    except FileNotFoundError as error:
        raise ValueError(f"{path}: {what} not found") from error
    except IsADirectoryError as error:
        raise ValueError(f"{path}: expected {_article(what)} {what}, found a folder") from error
    except OSError as error:
        raise ValueError(f"{path}: cannot read the {what} ({error.strerror or error})") from error


def _article(noun: str) -> str:
    return "an" if noun[:1].lower() in "aeiou" else "a"


def read_input_bytes(path: str | Path, what: str = "file") -> bytes:
    """The bytes of an input file; ``ValueError`` naming it when it is missing, a folder or unreadable."""
    path = Path(path)
    with input_file_errors(path, what):
        return path.read_bytes()


def read_input_text(path: str | Path, what: str = "file") -> str:
    """An input file as UTF-8 text (a leading byte-order mark is dropped); ``ValueError`` naming the
    file when it is missing, a folder, unreadable or not UTF-8."""
    data = read_input_bytes(path, what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text (byte {error.start}: {error.reason})") from error


def load_json(path: str | Path) -> Any:
    """Parses a JSON file; ``ValueError`` naming the file when it is missing, a folder, not UTF-8,
    malformed, nested too deeply or holds a number too long to convert."""
    path = Path(path)
    text = read_input_text(path)
    try:
        return json.loads(text)
    except RecursionError as error:
        raise ValueError(f"{path}: invalid JSON (nested too deeply)") from error
    except ValueError as error:  # JSONDecodeError, and int() of a number with too many digits
        raise ValueError(f"{path}: invalid JSON ({_excerpt(str(error))})") from error


def load_json_object(path: str | Path) -> dict:
    """:func:`load_json` of a file that must hold a JSON object; ``ValueError`` naming the file otherwise."""
    data = load_json(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def load_run_json(path: str | Path, fields: tuple[str, ...], kind: str, description: str | None = None) -> dict:
    """A run directory's JSON object file that must hold ``fields``; ``kind`` names the method's run
    directories in the message of a missing file (``"an HRNet"``: "is DIR an HRNet run directory?");
    with ``description``, a file that is not valid JSON is reported as ``"<path>: corrupt <description>
    (<why>)"``.

    Raises:
        ValueError: the file is missing, not valid JSON, not a JSON object or lacks fields (naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file not found (is {path.parent} {kind} run directory?)")
    try:
        data = load_json(path)
    except ValueError as error:
        if description is None:
            raise
        raise ValueError(f"{path}: corrupt {description} ({error})") from error
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}")
    missing = [name for name in fields if name not in data]
    if missing:
        raise ValueError(f"{path}: missing field(s) {missing}")
    return data


def check_run_files(run_dir: str | Path, names: tuple[str, ...], kind: str) -> Path:
    """``run_dir`` as a Path, checked to be a directory holding every file of ``names`` (``kind`` as in
    :func:`load_run_json`).

    Raises:
        ValueError: not a directory, or the first missing file.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"run_dir: {run_dir} is not a directory")
    for name in names:
        if not (run_dir / name).is_file():
            raise ValueError(f"{run_dir / name}: file not found (is {run_dir} {kind} run directory?)")
    return run_dir


def load_npz(path: str | Path, what: str = "arrays") -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file (no pickled objects); ``ValueError`` naming the file when it is
    missing, a folder, truncated or not an ``.npz`` archive (``what`` says what it should hold)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: {what} file not found" if not path.exists() else f"{path}: not a file ({what})")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: not a readable .npz file of {what} ({_excerpt(str(error)) or type(error).__name__}; "
                         "truncated or overwritten?)") from error


def read_cache(path: str | Path, keys: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """The arrays of a cache ``.npz`` file, or ``None`` when it is absent, unreadable (truncated,
    overwritten) or lacks one of ``keys``: a cache that cannot be used is made again."""
    if not Path(path).is_file():
        return None
    try:
        arrays = load_npz(path, "cached arrays")
    except ValueError:
        return None
    return arrays if all(key in arrays for key in keys) else None


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
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    return write_bytes_atomically(path, buffer.getvalue())


def save_keras_model_atomically(model, path: str | Path) -> Path:
    """Saves a Keras model in the native ``.keras`` format through a temporary ``.keras`` file."""
    path = Path(path)
    if path.suffix != ".keras":
        raise ValueError(f"path: expected a file name ending in .keras, got {path}")
    prepare_output_file(path)
    temporary = path.with_name(TEMPORARY_PREFIX + path.stem + ".keras")
    try:
        model.save(temporary)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path
