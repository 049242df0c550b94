"""Which method wrote a run directory: each method's ``run_dir`` module recognises its own."""

from __future__ import annotations

from pathlib import Path

from paz6d.aae import run_dir as aae_run_dir
from paz6d.keypointnet import run_dir as keypointnet_run_dir
from paz6d.ssd import run_dir as ssd_run_dir

#: Method name -> the module that owns that method's run directories.
RUN_DIR_MODULES = {"aae": aae_run_dir, "keypointnet": keypointnet_run_dir, "ssd": ssd_run_dir}


def method_of(run_dir: str | Path) -> str:
    """``"aae"``, ``"keypointnet"`` or ``"ssd"``: the method whose training wrote ``run_dir``.

    Raises:
        ValueError: not a directory, or no method recognises it (the message names the marker files).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"run_dir: {run_dir} is not a directory")
    found = [method for method, module in RUN_DIR_MODULES.items() if module.is_run_dir(run_dir)]
    if len(found) != 1:
        markers = "; ".join(f"{method}: {' + '.join(module.MARKER_FILES)}"
                            for method, module in RUN_DIR_MODULES.items())
        state = "matches several methods" if found else "is not a run directory of any method"
        raise ValueError(f"run_dir: {run_dir} {state} (expected the files of exactly one: {markers})")
    return found[0]
