"""Bad input to `paz6d generate` is rejected before any work, with a clear error and no output."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest
import trimesh

from data_gen import cli


def run_cli(*arguments: str) -> int:
    parser = argparse.ArgumentParser()
    cli.configure(parser)
    return cli.run(parser.parse_args(list(arguments)))


@pytest.fixture
def cube(tmp_path) -> Path:
    path = tmp_path / "cube.ply"
    trimesh.creation.box((0.05, 0.05, 0.05)).export(path)
    return path


def expect_rejection(tmp_path, pattern: str, *arguments: str, out: Path | None = None):
    out = out if out is not None else tmp_path / "out"
    with pytest.raises(ValueError, match=pattern):
        run_cli("--out", str(out), "--no-progress", *arguments)
    assert not out.exists(), "a rejected run must not leave output behind"


def test_missing_mesh(tmp_path):
    expect_rejection(tmp_path, "missing.ply: mesh file not found", "--meshes", str(tmp_path / "missing.ply"),
                     "--num-images", "2")


def test_unreadable_mesh(tmp_path):
    path = tmp_path / "garbage.ply"
    path.write_bytes(b"ply\nformat nonsense\n\x00\x01")
    expect_rejection(tmp_path, "garbage.ply", "--meshes", str(path), "--num-images", "2")


def test_empty_mesh(tmp_path):
    path = tmp_path / "empty.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    expect_rejection(tmp_path, "empty.ply", "--meshes", str(path), "--num-images", "2")


def test_mesh_with_nan(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    expect_rejection(tmp_path, "nan.obj.*(NaN|empty)", "--meshes", str(path), "--num-images", "2")


@pytest.mark.parametrize("arguments, pattern", [
    (("--num-images", "0"), "--num-images: expected a positive integer"),
    (("--num-images", "2", "--width", "0"), "--width: expected a positive integer"),
    (("--num-images", "2", "--height", "-5"), "--height: expected a positive integer"),
    (("--num-images", "2", "--distance", "0.5", "0.2"), "--distance: expected a finite range"),
    (("--num-images", "2", "--distance", "0.02", "0.5"), "--distance: minimum .* inside the largest object"),
    (("--num-images", "2", "--distance", "0.1", "0.1", "--width", "16", "--height", "16",
      "--intrinsics", "500", "500", "8", "8"), "--distance: even at the maximum"),
    (("--num-images", "2", "--objects-per-image", "3", "1"), "--objects-per-image: "),
    (("--num-images", "2", "--crop-size", "-1"), "--crop-size: "),
    (("--num-images", "2", "--depth-scale", "0.001", "--distance", "0.5", "80"), "--depth-scale: "),
    (("--num-images", "2", "--workers", "0"), "--workers: expected a positive integer"),
])
def test_bad_numbers(tmp_path, cube, arguments, pattern):
    expect_rejection(tmp_path, pattern, "--meshes", str(cube), *arguments)


def test_unwritable_output(tmp_path, cube):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    expect_rejection(tmp_path, "is not a folder", "--meshes", str(cube), "--num-images", "2",
                     out=blocker / "out")
    expect_rejection(tmp_path, "--out: cannot write", "--meshes", str(cube), "--num-images", "2",
                     out=Path("/proc/paz6d-generate-test"))


def test_bad_backgrounds_and_symmetries(tmp_path, cube):
    (tmp_path / "empty_backgrounds").mkdir()
    expect_rejection(tmp_path, "--backgrounds: no images", "--meshes", str(cube), "--num-images", "2",
                     "--backgrounds", str(tmp_path / "empty_backgrounds"))
    broken = tmp_path / "symmetries.json"
    broken.write_text('{"7": {"symmetries_discrete": []}}')
    expect_rejection(tmp_path, "--symmetries: .* key '7' is not one of the object ids", "--meshes", str(cube),
                     "--num-images", "2", "--symmetries", str(broken))


def test_zero_area_mesh(tmp_path):
    path = tmp_path / "flat.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    expect_rejection(tmp_path, "flat.obj", "--meshes", str(path), "--num-images", "2")


def test_other_settings_in_an_existing_output_are_refused(tmp_path, cube):
    out = tmp_path / "out"
    arguments = ["--meshes", str(cube), "--num-images", "1", "--width", "32", "--height", "24", "--no-progress",
                 "--out", str(out), "--distractors", "0", "--occluder-probability", "0"]
    assert run_cli(*arguments) == 0
    with pytest.raises(ValueError, match="other settings \\(seed differ"):
        run_cli(*arguments, "--seed", "5")
    assert np.asarray(sorted(p.name for p in (out / "train" / "000000" / "rgb").iterdir())).tolist() == ["000000.png"]


def test_paz6d_generate_command_prints_a_summary_and_exits_2_on_bad_input(tmp_path, cube, capsys):
    from paz6d.cli import main

    out = tmp_path / "cli"
    assert main(["generate", "--meshes", str(cube), "--out", str(out), "--num-images", "2", "--width", "32",
                 "--height", "24", "--no-progress"]) == 0
    summary = capsys.readouterr().out
    assert "2 images" in summary and "2 rendered, 0 already done" in summary and "images/s" in summary
    assert main(["generate", "--meshes", str(cube), "--out", str(out), "--num-images", "2", "--width", "32",
                 "--height", "24", "--no-progress"]) == 0
    assert "0 rendered, 2 already done" in capsys.readouterr().out
    assert main(["generate", "--meshes", str(tmp_path / "nope.ply"), "--out", str(tmp_path / "x"),
                 "--num-images", "1"]) == 2
    assert "nope.ply: mesh file not found" in capsys.readouterr().err


def test_command_modules_import_no_gl_or_tensorflow():
    import subprocess
    import sys

    code = ("import sys, data_gen.cli, renderers, paz6d.datasets.bop; "
            "print([m for m in ('pyrender', 'OpenGL', 'tensorflow') if m in sys.modules])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.stdout.strip() == "[]"
