"""Processors: named callables that compose into pipelines.

A :class:`Processor` wraps one step; a :class:`SequentialProcessor` chains steps, feeding each
step's output to the next. Any Python callable may be a step (plain functions included), and
sequences nest.

Example:
    >>> from paz6d.abstract import SequentialProcessor
    >>> pipeline = SequentialProcessor([lambda x: x + 1, lambda x: 2 * x])
    >>> pipeline(3)
    8
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np


class Processor:
    """Base class of a processing step: subclasses implement :meth:`call`.

    Args:
        name: display name; defaults to the class name.
    """

    def __init__(self, name: str | None = None):
        self._name = name

    @property
    def name(self) -> str:
        return self._name or type(self).__name__

    @name.setter
    def name(self, value: str) -> None:
        self._name = value

    def call(self, *args, **kwargs) -> Any:
        raise NotImplementedError(f"{type(self).__name__} must implement call()")

    def __call__(self, *args, **kwargs) -> Any:
        return self.call(*args, **kwargs)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


class RandomProcessor(Processor):
    """A processor that draws random numbers from its own ``numpy.random.Generator``.

    Args:
        seed: an int, a ``SeedSequence``, a ``Generator`` (used as is) or None (fresh entropy).
        name: display name.
    """

    def __init__(self, seed: int | np.random.SeedSequence | np.random.Generator | None = None,
                 name: str | None = None):
        super().__init__(name)
        self.generator = np.random.default_rng(seed)

    def reseed(self, seed: int | np.random.SeedSequence | np.random.Generator | None) -> None:
        """Replaces the generator (e.g. one per sample, so results do not depend on worker order)."""
        self.generator = np.random.default_rng(seed)


def random_processors(processor: Callable) -> list[RandomProcessor]:
    """All :class:`RandomProcessor` objects reachable from ``processor`` (itself, the steps of
    sequences and processors held in attributes, lists, tuples or dicts), in a fixed depth-first
    order, each once."""
    found: list[RandomProcessor] = []
    seen: set[int] = set()

    def visit(value: Any) -> None:
        if isinstance(value, (list, tuple)):
            for item in value:
                visit(item)
        elif isinstance(value, dict):
            for item in value.values():
                visit(item)
        elif isinstance(value, Processor) and id(value) not in seen:
            seen.add(id(value))
            if isinstance(value, RandomProcessor):
                found.append(value)
            for attribute in vars(value).values():
                visit(attribute)

    visit(processor)
    return found


def reseed(processor: Callable, seed: int | Iterable[int] | np.random.SeedSequence) -> None:
    """Gives every random processor inside ``processor`` an independent generator derived from
    ``seed`` (spawned from one ``SeedSequence`` in :func:`random_processors` order)."""
    sequence = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    targets = random_processors(processor)
    for target, child in zip(targets, sequence.spawn(len(targets))):
        target.reseed(child)


def _step_name(step: Callable) -> str:
    return getattr(step, "name", None) or getattr(step, "__name__", None) or type(step).__name__


class SequentialProcessor(Processor):
    """Applies its steps in order: ``y = step_n(...step_2(step_1(x)))``.

    The first step receives all call arguments; every later step receives the previous
    output as one value. Steps may be processors, nested sequences or any callable.
    """

    def __init__(self, steps: Iterable[Callable] | None = None, name: str | None = None):
        super().__init__(name)
        self._steps: list[Callable] = []
        for step in steps or []:
            self.add(step)

    @staticmethod
    def _check(step: Callable) -> Callable:
        if not callable(step):
            raise ValueError(f"step: expected a callable (Processor or function), got {type(step).__name__}")
        return step

    def add(self, step: Callable) -> "SequentialProcessor":
        """Appends a step; returns ``self`` for chaining."""
        self._steps.append(self._check(step))
        return self

    def insert(self, index: int, step: Callable) -> "SequentialProcessor":
        """Inserts a step before position ``index``."""
        self._steps.insert(index, self._check(step))
        return self

    def pop(self, index: int = -1) -> Callable:
        """Removes and returns the step at ``index`` (default: last)."""
        if not self._steps:
            raise IndexError("pop from an empty SequentialProcessor")
        return self._steps.pop(index)

    def remove(self, name: str) -> Callable:
        """Removes and returns the first step whose name is ``name``."""
        for index, step in enumerate(self._steps):
            if _step_name(step) == name:
                return self._steps.pop(index)
        raise ValueError(f"name: no step named {name!r}; steps are {[_step_name(s) for s in self._steps]}")

    def __len__(self) -> int:
        return len(self._steps)

    def __getitem__(self, index: int | slice) -> Callable | "SequentialProcessor":
        if isinstance(index, slice):
            return SequentialProcessor(self._steps[index], name=self._name)
        return self._steps[index]

    def __iter__(self):
        return iter(self._steps)

    @property
    def steps(self) -> list[Callable]:
        """A copy of the list of steps."""
        return list(self._steps)

    def call(self, *args, **kwargs) -> Any:
        if not self._steps:
            if kwargs or len(args) != 1:
                return args
            return args[0]
        output = self._steps[0](*args, **kwargs)
        for step in self._steps[1:]:
            output = step(output)
        return output

    def __repr__(self) -> str:
        inner = ", ".join(_step_name(step) for step in self._steps)
        return f"SequentialProcessor(name={self.name!r}, steps=[{inner}])"
