"""``scripts/kill_resume.py``: a trainer killed with SIGKILL part-way resumes to the weights of an
uninterrupted run (one method here; the script runs all eight)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "kill_resume.py"


def _script():
    spec = importlib.util.spec_from_file_location("kill_resume", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_trainer_has_a_recipe():
    from paz6d.methods import methods

    assert sorted(_script().RECIPES) == sorted(method.name for method in methods())


@pytest.mark.slow  # three trainings in their own processes
def test_a_killed_spatial_transformer_training_resumes_to_the_uninterrupted_weights(tmp_path, capsys):
    assert _script().main(["--methods", "stn", "--work", str(tmp_path)]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["ok"] and 0 < result["killed_at"] < result["steps"] and result["differing"] == 0
