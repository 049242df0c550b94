"""Command-line flags derived from config dataclasses: each setting has one name, one default and one
help text, written once, in the dataclass.

A field becomes a flag named after it (``mesh_scale`` -> ``--mesh-scale``) whose default is the
field's default and whose type comes from the annotation:

==============================  ===============================================================
annotation                      flag
==============================  ===============================================================
``int``, ``float``, ``str``,    one value of that type
``Path``
``bool``                        ``--x`` / ``--no-x`` (:class:`argparse.BooleanOptionalAction`)
``Literal["a", "b"]``           one of the listed values
``tuple[T, T]`` (fixed length)  exactly that many values
``tuple[T, ...]``               one or more values (a required one may also be repeated)
``X | None``                    as ``X``; ``None`` when the flag is not given
==============================  ===============================================================

Help text, ``metavar``, ``choices`` (for a ``str`` field whose values live in a constant) and
``one_of`` (alternatives such as ``--mesh`` or ``--dataset``) come from the field's metadata, most
simply written with :func:`option`. A field without a default is a
required flag. Checks stay in the dataclass (``__post_init__``): :func:`config_from_args` reports a
``ValueError`` that starts with a field name (``"mesh_scale: expected ..."``) under the flag's name
(``"--mesh-scale: expected ..."``).

Example::

    @dataclass(frozen=True)
    class Settings:
        out: Path = option(help="output folder")
        mesh_scale: float = option(1.0, "mesh units to metres")

    add_config_arguments(parser, Settings)
    settings = config_from_args(Settings, parser.parse_args())
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import types
import typing
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Literal, Union


_SCALAR_TYPES = (int, float, str, Path)


def option(default: Any = dataclasses.MISSING, help: str = "", *, metavar: str | tuple[str, ...] | None = None,
           choices: Iterable | None = None, one_of: str | None = None,
           default_factory: Any = dataclasses.MISSING) -> Any:
    """A dataclass field with the metadata its flag needs (no ``default``: a required flag).

    Fields with the same ``one_of`` name are alternatives: exactly one of their flags must be given
    (an argparse mutually exclusive group; the dataclass should check the same for library callers).
    """
    metadata = {"help": help}
    if one_of is not None:
        metadata["one_of"] = one_of
    if metavar is not None:
        metadata["metavar"] = metavar
    if choices is not None:
        metadata["choices"] = tuple(choices)
    return dataclasses.field(default=default, default_factory=default_factory, metadata=metadata)


def flag_name(field_name: str) -> str:
    """``"mesh_scale"`` -> ``"--mesh-scale"``."""
    return "--" + field_name.replace("_", "-")


def flag_fields(config_class: type, exclude: Iterable[str] = ()) -> list[dataclasses.Field]:
    """The fields of ``config_class`` that become flags (all but ``exclude``)."""
    if not dataclasses.is_dataclass(config_class):
        raise TypeError(f"config_class: expected a dataclass, got {config_class!r}")
    names = {field.name for field in dataclasses.fields(config_class)}
    unknown = set(exclude) - names
    if unknown:
        raise ValueError(f"exclude: {sorted(unknown)} are not fields of {config_class.__name__}")
    return [field for field in dataclasses.fields(config_class) if field.init and field.name not in set(exclude)]


def field_default(field: dataclasses.Field) -> Any:
    """The field's default (``dataclasses.MISSING`` for a required field)."""
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def _argument_options(config_class: type, field: dataclasses.Field, annotation: Any) -> dict:
    """``add_argument`` keyword arguments for one field, from its annotation."""
    where = f"{config_class.__name__}.{field.name}"
    if typing.get_origin(annotation) in (Union, types.UnionType):
        members = [member for member in typing.get_args(annotation) if member is not type(None)]
        if len(members) != 1 or len(typing.get_args(annotation)) != 2:
            raise TypeError(f"{where}: only 'X | None' unions can become a flag, got {annotation}")
        annotation = members[0]
        if annotation is bool:
            raise TypeError(f"{where}: 'bool | None' has no flag form; use a bool with a default")
    origin, arguments = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is bool:
        return {"action": argparse.BooleanOptionalAction}
    if origin is Literal:
        return {"type": type(arguments[0]), "choices": arguments}
    if origin is tuple and len(arguments) == 2 and arguments[1] is Ellipsis and arguments[0] in _SCALAR_TYPES:
        return {"type": _flag_type(arguments[0]), "nargs": "+"}
    if origin is tuple and arguments and len(set(arguments)) == 1 and arguments[0] in _SCALAR_TYPES:
        return {"type": _flag_type(arguments[0]), "nargs": len(arguments)}
    if annotation in _SCALAR_TYPES:
        return {"type": _flag_type(annotation)}
    raise TypeError(f"{where}: no flag form for the annotation {annotation}; exclude the field or change its type")


def path_argument(text: str) -> Path:
    """A path flag's value: any text but the empty string (``Path("")`` would quietly be the current folder)."""
    if not text:
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return Path(text)


def _flag_type(annotation: type) -> Callable[[str], Any]:
    return path_argument if annotation is Path else annotation


def _display(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return " ".join(str(item) for item in value) if value else "none"
    return str(value)


def add_config_arguments(parser: argparse.ArgumentParser | argparse._ArgumentGroup, config_class: type,
                         exclude: Iterable[str] = ()) -> None:
    """Adds one flag per field of ``config_class`` (except ``exclude``) to ``parser``."""
    hints = typing.get_type_hints(config_class)
    alternatives: dict[str, argparse._MutuallyExclusiveGroup] = {}
    for field in flag_fields(config_class, exclude):
        options = _argument_options(config_class, field, hints[field.name])
        default = field_default(field)
        help_text = field.metadata.get("help", "").replace("%", "%%")  # argparse formats help with %
        if default is dataclasses.MISSING:
            options["required"] = True
            if options.get("nargs") == "+":
                options["action"] = "extend"  # --x a b and --x a --x b both work
        else:
            options["default"] = default
            if options.get("nargs") == "+" and default == ():
                options.update(action="extend", default=[])  # a repeatable flag, none by default (a tuple again
                #                                              in config_from_args)
            if options.get("action") is argparse.BooleanOptionalAction:
                shown = flag_name(field.name) if default else "--no-" + flag_name(field.name)[2:]
                help_text = f"{help_text} (default: {shown})".strip()
            elif default is not None:
                help_text = f"{help_text} (default: {_display(default)})".strip()
        if "choices" in field.metadata:
            options["choices"] = field.metadata["choices"]
        if "metavar" in field.metadata:
            options["metavar"] = field.metadata["metavar"]
        target = parser
        if "one_of" in field.metadata:
            name = field.metadata["one_of"]
            if name not in alternatives:
                alternatives[name] = parser.add_mutually_exclusive_group(required=True)
            target = alternatives[name]
        target.add_argument(flag_name(field.name), dest=field.name, help=help_text, **options)


@contextlib.contextmanager
def flags_in_errors(*config_classes: type) -> Iterator[None]:
    """Re-raises a ``ValueError`` whose message starts with a field name of ``config_classes``
    (``"mesh_scale: ..."``) with the flag's name instead (``"--mesh-scale: ..."``)."""
    try:
        yield
    except ValueError as error:
        message = str(error)
        for config_class in config_classes:
            for field in flag_fields(config_class):
                if message.startswith(f"{field.name}:"):
                    raise ValueError(flag_name(field.name) + message[len(field.name):]) from error
        raise


def config_from_args(config_class: type, args: argparse.Namespace, exclude: Iterable[str] = (), **values: Any):
    """``config_class`` built from the flags :func:`add_config_arguments` added (lists become tuples),
    plus ``values`` for excluded fields or to override a flag.

    Raises:
        ValueError: the dataclass's own check, naming the flag (:func:`flags_in_errors`).
    """
    for field in flag_fields(config_class, exclude):
        if field.name not in values:
            value = getattr(args, field.name)
            values[field.name] = tuple(value) if isinstance(value, list) else value
    with flags_in_errors(config_class):
        return config_class(**values)


def config_inputs(settings: Any, outputs: tuple[str, ...] = ("out",)) -> dict[str, Path]:
    """``{flag: path}`` of the ``Path`` settings other than the ``outputs`` fields: the files and folders
    a command reads."""
    return {flag_name(field.name): getattr(settings, field.name) for field in dataclasses.fields(settings)
            if field.name not in outputs and isinstance(getattr(settings, field.name), Path)}


def training_output(settings: Any, method: str) -> contextlib.AbstractContextManager[Path]:
    """``settings.out`` checked by the one output rule and claimed for ``method`` while the block runs
    (:func:`paz6d.run_dirs.run_output`, with the settings' other paths as the inputs)."""
    from paz6d.run_dirs import run_output  # here: it imports every method's run_dir module

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
