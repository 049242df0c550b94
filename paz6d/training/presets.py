"""A training run's settings: a named preset of a method's ``CONFIGS`` with the run's overrides and
flag values applied (shared by the settings dataclasses of ``paz6d train <method>``), and the check that a
resumed run is the same run.

Light: standard library only, so the ``paz6d train <method>`` parsers stay cheap.
"""

from __future__ import annotations

from pathlib import Path


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


def check_same_run(out: str | Path, previous: dict | None, config: dict, keys: tuple[str, ...],
                   fixed_settings: tuple[str, ...]) -> None:
    """Checks that a run directory's earlier ``config.json`` (``previous``; ``None``: a new run) describes
    the run ``config``: the same ``keys`` and the same ``fixed_settings`` of its ``"settings"``.

    Raises:
        ValueError: naming ``out`` and every key that differs.
    """
    if previous is None:
        return
    changed = [key for key in keys if previous.get(key) != config[key]]
    changed += [key for key in fixed_settings if previous.get("settings", {}).get(key) != config["settings"].get(key)]
    if changed:
        raise ValueError(f"out: {out} holds a different run ({', '.join(changed)} differ); choose another --out")
