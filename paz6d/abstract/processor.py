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
    output as one value. Steps may be processors, nested sequences or any callable; each has a
    name (its ``name``, else its ``__name__``, else its type's name) by which it can be looked up
    (``pipeline["crop"]``), replaced, removed, or used as an insertion point.
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

    @property
    def names(self) -> list[str]:
        """The names of the steps, in order."""
        return [_step_name(step) for step in self._steps]

    def index(self, name: str) -> int:
        """Position of the first step named ``name``.

        Raises:
            ValueError: no such step (the message lists the step names).
        """
        for index, step in enumerate(self._steps):
            if _step_name(step) == name:
                return index
        raise ValueError(f"name: no step named {name!r}; steps are {self.names}")

    def add(self, step: Callable) -> "SequentialProcessor":
        """Appends a step; returns ``self`` for chaining."""
        self._steps.append(self._check(step))
        return self

    def insert(self, index: int | str, step: Callable, after: bool = False) -> "SequentialProcessor":
        """Inserts a step before (or, with ``after``, after) position ``index`` or the step named ``index``."""
        position = self.index(index) if isinstance(index, str) else int(index)
        if after:
            position = position + 1 if position >= 0 else len(self._steps) + position + 1
        self._steps.insert(position, self._check(step))
        return self

    def replace(self, name: str, step: Callable) -> Callable:
        """Puts ``step`` in place of the first step named ``name``; returns the step it replaced."""
        index = self.index(name)
        old, self._steps[index] = self._steps[index], self._check(step)
        return old

    def pop(self, index: int = -1) -> Callable:
        """Removes and returns the step at ``index`` (default: last)."""
        if not self._steps:
            raise IndexError("pop from an empty SequentialProcessor")
        return self._steps.pop(index)

    def remove(self, name: str) -> Callable:
        """Removes and returns the first step whose name is ``name``."""
        return self._steps.pop(self.index(name))

    def __len__(self) -> int:
        return len(self._steps)

    def __getitem__(self, index: int | slice | str) -> Callable | "SequentialProcessor":
        if isinstance(index, slice):
            return SequentialProcessor(self._steps[index], name=self._name)
        if isinstance(index, str):
            return self._steps[self.index(index)]
        return self._steps[index]

    def __iter__(self):
        return iter(self._steps)

    @property
    def steps(self) -> list[Callable]:
        """A copy of the list of steps."""
        return list(self._steps)

    def run_steps(self, value: Any, start: str | None = None, stop: str | None = None) -> Any:
        """Runs the steps from the one named ``start`` (default: the first) up to, not including, the
        one named ``stop`` (default: to the end) on one value (for :class:`KeyedStep` pipelines, the
        dict of named values)."""
        first = 0 if start is None else self.index(start)
        last = len(self._steps) if stop is None else self.index(stop)
        for step in self._steps[first:last]:
            value = step(value)
        return value

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
        return f"{type(self).__name__}(name={self.name!r}, steps={self.names})"


class KeyedStep(Processor):
    """A pipeline step over named values: calls ``processor`` with some values of a dict and adds its
    results to (a copy of) that dict.

    Pipelines whose steps need more than the previous step's output (the image, the box, the
    camera...) pass one dict from step to step; each :class:`KeyedStep` says which values it reads
    and which it writes, so a step can be replaced by any callable with the same inputs and outputs.

    Args:
        processor: any callable.
        inputs: keys whose values are passed as positional arguments, in order.
        outputs: one key (the whole result) or several keys (the result is a tuple of that length).
        name: the step's name (default: the processor's name).
        per_sample: the input values are sequences of one entry per sample (a batch): ``processor``
            runs once per sample and each output is a list. A sample whose input is an exception
            (an earlier step's failure) skips the processor and passes the exception on.
        failures: exception types that, with ``per_sample``, become the failing sample's outputs
            instead of being raised, so one bad sample does not stop a batch.

    Example:
        >>> step = KeyedStep(lambda a, b: a + b, inputs=("a", "b"), outputs="total", name="add")
        >>> step({"a": 1, "b": 2})
        {'a': 1, 'b': 2, 'total': 3}
    """

    def __init__(self, processor: Callable, inputs: str | Iterable[str], outputs: str | Iterable[str],
                 name: str | None = None, per_sample: bool = False, failures: tuple[type[Exception], ...] = ()):
        super().__init__(name or _step_name(processor))
        self.processor = SequentialProcessor._check(processor)
        self.inputs = (inputs,) if isinstance(inputs, str) else tuple(inputs)
        self.outputs = (outputs,) if isinstance(outputs, str) else tuple(outputs)
        if not self.outputs:
            raise ValueError("outputs: expected at least one key")
        self.per_sample, self.failures = bool(per_sample), tuple(failures)

    def _arguments(self, values: dict) -> list:
        if not isinstance(values, dict):
            raise ValueError(f"step {self.name!r}: expected a dict of named values, got {type(values).__name__}")
        missing = [key for key in self.inputs if key not in values]
        if missing:
            raise ValueError(f"step {self.name!r}: needs {missing}, but the values are {sorted(values)}")
        return [values[key] for key in self.inputs]

    def _split(self, result) -> tuple:
        if len(self.outputs) == 1:
            return (result,)
        if not isinstance(result, tuple) or len(result) != len(self.outputs):
            raise ValueError(f"step {self.name!r}: expected a tuple of {len(self.outputs)} results "
                             f"{list(self.outputs)}, got {type(result).__name__}")
        return result

    def _run_sample(self, arguments: tuple) -> tuple:
        failed = next((value for value in arguments if isinstance(value, BaseException)), None)
        if failed is not None:
            return (failed,) * len(self.outputs)
        try:
            return self._split(self.processor(*arguments))
        except self.failures as error:
            return (error,) * len(self.outputs)

    def call(self, values: dict) -> dict:
        arguments = self._arguments(values)
        if self.per_sample:
            lengths = {len(argument) for argument in arguments}
            if len(lengths) > 1:
                raise ValueError(f"step {self.name!r}: inputs {list(self.inputs)} have different batch sizes "
                                 f"{[len(argument) for argument in arguments]}")
            samples = [self._run_sample(sample) for sample in zip(*arguments)]
            results = tuple([sample[i] for sample in samples] for i in range(len(self.outputs)))
        else:
            results = self._split(self.processor(*arguments))
        return {**values, **dict(zip(self.outputs, results))}

    def __repr__(self) -> str:
        return (f"KeyedStep(name={self.name!r}, processor={_step_name(self.processor)!r}, "
                f"inputs={list(self.inputs)}, outputs={list(self.outputs)})")
