"""Runs a generation: checks inputs, renders the missing images in worker processes, merges.

Resumable: an image whose shard exists is not redone; re-running the same command after a crash
(even SIGKILL) completes the set. Deterministic: image ``i`` depends only on ``(seed, i)``, so
the files are byte-identical for any number of workers or backend.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Iterable

from tqdm import tqdm

from data_gen import bop_writer
from data_gen.assets import Assets, load_assets
from data_gen.config import BACKENDS, GenerationConfig, check_output_writable
from data_gen.files import remove_stale_temporaries



@dataclass
class GenerationSummary:
    """What a run did."""

    images_total: int
    images_rendered: int
    images_skipped: int
    files_written: int
    seconds: float

    @property
    def images_per_second(self) -> float:
        return self.images_rendered / self.seconds if self.seconds > 0 else 0.0


def render_indices(producer, indices: Iterable[int], output, on_image: Callable[[int], None]) -> int:
    """Renders ``indices`` with ``producer`` while a thread encodes and writes the previous image
    (PNG encoding releases the GIL); at most one image waits. Returns the number of files written."""
    from data_gen.producer import write_files

    written = 0
    with ThreadPoolExecutor(max_workers=1) as writer:
        pending = None
        for index in indices:
            image = producer.render(index)
            if pending is not None:
                written += pending.result()
                on_image(1)
            pending = writer.submit(lambda image=image: write_files(output, producer.encode(image)))
        if pending is not None:
            written += pending.result()
            on_image(1)
    return written


_worker_producer = None


def raster_threads(cores: int, workers: int) -> int:
    """llvmpipe raster threads per worker process (``LP_NUM_THREADS``): Mesa starts one per core
    in every process by default, so ``workers`` processes would oversubscribe the cores. Each
    worker gets ``cores // workers``, and 0 (rasterize in the worker's own thread) instead of 1: a
    single extra thread only adds hand-offs (2 workers on 2 cores, 1,000 images at 640x480:
    36.4 images/s with 1 raster thread each, 40.9 with 0)."""
    threads = max(1, cores) // workers
    return threads if threads >= 2 else 0


def _start_worker(config: GenerationConfig, raster_threads: int) -> None:
    """Worker process set-up: ``LP_NUM_THREADS = raster_threads`` (see :func:`raster_threads`)
    unless the user set it."""
    global _worker_producer
    os.environ.setdefault("LP_NUM_THREADS", str(raster_threads))
    from data_gen.producer import ImageProducer

    _worker_producer = ImageProducer(config)


def _work(indices: list[int]) -> tuple[int, int]:
    written = render_indices(_worker_producer, indices, _worker_producer.config.out, lambda count: None)
    return len(indices), written


def _chunks(indices: list[int], size: int) -> list[list[int]]:
    return [indices[start:start + size] for start in range(0, len(indices), size)]


def _run_local(config: GenerationConfig, assets: Assets, pending: list[int], workers: int, progress: tqdm) -> int:
    if workers == 1:
        from data_gen.producer import ImageProducer

        producer = ImageProducer(config, assets)
        try:
            return render_indices(producer, pending, config.out, progress.update)
        finally:
            producer.close()
    chunk = max(1, min(8, len(pending) // (4 * workers)))
    written = 0
    context = multiprocessing.get_context("spawn")  # fresh processes: one GL context each, no inherited state
    threads = raster_threads(os.cpu_count() or 1, workers)
    with context.Pool(workers, initializer=_start_worker, initargs=(config, threads)) as pool:
        for images, files in pool.imap_unordered(_work, _chunks(pending, chunk)):
            written += files
            progress.update(images)
    return written


def generate(config: GenerationConfig, workers: int = 1, backend: str = "local", ray_address: str | None = None,
             show_progress: bool = True) -> GenerationSummary:
    """Generates (or completes) the data set described by ``config``.

    Args:
        config: what to generate.
        workers: parallel worker processes (local) or Ray actors.
        backend: ``"local"`` (multiprocessing, spawn) or ``"ray"`` (needs the ``ray`` extra).
        ray_address: Ray cluster address (``None``: start a local Ray instance).
        show_progress: tqdm progress bar on stderr.

    Raises:
        ValueError: bad input (checked before anything is written).
    """
    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise ValueError(f"workers: expected a positive integer, got {workers!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend: expected one of {BACKENDS}, got {backend!r}")
    if backend == "ray":
        from data_gen.ray_backend import import_ray

        import_ray()
    assets = load_assets(config)
    check_output_writable(config.out)
    started = time.perf_counter()
    config.out.mkdir(parents=True, exist_ok=True)
    bop_writer.write_state(config)
    remove_stale_temporaries(config.out)
    written = len(bop_writer.write_static_files(config, assets))
    pending = [index for index in range(config.num_images) if not bop_writer.shard_path(config, index).exists()]
    with tqdm(total=config.num_images, initial=config.num_images - len(pending), unit="img",
              desc="paz6d generate", disable=not show_progress) as progress:
        if pending and backend == "local":
            written += _run_local(config, assets, pending, int(workers), progress)
        elif pending:
            from data_gen.ray_backend import run_with_ray

            written += run_with_ray(config, pending, int(workers), ray_address, progress)
    written += len(bop_writer.merge_scenes(config, assets.object_ids))
    return GenerationSummary(config.num_images, len(pending), config.num_images - len(pending), written,
                             time.perf_counter() - started)
