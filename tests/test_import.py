"""Importing the packages is cheap and TensorFlow-free; docstring examples run."""

from __future__ import annotations

import doctest
import importlib
import json
import subprocess
import sys

import pytest

HEAVY = ("tensorflow", "keras", "pyrender", "OpenGL", "open3d")
DOCUMENTED_MODULES = ["paz6d.backend.quaternion", "paz6d.backend.boxes", "paz6d.backend.image",
                      "paz6d.backend.keypoints", "paz6d.abstract.processor",
                      "paz6d.processors.image", "paz6d.synthesis.augment"]


def import_in_fresh_interpreter(statement: str) -> dict:
    """Runs ``statement`` in a new interpreter; returns the CPU seconds it took and the heavy
    modules it loaded (CPU time, unlike wall time, does not grow when other jobs share the machine)."""
    code = ("import json, sys, time\n"
            "start = time.process_time()\n"
            f"{statement}\n"
            "seconds = time.process_time() - start\n"
            f"print(json.dumps({{'seconds': seconds, 'heavy': [name for name in {HEAVY!r} if name in sys.modules]}}))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_top_level_packages_import_fast_without_tensorflow():
    report = import_in_fresh_interpreter("import paz6d, renderers, data_gen, evaluation")
    assert report["heavy"] == []
    assert report["seconds"] < 1.5, f"importing the packages took {report['seconds']:.2f} s of CPU"


def test_paz6d_alone_imports_in_well_under_a_second():
    report = import_in_fresh_interpreter("import paz6d, paz6d.abstract")
    assert report["heavy"] == [] and report["seconds"] < 1.0


def test_backends_and_processors_do_not_import_tensorflow():
    modules = ["paz6d.backend." + name for name in ("boxes", "camera", "checks", "image", "keypoints", "mesh", "pnp",
                                                     "quaternion", "tensorflow_guard", "transform")]
    modules += ["paz6d.processors." + name for name in ("boxes", "image", "keypoints", "pose")]
    modules += ["paz6d.abstract.processor"]
    report = import_in_fresh_interpreter("; ".join(f"import {module}" for module in modules))
    assert report["heavy"] == []


@pytest.mark.parametrize("module_name", DOCUMENTED_MODULES)
def test_docstring_examples_run(module_name):
    result = doctest.testmod(importlib.import_module(module_name))
    assert result.attempted > 0 and result.failed == 0
