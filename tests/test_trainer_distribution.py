"""Data-parallel training in the shared trainer: two logical CPU devices give one device's loss curve."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import types

import numpy as np
import pytest

from paz6d.training.distribution import DISTRIBUTIONS, is_chief, make_strategy, split_batch

# Runs in a fresh interpreter: logical devices must be configured before TensorFlow initializes.
SCRIPT = textwrap.dedent('''
    import contextlib, csv, json, sys
    from pathlib import Path

    import numpy as np

    from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow

    tf = import_tensorflow()
    cpu = tf.config.list_physical_devices("CPU")[0]
    tf.config.set_logical_device_configuration(cpu, [tf.config.LogicalDeviceConfiguration()] * 2)
    keras = import_keras()
    from paz6d.training.distribution import make_strategy
    from paz6d.training.trainer import Trainer

    rng = np.random.default_rng(1)
    W_true = rng.normal(size=(4, 2)).astype("float32")
    inputs = rng.normal(size=(10, 8, 4)).astype("float32")  # global batch: 8

    def data(step):
        x = inputs[step % len(inputs)]
        return x, x @ W_true

    def loss_fn(model, batch):
        x, y = batch
        return keras.ops.mean((model(x, training=True) - y) ** 2)

    def train(run_dir, strategy, steps):
        with strategy.scope() if strategy is not None else contextlib.nullcontext():
            keras.utils.set_random_seed(0)
            model = keras.Sequential([keras.Input((4,)), keras.layers.Dense(8, activation="tanh"),
                                      keras.layers.Dense(2)])
            optimizer = keras.optimizers.Adam(0.05)
        trainer = Trainer(model, optimizer, loss_fn, data, run_dir, steps, checkpoint_every=100, log_every=1,
                          progress=False, tensorboard=False, strategy=strategy)
        trainer.fit()
        with (Path(run_dir) / "log.csv").open() as handle:
            return [float(row["loss"]) for row in csv.DictReader(handle)]

    root = Path(sys.argv[1])
    mirrored = make_strategy("mirrored", devices=["/cpu:0", "/cpu:1"])
    train(root / "mirrored", mirrored, 6)  # interrupted after 6 steps ...
    curves = {"one": train(root / "one", None, 12),
              "mirrored": train(root / "mirrored", mirrored, 12),  # ... and resumed from its checkpoint
              "multi-worker": train(root / "multi", make_strategy("multi-worker"), 12)}
    print(json.dumps({"replicas": mirrored.num_replicas_in_sync, "curves": curves}))
''')


@pytest.mark.slow  # two logical devices in a subprocess; one-device training runs in every trainer's tests
@pytest.mark.timeout(300)
def test_two_logical_devices_give_the_loss_curve_of_one_device(tmp_path):
    result = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True,
                            timeout=280)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.splitlines()[-1])
    assert report["replicas"] == 2
    one = np.array(report["curves"]["one"])
    assert len(one) == 12 and one[-1] < 0.5 * one[0]  # it trains
    np.testing.assert_allclose(report["curves"]["mirrored"], one, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(report["curves"]["multi-worker"], one, rtol=1e-4, atol=1e-6)


def test_split_batch_gives_each_replica_an_equal_share_of_every_array():
    batch = ({"image": np.arange(12).reshape(6, 2)}, [np.arange(6), np.arange(6) * 10])
    first, second = split_batch(batch, 0, 2), split_batch(batch, 1, 2)
    np.testing.assert_array_equal(first[0]["image"], [[0, 1], [2, 3], [4, 5]])
    np.testing.assert_array_equal(second[1][1], [30, 40, 50])
    assert isinstance(first[1], list)
    with pytest.raises(ValueError, match="batch of 6 does not split evenly into 4 replicas"):
        split_batch(batch, 0, 4)


def test_strategy_names_and_chief():
    assert DISTRIBUTIONS == ("none", "mirrored", "multi-worker")
    assert make_strategy("none") is None and is_chief(None)
    with pytest.raises(ValueError, match="distribution: expected one of"):
        make_strategy("horovod")
    with pytest.raises(ValueError, match="devices: only for the 'mirrored'"):
        make_strategy("multi-worker", devices=["/cpu:0"])

    def strategy(task_type, task_id, jobs):
        spec = types.SimpleNamespace(as_dict=lambda: {job: ["host:1"] for job in jobs})
        resolver = types.SimpleNamespace(task_type=task_type, task_id=task_id, cluster_spec=lambda: spec)
        return types.SimpleNamespace(cluster_resolver=resolver)

    assert is_chief(strategy("worker", 0, ["worker"])) and not is_chief(strategy("worker", 1, ["worker"]))
    assert is_chief(strategy("chief", 0, ["chief", "worker"]))
    assert not is_chief(strategy("worker", 0, ["chief", "worker"]))


def test_a_model_built_outside_the_strategy_scope_is_refused(tmp_path):
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.training.trainer import Trainer

    keras = import_keras()
    model = keras.Sequential([keras.Input((4,)), keras.layers.Dense(2)])
    strategy = make_strategy("mirrored", devices=["/cpu:0"])
    with pytest.raises(ValueError, match=r"not created in strategy.scope\(\)"):
        Trainer(model, keras.optimizers.Adam(), lambda m, b: 0.0, lambda step: None, tmp_path, 5, strategy=strategy)
