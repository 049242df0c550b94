"""paz6d.backend.lazy_exports: packages whose names load their module on first use."""

import subprocess
import sys

import pytest


def run_python(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()


def test_a_name_imports_only_its_module_and_only_when_used():
    out = run_python(
        "import sys, paz6d.datasets.bop as bop\n"
        "print('paz6d.datasets.bop.units' in sys.modules)\n"
        "print(bop.MM_PER_M)\n"
        "print('paz6d.datasets.bop.units' in sys.modules, 'paz6d.datasets.bop.reader' in sys.modules)\n"
        "print('MM_PER_M' in vars(bop))")
    assert out.splitlines() == ["False", "1000.0", "True False", "True"]


def test_unknown_names_and_dir():
    import paz6d.datasets.bop as bop
    import renderers

    with pytest.raises(AttributeError, match="has no attribute 'Nope'"):
        bop.Nope  # noqa: B018
    assert {"BOPDataset", "MM_PER_M", "read_pose_results"} <= set(dir(bop))
    assert renderers.__all__ == sorted(["DEFAULT_LIGHTS", "Light", "Lighting", "PlatformUnavailableError",
                                        "select_platform", "ANTIALIAS_MODES", "Renderer", "RenderOutput"])
