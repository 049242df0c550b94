"""The shared typed settings of ``paz6d train <method>`` (:mod:`paz6d.training.settings`) and every method's
presets."""

from __future__ import annotations

import json
from dataclasses import FrozenInstanceError, dataclass

import numpy as np
import pytest

from paz6d.training.settings import (Settings, check_same_run, positive, recorded_settings, run_settings, setting,
                                     share)


@dataclass(frozen=True)
class Inner(Settings):
    strength: float = share(0.5)


@dataclass(frozen=True)
class Example(Settings):
    size: int = positive(64)
    count: int = setting(2, minimum=0)
    rate: float = positive(1e-3)
    fraction: float = share(0.25)
    widths: tuple[int, ...] = positive((8, 16))
    scale: tuple[float, float] = setting((0.5, 2.0), positive=True, ordered=True)
    kind: str = setting("a", choices=("a", "b"))
    flag: bool = False
    optional: int | None = None
    inner: Inner = Inner()

    def check(self):
        if self.size % 2 ** len(self.widths):
            raise ValueError(f"size: expected a multiple of {2 ** len(self.widths)}, got {self.size}")


PRESETS = {"small": Example(), "large": Example(size=128, widths=(8, 16, 32))}


def test_settings_are_frozen_and_checked_once_where_made():
    example = Example(rate=1, widths=[4, 8], scale=[1, 3], count=np.int64(3))
    assert example.rate == 1.0 and isinstance(example.rate, float) and example.widths == (4, 8)
    assert example.scale == (1.0, 3.0) and type(example.count) is int
    with pytest.raises(FrozenInstanceError):
        example.size = 3
    assert example.replace(size=32).size == 32 and example.size == 64


@pytest.mark.parametrize("changes, message", [
    ({"size": 0}, "size: expected a positive number, got 0"),
    ({"size": 2.5}, "size: expected a whole number, got 2.5"),
    ({"size": True}, "size: expected a whole number, got True"),
    ({"size": "64"}, "size: expected a whole number"),
    ({"count": -1}, "count: expected at least 0, got -1"),
    ({"rate": float("nan")}, "rate: expected a finite number, got nan"),
    ({"rate": float("inf")}, "rate: expected a finite number"),
    ({"rate": -1e-3}, "rate: expected a positive number"),
    ({"fraction": 1.5}, "fraction: expected at most 1.0, got 1.5"),
    ({"fraction": -0.1}, "fraction: expected at least 0.0"),
    ({"widths": ()}, "widths: expected a list of one or more values"),
    ({"widths": (8, 0)}, "widths: expected a positive number, got 0"),
    ({"widths": 8}, "widths: expected a list of one or more values, got 8"),
    ({"scale": (1.0, 2.0, 3.0)}, "scale: expected a list of 2 values"),
    ({"scale": (2.0, 1.0)}, r"scale: expected values that do not decrease \(LOW <= HIGH\)"),
    ({"kind": "c"}, r"kind: expected one of \('a', 'b'\), got 'c'"),
    ({"flag": 1}, "flag: expected true or false, got 1"),
    ({"optional": 1.5}, "optional: expected a whole number"),
    ({"inner": {"strength": 2.0}}, "inner.strength: expected at most 1.0"),
    ({"inner": {"power": 2.0}}, "inner.power: unknown setting; known: strength"),
    ({"inner": 3}, "inner: expected Inner settings, got 3"),
    ({"size": 40, "widths": (8, 16, 32, 64)}, "size: expected a multiple of 16, got 40"),  # check(): across fields
])
def test_bad_values_name_the_field(changes, message):
    with pytest.raises(ValueError, match=f"^{message}"):
        Example(**changes)
    with pytest.raises(ValueError, match=f"^{message}"):
        Example().replace(**changes)


def test_to_dict_and_from_dict_round_trip_through_json():
    example = Example(widths=(8, 16), optional=3, inner=Inner(0.75))
    data = json.loads(json.dumps(example.to_dict()))
    assert data["widths"] == [8, 16] and data["inner"] == {"strength": 0.75}
    assert Example.from_dict(data) == example


def test_from_dict_gives_absent_fields_their_defaults_and_refuses_unknown_ones():
    assert Example.from_dict({"size": 32}) == Example(size=32)
    assert Example.from_dict({"inner": {}}).inner == Inner()
    with pytest.raises(ValueError, match="^sizes: unknown setting; known: size, count, rate"):
        Example.from_dict({"sizes": 32})
    with pytest.raises(ValueError, match="^settings: expected an object of settings, got"):
        Example.from_dict([1, 2])


def test_run_settings_apply_the_flags_to_a_preset_or_to_given_settings():
    assert run_settings(PRESETS, "large", None) == PRESETS["large"]
    assert run_settings(PRESETS, "small", None, size=32, count=None) == Example(size=32)
    given = Example(rate=0.5)
    assert run_settings(PRESETS, "small", given, count=5) == Example(rate=0.5, count=5)
    with pytest.raises(ValueError, match=r"^config: expected one of \['large', 'small'\], got 'huge'"):
        run_settings(PRESETS, "huge", None)
    with pytest.raises(ValueError, match="^size: expected a positive number, got 0"):
        run_settings(PRESETS, "small", None, size=0)
    with pytest.raises(ValueError, match="^settings: expected Example settings, got"):
        run_settings(PRESETS, "small", Inner())


def test_check_same_run_compares_the_recorded_settings(tmp_path):
    path = tmp_path / "config.json"
    config = {"seed": 0, "settings": Example().to_dict()}
    check_same_run(path, None, config, ("seed",), Example(), ("size",))  # a new run
    check_same_run(path, {"seed": 0, "settings": {"size": 64}}, config, ("seed",), Example(), ("size", "count"))
    check_same_run(path, config, config, ("seed",), Example(rate=0.5), ("size",))  # rate may change
    with pytest.raises(ValueError, match=f"^out: {tmp_path} holds a different run \\(seed, size differ\\)"):
        check_same_run(path, {"seed": 1, "settings": {"size": 32}}, config, ("seed",), Example(), ("size",))
    with pytest.raises(ValueError, match=f"^{path}: settings: size: expected a positive number"):
        check_same_run(path, {"seed": 0, "settings": {"size": -1}}, config, ("seed",), Example(), ("size",))
    with pytest.raises(ValueError, match=f"^{path}: settings: settings: expected an object"):
        recorded_settings(Example, path, {"seed": 0})


def _preset_tables():
    from paz6d.hrnet.config import CONFIGS as HRNET
    from paz6d.keypointnet.config import CONFIGS as KEYPOINTNET
    from paz6d.probabilistic_keypoints.config import CONFIGS as PROBABILISTIC
    from paz6d.segmentation.config import CONFIGS as SEGMENTATION
    from paz6d.ssd.config import CONFIGS as SSD
    from paz6d.stn.config import CONFIGS as STN

    return {"stn": STN, "segmentation": SEGMENTATION, "hrnet": HRNET, "probabilistic_keypoints": PROBABILISTIC,
            "keypointnet": KEYPOINTNET, "ssd": SSD}


@pytest.mark.parametrize("method, name", [(method, name) for method, presets in _preset_tables().items()
                                          for name in presets])
def test_every_preset_reads_back_from_its_config_json_form(method, name):
    preset = _preset_tables()[method][name]
    assert type(preset).from_dict(json.loads(json.dumps(preset.to_dict()))) == preset
