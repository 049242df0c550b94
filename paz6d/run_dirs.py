"""Which method wrote a run directory: each method's ``run_dir`` module recognises its own; and the
check every ``paz6d train <method>`` and ``paz6d benchmark`` makes before writing into its ``--out``."""

from __future__ import annotations

import json
import os
from pathlib import Path

from paz6d.aae import run_dir as aae_run_dir
from paz6d.hrnet import run_dir as hrnet_run_dir
from paz6d.keypointnet import run_dir as keypointnet_run_dir
from paz6d.probabilistic_keypoints import run_dir as probabilistic_keypoints_run_dir
from paz6d.segmentation import run_dir as segmentation_run_dir
from paz6d.ssd import run_dir as ssd_run_dir
from paz6d.stn import run_dir as stn_run_dir

#: Method name (as in ``paz6d train <method>``) -> the module that owns that method's run directories;
#: each names the files that mark its run directories in ``MARKER_FILES``.
RUN_DIR_MODULES = {"aae": aae_run_dir, "keypointnet": keypointnet_run_dir, "ssd": ssd_run_dir,
                   "hrnet": hrnet_run_dir, "probabilistic-keypoints": probabilistic_keypoints_run_dir,
                   "stn": stn_run_dir, "segmentation": segmentation_run_dir}


#: Marker files of the other commands that own an output folder (no ``run_dir`` module of their own).
OTHER_MARKER_FILES = {"emotion": ("classes.json",), "benchmark lmo": ("report.json",)}

#: The file naming the command that owns an output folder, written by :func:`prepare_run_output`.
OWNER_FILE = ".paz6d-run.json"


def _owner(out: Path) -> str | None:
    """The owner recorded in ``out/OWNER_FILE``, else the one method whose marker files ``out`` holds."""
    stamp = out / OWNER_FILE
    if os.path.lexists(stamp):
        from paz6d.backend.files import load_json_object

        method = load_json_object(stamp).get("method") if stamp.is_file() and not stamp.is_symlink() else None
        if not isinstance(method, str):
            raise ValueError(f'{stamp}: expected a regular file holding {{"method": "<name>"}}; remove it '
                             "only if the folder is yours")
        return method
    found = [method for method in RUN_DIR_MODULES if is_run_dir(out, method)]
    found += [name for name, markers in OTHER_MARKER_FILES.items() if all((out / m).is_file() for m in markers)]
    return found[0] if len(found) == 1 else (", ".join(found) if found else None)


def prepare_run_output(out: str | Path, method: str, inputs: dict[str, str | Path | None] | None = None,
                       flag: str = "--out") -> Path:
    """The output rule for a command's output folder (:func:`paz6d.backend.paths.check_outputs`: not a
    symbolic link, a file or a data set, not one of ``inputs``), and ownership: an existing folder
    that another command or method wrote (its :data:`OWNER_FILE`, else its marker files) is refused.
    Then creates ``out`` and records ``method`` as its owner.

    Args:
        out: the output folder.
        method: the owner's name (``"ssd"``, ``"emotion"``, ``"benchmark lmo"``).
        inputs: ``{flag: path}`` of the files and folders the command reads.
        flag: the flag that named ``out``, for messages.

    Raises:
        ValueError: naming the flag, the folder and its owner.
    """
    from paz6d.backend.files import write_json_atomically
    from paz6d.backend.paths import check_outputs

    out = Path(out)
    check_outputs({}, inputs or {}, {flag: out})
    if out.is_dir():
        owner = _owner(out)
        if owner is not None and owner != method:
            raise ValueError(f"{flag}: {out} is an output folder of {owner}, not {method}; give a new folder "
                             f"(or a {method} run to resume)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"{flag}: cannot create the folder {out} ({error.strerror or error})") from error
    if not os.path.lexists(out / OWNER_FILE):
        write_json_atomically(out / OWNER_FILE, {"method": method})
    return out


def is_run_dir(run_dir: str | Path, method: str) -> bool:
    """True when ``run_dir`` holds every marker file of ``method``'s run directories."""
    return all((Path(run_dir) / name).is_file() for name in RUN_DIR_MODULES[method].MARKER_FILES)


def method_of(run_dir: str | Path) -> str:
    """The method (a key of :data:`RUN_DIR_MODULES`) whose training wrote ``run_dir``.

    Raises:
        ValueError: not a directory, or no method recognises it (the message names the marker files).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"run_dir: {run_dir} is not a directory")
    found = [method for method in RUN_DIR_MODULES if is_run_dir(run_dir, method)]
    if len(found) != 1:
        markers = "; ".join(f"{method}: {' + '.join(module.MARKER_FILES)}"
                            for method, module in RUN_DIR_MODULES.items())
        state = "matches several methods" if found else "is not a run directory of any method"
        raise ValueError(f"run_dir: {run_dir} {state} (expected the files of exactly one: {markers})")
    return found[0]
