"""The shared Trainer's files in a run directory and their validators (light: numpy only)::

    run_dir/
      checkpoint.json              {"step": 1000, "path": "checkpoints/step_00001000", "kept": [800, 1000]}
      checkpoints/step_00001000/   model.weights.h5 (Keras HDF5 weights), optimizer.npz (the optimizer's
                                   variables "0", "1", ... in its order), state.json
      log.csv                      step, wall time, data/step seconds, every metric; one row per logged step

One validator per file, each raising ``ValueError`` naming the file and what is wrong:
:func:`read_pointer` (``checkpoint.json``, and that its folder holds both checkpoint files),
:func:`check_weights_file` (``model.weights.h5``), :func:`read_optimizer_state` (``optimizer.npz``) and
:func:`read_log` (``log.csv``). :func:`check_training_files` runs them all when a run directory is opened
to resume (:func:`paz6d.run_dirs.prepare_run_output`, before any long work); the
:class:`~paz6d.training.trainer.Trainer` reads the files through them when it restores, and checks there
what only the network tells: the step against its total, the weights and the optimizer state against
its variables.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.files import load_json, load_npz, read_input_text
from paz6d.backend.paths import path_inside

CHECKPOINT_POINTER = "checkpoint.json"
LOG_FILE = "log.csv"
WEIGHTS_FILE = "model.weights.h5"
OPTIMIZER_FILE = "optimizer.npz"
STATE_FILE = "state.json"
#: The first bytes of every HDF5 file (Keras writes ``.weights.h5`` files without a user block).
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass(frozen=True)
class Checkpoint:
    """What ``checkpoint.json`` points to.

    Attributes:
        step: the step of the latest checkpoint.
        folder: its folder (inside the run directory), holding :data:`WEIGHTS_FILE` and :data:`OPTIMIZER_FILE`.
        kept: the steps of the checkpoints the run keeps, oldest first, ``step`` last.
    """

    step: int
    folder: Path
    kept: list[int]

    @property
    def weights(self) -> Path:
        return self.folder / WEIGHTS_FILE

    @property
    def optimizer(self) -> Path:
        return self.folder / OPTIMIZER_FILE


def read_pointer(run_dir: str | Path) -> Checkpoint | None:
    """The latest checkpoint from ``run_dir/checkpoint.json``, or ``None`` when there is none.

    Raises:
        ValueError: the pointer is not valid JSON, its ``step`` is no non-negative integer, its ``kept`` no
            list of steps up to ``step``, its ``path`` leads outside the run directory, or the folder lacks
            a checkpoint file (naming the file).
    """
    run_dir = Path(run_dir)
    pointer = run_dir / CHECKPOINT_POINTER
    if not pointer.exists():
        return None
    try:
        data = load_json(pointer)
        step, kept = data["step"], data.get("kept", [data["step"]])
        if type(step) is not int or step < 0:
            raise ValueError(f'"step" must be a non-negative integer, got {step!r:.40}')
        if not isinstance(kept, list) or not all(type(item) is int and 0 <= item <= step for item in kept):
            raise ValueError(f'"kept" must be a list of steps up to "step", got {kept!r:.60}')
        folder = path_inside(run_dir, data["path"], f'{pointer}: "path"')
    except (KeyError, TypeError, ValueError, AttributeError, RecursionError) as error:
        raise ValueError(f"{pointer}: corrupt checkpoint pointer ({error}); delete it to start over") from error
    checkpoint = Checkpoint(step, folder, [item for item in kept if item != step] + [step])
    for path in (checkpoint.weights, checkpoint.optimizer):
        if not path.is_file():
            raise ValueError(f"{pointer}: points to {folder}, which has no {path.name}; delete {pointer.name} to "
                             f"start over")
    return checkpoint


def check_weights_file(path: str | Path) -> Path:
    """``path``, checked to be an HDF5 file (the checkpoint's network weights; what they fit is checked
    when they are loaded).

    Raises:
        ValueError: missing, unreadable or not HDF5 (naming the file).
    """
    path = Path(path)
    try:
        with path.open("rb") as stream:
            head = stream.read(len(HDF5_SIGNATURE))
    except OSError as error:
        raise ValueError(f"{path}: cannot read the checkpoint's weights ({error.strerror or error})") from error
    if head != HDF5_SIGNATURE:
        raise ValueError(f"{path}: not an HDF5 weights file (corrupt or overwritten); delete its checkpoint "
                         f"folder and {CHECKPOINT_POINTER} to start over")
    return path


def read_optimizer_state(path: str | Path) -> list[np.ndarray]:
    """The optimizer's variables stored in ``optimizer.npz`` (arrays ``"0"``, ``"1"``, ... in order).

    Raises:
        ValueError: unreadable, or its arrays are not named ``0`` to ``n - 1`` (naming the file).
    """
    arrays = load_npz(path, "optimizer state")
    expected = [str(index) for index in range(len(arrays))]
    if sorted(arrays, key=lambda name: (len(name), name)) != expected:
        raise ValueError(f"{path}: expected the optimizer's variables as arrays '0' to '{len(arrays) - 1}', got "
                         f"{sorted(arrays)[:8]}")
    return [arrays[name] for name in expected]


def read_log(path: str | Path) -> list[dict[str, str]]:
    """The rows of ``log.csv`` (``[]`` when there is none): a header holding ``step``, then one row per
    logged step, steps positive integers in increasing order.

    Raises:
        ValueError: not UTF-8 CSV, no ``step`` column, a row of another length or a bad step (naming the
            file and line).
    """
    path = Path(path)
    if not path.exists():
        return []
    lines = read_input_text(path, "training log").splitlines()
    try:
        table = list(csv.reader(lines))
    except csv.Error as error:
        raise ValueError(f"{path}: not a readable CSV training log ({error})") from error
    if not table or "step" not in table[0]:
        raise ValueError(f"{path}: line 1: expected a header with a 'step' column, got {table[0][:8] if table else []}")
    header, rows, previous = table[0], [], 0
    for number, values in enumerate(table[1:], start=2):
        step = values[header.index("step")] if len(values) == len(header) else None
        if step is None or not (step.isascii() and step.isdigit()) or not previous < int(step):
            raise ValueError(f"{path}: line {number}: expected {len(header)} values with a step after {previous}, "
                             f"got {values[:8]}")
        previous = int(step)
        rows.append(dict(zip(header, values)))
    return rows


def check_training_files(run_dir: str | Path) -> Checkpoint | None:
    """Runs every validator on the Trainer's files in ``run_dir`` (a run about to resume); returns its
    latest checkpoint (``None``: there is none).

    Raises:
        ValueError: naming the first file that is corrupt or missing.
    """
    checkpoint = read_pointer(run_dir)
    if checkpoint is not None:
        check_weights_file(checkpoint.weights)
        read_optimizer_state(checkpoint.optimizer)
    read_log(Path(run_dir) / LOG_FILE)
    return checkpoint
