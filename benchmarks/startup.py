"""Start-up time of ``paz6d`` commands against a bare ``python -c pass``, in one run.

Each command is run as a fresh process (the ``paz6d`` console script next to this Python, else
``python -m paz6d``) with ``--help``, which builds the command's parser and exits: the time every
command pays before it does any work. Best of ``--repeats`` wall times after one warm-up run each;
the child processes may write bytecode caches (``PYTHONDONTWRITEBYTECODE`` is removed from their
environment) as an installed package has them. Run: ``.venv/bin/python benchmarks/startup.py
[--repeats 7] [--budget 0.25]``; the exit status is 1 when a command is over ``--budget`` seconds.
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


def best_time(command: list[str], repeats: int, environment: dict[str, str]) -> float:
    """Best wall time [s] of ``repeats`` runs of ``command`` after one warm-up run (which must succeed)."""
    subprocess.run(command, check=True, capture_output=True, env=environment, timeout=300)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, env=environment, timeout=300)
        times.append(time.perf_counter() - start)
    return min(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per command (best is reported)")
    parser.add_argument("--budget", type=float, default=0.25, help="seconds a command may take to start")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats: expected a positive number, got {args.repeats}")
    environment = {name: value for name, value in os.environ.items() if name != "PYTHONDONTWRITEBYTECODE"}
    load = os.getloadavg()[0]
    bare = best_time([sys.executable, "-c", "pass"], args.repeats, environment)
    print(f"load average {load:.2f}; python -c pass: {bare:.3f} s (best of {args.repeats})")
    print(f"{'command':<34s} {'wall [s]':>9s} {'/ pass':>7s} {'-pass [s]':>10s}")
    over = []
    executable = paz6d_executable()
    for command in COMMANDS:
        seconds = best_time([*executable, *command], args.repeats, environment)
        name = "paz6d " + " ".join(command)
        print(f"{name:<34s} {seconds:9.3f} {seconds / bare:6.1f}x {seconds - bare:10.3f}")
        if seconds > args.budget:
            over.append(name)
    if over:
        print(f"over the {args.budget} s budget: {', '.join(over)}")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
