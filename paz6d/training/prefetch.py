"""Overlap batch preparation with training: a ``data(step)`` callable that prepares the next step's
batch in a background thread.

Made for :class:`paz6d.training.trainer.Trainer`'s ``data(step) -> batch`` contract: the batch of a
step still depends only on the step index (resume stays deterministic); numpy/OpenCV release the GIL
for most of their work, so the next batch is built while TensorFlow runs the current step.

Example:
    >>> data = PrefetchedBatches(lambda step: step * 2)
    >>> data(0), data(1), data(5)
    (0, 2, 10)
    >>> data.close()
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any


class PrefetchedBatches:
    """``data(step)`` returning ``make_batch(step)`` and starting ``make_batch(step + 1)`` in a thread.

    A call for any other step than the prefetched one (e.g. after a resume) is computed directly.
    Exceptions raised while prefetching surface at the call that wants that batch.
    """

    def __init__(self, make_batch: Callable[[int], Any]):
        if not callable(make_batch):
            raise ValueError(f"make_batch: expected a callable make_batch(step), got {type(make_batch).__name__}")
        self._make_batch = make_batch
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="prefetch")
        self._pending: tuple[int, Future] | None = None

    def __call__(self, step: int) -> Any:
        if self._pending is not None and self._pending[0] == step:
            batch = self._pending[1].result()
        else:
            if self._pending is not None:
                self._pending[1].cancel()
            batch = self._make_batch(step)
        self._pending = (step + 1, self._executor.submit(self._make_batch, step + 1))
        return batch

    def close(self) -> None:
        """Stops the background thread (a pending batch is dropped)."""
        if self._pending is not None:
            self._pending[1].cancel()
            self._pending = None
        self._executor.shutdown(wait=True)

    def __enter__(self) -> "PrefetchedBatches":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
