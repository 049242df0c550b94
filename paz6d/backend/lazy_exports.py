"""Packages that re-export their modules' names but import a module only when one of its names is used.

Example (in a package's ``__init__.py``)::

    __getattr__, __dir__, __all__ = lazy_exports(__name__, {"reader": ("BOPDataset",), "units": ("MM_PER_M",)})
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence


def lazy_exports(package: str, exports: Mapping[str, Sequence[str]]) -> tuple[Callable, Callable, list[str]]:
    """The module-level ``__getattr__``, ``__dir__`` and ``__all__`` of ``package`` that export each name
    of ``exports`` (module name relative to the package -> its exported names), importing the module
    on first use and caching the name in the package."""
    module_of = {name: module for module, names in exports.items() for name in names}
    names = sorted(module_of)

    def __getattr__(name: str):
        if name not in module_of:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module_of[name]}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__, names
