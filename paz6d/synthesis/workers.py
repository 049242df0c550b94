"""One pool of render worker processes for every producer of synthetic images.

Each worker is a fresh *spawn* process (no inherited GL or TensorFlow state) that builds one
state object (``setup(*setup_args)``, e.g. a renderer with its GL context and the loaded meshes)
and then runs ``work(state, task)`` for the tasks it is handed. Results come back in task order.
``processes=0`` runs everything in the calling process (the state is closed at the end).

Mesa's llvmpipe starts one raster thread per core in every process; each worker gets its share,
``LP_NUM_THREADS`` = :func:`raster_threads` (a value the user set wins).
"""

from __future__ import annotations

import multiprocessing
import os
from typing import Any, Callable, Sequence

from tqdm.auto import tqdm

from paz6d.backend.checks import is_whole_number

_STATE: dict[str, Any] = {}


def raster_threads(cores: int, workers: int) -> int:
    """llvmpipe raster threads per worker process (``LP_NUM_THREADS``): Mesa starts one per core
    in every process by default, so ``workers`` processes would oversubscribe the cores. Each
    worker gets ``cores // workers``, and 0 (rasterize in the worker's own thread) instead of 1: a
    single extra thread only adds hand-offs (2 workers on 2 cores, 1,000 images at 640x480:
    36.4 images/s with 1 raster thread each, 40.9 with 0)."""
    threads = max(1, cores) // workers
    return threads if threads >= 2 else 0


def progress_bar(total: int, description: str, unit: str, enabled: bool = True, initial: int = 0) -> tqdm:
    """The tqdm bar (stderr) that producers of images show."""
    return tqdm(total=total, initial=initial, desc=description, unit=unit, disable=not enabled, dynamic_ncols=True)


def _start_worker(setup: Callable[..., Any], setup_args: tuple, threads: int) -> None:
    """Worker process set-up: ``LP_NUM_THREADS = threads`` unless the user set it, then the state."""
    os.environ.setdefault("LP_NUM_THREADS", str(threads))
    _STATE["state"] = setup(*setup_args)


def _run_task(job: tuple[Callable[[Any, Any], Any], Any]) -> Any:
    work, task = job
    return work(_STATE["state"], task)


def close_state(state: Any) -> None:
    """Calls ``state.close()`` when the state has one (renderers release their GL context)."""
    close = getattr(state, "close", None)
    if close is not None:
        close()


def run_in_workers(setup: Callable[..., Any], setup_args: tuple, work: Callable[[Any, Any], Any],
                   tasks: Sequence[Any], processes: int, progress: tqdm | None = None,
                   task_size: Callable[[Any], int] = len) -> list:
    """``[work(state, task) for task in tasks]``, computed in ``processes`` spawn workers.

    Args:
        setup: builds a worker's state from ``setup_args`` (module-level, picklable; it runs in
            the worker, so GL is only loaded there).
        setup_args: picklable arguments of ``setup``.
        work: module-level ``work(state, task)``; its result must be picklable.
        tasks: picklable tasks, e.g. chunks of image indices.
        processes: worker processes (at most one per task); 0 works in this process.
        progress: bar advanced by ``task_size(task)`` when a task's result arrives.
        task_size: the number of images in a task, for ``progress``.

    Returns:
        The results in task order (whatever order the workers finish in).
    """
    if not is_whole_number(processes) or processes < 0:
        raise ValueError(f"processes: expected 0 (this process) or a positive number of workers, got {processes!r}")
    results = []
    if processes == 0 or not tasks:
        state = setup(*setup_args) if tasks else None
        try:
            for task in tasks:
                results.append(work(state, task))
                if progress is not None:
                    progress.update(task_size(task))
        finally:
            close_state(state)
        return results
    count = min(int(processes), len(tasks))
    threads = raster_threads(os.cpu_count() or 1, count)
    context = multiprocessing.get_context("spawn")  # fresh processes: one GL context each, no inherited state
    with context.Pool(count, initializer=_start_worker, initargs=(setup, setup_args, threads)) as pool:
        for task, result in zip(tasks, pool.imap(_run_task, [(work, task) for task in tasks])):
            results.append(result)
            if progress is not None:
                progress.update(task_size(task))
    return results


def chunks(items: Sequence[Any], size: int) -> list:
    """``items`` cut into consecutive pieces of ``size`` (the last may be shorter)."""
    if int(size) < 1:
        raise ValueError(f"size: expected a positive chunk size, got {size}")
    return [items[start:start + size] for start in range(0, len(items), size)]
