"""Which method wrote a run directory (each registered method's ``RunDir`` recognises its own, see
:mod:`paz6d.methods`); and the check every ``paz6d train <method>`` and ``paz6d benchmark`` makes before
writing into its ``--out``: the folder's owner and, when it is a run to resume, its files."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from paz6d import methods as registry
from paz6d.backend.files import load_json_object, write_json_atomically
from paz6d.backend.paths import check_outputs
from paz6d.cli_options import config_from_args, config_inputs, flags_in_errors
from paz6d.training.checkpoints import check_training_files

#: Method name -> the module of its run directory class (file names, ``read_model``), for the methods
#: registered when this module was imported.
RUN_DIR_MODULES = {method.name: importlib.import_module(method.run_dir.__module__) for method in registry.methods()}

#: Marker files of the other commands that own an output folder (no ``run_dir`` module of their own).
OTHER_MARKER_FILES = {"benchmark lmo": ("report.json",)}

#: The file naming the command that owns an output folder, written by :func:`prepare_run_output`.
OWNER_FILE = ".paz6d-run.json"


def _owner(out: Path) -> str | None:
    """The owner recorded in ``out/OWNER_FILE``, else the one method whose marker files ``out`` holds."""
    stamp = out / OWNER_FILE
    if os.path.lexists(stamp):
        method = load_json_object(stamp).get("method") if stamp.is_file() and not stamp.is_symlink() else None
        if not isinstance(method, str):
            raise ValueError(f'{stamp}: expected a regular file holding {{"method": "<name>"}}; remove it '
                             "only if the folder is yours")
        return method
    found = [method.name for method in registry.methods() if method.run_dir.is_run_dir(out)]
    found += [name for name, markers in OTHER_MARKER_FILES.items() if all((out / m).is_file() for m in markers)]
    return found[0] if len(found) == 1 else (", ".join(found) if found else None)


def check_resumed_run(out: Path, method: str) -> None:
    """Opens ``out``, an existing output folder of ``method``, to resume it: the validators of its files run
    (the method's ``config.json`` check, :meth:`~paz6d.run_dir.RunDir.check_config`, when ``method`` is a
    registered method; the Trainer's ``checkpoint.json``, checkpoint files and ``log.csv``) before the
    command's long work.

    Raises:
        ValueError: naming the first corrupt file and field.
    """
    run_dir = next((known.run_dir for known in registry.methods() if known.name == method), None)
    if run_dir is not None and run_dir.config_path(out).is_file():
        run_dir.read_config(out)
    check_training_files(out)


def prepare_run_output(out: str | Path, method: str, inputs: dict[str, str | Path | None] | None = None,
                       flag: str = "--out") -> Path:
    """The output rule for a command's output folder (:func:`paz6d.backend.paths.check_outputs`: not a
    symbolic link, a file or a data set, not one of ``inputs``), and ownership: an existing folder
    that another command or method wrote (its :data:`OWNER_FILE`, else its marker files) is refused,
    one of ``method`` is opened to resume (:func:`check_resumed_run`). Then creates ``out`` and records
    ``method`` as its owner.

    Args:
        out: the output folder.
        method: the owner's name (``"ssd"``, ``"emotion"``, ``"benchmark lmo"``).
        inputs: ``{flag: path}`` of the files and folders the command reads.
        flag: the flag that named ``out``, for messages.

    Raises:
        ValueError: naming the flag, the folder and its owner.
    """
    out = Path(out)
    check_outputs({}, inputs or {}, {flag: out})
    if out.is_dir():
        owner = _owner(out)
        if owner is not None and owner != method:
            raise ValueError(f"{flag}: {out} is an output folder of {owner}, not {method}; give a new folder "
                             f"(or a {method} run to resume)")
        check_resumed_run(out, method)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"{flag}: cannot create the folder {out} ({error.strerror or error})") from error
    if not os.path.lexists(out / OWNER_FILE):
        write_json_atomically(out / OWNER_FILE, {"method": method})
    return out


@contextlib.contextmanager
def run_output(out: str | Path, method: str, inputs: dict[str, str | Path | None] | None = None,
               flag: str = "--out") -> Iterator[Path]:
    """:func:`prepare_run_output` around a command's work: when the work fails having written nothing
    but the owner file, the owner file (and the folder, when this call created it) is removed again,
    so a refused command leaves no trace and claims no folder."""
    out = Path(out)
    existed = os.path.lexists(out)
    prepare_run_output(out, method, inputs, flag)
    try:
        yield out
    except BaseException:
        if [path.name for path in out.iterdir()] == [OWNER_FILE]:
            (out / OWNER_FILE).unlink()
            if not existed:
                out.rmdir()
        raise


def is_run_dir(run_dir: str | Path, method: str) -> bool:
    """True when ``run_dir`` holds every marker file of ``method``'s run directories."""
    return registry.get(method).run_dir.is_run_dir(run_dir)


def method_of(run_dir: str | Path) -> str:
    """The name of the method whose training wrote ``run_dir`` (:func:`paz6d.methods.method_of`).

    Raises:
        ValueError: not a directory, or no method recognises it (the message names the marker files).
    """
    return registry.method_of(run_dir).name


def training_output(settings: Any, method: str) -> contextlib.AbstractContextManager[Path]:
    """``settings.out`` checked by the one output rule and claimed for ``method`` while the block runs
    (:func:`run_output`, with the settings' other paths as the inputs)."""
    return run_output(settings.out, method, config_inputs(settings))


def run_training(config_class: type, args: argparse.Namespace, train: Callable[[Any], dict]) -> int:
    """The ``run`` of a ``paz6d train <method>`` command (the method is ``args.model``): the run's
    settings from the flags (every field but ``settings``), ``--out`` checked and claimed
    (:func:`training_output`), ``train(settings)`` and its summary printed as JSON; returns the exit
    status 0.

    Raises:
        ValueError: bad settings or a failed run, naming the flag (:func:`flags_in_errors`).
    """
    job = config_from_args(config_class, args, exclude=("settings",))
    with flags_in_errors(config_class), training_output(job, args.model):
        summary = train(job)
    print(json.dumps(summary, indent=2))
    return 0
