"""Shared trainer: checkpoints, resume (bit-identical to an uninterrupted run), logs, samples, bad input."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from paz6d.backend.tensorflow_guard import import_keras


def _problem(seed: int = 0, ema_momentum: float | None = None):
    """A tiny linear regression y = x @ W_true: model, optimizer, loss_fn, data(step)."""
    keras = import_keras()
    keras.utils.set_random_seed(seed)
    model = keras.Sequential([keras.Input((4,)), keras.layers.Dense(2)])
    optimizer = keras.optimizers.Adam(0.05, use_ema=ema_momentum is not None, ema_momentum=ema_momentum or 0.99)
    rng = np.random.default_rng(1)
    W_true = rng.normal(size=(4, 2)).astype("float32")
    inputs = rng.normal(size=(20, 8, 4)).astype("float32")

    def data(step):
        x = inputs[step % len(inputs)]
        return x, x @ W_true

    def loss_fn(model, batch):
        x, y = batch
        error = model(x, training=True) - y
        return {"loss": keras.ops.mean(error ** 2), "max_error": keras.ops.max(keras.ops.abs(error))}

    return model, optimizer, loss_fn, data


def _trainer(run_dir, steps, data=None, ema_momentum=None, **kwargs):
    from paz6d.training.trainer import Trainer

    model, optimizer, loss_fn, default_data = _problem(ema_momentum=ema_momentum)
    options = dict(checkpoint_every=5, log_every=1, progress=False)
    options.update(kwargs)
    return Trainer(model, optimizer, loss_fn, data or default_data, run_dir, steps, **options)


def _log_steps(run_dir):
    with (run_dir / "log.csv").open() as handle:
        return [int(row["step"]) for row in csv.DictReader(handle)]


def test_fit_lowers_loss_and_writes_logs_checkpoints_samples(tmp_path):
    drawn = []

    def sample_callback(model, step, path):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figure = plt.figure(figsize=(1, 1))
        plt.plot(np.asarray(model.layers[0].kernel).ravel())
        figure.savefig(path)
        plt.close(figure)
        drawn.append(step)

    trainer = _trainer(tmp_path, 30, sample_every=10, sample_callback=sample_callback)
    summary = trainer.fit()
    assert summary.start_step == 0 and summary.final_step == 30
    assert _log_steps(tmp_path) == list(range(1, 31))
    with (tmp_path / "log.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert {"loss", "max_error", "data_seconds", "step_seconds"} <= set(rows[0])
    assert float(rows[-1]["loss"]) < 0.5 * float(rows[0]["loss"])
    assert drawn == [10, 20, 30]
    assert sorted(p.name for p in (tmp_path / "samples").iterdir()) == [
        "step_00000010.png", "step_00000020.png", "step_00000030.png"]
    events = list((tmp_path / "tensorboard").glob("events.out.tfevents.*"))
    assert len(events) == 1
    from tensorflow.python.summary.summary_iterator import summary_iterator
    from tensorflow.python.framework import tensor_util

    logged = {(event.step, value.tag): float(tensor_util.MakeNdarray(value.tensor))
              for event in summary_iterator(str(events[0])) for value in event.summary.value}
    assert logged[(30, "loss")] == pytest.approx(float(rows[-1]["loss"]), rel=1e-6)
    assert (1, "max_error") in logged
    pointer = json.loads((tmp_path / "checkpoint.json").read_text())
    assert pointer["step"] == 30
    assert len(list((tmp_path / "checkpoints").glob("step_*"))) == 2  # keep_checkpoints=2
    assert summary.loader_samples_per_second > 0 and summary.model_samples_per_second > 0


def test_resume_after_crash_matches_uninterrupted_run(tmp_path):
    reference = _trainer(tmp_path / "reference", 20)
    reference.fit()

    model, optimizer, loss_fn, data = _problem()

    def crashing_data(step):
        if step == 13:
            raise RuntimeError("simulated crash")
        return data(step)

    crashed = _trainer(tmp_path / "resumed", 20, data=crashing_data)
    with pytest.raises(RuntimeError, match="simulated crash"):
        crashed.fit()
    assert json.loads((tmp_path / "resumed" / "checkpoint.json").read_text())["step"] == 10
    assert _log_steps(tmp_path / "resumed")[-1] == 13

    resumed = _trainer(tmp_path / "resumed", 20)
    summary = resumed.fit()
    assert summary.start_step == 10 and summary.final_step == 20
    assert _log_steps(tmp_path / "resumed") == list(range(1, 21))  # rows 11..13 of the crashed run replaced
    assert int(resumed.optimizer.iterations.numpy()) == 20
    for got, want in zip(resumed.model.get_weights(), reference.model.get_weights()):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)  # float32 arithmetic, same op order


def test_prefetching_gives_the_same_result(tmp_path):
    plain = _trainer(tmp_path / "plain", 12)
    plain.fit()
    calls = []
    model, optimizer, loss_fn, data = _problem()

    def counted(step):
        calls.append(step)
        return data(step)

    prefetched = _trainer(tmp_path / "prefetched", 12, data=counted, prefetch=3, prefetch_workers=2)
    prefetched.fit()
    assert sorted(calls) == list(range(12))  # every batch made once, none past the end
    for got, want in zip(prefetched.model.get_weights(), plain.model.get_weights()):
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


def test_weight_averaging_ends_with_the_averaged_weights_and_resumes(tmp_path):
    trajectory = []

    def record(model, step, path):
        trajectory.append([np.array(weight) for weight in model.get_weights()])

    raw = _trainer(tmp_path / "raw", 12, sample_every=1, sample_callback=record)
    raw.fit()
    momentum = 0.8
    expected = trajectory[0]
    for weights in trajectory[1:]:  # Keras: the average starts at the first step's weights
        expected = [momentum * average + (1 - momentum) * weight for average, weight in zip(expected, weights)]
    averaged = _trainer(tmp_path / "ema", 12, ema_momentum=momentum)
    averaged.fit()
    for got, want, last in zip(averaged.model.get_weights(), expected, trajectory[-1]):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        assert not np.allclose(got, last, atol=1e-4)  # not the raw weights
    checkpoint = _trainer(tmp_path / "ema", 12, ema_momentum=momentum)
    checkpoint.restore()  # checkpoints keep the raw weights
    for got, want in zip(checkpoint.model.get_weights(), trajectory[-1]):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    _trainer(tmp_path / "split", 5, ema_momentum=momentum).fit()  # stopped early, then extended
    resumed = _trainer(tmp_path / "split", 12, ema_momentum=momentum)
    resumed.fit()
    for got, want in zip(resumed.model.get_weights(), expected):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


def test_keyboard_interrupt_saves_a_checkpoint(tmp_path):
    model, optimizer, loss_fn, data = _problem()

    def interrupting_data(step):
        if step == 7:
            raise KeyboardInterrupt
        return data(step)

    trainer = _trainer(tmp_path, 20, data=interrupting_data)
    with pytest.raises(KeyboardInterrupt):
        trainer.fit()
    assert trainer.latest_checkpoint()[0] == 7
    assert _trainer(tmp_path, 20).fit().start_step == 7


def test_extending_a_finished_run_continues(tmp_path):
    _trainer(tmp_path, 10).fit()
    summary = _trainer(tmp_path, 15).fit()
    assert (summary.start_step, summary.final_step) == (10, 15)
    finished = _trainer(tmp_path, 15).fit()  # nothing left to do: nothing measured, and JSON can hold that
    assert finished.final_step == 15
    assert finished.loader_samples_per_second is None and finished.model_samples_per_second is None


def test_learning_rate_function_sets_each_steps_rate_and_resumes_like_an_uninterrupted_run(tmp_path):
    seen = []

    def rate(step):
        seen.append(step)
        return 0.05 if step < 12 else 0.005

    reference = _trainer(tmp_path / "reference", 20, learning_rate=rate)
    reference.fit()
    assert seen == list(range(20)) and float(reference.optimizer.learning_rate) == pytest.approx(0.005)
    constant = _trainer(tmp_path / "constant", 20)
    constant.fit()
    assert not np.allclose(constant.model.get_weights()[0], reference.model.get_weights()[0])
    _trainer(tmp_path / "resumed", 10, learning_rate=rate).fit()  # stops before the drop; its checkpoint says 0.05
    resumed = _trainer(tmp_path / "resumed", 20, learning_rate=rate)
    assert resumed.fit().start_step == 10
    for got, want in zip(resumed.model.get_weights(), reference.model.get_weights()):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    keras = import_keras()
    from paz6d.training.trainer import Trainer

    model, _, loss_fn, data = _problem()
    schedule = keras.optimizers.schedules.ExponentialDecay(0.05, 10, 0.5)
    with pytest.raises(ValueError, match="learning_rate: the optimizer must have a constant rate"):
        Trainer(model, keras.optimizers.Adam(schedule), loss_fn, data, tmp_path / "bad", 5, learning_rate=rate)


def test_iterable_data_and_custom_train_step(tmp_path):
    from paz6d.training.trainer import Trainer

    model, optimizer, _, data = _problem()
    seen = []

    def train_step(batch):
        seen.append(batch[0].shape)
        return {"loss": float(np.mean(batch[1] ** 2))}

    trainer = Trainer(model, optimizer, None, (data(i) for i in range(6)), tmp_path, 10,
                      train_step=train_step, progress=False, tensorboard=False)
    summary = trainer.fit()
    assert summary.final_step == 6 and len(seen) == 6  # the iterable ran out first


def test_bad_arguments_and_corrupt_pointer(tmp_path):
    with pytest.raises(ValueError, match="steps"):
        _trainer(tmp_path, 0)
    with pytest.raises(ValueError, match="checkpoint_every"):
        _trainer(tmp_path, 5, checkpoint_every=0)
    (tmp_path / "checkpoint.json").write_text("{not json")
    with pytest.raises(ValueError, match="checkpoint.json"):
        _trainer(tmp_path, 5).fit()


def _tree(folder):
    """Every path under ``folder`` with its bytes (folders as None), for before/after comparisons."""
    return {str(path.relative_to(folder)): (path.read_bytes() if path.is_file() else None)
            for path in sorted(folder.rglob("*"))}


def test_pruning_never_deletes_stale_checkpoints_of_an_earlier_run(tmp_path):
    run = tmp_path / "run"
    _trainer(run, 10).fit()
    (run / "checkpoint.json").unlink()  # "delete checkpoint.json to start over", stale folders left behind
    for old, new in (("step_00000005", "step_00000090"), ("step_00000010", "step_00000091")):
        (run / "checkpoints" / old).rename(run / "checkpoints" / new)
    stale = _tree(run / "checkpoints")
    summary = _trainer(run, 20).fit()  # a fresh run: checkpoints 5, 10, 15, 20, keeps its last two
    assert (summary.start_step, summary.final_step) == (0, 20)
    pointer = json.loads((run / "checkpoint.json").read_text())
    assert pointer == {"step": 20, "path": "checkpoints/step_00000020", "kept": [15, 20]}
    names = sorted(path.name for path in (run / "checkpoints").iterdir())
    assert names == ["step_00000015", "step_00000020", "step_00000090", "step_00000091"]
    assert {key: value for key, value in _tree(run / "checkpoints").items() if "0009" in key} == stale
    assert _trainer(run, 25).fit().start_step == 20  # the next resume finds its checkpoint


def test_checkpoints_kept_across_a_resume_are_pruned_by_step(tmp_path):
    _trainer(tmp_path, 10).fit()
    assert json.loads((tmp_path / "checkpoint.json").read_text())["kept"] == [5, 10]
    _trainer(tmp_path, 20).fit()  # the resumed run owns 5 and 10 too, and prunes them
    assert sorted(path.name for path in (tmp_path / "checkpoints").iterdir()) == ["step_00000015", "step_00000020"]


@pytest.mark.parametrize("folder", ["checkpoints", "tensorboard", "samples"])
def test_symlinked_run_folders_are_refused_before_anything_is_written(tmp_path, folder):
    outside = tmp_path / "outside"
    for name in ("step_00000001", "step_00000002", "step_00000003"):
        (outside / name).mkdir(parents=True)
        (outside / name / "model.weights.h5").write_bytes(b"the user's own")
    before = _tree(outside)
    run = tmp_path / "run"
    run.mkdir()
    (run / folder).symlink_to(outside, target_is_directory=True)
    with pytest.raises(ValueError, match=f"{folder}: a symbolic link"):
        _trainer(run, 10).fit()
    assert _tree(outside) == before
    assert sorted(path.name for path in run.iterdir()) == [folder]


@pytest.mark.parametrize("pointer, expected", [
    ({"step": 5, "path": "../outside"}, "expected a relative path inside"),
    ({"step": 5, "path": "/tmp"}, "expected a relative path inside"),
    ({"step": 5, "path": 7}, "expected a relative path inside"),
    ({"step": -1, "path": "checkpoints/step_00000005"}, '"step" must be a non-negative integer'),
    ({"step": True, "path": "checkpoints/step_00000005"}, '"step" must be a non-negative integer'),
    ({"step": 5, "path": "checkpoints/step_00000005", "kept": [9]}, '"kept" must be a list'),
    ([5], "corrupt checkpoint pointer"),
])
def test_checkpoint_pointer_outside_the_run_or_malformed_is_refused(tmp_path, pointer, expected):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "model.weights.h5").write_bytes(b"not ours")
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.json").write_text(json.dumps(pointer))
    with pytest.raises(ValueError, match="checkpoint.json") as error:
        _trainer(run, 10).fit()
    assert expected in str(error.value)


def _spoil_checkpoint(run, relative, content):
    path = run / relative
    if content is None:
        path.unlink()
    else:
        path.write_bytes(content)


CHECKPOINT_10 = "checkpoints/step_00000010"


@pytest.mark.parametrize("relative, content, expected", [
    ("log.csv", b"step,loss\nabc,1\n", "log.csv: line 2"),
    ("log.csv", b"a,b\n1,2\n", "log.csv: line 1: expected a header with a 'step' column"),
    ("log.csv", b"step,loss\n1\x00,1\n", "log.csv: line 2"),
    ("log.csv", b"step,loss\n5,1\n3,1\n", "log.csv: line 3"),
    ("log.csv", b"step,loss\n\xff\n", "log.csv: not UTF-8"),
    (f"{CHECKPOINT_10}/model.weights.h5", b"garbage", "model.weights.h5: not an HDF5 weights file"),
    (f"{CHECKPOINT_10}/model.weights.h5", None, "has no model.weights.h5"),
    (f"{CHECKPOINT_10}/optimizer.npz", b"garbage", "optimizer.npz: not a readable .npz file"),
    (f"{CHECKPOINT_10}/optimizer.npz", None, "has no optimizer.npz"),
])
def test_corrupt_checkpoint_and_log_files_are_refused_naming_the_file(tmp_path, relative, content, expected):
    from paz6d.training.checkpoints import check_training_files

    run = tmp_path / "run"
    _trainer(run, 10).fit()
    _spoil_checkpoint(run, relative, content)
    before = _tree(run)
    with pytest.raises(ValueError, match=expected):
        check_training_files(run)  # when the run directory is opened (paz6d.run_dirs.prepare_run_output)
    with pytest.raises(ValueError, match=expected):
        _trainer(run, 20).fit()
    assert _tree(run) == before


def test_a_truncated_weights_file_is_refused_when_restored(tmp_path):
    run = tmp_path / "run"
    _trainer(run, 10).fit()
    weights = run / CHECKPOINT_10 / "model.weights.h5"
    weights.write_bytes(weights.read_bytes()[:600])  # the HDF5 signature survives, the data does not
    with pytest.raises(ValueError, match="model.weights.h5: not the weights of this network"):
        _trainer(run, 20).fit()


@pytest.mark.parametrize("steps", [20, 5])
def test_a_checkpoint_beyond_the_runs_steps_is_refused(tmp_path, steps):
    run = tmp_path / "run"
    _trainer(run, 10).fit()
    if steps == 20:  # a pointer claiming a million steps
        (run / "checkpoint.json").write_text(json.dumps({"step": 10 ** 6, "path": CHECKPOINT_10}))
    before = _tree(run)
    beyond = 10 ** 6 if steps == 20 else 10
    with pytest.raises(ValueError, match=f"checkpoint.json: step {beyond} is beyond this run's {steps} steps"):
        _trainer(run, steps).fit()
    assert _tree(run) == before  # no "finished" run of a million steps recorded


def test_checkpoint_files_of_another_network_are_refused_naming_the_file(tmp_path):
    from paz6d.training.trainer import Trainer

    keras = import_keras()
    _, _, loss_fn, data = _problem()
    deeper = keras.Sequential([keras.Input((4,)), keras.layers.Dense(8), keras.layers.Dense(2)])
    Trainer(deeper, keras.optimizers.Adam(0.01), loss_fn, data, tmp_path / "other", 10, checkpoint_every=5,
            progress=False, tensorboard=False).fit()
    run = tmp_path / "run"
    _trainer(run, 10).fit()
    ours = run / CHECKPOINT_10
    original = (ours / "optimizer.npz").read_bytes()
    (ours / "optimizer.npz").write_bytes((tmp_path / "other" / CHECKPOINT_10 / "optimizer.npz").read_bytes())
    with pytest.raises(ValueError, match=r"optimizer.npz: the state of another network or optimizer "
                                         r"\(10 variables, this optimizer has 6\)"):
        _trainer(run, 20).fit()
    with np.load(tmp_path / "other" / CHECKPOINT_10 / "optimizer.npz") as stored:
        arrays = [stored[str(index)] for index in range(6)]
    arrays[2] = np.zeros((3, 3), np.float32)  # as many variables, one of another shape
    np.savez(ours / "optimizer.npz", **{str(index): array for index, array in enumerate(arrays)})
    with pytest.raises(ValueError, match=r"optimizer.npz: .*variable 2 has shape \(3, 3\), here \(4, 2\)"):
        _trainer(run, 20).fit()
    (ours / "optimizer.npz").write_bytes(original)
    (ours / "model.weights.h5").write_bytes((tmp_path / "other" / CHECKPOINT_10 / "model.weights.h5").read_bytes())
    with pytest.raises(ValueError, match="model.weights.h5: not the weights of this network"):
        _trainer(run, 20).fit()


KILLED_TRAINING = """
import sys, time
sys.path.insert(0, sys.argv[2])
from test_trainer import _problem, _trainer
_, _, _, data = _problem()
def slow(step):
    time.sleep(0.05)
    return data(step)
_trainer(sys.argv[1], 40, data=slow, tensorboard=False).fit()
"""


def test_resume_after_sigkill_matches_an_uninterrupted_run(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    run = tmp_path / "killed"
    repository = Path(__file__).resolve().parents[1]
    process = subprocess.Popen([sys.executable, "-c", KILLED_TRAINING, str(run), str(Path(__file__).parent)],
                               env={**os.environ, "PYTHONPATH": str(repository)}, cwd=repository)
    pointer = run / "checkpoint.json"
    deadline = time.monotonic() + 300  # importing TensorFlow takes a minute on a loaded machine
    while time.monotonic() < deadline and process.poll() is None and \
            (not pointer.exists() or json.loads(pointer.read_text())["step"] < 10):
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    process.wait()
    killed_at = json.loads(pointer.read_text())["step"]
    assert 10 <= killed_at < 40, "the run should have been killed part-way"
    resumed = _trainer(run, 40, tensorboard=False)
    assert resumed.fit().start_step == killed_at
    assert _log_steps(run) == list(range(1, 41))
    reference = _trainer(tmp_path / "reference", 40, tensorboard=False)
    reference.fit()
    for got, want in zip(resumed.model.get_weights(), reference.model.get_weights()):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    assert int(resumed.optimizer.iterations.numpy()) == 40
