"""The ``paz6d`` command: help for every subcommand in ``paz6d.cli.COMMANDS`` and the dispatcher."""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

from paz6d import cli


def command_paths() -> list[tuple[str, ...]]:
    """Every runnable command as its argument path, e.g. ``("train", "aae")``."""
    paths = []
    for name, (target, _) in cli.COMMANDS.items():
        if isinstance(target, dict):
            paths += [(name, model) for model in target]
        else:
            paths.append((name,))
    return paths


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
    code = ("import json, sys\nfrom paz6d.cli import build_parser\nbuild_parser()\n"
            "print(json.dumps([name for name in ('tensorflow', 'keras', 'pyrender', 'OpenGL', 'open3d') "
            "if name in sys.modules]))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == []  # building every subcommand parser loads no heavy library


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
