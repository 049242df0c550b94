"""Run independent jobs in spawned processes, a few at a time (``paz6d benchmark lmo --jobs N``).

Each job is a module-level function called in a fresh ``spawn`` process, so it may import TensorFlow and
start its own rendering processes (the processes are not daemonic). Small networks use two or more CPU cores
poorly, so several trainings side by side, each on fewer threads, finish sooner than one after the other
(``docs/real_photos.md``).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from multiprocessing.connection import wait


def threads_per_job(jobs: int, cores: int | None = None) -> int:
    """CPU threads each of ``jobs`` side-by-side processes may use: the cores shared out, at least 1."""
    return max(1, (cores or os.cpu_count() or 1) // max(1, jobs))


def run_in_processes(tasks: Sequence[tuple[str, Callable, tuple]], jobs: int) -> None:
    """Calls ``function(*args)`` of every ``(name, function, args)`` task, each in its own spawned process,
    at most ``jobs`` at once, in the given order.

    Raises:
        ValueError: ``jobs`` below 1.
        RuntimeError: a task's process failed (its traceback is on stderr); the message names the task. The
            tasks still running are stopped; those not started yet are not started.
    """
    if int(jobs) < 1:
        raise ValueError(f"jobs: expected at least 1 process, got {jobs}")
    context = multiprocessing.get_context("spawn")
    waiting, running = list(tasks), {}
    try:
        while waiting or running:
            while waiting and len(running) < jobs:
                name, function, args = waiting.pop(0)
                process = context.Process(target=function, args=args, name=f"paz6d {name}")
                process.start()
                running[process.sentinel] = (name, process)
            for sentinel in wait(list(running)):
                name, process = running.pop(sentinel)
                process.join()
                if process.exitcode != 0:
                    raise RuntimeError(f"{name}: its process failed (exit code {process.exitcode}; its error is "
                                       f"printed above)")
    finally:
        for _, process in running.values():
            process.terminate()
            process.join()
