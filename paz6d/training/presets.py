"""A training run's settings: a named preset of a method's ``CONFIGS`` with the run's overrides and
flag values applied. Shared by the settings dataclasses of ``paz6d train <method>``.

Light: standard library only, so the ``paz6d train <method>`` parsers stay cheap.
"""

from __future__ import annotations


def preset_settings(configs: dict[str, dict], config: str, overrides: dict, check_overrides: bool = True,
                    known: str = "settings are") -> dict:
    """``configs[config]`` with ``overrides`` applied (a new dict).

    Args:
        configs: preset name -> settings.
        config: the preset chosen.
        overrides: settings replacing the preset's; with ``check_overrides`` each must be one of its keys
            (``known`` introduces the list of keys in the message).

    Raises:
        ValueError: an unknown preset or (with ``check_overrides``) an unknown setting.
    """
    if config not in configs:
        raise ValueError(f"config: expected one of {sorted(configs)}, got {config!r}")
    if check_overrides:
        unknown = sorted(set(overrides) - set(configs[config]))
        if unknown:
            raise ValueError(f"overrides: unknown setting(s) {unknown}; {known} {sorted(configs[config])}")
    return {**configs[config], **overrides}


def apply_steps(settings: dict, steps: int | None) -> dict:
    """``settings`` with ``steps`` (a flag; ``None``: the preset's) applied in place; returns it.

    Raises:
        ValueError: ``steps`` not positive.
    """
    if steps is not None:
        if steps <= 0:
            raise ValueError(f"steps: expected a positive number of steps, got {steps}")
        settings["steps"] = int(steps)
    return settings


def apply_positive_integers(settings: dict, values: dict[str, int | None]) -> dict:
    """``settings`` with each given (not ``None``) value of ``values`` applied in place as an ``int``;
    returns it.

    Raises:
        ValueError: a value that is not positive (naming it).
    """
    for name, value in values.items():
        if value is not None:
            if int(value) <= 0:
                raise ValueError(f"{name}: expected a positive integer, got {value}")
            settings[name] = int(value)
    return settings
