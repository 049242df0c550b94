"""The registry of methods: the one list of paz6d's methods, name -> :class:`~paz6d.method.Method`.

``paz6d estimate``, :class:`~paz6d.detect_and_estimate.DetectAndEstimatePose6D`, ``paz6d export``
(:mod:`paz6d.export.networks`) and :func:`paz6d.run_dirs.method_of` loop over it and never name a method.
Adding a method is one package that exports ``METHOD`` and one line below (or :func:`register` at run time,
e.g. in a test)::

    from paz6d.methods import method_of
    method = method_of("runs/aae_5")              # the record whose marker files the folder holds
    pipeline = method.load("runs/aae_5", camera=K)  # pipeline(image, box, *, camera=None, depth=None)

Importing this module loads every method package's record (light: no TensorFlow).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from paz6d import aae, faces, hrnet, keypointnet, probabilistic_keypoints, segmentation, ssd, stn
from paz6d.method import TASKS, Method

_METHODS: dict[str, Method] = {}


def register(method: Method) -> Method:
    """Adds ``method`` to the registry; returns it.

    Raises:
        ValueError: not a :class:`Method`, or its name or an alias already taken.
    """
    if not isinstance(method, Method):
        raise ValueError(f"method: expected a paz6d.method.Method, got {type(method).__name__}")
    taken = {name for known in _METHODS.values() for name in (known.name, *known.aliases)}
    clashes = sorted(taken & {method.name, *method.aliases})
    if clashes:
        raise ValueError(f"method {method.name!r}: names {clashes} are taken by registered methods")
    _METHODS[method.name] = method
    return method


def unregister(name: str) -> Method:
    """Removes the method ``name`` from the registry; returns its record."""
    return _METHODS.pop(get(name).name)


@contextmanager
def registered(method: Method) -> Iterator[Method]:
    """``with registered(method):`` the method is in the registry for the block (for tests)."""
    register(method)
    try:
        yield method
    finally:
        _METHODS.pop(method.name, None)


def methods(task: str | None = None) -> tuple[Method, ...]:
    """Every registered method in registration order, or those of one task (see :data:`~paz6d.method.TASKS`)."""
    if task is not None and task not in TASKS:
        raise ValueError(f"task: expected one of {TASKS}, got {task!r}")
    return tuple(method for method in _METHODS.values() if task is None or method.task == task)


def get(name: str) -> Method:
    """The method called ``name`` (or with ``name`` among its aliases).

    Raises:
        ValueError: no such method (naming the registered ones).
    """
    for method in _METHODS.values():
        if name == method.name or name in method.aliases:
            return method
    raise ValueError(f"method: expected one of {list(_METHODS)}, got {name!r}")


def method_of(run_dir: str | Path) -> Method:
    """The method whose training wrote ``run_dir``: the one whose marker files it holds.

    Raises:
        ValueError: not a directory, or not exactly one method recognises it (the message names the
            marker files of each).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"run_dir: {run_dir} is not a directory")
    found = [method for method in _METHODS.values() if method.run_dir.is_run_dir(run_dir)]
    if len(found) != 1:
        markers = "; ".join(f"{method.name}: {' + '.join(method.run_dir.MARKER_FILES)}" for method in _METHODS.values())
        state = "matches several methods" if found else "is not a run directory of any method"
        raise ValueError(f"run_dir: {run_dir} {state} (expected the files of exactly one: {markers})")
    return found[0]


for _method in (aae.METHOD, keypointnet.METHOD, ssd.METHOD, hrnet.METHOD, probabilistic_keypoints.METHOD,
                stn.METHOD, segmentation.METHOD, faces.METHOD):
    register(_method)
