"""paz6d.cli_options: flags derived from a dataclass (name, default, type, help), and back."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from paz6d.cli_options import add_config_arguments, config_from_args, flag_name, flags_in_errors, option

MODES = ("fast", "exact")


@dataclass(frozen=True)
class Settings:
    out: Path = option(help="output folder")
    inputs: tuple[Path, ...] = option(help="input files", metavar="PATH")
    mesh_scale: float = option(1.0, "units to metres; 100 % means 1")
    count: int | None = option(None, "how many (default: all)")
    size: tuple[int, int] = option((64, 48), "width and height", metavar=("W", "H"))
    levels: tuple[float, ...] = option((0.5, 1.0), "thresholds")
    mode: str = option("fast", "speed or accuracy", choices=MODES)
    colour: Literal["red", "green"] = option("red", "colour")
    progress: bool = option(True, "progress bar")
    eager: bool = option(False, "no compilation")
    mesh: Path | None = option(None, "a mesh", one_of="source")
    dataset: Path | None = option(None, "a data set", one_of="source")
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.mesh_scale <= 0:
            raise ValueError(f"mesh_scale: expected a positive factor, got {self.mesh_scale}")


def parser_for(config_class=Settings, exclude=("extra",)) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tool")
    add_config_arguments(parser, config_class, exclude)
    return parser


REQUIRED = ["--out", "o", "--inputs", "a", "--mesh", "m.ply"]


def test_flags_take_names_defaults_and_types_from_the_fields():
    parser = parser_for()
    args = parser.parse_args(REQUIRED)
    assert vars(args) == {"out": Path("o"), "inputs": [Path("a")], "mesh_scale": 1.0, "count": None, "size": (64, 48),
                          "levels": (0.5, 1.0), "mode": "fast", "colour": "red", "progress": True, "eager": False,
                          "mesh": Path("m.ply"), "dataset": None}
    assert flag_name("mesh_scale") == "--mesh-scale"
    text = parser.format_help()
    assert "--mesh-scale MESH_SCALE" in text and "100 % means 1 (default: 1.0)" in text
    assert "--size W H" in text and "(default: 64 48)" in text and "--progress, --no-progress" in text
    assert "(--mesh MESH | --dataset DATASET)" in text


def test_round_trip_args_to_config():
    args = parser_for().parse_args(["--out", "o", "--inputs", "a", "b", "--inputs", "c", "--mesh-scale", "0.001",
                                    "--count", "3", "--size", "8", "6", "--levels", "0.1", "--mode", "exact",
                                    "--colour", "green", "--no-progress", "--eager", "--dataset", "d"])
    settings = config_from_args(Settings, args, exclude=("extra",), extra={"k": 1})
    assert settings == Settings(out=Path("o"), inputs=(Path("a"), Path("b"), Path("c")), mesh_scale=0.001, count=3,
                                size=(8, 6), levels=(0.1,), mode="exact", colour="green", progress=False, eager=True,
                                dataset=Path("d"), extra={"k": 1})


@pytest.mark.parametrize("arguments", [
    ["--mode", "slow"], ["--colour", "blue"], ["--size", "8"], ["--count", "many"], ["--dataset", "d"], []])
def test_bad_flags_are_refused_by_the_parser(arguments):
    required = REQUIRED if arguments != [] else ["--out", "o", "--mesh", "m"]  # [] : --inputs missing
    with pytest.raises(SystemExit):
        parser_for().parse_args(required + arguments)


def test_the_dataclass_check_names_the_flag():
    args = parser_for().parse_args(REQUIRED + ["--mesh-scale", "-2"])
    with pytest.raises(ValueError, match=r"^--mesh-scale: expected a positive factor, got -2.0$"):
        config_from_args(Settings, args, exclude=("extra",))
    with pytest.raises(ValueError, match="^--count: too many$"), flags_in_errors(Settings):
        raise ValueError("count: too many")
    with pytest.raises(ValueError, match="^other: unchanged$"), flags_in_errors(Settings):
        raise ValueError("other: unchanged")


def test_fields_without_a_flag_form_must_be_excluded():
    with pytest.raises(TypeError, match=r"Settings.extra: no flag form"):
        parser_for(exclude=())
    with pytest.raises(ValueError, match="not fields of Settings"):
        parser_for(exclude=("extra", "missing"))

    @dataclass
    class Ambiguous:
        value: int | str = 1

    with pytest.raises(TypeError, match="only 'X | None' unions"):
        parser_for(Ambiguous, exclude=())
