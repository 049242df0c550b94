"""The ``paz6d`` command: help for every subcommand in ``paz6d.cli.COMMANDS`` and the dispatcher."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

from paz6d import cli


def command_paths_and_modules() -> list[tuple[tuple[str, ...], str]]:
    """Every runnable command's argument path and module name."""
    pairs = []
    for name, (target, _) in cli.COMMANDS.items():
        if isinstance(target, dict):
            pairs += [((name, model), module) for model, (module, _) in target.items()]
        else:
            pairs.append(((name,), target))
    return pairs


def command_paths() -> list[tuple[str, ...]]:
    """Every runnable command as its argument path, e.g. ``("train", "aae")``."""
    return [path for path, _ in command_paths_and_modules()]


def test_top_level_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert name in text


@pytest.mark.parametrize("path", command_paths(), ids=" ".join)
def test_subcommand_help_exits_zero(path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main([*path, "--help"])
    assert exit_info.value.code == 0
    assert f"usage: paz6d {' '.join(path)}" in capsys.readouterr().out


def test_console_script_help_is_cheap():
    script = Path(sys.executable).with_name("paz6d")
    executable = [str(script)] if script.exists() else [shutil.which("paz6d") or "paz6d"]
    result = subprocess.run([*executable, "--help"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "usage: paz6d" in result.stdout
    module = subprocess.run([sys.executable, "-m", "paz6d", "--help"], capture_output=True, text=True, timeout=120)
    assert module.returncode == 0 and module.stdout == result.stdout  # python -m paz6d is the same command


# Imported by no command at parser-build time: each costs 0.1-2 s (trimesh pulls scipy.spatial/linalg and networkx).
# The renderers package itself loads nothing (its names are imported on first use), and renderers.platform
# and renderers.antialias only hold names for the flags; renderers.renderer is the rendering code.
HEAVY_MODULES = ("trimesh", "scipy.linalg", "scipy.spatial", "renderers.renderer", "tensorflow", "keras", "numba",
                 "matplotlib", "open3d", "pyrender", "OpenGL")


def _modules_loaded_by(code: str, names) -> list[str]:
    """Which of ``names`` a fresh interpreter has imported after running ``code``."""
    script = f"import json, sys\n{code}\nprint(json.dumps([name for name in {list(names)!r} if name in sys.modules]))"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])


def test_building_every_command_parser_loads_no_heavy_library():
    code = "from paz6d.cli import build_parser\nbuild_parser(load_commands=True)"
    assert _modules_loaded_by(code, HEAVY_MODULES) == []


def test_a_command_parser_imports_only_its_own_module():
    modules = [module for _, module in command_paths_and_modules()]
    top = "from paz6d.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    assert _modules_loaded_by(top, modules) == []
    evaluate = top.replace("['--help']", "['evaluate', 'coco', '--help']")
    assert _modules_loaded_by(evaluate, modules) == ["evaluation.cli"]



@pytest.fixture
def fake_command(monkeypatch):
    """Replaces the command table with one command backed by an in-memory module."""
    module = types.ModuleType("fake_paz6d_command")

    def configure(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--value", type=int, required=True)

    def run(args: argparse.Namespace) -> int:
        if args.value < 0:
            raise ValueError(f"--value: expected a non-negative number, got {args.value}")
        return args.value

    module.configure, module.run = configure, run
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setattr(cli, "COMMANDS", {"fake": (module.__name__, "a fake command"),
                                          "group": ({"inner": (module.__name__, "nested fake")}, "a group")})


def test_main_dispatches_and_reports_value_errors(fake_command, capsys):
    assert cli.main(["fake", "--value", "3"]) == 3
    assert cli.main(["group", "inner", "--value", "0"]) == 0
    assert cli.main(["fake", "--value", "-1"]) == 2
    assert "paz6d fake: error: --value: expected a non-negative number, got -1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["fake"])
    assert exit_info.value.code == 2  # argparse: missing required argument
    with pytest.raises(SystemExit):
        cli.main([])


# ------------------------------------------------------------------ flags derived from config dataclasses

def _command_configs() -> dict[tuple[str, ...], list[tuple[type, tuple[str, ...]]]]:
    """Each command's config dataclasses and the fields that are not flags."""
    from data_gen.config import GenerationConfig, GenerationRun
    from paz6d.aae.config import AAETraining
    from paz6d.benchmark.command import LmoOptions
    from paz6d.demo.command import DemoOptions
    from paz6d.faces.emotion_config import EmotionTraining
    from paz6d.hrnet.config import HRNetTraining
    from paz6d.keypointnet.config import KeypointTraining
    from paz6d.probabilistic_keypoints.config import ProbabilisticTraining
    from paz6d.segmentation.config import SegmentationTraining
    from paz6d.ssd.config import SSDTraining
    from paz6d.stn.config import STNTraining

    return {("generate",): [(GenerationConfig, ()), (GenerationRun, ())], ("train", "aae"): [(AAETraining, ())],
            ("train", "keypointnet"): [(KeypointTraining, ("settings",))],
            ("train", "stn"): [(STNTraining, ("settings",))],
            ("train", "segmentation"): [(SegmentationTraining, ("settings",))],
            ("train", "hrnet"): [(HRNetTraining, ("settings",))],
            ("train", "probabilistic-keypoints"): [(ProbabilisticTraining, ("settings",))],
            ("train", "ssd"): [(SSDTraining, ("settings",))],
            ("train", "emotion"): [(EmotionTraining, ())], ("demo",): [(DemoOptions, ())],
            ("benchmark", "lmo"): [(LmoOptions, ())]}


def _subparser(path: tuple[str, ...]) -> argparse.ArgumentParser:
    parser = cli.build_parser(load_commands=True)
    for name in path:
        parser = next(action for action in parser._actions
                      if isinstance(action, argparse._SubParsersAction)).choices[name]
    return parser


def _flag_actions(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {action.dest: action for action in parser._actions if action.option_strings and action.dest != "help"}


@pytest.mark.parametrize("path", list(_command_configs()), ids=" ".join)
def test_every_config_field_is_a_flag_with_the_fields_default(path):
    from paz6d.cli_options import field_default, flag_fields, flag_name

    actions = _flag_actions(_subparser(path))
    fields = [field for config_class, exclude in _command_configs()[path]
              for field in flag_fields(config_class, exclude)]
    assert sorted(actions) == sorted(field.name for field in fields)  # a new field is a new flag, and nothing else
    for field in fields:
        action = actions[field.name]
        assert action.option_strings[0] == flag_name(field.name)
        default = field_default(field)
        if default is dataclasses.MISSING:
            assert action.required, field.name
        else:
            expected = [] if default == () else default  # a repeatable flag collects into a list
            assert action.default == expected and not action.required, field.name


@pytest.mark.parametrize("path", list(_command_configs()), ids=" ".join)
def test_parsed_defaults_build_the_default_config(path, tmp_path):
    """args -> config with only the required flags gives the dataclass's defaults."""
    from paz6d.cli_options import config_from_args, field_default, flag_fields, flag_name

    required = {("generate",): ["--meshes", "a.ply", "--out", "o", "--num-images", "3"],
                ("train", "aae"): ["--mesh", "a.ply", "--out", "o"],
                ("train", "keypointnet"): ["--mesh", "a.ply", "--out", "o"], ("train", "stn"): ["--out", "o"],
                ("train", "segmentation"): ["--dataset", "d", "--out", "o"],
                ("train", "hrnet"): ["--mesh", "a.ply", "--out", "o"],
                ("train", "probabilistic-keypoints"): ["--mesh", "a.ply", "--out", "o"],
                ("train", "ssd"): ["--dataset", "d", "--out", "o"],
                ("train", "emotion"): ["--data", "d.csv", "--out", "o"], ("demo",): [],
                ("benchmark", "lmo"): ["--out", "o"]}[path]
    args = _subparser(path).parse_args(required)
    for config_class, exclude in _command_configs()[path]:
        config = config_from_args(config_class, args, exclude)
        for field in flag_fields(config_class, exclude):
            default = field_default(field)
            if flag_name(field.name) not in required and field.name != "mesh_scale":  # mesh_scale: by source
                assert getattr(config, field.name) == default, field.name


def test_one_spelling_for_the_same_setting_in_every_command():
    retired = {"--scale", "--quiet", "--inplane", "--elevation", "--noise", "--mesh-path", "--output"}
    for path in command_paths():
        parser = _subparser(path)
        strings = {string for action in parser._actions for string in action.option_strings}
        for subparsers in (action for action in parser._actions if isinstance(action, argparse._SubParsersAction)):
            strings |= {string for sub in subparsers.choices.values() for action in sub._actions
                        for string in action.option_strings}
        assert not strings & retired, (path, strings & retired)
        assert ("--no-progress" in strings) == ("--progress" in strings), path


def test_generate_round_trip_and_errors_name_the_flag(tmp_path):
    from data_gen.config import GenerationConfig
    from paz6d.cli_options import config_from_args

    parser = _subparser(("generate",))
    args = parser.parse_args(["--meshes", "a.ply", "b.ply", "--meshes", "c.ply", "--out", str(tmp_path),
                              "--num-images", "4", "--mesh-scale", "0.001", "--objects-per-image", "2", "2",
                              "--intrinsics", "500", "500", "320", "240", "--rotation", "view-sphere",
                              "--no-progress", "--rgb-format", "jpg"])
    config = config_from_args(GenerationConfig, args)
    assert config.meshes == (Path("a.ply"), Path("b.ply"), Path("c.ply")) and config.mesh_scale == 0.001
    assert config.objects_per_image == (2, 2) and config.intrinsics == (500.0, 500.0, 320.0, 240.0)
    assert config.rotation == "view-sphere" and config.rgb_format == "jpg" and args.progress is False
    with pytest.raises(SystemExit):
        parser.parse_args(["--meshes", "a.ply", "--out", "o", "--num-images", "1", "--rgb-format", "gif"])
    args = parser.parse_args(["--meshes", "a.ply", "--out", "o", "--num-images", "1", "--mesh-scale", "-1"])
    with pytest.raises(ValueError, match="^--mesh-scale: expected a positive number"):
        config_from_args(GenerationConfig, args)


def test_train_commands_resolve_the_mesh_scale_by_source_and_name_flags_in_errors():
    from paz6d.aae.config import AAETraining
    from paz6d.cli_options import config_from_args
    from paz6d.faces.emotion_config import EmotionTraining

    parser = _subparser(("train", "aae"))
    with pytest.raises(SystemExit):
        parser.parse_args(["--mesh", "a.ply", "--dataset", "d", "--out", "o"])  # one source only
    assert config_from_args(AAETraining, parser.parse_args(["--mesh", "a.ply", "--out", "o"])).mesh_scale == 1.0
    job = config_from_args(AAETraining, parser.parse_args(["--dataset", "d", "--out", "o", "--steps", "7"]))
    assert job.mesh_scale == 0.001 and job.model_config.steps == 7  # BOP meshes are millimetres
    with pytest.raises(ValueError, match="^--steps: expected a positive number"):
        config_from_args(AAETraining, parser.parse_args(["--mesh", "a.ply", "--out", "o", "--steps", "0"]))
    parser = _subparser(("train", "emotion"))
    job = config_from_args(EmotionTraining, parser.parse_args(["--data", "d", "--out", "o", "--no-augment", "--eager"]))
    assert job.augment is False and job.eager is True and job.progress is True
    with pytest.raises(ValueError, match="^--batch-size: expected a positive integer"):
        config_from_args(EmotionTraining, parser.parse_args(["--data", "d", "--out", "o", "--batch-size", "0"]))
