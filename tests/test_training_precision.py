"""The shared precision setting: the CPU flag check, ``auto`` and the body's dtype policy."""

import pytest

from paz6d.training import precision


@pytest.mark.parametrize("flags, expected", [("fpu avx2 avx512f", False), ("fpu avx512f avx512_bf16 avx512vl", True),
                                             ("fpu amx_bf16 amx_tile", True), ("fpu avx512_bf16x", False)])
def test_native_bfloat16_reads_the_cpu_flags(tmp_path, flags, expected):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(f"processor\t: 0\nflags\t\t: {flags}\n")
    assert precision.native_bfloat16(cpuinfo) is expected
    assert precision.native_bfloat16(tmp_path / "missing") is False


def test_precision_setting_resolves_auto_from_the_cpu(monkeypatch):
    from paz6d.backend.tensorflow_guard import import_tensorflow

    gpus = import_tensorflow().config.list_physical_devices("GPU")
    assert precision.resolve_precision("float32") == "float32"
    assert precision.resolve_precision("bfloat16") == "bfloat16"
    monkeypatch.setattr(precision, "native_bfloat16", lambda: True)
    assert precision.resolve_precision("auto") == ("float32" if gpus else "bfloat16")
    monkeypatch.setattr(precision, "native_bfloat16", lambda: False)
    assert precision.resolve_precision("auto") == "float32"
    with pytest.raises(ValueError, match="precision: expected 'auto'"):
        precision.resolve_precision("half")


def test_body_policy_names_the_keras_policy():
    assert precision.body_policy("float32") == "float32"
    assert precision.body_policy("bfloat16") == "mixed_bfloat16"
    with pytest.raises(ValueError, match="compute_dtype: expected one of"):
        precision.body_policy("float16")
