"""Which method wrote a run directory: each method's ``run_dir`` module recognises its own."""

from __future__ import annotations

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
