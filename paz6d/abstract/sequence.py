"""Batch dispatch for training: apply a processor to dataset samples and stack the results.

Three front ends share one deterministic core, :class:`BatchDispatcher`:

* ``BatchDispatcher`` itself (numpy only), e.g. for custom loops;
* ``ProcessingSequence``, a ``keras.utils.PyDataset`` (``workers`` / ``use_multiprocessing``
  are handed to Keras, which runs ``__getitem__`` in threads or forked processes);
* :func:`to_tf_dataset`, a ``tf.data.Dataset`` whose parallel ``map`` builds the batches.

Determinism: epoch ``e``'s sample order is a permutation drawn from ``(seed, e)`` and sample
``i`` of epoch ``e`` is processed with every :class:`~paz6d.abstract.processor.RandomProcessor`
reseeded from ``(seed, e, i)``, on a per-thread copy of the processor. The batches therefore
depend only on ``seed`` and the epoch, never on the number of workers or their timing, and the
three front ends produce identical batches. (With Keras ``fit``, pass ``shuffle=False``: this
class already shuffles with its seed, whereas Keras would reorder batches unseeded.)

Keras and TensorFlow are imported only when ``ProcessingSequence`` or :func:`to_tf_dataset`
is first used, through :mod:`paz6d.backend.tensorflow_guard`.

Example:
    >>> import numpy as np
    >>> from paz6d.abstract.sequence import BatchDispatcher
    >>> dispatcher = BatchDispatcher(np.arange(5.0), lambda x: (x, 2 * x), batch_size=2, seed=0)
    >>> len(dispatcher), [part.shape for part in dispatcher.batch(0, epoch=0)]
    (3, [(2,), (2,)])
"""

from __future__ import annotations

import copy
import itertools
import math
import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from paz6d.abstract.processor import random_processors, reseed
from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow

_ORDER_STREAM = 0
_SAMPLE_STREAM = 1


def collate(outputs: Sequence[Any]) -> Any:
    """Stacks per-sample outputs into a batch, keeping the structure (dict, tuple/list, array).

    Raises:
        ValueError: the samples' structures or array shapes differ.
    """
    first = outputs[0]
    if isinstance(first, dict):
        for output in outputs:
            if not isinstance(output, dict) or output.keys() != first.keys():
                raise ValueError(f"processor output: expected every sample to give a dict with keys "
                                 f"{sorted(first)}, got {type(output).__name__}")
        return {key: collate([output[key] for output in outputs]) for key in first}
    if isinstance(first, (tuple, list)):
        for output in outputs:
            if not isinstance(output, (tuple, list)) or len(output) != len(first):
                raise ValueError(f"processor output: expected every sample to give a sequence of "
                                 f"{len(first)} items, got {type(output).__name__}")
        return tuple(collate([output[index] for output in outputs]) for index in range(len(first)))
    arrays = [np.asarray(output) for output in outputs]
    shapes = {array.shape for array in arrays}
    if len(shapes) != 1:
        raise ValueError(f"processor output: cannot stack arrays of different shapes {sorted(shapes)}; "
                         "make the processor return fixed-size arrays")
    return np.stack(arrays)


class BatchDispatcher:
    """Deterministic, seeded batches of processed samples.

    Args:
        samples: anything with ``len`` and integer indexing (list, array, dataset object).
        processor: callable applied to each sample; its output (array, tuple/list or dict of
            arrays with fixed shapes) is stacked by :func:`collate`.
        batch_size: samples per batch.
        seed: base seed (None draws fresh entropy once, at construction).
        shuffle: permute the samples each epoch (otherwise dataset order).
        drop_remainder: drop the last, smaller batch.
    """

    def __init__(self, samples: Sequence, processor: Callable, batch_size: int, seed: int | None = None,
                 shuffle: bool = True, drop_remainder: bool = False):
        if int(batch_size) < 1:
            raise ValueError(f"batch_size: expected a positive integer, got {batch_size}")
        if not callable(processor):
            raise ValueError(f"processor: expected a callable, got {type(processor).__name__}")
        if len(samples) == 0:
            raise ValueError("samples: expected a non-empty dataset")
        if seed is not None and int(seed) < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {seed}")
        self.samples = samples
        self.processor = processor
        self.batch_size = int(batch_size)
        self.seed = int(np.random.SeedSequence().entropy if seed is None else seed)
        self.shuffle = shuffle
        self.drop_remainder = drop_remainder
        self._randomized = bool(random_processors(processor))
        self._local = threading.local()
        if self.drop_remainder and len(samples) < self.batch_size:
            raise ValueError(f"batch_size: {batch_size} exceeds the {len(samples)} samples and drop_remainder "
                             "would leave no batch")

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        del state["_local"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._local = threading.local()

    def __len__(self) -> int:
        count = len(self.samples) / self.batch_size
        return math.floor(count) if self.drop_remainder else math.ceil(count)

    def order(self, epoch: int) -> np.ndarray:
        """Sample indices ``(len(samples),)`` in the order visited during ``epoch``."""
        if not self.shuffle:
            return np.arange(len(self.samples))
        return np.random.default_rng([self.seed, _ORDER_STREAM, int(epoch)]).permutation(len(self.samples))

    def _thread_processor(self) -> Callable:
        if not self._randomized:
            return self.processor
        processor = getattr(self._local, "processor", None)
        if processor is None:
            processor = copy.deepcopy(self.processor)
            self._local.processor = processor
        return processor

    def process(self, sample_index: int, epoch: int) -> Any:
        """Processor output for sample ``sample_index`` in ``epoch`` (random processors reseeded
        from ``(seed, epoch, sample_index)``)."""
        processor = self._thread_processor()
        if self._randomized:
            reseed(processor, [self.seed, _SAMPLE_STREAM, int(epoch), int(sample_index)])
        return processor(self.samples[int(sample_index)])

    def batch(self, index: int, epoch: int) -> Any:
        """Batch ``index`` (``0 <= index < len(self)``) of ``epoch``, stacked with :func:`collate`."""
        if not 0 <= index < len(self):
            raise IndexError(f"index: batch {index} out of range for {len(self)} batches")
        indices = self.order(epoch)[index * self.batch_size:(index + 1) * self.batch_size]
        return collate([self.process(sample_index, epoch) for sample_index in indices])


def _build_processing_sequence() -> type:
    keras = import_keras()

    class ProcessingSequence(keras.utils.PyDataset):
        """``keras.utils.PyDataset`` over a :class:`BatchDispatcher`.

        Args:
            samples, processor, batch_size, seed, shuffle, drop_remainder: see :class:`BatchDispatcher`.
            workers, use_multiprocessing, max_queue_size: handed to ``PyDataset`` (Keras runs
                ``__getitem__`` in that many threads, or forked processes).
            epoch: epoch of the first pass; the end of each pass advances it.
        """

        def __init__(self, samples: Sequence, processor: Callable, batch_size: int, seed: int | None = None,
                     shuffle: bool = True, drop_remainder: bool = False, workers: int = 1,
                     use_multiprocessing: bool = False, max_queue_size: int = 10, epoch: int = 0):
            super().__init__(workers=workers, use_multiprocessing=use_multiprocessing, max_queue_size=max_queue_size)
            self.dispatcher = BatchDispatcher(samples, processor, batch_size, seed, shuffle, drop_remainder)
            self.epoch = int(epoch)
            self._in_epoch = False

        def __len__(self) -> int:
            return len(self.dispatcher)

        def __getitem__(self, index: int) -> Any:
            return self.dispatcher.batch(index, self.epoch)

        def on_epoch_begin(self) -> None:
            self._in_epoch = True

        def on_epoch_end(self) -> None:
            # Keras also calls on_epoch_end when it resets its iterator before the first epoch;
            # only the end of an epoch that began advances the counter. Advancing here (not at
            # the next begin) matters because Keras forks its worker processes before calling
            # on_epoch_begin.
            if self._in_epoch:
                self.epoch += 1
            self._in_epoch = False

    ProcessingSequence.__module__ = __name__
    return ProcessingSequence


def __getattr__(name: str) -> Any:
    if name == "ProcessingSequence":
        sequence_class = _build_processing_sequence()
        globals()[name] = sequence_class
        return sequence_class
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def to_tf_dataset(samples: Sequence, processor: Callable, batch_size: int, seed: int | None = None,
                  shuffle: bool = True, drop_remainder: bool = False, num_parallel_calls: int | None = None,
                  epochs: int | None = None, first_epoch: int = 0):
    """A ``tf.data.Dataset`` of processed batches, identical to :meth:`BatchDispatcher.batch`.

    The dataset is the stream of epochs ``first_epoch, first_epoch + 1, ...`` (``epochs`` of
    them, endless when None), each epoch's batches in order; iterating it again starts over at
    ``first_epoch``. Train with ``model.fit(dataset, epochs=n, steps_per_epoch=len(dispatcher))``
    so Keras keeps one iterator across epochs. Batches are built by ``tf.numpy_function`` in an
    order-preserving parallel ``map`` (``num_parallel_calls`` batches at once; None =
    ``tf.data.AUTOTUNE``).

    Returns:
        ``tf.data.Dataset`` whose elements have the processor output's structure with a leading
        batch dimension (``None`` unless ``drop_remainder``); dtypes and per-sample shapes come
        from processing the first sample.
    """
    tf = import_tensorflow()
    if epochs is not None and int(epochs) < 1:
        raise ValueError(f"epochs: expected a positive number of epochs or None, got {epochs}")
    dispatcher = BatchDispatcher(samples, processor, batch_size, seed, shuffle, drop_remainder)
    example = dispatcher.process(int(dispatcher.order(first_epoch)[0]), first_epoch)
    flat_example = [np.asarray(leaf) for leaf in tf.nest.flatten(example)]
    dtypes = [tf.as_dtype(leaf.dtype) for leaf in flat_example]
    leading = dispatcher.batch_size if drop_remainder else None
    shapes = [(leading,) + leaf.shape for leaf in flat_example]

    def batch_keys():
        epoch_numbers = itertools.count(first_epoch) if epochs is None else range(first_epoch, first_epoch + epochs)
        for epoch in epoch_numbers:
            for index in range(len(dispatcher)):
                yield epoch, index

    def make_batch(epoch, index) -> list[np.ndarray]:
        leaves = tf.nest.flatten(dispatcher.batch(int(index), int(epoch)))
        return [np.asarray(leaf, dtype=dtype.as_numpy_dtype) for leaf, dtype in zip(leaves, dtypes)]

    def make_batch_tensors(epoch, index):
        leaves = tf.numpy_function(make_batch, [epoch, index], dtypes, stateful=False)
        for leaf, shape in zip(leaves, shapes):
            leaf.set_shape(shape)
        return tf.nest.pack_sequence_as(example, leaves)

    scalar = tf.TensorSpec((), tf.int64)
    dataset = tf.data.Dataset.from_generator(batch_keys, output_signature=(scalar, scalar))
    dataset = dataset.map(make_batch_tensors, deterministic=True,
                          num_parallel_calls=tf.data.AUTOTUNE if num_parallel_calls is None else num_parallel_calls)
    return dataset.prefetch(tf.data.AUTOTUNE)
