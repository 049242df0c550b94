"""Runs a generation: checks inputs, renders the missing images in worker processes
(:mod:`paz6d.synthesis.workers`), merges.

Resumable: an image whose shard exists is not redone; re-running the same command after a crash
(even SIGKILL) completes the set. Deterministic: image ``i`` depends only on ``(seed, i)``, so
the files are byte-identical for any number of workers or backend.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Iterable

from data_gen import bop_writer
from data_gen.assets import Assets, load_assets
from data_gen.config import BACKENDS, GenerationConfig, check_output_writable
from data_gen.files import remove_stale_temporaries
from data_gen.producer import ImageProducer, write_files
from data_gen.ray_backend import import_ray, run_with_ray
from paz6d.synthesis.workers import chunks, progress_bar, run_in_workers


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


def _render_chunk(producer, indices: list[int]) -> tuple[int, int]:
    """Worker task: renders and writes ``indices``; returns ``(images, files written)``."""
    return len(indices), render_indices(producer, indices, producer.config.out, lambda count: None)


def _run_local(config: GenerationConfig, assets: Assets, pending: list[int], workers: int, progress) -> int:
    if workers == 1:
        producer = ImageProducer(config, assets)
        try:
            return render_indices(producer, pending, config.out, progress.update)
        finally:
            producer.close()
    chunk = max(1, min(8, len(pending) // (4 * workers)))
    results = run_in_workers(ImageProducer, (config,), _render_chunk, chunks(pending, chunk), workers, progress)
    return sum(files for _, files in results)


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
        import_ray()
    assets = load_assets(config)
    check_output_writable(config.out)
    started = time.perf_counter()
    config.out.mkdir(parents=True, exist_ok=True)
    bop_writer.write_state(config)
    remove_stale_temporaries(config.out)
    written = len(bop_writer.write_static_files(config, assets))
    # Resume: an image is redone unless its record and every file it names are on disk (not empty).
    pending = [index for index in range(config.num_images) if not bop_writer.image_complete(config, index)]
    with progress_bar(config.num_images, "paz6d generate", "img", show_progress,
                      initial=config.num_images - len(pending)) as progress:
        if pending and backend == "local":
            written += _run_local(config, assets, pending, int(workers), progress)
        elif pending:
            written += run_with_ray(config, pending, int(workers), ray_address, progress)
    written += len(bop_writer.merge_scenes(config, assets.object_ids))
    return GenerationSummary(config.num_images, len(pending), config.num_images - len(pending), written,
                             time.perf_counter() - started)
