"""Data-parallel training with TensorFlow distribution strategies, chosen by name.

=================  ==========================================================================
``distribution``   strategy
=================  ==========================================================================
``"none"``         no strategy (``None``): one device, what :class:`Trainer` does by default
``"mirrored"``     ``tf.distribute.MirroredStrategy``: one replica per GPU of this machine (or
                   the ``devices`` given, e.g. two logical CPUs), gradients all-reduced each step
``"multi-worker"`` ``tf.distribute.MultiWorkerMirroredStrategy``: the same across machines; each
                   machine runs the same program with its ``TF_CONFIG`` (cluster and task index)
=================  ==========================================================================

Build the model and the optimizer inside ``strategy.scope()`` and pass the strategy to
:class:`~paz6d.training.trainer.Trainer`; each global batch that ``data(step)`` returns is split
evenly between the replicas, so the same global batch gives the same loss curve on any number of
replicas (to float round-off)::

    strategy = make_strategy("mirrored")
    with strategy.scope():
        model, optimizer = build_model(), keras.optimizers.Adam(1e-3)
    Trainer(model, optimizer, loss_fn, data, run_dir, steps, strategy=strategy).fit()

With ``"multi-worker"`` every worker computes the same global batch (``data(step)`` is
deterministic) and keeps its slice; the chief (task 0) writes checkpoints, logs and samples, and the
other workers read the checkpoints at resume, so ``run_dir`` must be on storage they all see.
"""

from __future__ import annotations

from typing import Any, Sequence

from paz6d.backend.tensorflow_guard import import_tensorflow

DISTRIBUTIONS = ("none", "mirrored", "multi-worker")


def make_strategy(distribution: str, devices: Sequence[str] | None = None) -> Any:
    """The ``tf.distribute.Strategy`` for ``distribution`` (one of :data:`DISTRIBUTIONS`); ``None`` for
    ``"none"``.

    Args:
        distribution: ``"none"``, ``"mirrored"`` or ``"multi-worker"``.
        devices: for ``"mirrored"`` only: the replicas' devices (default: every GPU, else the CPU).
    """
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution: expected one of {DISTRIBUTIONS}, got {distribution!r}")
    if devices is not None and distribution != "mirrored":
        raise ValueError(f"devices: only for the 'mirrored' distribution, got {distribution!r}")
    if distribution == "none":
        return None
    tf = import_tensorflow()
    if distribution == "mirrored":
        return tf.distribute.MirroredStrategy(devices=None if devices is None else list(devices))
    return tf.distribute.MultiWorkerMirroredStrategy()


def is_chief(strategy: Any) -> bool:
    """Whether this process writes the run's files: always, except on the non-chief workers of a
    multi-worker strategy (the chief is task ``chief``, or ``worker`` 0 in a cluster without one)."""
    resolver = getattr(strategy, "cluster_resolver", None)
    if resolver is None or not resolver.task_type:
        return True
    if resolver.task_type == "chief":
        return True
    has_chief = "chief" in resolver.cluster_spec().as_dict()
    return resolver.task_type == "worker" and resolver.task_id == 0 and not has_chief


def split_batch(batch: Any, replica: int, replicas: int) -> Any:
    """Replica ``replica``'s share of ``batch`` (arrays in nested tuples/lists/dicts, split along
    their first axis into ``replicas`` equal parts)."""
    if isinstance(batch, dict):
        return {key: split_batch(value, replica, replicas) for key, value in batch.items()}
    if isinstance(batch, (tuple, list)):
        return type(batch)(split_batch(value, replica, replicas) for value in batch)
    size = batch.shape[0]
    if size % replicas:
        raise ValueError(f"batch: a global batch of {size} does not split evenly into {replicas} replicas; "
                         f"use a batch size divisible by {replicas}")
    share = size // replicas
    return batch[replica * share:(replica + 1) * share]
