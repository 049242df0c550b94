"""Batch dispatch: the numpy core, the Keras PyDataset front end and the tf.data front end must
give the same seeded batches whatever the number of workers."""

from __future__ import annotations

import pickle
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from paz6d.abstract import Processor
from paz6d.abstract.sequence import BatchDispatcher, collate
from paz6d.synthesis.augment import RandomBrightness, RandomImageNoise

SAMPLES = [(np.full((4, 4, 3), 20 * index, np.uint8), index) for index in range(10)]


class Augment(Processor):
    """``(image, label)`` to ``(float32 image, float32 label)`` with two random steps."""

    def __init__(self):
        super().__init__()
        self.brightness = RandomBrightness(max_delta=30.0, seed=0)
        self.noise = RandomImageNoise(max_std=5.0, seed=0)

    def call(self, sample):
        image, label = sample
        return self.noise(self.brightness(image)).astype(np.float32) / 255.0, np.float32(label)


def all_batches(dispatcher: BatchDispatcher, epoch: int) -> list:
    return [dispatcher.batch(index, epoch) for index in range(len(dispatcher))]


def assert_batches_equal(actual, expected):
    assert len(actual) == len(expected)
    for got, want in zip(actual, expected):
        assert len(got) == len(want)
        for got_part, want_part in zip(got, want):
            np.testing.assert_array_equal(np.asarray(got_part), want_part)


def test_dispatcher_orders_each_epoch_with_its_seed():
    dispatcher = BatchDispatcher(SAMPLES, Augment(), batch_size=4, seed=3)
    assert len(dispatcher) == 3
    assert len(BatchDispatcher(SAMPLES, Augment(), 4, seed=3, drop_remainder=True)) == 2
    first, second = dispatcher.order(0), dispatcher.order(1)
    assert sorted(first) == list(range(10)) and not np.array_equal(first, second)
    np.testing.assert_array_equal(first, BatchDispatcher(SAMPLES, Augment(), 4, seed=3).order(0))
    assert not np.array_equal(first, BatchDispatcher(SAMPLES, Augment(), 4, seed=4).order(0))
    np.testing.assert_array_equal(BatchDispatcher(SAMPLES, Augment(), 4, shuffle=False).order(5), np.arange(10))
    labels = np.concatenate([batch[1] for batch in all_batches(dispatcher, 0)])
    np.testing.assert_array_equal(labels, first)  # every sample once, in the epoch's order
    assert [batch[0].shape for batch in all_batches(dispatcher, 0)] == [(4, 4, 4, 3), (4, 4, 4, 3), (2, 4, 4, 3)]


def test_batches_do_not_depend_on_threads_or_batch_composition():
    dispatcher = BatchDispatcher(SAMPLES, Augment(), batch_size=4, seed=11)
    sequential = all_batches(dispatcher, 2)
    keys = [(index, 2) for index in range(len(dispatcher))] * 3
    with ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda key: dispatcher.batch(*key), keys))
    for position, (index, _) in enumerate(keys):
        assert_batches_equal([threaded[position]], [sequential[index]])
    assert_batches_equal(all_batches(BatchDispatcher(SAMPLES, Augment(), 4, seed=11), 2), sequential)
    different_seed = all_batches(BatchDispatcher(SAMPLES, Augment(), 4, seed=12), 2)
    assert not np.array_equal(different_seed[0][0], sequential[0][0])
    different_epoch = all_batches(dispatcher, 3)
    assert not np.array_equal(different_epoch[0][0], sequential[0][0])
    # A sample's augmentation depends on (seed, epoch, sample), not on which batch it lands in.
    by_label = {int(label): image for images, labels in sequential for image, label in zip(images, labels)}
    regrouped = BatchDispatcher(SAMPLES, Augment(), batch_size=3, seed=11)
    for images, labels in all_batches(regrouped, 2):
        for image, label in zip(images, labels):
            np.testing.assert_array_equal(image, by_label[int(label)])


def test_dispatcher_leaves_the_callers_processor_alone():
    augment = Augment()
    state = augment.brightness.generator.bit_generator.state
    BatchDispatcher(SAMPLES, augment, 4, seed=0).batch(0, 0)
    assert augment.brightness.generator.bit_generator.state == state
    plain = BatchDispatcher(SAMPLES, lambda sample: sample[1], 4, shuffle=False)
    np.testing.assert_array_equal(plain.batch(2, 0), [8, 9])
    restored = pickle.loads(pickle.dumps(BatchDispatcher(SAMPLES, Augment(), 4, seed=5)))
    assert_batches_equal(all_batches(restored, 1), all_batches(BatchDispatcher(SAMPLES, Augment(), 4, seed=5), 1))


def test_collate_keeps_structure_and_rejects_ragged_samples():
    batch = collate([{"image": np.zeros((2, 2)), "meta": (1, np.ones(3))}] * 3)
    assert batch["image"].shape == (3, 2, 2) and batch["meta"][0].shape == (3,) and batch["meta"][1].shape == (3, 3)
    assert isinstance(collate([[1, 2], [3, 4]]), tuple)
    with pytest.raises(ValueError, match=r"cannot stack arrays of different shapes \[\(2,\), \(3,\)\]"):
        collate([np.zeros(2), np.zeros(3)])
    with pytest.raises(ValueError, match=r"expected every sample to give a dict with keys \['a'\]"):
        collate([{"a": 1}, {"b": 1}])
    with pytest.raises(ValueError, match="expected every sample to give a sequence of 2 items"):
        collate([(1, 2), (1, 2, 3)])


def test_dispatcher_validation():
    with pytest.raises(ValueError, match="batch_size: expected a positive integer, got 0"):
        BatchDispatcher(SAMPLES, Augment(), 0)
    with pytest.raises(ValueError, match="samples: expected a non-empty dataset"):
        BatchDispatcher([], Augment(), 2)
    with pytest.raises(ValueError, match="processor: expected a callable, got int"):
        BatchDispatcher(SAMPLES, 3, 2)
    with pytest.raises(ValueError, match="seed: expected a non-negative integer, got -1"):
        BatchDispatcher(SAMPLES, Augment(), 2, seed=-1)
    with pytest.raises(ValueError, match="batch_size: 20 exceeds the 10 samples and drop_remainder"):
        BatchDispatcher(SAMPLES, Augment(), 20, drop_remainder=True)
    with pytest.raises(IndexError, match="index: batch 3 out of range for 3 batches"):
        BatchDispatcher(SAMPLES, Augment(), 4).batch(3, 0)


def test_importing_the_sequence_module_does_not_import_tensorflow():
    code = ("import sys, paz6d.abstract, paz6d.abstract.sequence, paz6d.synthesis.augment; "
            "print(sorted(name for name in ('tensorflow', 'keras') if name in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert result.stdout.strip() == "[]"


@pytest.fixture(scope="module")
def keras():
    from paz6d.backend.tensorflow_guard import import_keras

    return import_keras()


def tiny_model(keras):
    inputs = keras.Input((4, 4, 3))
    outputs = keras.layers.Dense(1)(keras.layers.Flatten()(inputs))
    model = keras.Model(inputs, outputs)
    model.compile(optimizer=keras.optimizers.SGD(0.01), loss="mse")
    return model


def test_processing_sequence_is_a_pydataset_serving_the_dispatcher_batches(keras):
    from paz6d.abstract.sequence import ProcessingSequence

    sequence = ProcessingSequence(SAMPLES, Augment(), 4, seed=7, workers=3, use_multiprocessing=True,
                                  max_queue_size=5)
    assert isinstance(sequence, keras.utils.PyDataset)
    assert (sequence.workers, sequence.use_multiprocessing, sequence.max_queue_size) == (3, True, 5)
    assert len(sequence) == 3
    reference = BatchDispatcher(SAMPLES, Augment(), 4, seed=7)
    assert_batches_equal([sequence[index] for index in range(3)], all_batches(reference, 0))
    sequence.on_epoch_end()  # Keras calls this once before the first epoch: no epoch passed yet
    assert sequence.epoch == 0
    sequence.on_epoch_begin()
    sequence.on_epoch_end()
    assert sequence.epoch == 1
    assert_batches_equal([sequence[index] for index in range(3)], all_batches(reference, 1))
    with pytest.raises(IndexError):
        sequence[3]


def test_keras_fit_with_thread_workers_sees_each_epochs_batches(keras):
    from paz6d.abstract.sequence import ProcessingSequence

    class RecordingSequence(ProcessingSequence):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.requests = []

        def __getitem__(self, index):
            self.requests.append((self.epoch, index))
            return super().__getitem__(index)

    sequence = RecordingSequence(SAMPLES, Augment(), 4, seed=1, workers=2)
    history = tiny_model(keras).fit(sequence, epochs=2, shuffle=False, verbose=0)
    assert np.all(np.isfinite(history.history["loss"]))
    assert {(epoch, index) for epoch in (0, 1) for index in range(3)} <= set(sequence.requests)
    assert {epoch for epoch, _ in sequence.requests} == {0, 1}
    assert sequence.epoch == 2


@pytest.mark.timeout(300)  # forked workers must never hang the suite
def test_keras_fit_with_worker_processes(keras):
    from paz6d.abstract.sequence import ProcessingSequence

    sequence = ProcessingSequence(SAMPLES, Augment(), 4, seed=1, workers=2, use_multiprocessing=True)
    history = tiny_model(keras).fit(sequence, epochs=1, shuffle=False, verbose=0)
    assert np.isfinite(history.history["loss"][0]) and sequence.epoch == 1


def test_tf_dataset_gives_the_dispatcher_batches(keras):
    from paz6d.abstract.sequence import to_tf_dataset

    reference = BatchDispatcher(SAMPLES, Augment(), 4, seed=9)
    expected = all_batches(reference, 0) + all_batches(reference, 1)
    for parallel in (1, 4):
        dataset = to_tf_dataset(SAMPLES, Augment(), 4, seed=9, num_parallel_calls=parallel, epochs=2)
        assert_batches_equal(list(dataset.as_numpy_iterator()), expected)
    assert_batches_equal(list(dataset.as_numpy_iterator()), expected)  # iterating again starts over
    later = to_tf_dataset(SAMPLES, Augment(), 4, seed=9, epochs=1, first_epoch=1)
    assert_batches_equal(list(later.as_numpy_iterator()), all_batches(reference, 1))
    fixed = to_tf_dataset(SAMPLES, Augment(), 4, seed=9, drop_remainder=True, epochs=1)
    assert fixed.element_spec[0].shape.as_list() == [4, 4, 4, 3]
    assert len(list(fixed)) == 2
    assert to_tf_dataset(SAMPLES, Augment(), 4, seed=9, epochs=1).element_spec[0].shape.as_list() == [None, 4, 4, 3]
    as_dict = to_tf_dataset(SAMPLES, lambda sample: {"label": np.int32(sample[1])}, 4, shuffle=False, epochs=1)
    np.testing.assert_array_equal(next(as_dict.as_numpy_iterator())["label"], [0, 1, 2, 3])
    with pytest.raises(ValueError, match="epochs: expected a positive number of epochs or None, got 0"):
        to_tf_dataset(SAMPLES, Augment(), 4, epochs=0)


def test_tf_dataset_trains_with_fit(keras):
    from paz6d.abstract.sequence import to_tf_dataset

    dataset = to_tf_dataset(SAMPLES, Augment(), 4, seed=2)
    history = tiny_model(keras).fit(dataset, epochs=2, steps_per_epoch=3, shuffle=False, verbose=0)
    assert len(history.history["loss"]) == 2 and np.all(np.isfinite(history.history["loss"]))
