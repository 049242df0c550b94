"""Typed, frozen training settings, the one settings mechanism of the ``paz6d train <method>`` commands.

A method's settings (model, data and schedule) are a frozen dataclass deriving from :class:`Settings` with
named presets (``QUICK``, ``FULL``, ... collected in the method's ``CONFIGS``); every field is declared with
:func:`setting` (its default and the range its values must lie in) and is checked once, where the settings
are made: its type (from the annotation), finite numbers, the range, and the class's :meth:`Settings.check`
across fields. A check fails with a ``ValueError`` that starts with the field's name (``"steps: expected
..."``), so that the command line reports it under the flag of the same name (:mod:`paz6d.cli_options`).

A run's settings are a preset (or settings given to the run's dataclass, e.g. a tiny network in tests)
with the run's flags applied (:func:`run_settings`). ``to_dict``/``from_dict`` write and read them as the
``"settings"`` object of the run's ``config.json``: :meth:`Settings.from_dict` refuses unknown fields and
gives absent ones their defaults (the values the trainers used before the field existed);
:func:`check_same_run` compares a resumed run with the one its ``config.json`` records.

Light: standard library only, so that the ``paz6d train <method>`` parsers stay cheap.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from pathlib import Path
from typing import Any, TypeVar, Union

S = TypeVar("S", bound="Settings")


def setting(default: Any, *, minimum: float | None = None, maximum: float | None = None, positive: bool = False,
            choices: tuple | None = None, ordered: bool = False) -> Any:
    """A field of a :class:`Settings` class: its ``default`` and what its value (each element of a tuple)
    must be: at least ``minimum``, at most ``maximum``, above 0 (``positive``), one of ``choices``;
    ``ordered``: a tuple whose values do not decrease (a range ``(low, high)``)."""
    rules = {"minimum": minimum, "maximum": maximum, "positive": positive, "choices": choices, "ordered": ordered}
    return dataclasses.field(default=default, metadata={key: value for key, value in rules.items()
                                                      if value is not None and value is not False})


def positive(default: Any) -> Any:
    """A :func:`setting` above 0 (sizes, counts, steps, rates)."""
    return setting(default, positive=True)


def share(default: Any) -> Any:
    """A :func:`setting` in [0, 1] (probabilities, fractions)."""
    return setting(default, minimum=0.0, maximum=1.0)


def _fail(name: str, expected: str, value: Any) -> typing.NoReturn:
    raise ValueError(f"{name}: expected {expected}, got {value!r}")


def _checked_number(value: Any, kind: type, name: str, rules: dict) -> Any:
    """``value`` as ``kind`` (bool, int, float or str) within ``rules``."""
    if kind is bool:
        if not isinstance(value, bool):
            _fail(name, "true or false", value)
        return value
    if kind is str:
        if not isinstance(value, str):
            _fail(name, "a string", value)
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            _fail(name, "a whole number", value)
        value = int(value)
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            _fail(name, "a finite number", value)
        value = float(value)
    else:
        raise TypeError(f"{name}: settings cannot hold a {kind}")
    if "choices" in rules and value not in rules["choices"]:
        _fail(name, f"one of {rules['choices']}", value)
    if rules.get("positive") and not value > 0:
        _fail(name, "a positive number", value)
    if "minimum" in rules and not value >= rules["minimum"]:
        _fail(name, f"at least {rules['minimum']}", value)
    if "maximum" in rules and not value <= rules["maximum"]:
        _fail(name, f"at most {rules['maximum']}", value)
    return value


def _checked(value: Any, annotation: Any, name: str, rules: dict) -> Any:
    """``value`` checked against the field's ``annotation`` (``X | None``, ``tuple[X, ...]``, ``tuple[X, X]``,
    a :class:`Settings` class, or bool, int, float, str) and ``rules``; lists become tuples, a dict for a
    :class:`Settings` field its ``from_dict``."""
    origin, arguments = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (Union, types.UnionType):
        if value is None:
            return None
        (member,) = [argument for argument in arguments if argument is not type(None)]
        return _checked(value, member, name, rules)
    if origin is tuple:
        variable = len(arguments) == 2 and arguments[1] is Ellipsis
        count = "one or more" if variable else str(len(arguments))
        if not isinstance(value, (tuple, list)) or (len(value) == 0 if variable else len(value) != len(arguments)):
            _fail(name, f"a list of {count} values", value)
        items = tuple(_checked_number(item, arguments[0], name, rules) for item in value)
        if rules.get("ordered") and any(low > high for low, high in zip(items, items[1:])):
            _fail(name, "values that do not decrease (LOW <= HIGH)", value)
        return items
    if isinstance(annotation, type) and issubclass(annotation, Settings):
        if isinstance(value, dict):
            try:
                return annotation.from_dict(value)
            except ValueError as error:
                raise ValueError(f"{name}.{error}") from error
        if not isinstance(value, annotation):
            _fail(name, f"{annotation.__name__} settings", value)
        return value
    return _checked_number(value, annotation, name, rules)


@functools.cache
def _annotations(settings_class: type) -> dict[str, Any]:
    return typing.get_type_hints(settings_class)


@dataclasses.dataclass(frozen=True)
class Settings:
    """Base of a method's settings: a frozen dataclass of :func:`setting` fields, checked when made."""

    def __post_init__(self):
        annotations = _annotations(type(self))
        for item in dataclasses.fields(self):
            value = _checked(getattr(self, item.name), annotations[item.name], item.name, dict(item.metadata))
            object.__setattr__(self, item.name, value)
        self.check()

    def check(self) -> None:
        """Checks across fields (none here); raises ``ValueError`` starting with a field's name."""

    def replace(self: S, **changes: Any) -> S:
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The settings as JSON values (tuples as lists), for a run's ``config.json``."""
        return _json_values(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls: type[S], data: dict[str, Any]) -> S:
        """Settings from :meth:`to_dict`'s form; absent fields take their defaults.

        Raises:
            ValueError: not an object, an unknown field (naming the known ones) or a bad value.
        """
        if not isinstance(data, dict):
            _fail("settings", "an object of settings", data)
        known = [item.name for item in dataclasses.fields(cls)]
        unknown = sorted(set(data) - set(known))
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown setting; known: {', '.join(known)}")
        return cls(**data)


def _json_values(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _json_values(item) for key, item in value.items()}
    if isinstance(value, (tuple, list)):
        return [_json_values(item) for item in value]
    return value


def run_settings(presets: dict[str, S], config: str, settings: S | None, **flags: Any) -> S:
    """A run's settings: ``settings`` (``None``: the preset ``presets[config]``) with each flag that is not
    ``None`` applied (checked as its field).

    Raises:
        ValueError: an unknown preset (``"config: ..."``) or a bad flag value (``"<flag>: ..."``).
    """
    if config not in presets:
        _fail("config", f"one of {sorted(presets)}", config)
    chosen = presets[config] if settings is None else settings
    if not isinstance(chosen, type(presets[config])):
        _fail("settings", f"{type(presets[config]).__name__} settings", settings)
    return with_flags(chosen, **flags)


def with_flags(settings: S, **flags: Any) -> S:
    """``settings`` with each flag that is not ``None`` applied (checked as its field)."""
    return settings.replace(**{name: value for name, value in flags.items() if value is not None})


def recorded_settings(settings_class: type[S], config_path: str | Path, previous: dict) -> S:
    """The settings a run directory's ``config.json`` (``previous``, at ``config_path``) records.

    Raises:
        ValueError: naming the file, for settings that are missing or malformed.
    """
    try:
        return settings_class.from_dict(previous.get("settings"))
    except ValueError as error:
        raise ValueError(f"{config_path}: settings: {error}") from error


def changed_settings(earlier: Settings, settings: Settings, names: typing.Iterable[str] | None = None) -> list[str]:
    """The fields among ``names`` (default: all) whose values differ between ``earlier`` and ``settings``."""
    names = [item.name for item in dataclasses.fields(settings)] if names is None else names
    return [name for name in names if getattr(earlier, name) != getattr(settings, name)]


def check_same_run(config_path: str | Path, previous: dict | None, config: dict, keys: tuple[str, ...],
                   settings: Settings, fixed_settings: tuple[str, ...]) -> None:
    """Checks that a run directory's earlier ``config.json`` (``previous``, read from ``config_path``;
    ``None``: a new run) describes the run ``config`` with ``settings``: the same ``keys`` and the same
    ``fixed_settings``.

    Raises:
        ValueError: naming the run directory and every key that differs, or the file when its settings are
            malformed.
    """
    if previous is None:
        return
    changed = [key for key in keys if previous.get(key) != config[key]]
    changed += changed_settings(recorded_settings(type(settings), config_path, previous), settings, fixed_settings)
    if changed:
        raise ValueError(f"out: {Path(config_path).parent} holds a different run ({', '.join(changed)} differ); "
                         f"choose another --out")
