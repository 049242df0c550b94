"""Start-up time of ``paz6d`` commands against a bare ``python -c pass``, in one run.

Each command is run as a fresh process (the ``paz6d`` console script next to this Python, else
``python -m paz6d``) with ``--help``, which builds the command's parser and exits: the time every
command pays before it does any work. Best of ``--repeats`` wall times after one warm-up run each;
the child processes may write bytecode caches (``PYTHONDONTWRITEBYTECODE`` is removed from their
environment) as an installed package has them. With ``--before DIR`` (another checkout of paz6d,
e.g. ``git archive COMMIT | tar -x -C DIR``) each command also runs as ``python -m paz6d`` from that
folder, interleaved with the current code, and the ratio before/now is printed. Run:
``.venv/bin/python benchmarks/startup.py [--repeats 7] [--budget 0.25] [--before DIR]``; the exit
status is 1 when a command is over ``--budget`` seconds.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

COMMANDS = (("--help",), ("generate", "--help"), ("train", "aae", "--help"), ("train", "keypointnet", "--help"),
            ("train", "emotion", "--help"), ("train", "ssd", "--help"), ("detect", "--help"),
            ("estimate", "--help"), ("evaluate", "coco", "--help"), ("evaluate", "bop", "--help"),
            ("demo", "--help"))


def paz6d_executable() -> list[str]:
    """The ``paz6d`` console script of this Python's environment, or ``python -m paz6d``."""
    script = Path(sys.executable).with_name("paz6d")
    if script.exists():
        return [str(script)]
    found = shutil.which("paz6d")
    return [found] if found else [sys.executable, "-m", "paz6d"]


def best_times(commands: list[tuple[list[str], Path | None]], repeats: int,
               environment: dict[str, str]) -> list[float | None]:
    """Best wall time [s] of ``repeats`` interleaved runs of each ``(command, folder)`` after one
    warm-up run; ``None`` for a command that fails (e.g. one the ``--before`` code does not have)."""
    def once(command: list[str], folder: Path | None) -> float | None:
        start = time.perf_counter()
        result = subprocess.run(command, capture_output=True, env=environment, cwd=folder, timeout=300)
        return time.perf_counter() - start if result.returncode == 0 else None

    usable = [once(command, folder) is not None for command, folder in commands]
    times: list[list[float]] = [[] for _ in commands]
    for _ in range(repeats):
        for index, (command, folder) in enumerate(commands):
            if usable[index]:
                times[index].append(once(command, folder))
    return [min(values) if usable[index] else None for index, values in enumerate(times)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per command (best is reported)")
    parser.add_argument("--budget", type=float, default=0.25, help="seconds a command may take to start")
    parser.add_argument("--before", type=Path, help="another paz6d checkout to compare with (python -m paz6d there)")
    args = parser.parse_args(argv)
    if args.before is not None and not (args.before / "paz6d" / "cli.py").is_file():
        parser.error(f"--before: {args.before} has no paz6d/cli.py")
    if args.repeats < 1:
        parser.error(f"--repeats: expected a positive number, got {args.repeats}")
    environment = {name: value for name, value in os.environ.items() if name != "PYTHONDONTWRITEBYTECODE"}
    load = os.getloadavg()[0]
    (bare,) = best_times([([sys.executable, "-c", "pass"], None)], args.repeats, environment)
    print(f"load average {load:.2f}; python -c pass: {bare:.3f} s (best of {args.repeats})")
    print(f"{'command':<34s} {'wall [s]':>9s} {'/ pass':>7s} {'-pass [s]':>10s}"
          + ("" if args.before is None else f" {'before [s]':>10s} {'before/now':>10s}"))
    over = []
    executable = paz6d_executable()
    for command in COMMANDS:
        runs = [([*executable, *command], None)]
        if args.before is not None:
            runs.append(([sys.executable, "-m", "paz6d", *command], args.before))
        seconds, *before = best_times(runs, args.repeats, environment)
        name = "paz6d " + " ".join(command)
        row = f"{name:<34s} {seconds:9.3f} {seconds / bare:6.1f}x {seconds - bare:10.3f}"
        if before:
            row += f" {'-':>10s} {'-':>10s}" if before[0] is None else f" {before[0]:10.3f} {before[0] / seconds:9.1f}x"
        print(row)
        if seconds > args.budget:
            over.append(name)
    if over:
        print(f"over the {args.budget} s budget: {', '.join(over)}")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
