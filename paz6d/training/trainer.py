"""Shared training loop behind every ``paz6d train <model>``: checkpoints, resume, logs, progress, samples.

A :class:`Trainer` runs ``steps`` optimisation steps of a Keras 3 model (TensorFlow backend) and keeps
everything it needs to continue in ``run_dir``::

    run_dir/
      checkpoints/step_00001000/   model.weights.h5, optimizer.npz, state.json (one folder per checkpoint)
      checkpoint.json              {"step": 1000, "path": "checkpoints/step_00001000", "kept": [800, 1000]}
                                   (latest, atomic; "kept": the steps of the checkpoints this run wrote
                                   and keeps, the only ones it ever deletes)
      log.csv                      step, wall time, data/step seconds, every metric
      tensorboard/                 the same scalars as TensorBoard events (``tensorboard=True``)
      samples/step_00001000.png    whatever ``sample_callback`` draws

Re-running :meth:`Trainer.fit` with the same ``run_dir`` restores the weights and optimizer state of the
latest checkpoint and continues from its step; log rows written after that checkpoint (by a run that was
killed) are dropped so every step appears once. Ctrl-C saves a checkpoint before stopping. The files and
their validators are :mod:`paz6d.training.checkpoints`; restoring also refuses a checkpoint beyond
``steps``, and weights or optimizer state that are not this network's (naming the file).

For a deterministic data stream across resumes pass ``data`` as a function of the step index
(``data(step) -> batch``); an iterable is also accepted (it is simply continued).

Data-parallel training: pass ``strategy`` (:func:`paz6d.training.distribution.make_strategy`:
several GPUs of one machine, or several machines) with the model and optimizer built in its scope;
each global batch is split evenly between the replicas and the gradients are summed, so the loss
curve is that of one device at the same global batch.

Example:
    >>> trainer = Trainer(model, optimizer, loss_fn, data=lambda step: batches[step % len(batches)],
    ...                   run_dir="runs/x", steps=1000, checkpoint_every=200)   # doctest: +SKIP
    >>> summary = trainer.fit()                                                  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from paz6d.backend.files import write_csv_atomically, write_json_atomically
from paz6d.backend.tensorflow_guard import import_tensorflow
from paz6d.training.checkpoints import (CHECKPOINT_POINTER, LOG_FILE, OPTIMIZER_FILE, STATE_FILE, WEIGHTS_FILE,
                                        check_weights_file, read_log, read_optimizer_state, read_pointer)
from paz6d.training.distribution import is_chief, split_batch

#: Folders of ``run_dir`` the trainer writes into; none may be a symbolic link.
RUN_FOLDERS = ("checkpoints", "tensorboard", "samples")
_FIXED_COLUMNS = ["step", "wall_seconds", "data_seconds", "step_seconds"]


def _batch_size(batch: Any) -> int:
    """Leading dimension of the first array found in ``batch`` (tuple/list/dict/array)."""
    if isinstance(batch, Mapping):
        batch = next(iter(batch.values()))
    while isinstance(batch, (tuple, list)):
        batch = batch[0]
    return int(np.shape(batch)[0]) if np.ndim(batch) else 1


def _write_scalars(writer, step: int, scalars: Mapping[str, float]) -> None:
    """Writes scalars as TensorBoard "scalars"-plugin summaries (TF core only; the tensorboard package
    is needed to view them, not to write them)."""
    tf = import_tensorflow()
    from tensorflow.core.framework import summary_pb2

    metadata = summary_pb2.SummaryMetadata(plugin_data=summary_pb2.SummaryMetadata.PluginData(plugin_name="scalars"))
    with writer.as_default(step=step):
        for key, value in scalars.items():
            tf.summary.write(key, tf.constant(value, dtype=tf.float32), metadata=metadata)
    writer.flush()


@dataclass
class TrainingSummary:
    """What :meth:`Trainer.fit` did.

    Attributes:
        start_step: step the run started from (0, or the resumed checkpoint's step).
        final_step: step reached (``steps`` unless interrupted).
        metrics: mean of each metric over the last ``log_every`` steps.
        loader_samples_per_second: samples per second of time the loop waited for data (with prefetching
            this is the wait, not the loader's own speed: large means the data path keeps up).
        model_samples_per_second: samples per second of time spent in the optimisation step.
        Both are ``None`` when no step ran (a finished run re-run): nothing was measured.
    """

    start_step: int
    final_step: int
    metrics: dict[str, float]
    loader_samples_per_second: float | None
    model_samples_per_second: float | None


class Trainer:
    """Checkpointed, resumable training loop for a Keras 3 model.

    Args:
        model: a built ``keras.Model``.
        optimizer: a ``keras.optimizers.Optimizer``. With ``use_ema=True`` (an exponential moving
            average of the weights) the model ends a completed :meth:`fit` with the averaged weights;
            checkpoints keep the raw weights and the averages, so a resumed run continues the raw ones.
        loss_fn: ``loss_fn(model, batch) -> loss`` (scalar tensor) or a dict of scalar tensors with key
            ``"loss"`` (the others are logged as metrics). Ignored when ``train_step`` is given.
        data: ``data(step) -> batch`` (deterministic on resume) or an iterable of batches.
        run_dir: folder for checkpoints, logs and samples (created).
        steps: total number of optimisation steps (a resumed run stops at the same total).
        checkpoint_every: steps between checkpoints (a final one is always written).
        log_every: steps between log rows / TensorBoard scalars (means over the interval).
        sample_every: steps between ``sample_callback`` calls; 0 disables.
        sample_callback: ``sample_callback(model, step, png_path)`` draws a PNG (e.g. reconstructions).
        train_step: optional ``train_step(batch) -> dict of scalars`` replacing the built-in gradient
            step (it must update ``model``/``optimizer`` itself).
        keep_checkpoints: how many checkpoint folders to keep (oldest deleted first). Only folders that
            this run wrote (listed in ``checkpoint.json``'s ``"kept"``) are ever deleted, by step
            number: stale ``step_*`` folders of an earlier run stay.
        tensorboard: also write TensorBoard scalars to ``run_dir/tensorboard``.
        progress: show a tqdm bar.
        compile_step: wrap the built-in step in ``tf.function``.
        prefetch: with a callable ``data``, batches computed ahead in background threads (0 = none).
        prefetch_workers: threads computing batches (numpy/OpenCV release the GIL).
        learning_rate: optional ``learning_rate(step) -> rate`` of the step about to run (0-based), set on the
            optimizer's learning-rate variable before each step (the optimizer must be built with a
            constant rate, not a schedule): checkpoints keep the same variables as a constant rate's, and a
            resumed run follows the function from its step on.
        strategy: a ``tf.distribute`` strategy (:func:`~paz6d.training.distribution.make_strategy`)
            whose scope created ``model`` and ``optimizer``; None trains on one device. The global
            batch size must be divisible by its number of replicas; ``loss_fn`` sees one replica's
            share and should return means over it. Only the chief of a multi-worker cluster writes
            files. Not with ``train_step``.
    """

    def __init__(self, model, optimizer, loss_fn: Callable | None, data: Callable[[int], Any] | Iterable,
                 run_dir: str | Path, steps: int, checkpoint_every: int = 500, log_every: int = 10,
                 sample_every: int = 0, sample_callback: Callable | None = None,
                 train_step: Callable[[Any], Mapping[str, Any]] | None = None, keep_checkpoints: int = 2,
                 tensorboard: bool = True, progress: bool = True, compile_step: bool = True, prefetch: int = 0,
                 prefetch_workers: int = 1, strategy: Any = None,
                 learning_rate: Callable[[int], float] | None = None):
        if int(steps) <= 0:
            raise ValueError(f"steps: expected a positive number of training steps, got {steps}")
        for name, value in (("checkpoint_every", checkpoint_every), ("log_every", log_every),
                            ("keep_checkpoints", keep_checkpoints)):
            if int(value) <= 0:
                raise ValueError(f"{name}: expected a positive integer, got {value}")
        if int(prefetch) < 0 or int(prefetch_workers) < 1:
            raise ValueError(f"prefetch/prefetch_workers: expected >= 0 and >= 1, got {prefetch}, {prefetch_workers}")
        if int(sample_every) < 0:
            raise ValueError(f"sample_every: expected >= 0, got {sample_every}")
        if loss_fn is None and train_step is None:
            raise ValueError("loss_fn/train_step: give a loss function or a custom train_step")
        if not callable(data) and not isinstance(data, Iterable):
            raise ValueError(f"data: expected a callable data(step) or an iterable of batches, "
                             f"got {type(data).__name__}")
        if strategy is not None:
            if train_step is not None:
                raise ValueError("strategy: not with a custom train_step (it would have to distribute itself)")
            outside = [variable.path for variable in model.trainable_variables
                       if not strategy.extended.variable_created_in_scope(variable.value)]
            if outside:
                raise ValueError(f"model: {len(outside)} variables (e.g. {outside[0]}) were not created in "
                                 f"strategy.scope(); build the model and optimizer inside it")
        if learning_rate is not None and not hasattr(optimizer.learning_rate, "assign"):
            raise ValueError("learning_rate: the optimizer must have a constant rate (a variable), not a schedule")
        self.model = model
        self.optimizer = optimizer
        self.learning_rate = learning_rate
        self.loss_fn = loss_fn
        self.data = data
        self.run_dir = Path(run_dir)
        self.steps = int(steps)
        self.checkpoint_every = int(checkpoint_every)
        self.log_every = int(log_every)
        self.sample_every = int(sample_every)
        self.sample_callback = sample_callback
        self.keep_checkpoints = int(keep_checkpoints)
        self.tensorboard = tensorboard
        self.progress = progress
        self._custom_step = train_step
        self._compile_step = compile_step
        self._step_function = None
        self.prefetch = int(prefetch)
        self.prefetch_workers = int(prefetch_workers)
        self.strategy = strategy
        self.writes_files = is_chief(strategy)
        self._kept_steps: list[int] | None = None  # steps of this run's checkpoints on disk, oldest first

    # ----------------------------------------------------------------------------------- checkpoints
    @property
    def checkpoint_dir(self) -> Path:
        return self.run_dir / "checkpoints"

    def check_run_folders(self) -> None:
        """Refuses a ``run_dir`` whose ``checkpoints/``, ``tensorboard/`` or ``samples/`` is a symbolic
        link or not a folder: the trainer writes and deletes there, and must not do so elsewhere.

        Raises:
            ValueError: naming the folder.
        """
        for name in RUN_FOLDERS:
            path = self.run_dir / name
            if path.is_symlink():
                raise ValueError(f"{path}: a symbolic link; the trainer writes (and prunes) only inside its run "
                                 "directory; replace the link by a folder or give a new --out")
            if path.exists() and not path.is_dir():
                raise ValueError(f"{path}: expected a folder of the run, found a file")

    def latest_checkpoint(self) -> tuple[int, Path] | None:
        """``(step, folder)`` of the newest complete checkpoint in ``run_dir``, or None
        (:func:`~paz6d.training.checkpoints.read_pointer`)."""
        checkpoint = read_pointer(self.run_dir)
        return None if checkpoint is None else (checkpoint.step, checkpoint.folder)

    def _ensure_optimizer_built(self) -> None:
        """Creates the optimizer's variables (in the strategy's scope: mirrored like the model's)."""
        if not self.optimizer.built:
            with self.strategy.scope() if self.strategy is not None else contextlib.nullcontext():
                self.optimizer.build(self.model.trainable_variables)

    def save_checkpoint(self, step: int, metrics: Mapping[str, float] | None = None) -> Path:
        """Writes model weights + optimizer state for ``step`` (temp folder, then rename) and prunes old ones
        (only the chief of a multi-worker cluster writes; the others return the chief's folder)."""
        self._ensure_optimizer_built()
        if not self.writes_files:
            return self.checkpoint_dir / f"step_{step:08d}"
        self.check_run_folders()
        if self._kept_steps is None:
            checkpoint = read_pointer(self.run_dir)
            self._kept_steps = [] if checkpoint is None else checkpoint.kept
        self.checkpoint_dir.mkdir(parents=True, exist_ok=True)
        name = f"step_{step:08d}"
        final = self.checkpoint_dir / name
        if final.is_symlink() or (final.exists() and not final.is_dir()):
            raise ValueError(f"{final}: not a checkpoint folder (a symbolic link or a file); refusing to replace it")
        temporary = self.checkpoint_dir / (name + ".tmp")
        shutil.rmtree(temporary, ignore_errors=True)
        temporary.mkdir()
        self.model.save_weights(temporary / WEIGHTS_FILE)
        store: dict[str, np.ndarray] = {}
        self.optimizer.save_own_variables(store)
        np.savez(temporary / OPTIMIZER_FILE, **{key: np.asarray(value) for key, value in store.items()})
        (temporary / STATE_FILE).write_text(json.dumps({"step": step, "metrics": dict(metrics or {})}))
        shutil.rmtree(final, ignore_errors=True)
        os.replace(temporary, final)
        kept = [item for item in self._kept_steps if item != step] + [step]
        write_json_atomically(self.run_dir / CHECKPOINT_POINTER,
                              {"step": step, "path": f"checkpoints/{name}", "kept": kept[-self.keep_checkpoints:]},
                              indent=2)
        self._kept_steps = kept[-self.keep_checkpoints:]
        for old in kept[:-self.keep_checkpoints]:  # this run's own, no longer referenced
            folder = self.checkpoint_dir / f"step_{old:08d}"
            if folder.is_dir() and not folder.is_symlink():
                shutil.rmtree(folder, ignore_errors=True)
        return final

    def restore(self) -> int:
        """Loads the latest checkpoint into model/optimizer; returns its step (0 when there is none).

        Raises:
            ValueError: a corrupt checkpoint, one beyond ``steps``, or weights or optimizer state of
                another network (naming the file).
        """
        checkpoint = read_pointer(self.run_dir)
        self._kept_steps = [] if checkpoint is None else checkpoint.kept
        if checkpoint is None:
            return 0
        if checkpoint.step > self.steps:
            raise ValueError(f"{self.run_dir / CHECKPOINT_POINTER}: step {checkpoint.step} is beyond this run's "
                             f"{self.steps} steps; resume it with at least {checkpoint.step} steps, or start a new run")
        state = read_optimizer_state(checkpoint.optimizer)
        try:
            self.model.load_weights(check_weights_file(checkpoint.weights))
        except Exception as error:  # h5py and Keras raise many types for damaged or foreign files
            raise ValueError(f"{checkpoint.weights}: not the weights of this network ({type(error).__name__}: "
                             f"{str(error)[:300]})") from error
        self._ensure_optimizer_built()
        stored = [tuple(array.shape) for array in state]
        wanted = [tuple(variable.shape) for variable in self.optimizer.variables]
        differing = next((index for index, (got, want) in enumerate(zip(stored, wanted)) if got != want), None)
        if len(stored) != len(wanted) or differing is not None:
            detail = (f"{len(stored)} variables, this optimizer has {len(wanted)}" if len(stored) != len(wanted) else
                      f"variable {differing} has shape {stored[differing]}, here {wanted[differing]}")
            raise ValueError(f"{checkpoint.optimizer}: the state of another network or optimizer ({detail}); "
                             f"delete {CHECKPOINT_POINTER} to start over")
        self.optimizer.load_own_variables({str(index): array for index, array in enumerate(state)})
        return checkpoint.step

    # -------------------------------------------------------------------------------------- logging
    def _prepare_log(self, start_step: int) -> list[dict[str, str]]:
        """Keeps the log rows up to ``start_step`` (a killed run may have logged past its checkpoint)."""
        return [row for row in read_log(self.run_dir / LOG_FILE) if int(row["step"]) <= start_step]

    def _write_log(self, rows: list[dict[str, Any]]) -> None:
        if not self.writes_files:
            return
        columns = list(_FIXED_COLUMNS)
        for row in rows:
            columns.extend(key for key in row if key not in columns)
        write_csv_atomically(self.run_dir / LOG_FILE, columns, ([row.get(key, "") for key in columns] for row in rows))

    # ------------------------------------------------------------------------------------- stepping
    def _build_step(self):
        if self._custom_step is not None:
            return self._custom_step
        tf = import_tensorflow()
        model, optimizer, loss_fn, strategy = self.model, self.optimizer, self.loss_fn, self.strategy
        replicas = 1 if strategy is None else strategy.num_replicas_in_sync

        def step(batch):
            with tf.GradientTape() as tape:
                output = loss_fn(model, batch)
                metrics = dict(output) if isinstance(output, Mapping) else {"loss": output}
                if "loss" not in metrics:
                    raise ValueError(f"loss_fn: returned a dict without a 'loss' key (keys {sorted(metrics)})")
                loss = metrics["loss"] / replicas  # the optimizer sums the replicas' gradients
            variables = model.trainable_variables
            gradients = tape.gradient(loss, variables)
            optimizer.apply_gradients(zip(gradients, variables))
            return metrics

        def distributed_step(batch):
            metrics = strategy.run(step, args=(batch,))
            return {key: strategy.reduce(tf.distribute.ReduceOp.MEAN, value, axis=None)
                    for key, value in metrics.items()}

        function = step if strategy is None else distributed_step
        return tf.function(function) if self._compile_step else function

    def _distribute(self, batch):
        """``batch`` as the strategy's per-replica shares (unchanged without a strategy)."""
        if self.strategy is None:
            return batch
        tf = import_tensorflow()

        def share(context):
            part = split_batch(batch, context.replica_id_in_sync_group, context.num_replicas_in_sync)
            return tf.nest.map_structure(tf.convert_to_tensor, part)

        return self.strategy.experimental_distribute_values_from_function(share)

    def _next_batch(self, step: int, iterator, pending: dict | None, executor):
        if iterator is not None:
            return next(iterator)
        if pending is None:
            return self.data(step)
        ahead = step + self.prefetch
        if ahead < self.steps and ahead not in pending:
            pending[ahead] = executor.submit(self.data, ahead)
        future = pending.pop(step, None)
        return future.result() if future is not None else self.data(step)

    def fit(self) -> TrainingSummary:
        """Trains from the latest checkpoint (or from scratch) up to ``steps``; returns a summary."""
        from tqdm.auto import tqdm

        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.check_run_folders()
        start_step = self.restore()
        self._ensure_optimizer_built()  # not inside the first (distributed) step
        rows = self._prepare_log(start_step)
        self._write_log(rows)
        if self._step_function is None:
            self._step_function = self._build_step()
        writer = None
        if self.tensorboard and self.writes_files:
            tf = import_tensorflow()
            writer = tf.summary.create_file_writer(str(self.run_dir / "tensorboard"))
        iterator = None if callable(self.data) else iter(self.data)
        executor, pending = None, None
        if iterator is None and self.prefetch:
            executor = ThreadPoolExecutor(max_workers=self.prefetch_workers, thread_name_prefix="prefetch")
            pending = {ahead: executor.submit(self.data, ahead)
                       for ahead in range(start_step, min(start_step + self.prefetch, self.steps))}
        sums: dict[str, float] = {}
        count = 0
        data_seconds = step_seconds = 0.0
        interval_data = interval_step = 0.0
        samples = 0
        last_metrics: dict[str, float] = {}
        started = time.perf_counter()
        step = start_step
        rate_set = None  # the rate last given to the optimizer by ``learning_rate`` in this fit
        bar = tqdm(total=self.steps, initial=start_step, desc=f"train {self.run_dir.name}",
                   disable=not self.progress, dynamic_ncols=True)
        try:
            while step < self.steps:
                tick = time.perf_counter()
                try:
                    batch = self._next_batch(step, iterator, pending, executor)
                except StopIteration:
                    break
                tock = time.perf_counter()
                if self.learning_rate is not None:
                    rate = float(self.learning_rate(step))
                    if rate != rate_set:  # first step of this fit (the checkpoint's rate) or a change
                        self.optimizer.learning_rate.assign(rate)
                        rate_set = rate
                metrics = self._step_function(self._distribute(batch))
                values = {key: float(np.asarray(value)) for key, value in metrics.items()}
                done = time.perf_counter()
                if not all(np.isfinite(v) for v in values.values()):
                    raise FloatingPointError(f"training diverged at step {step + 1}: {values}")
                step += 1
                samples += _batch_size(batch)
                interval_data += tock - tick
                interval_step += done - tock
                data_seconds += tock - tick
                step_seconds += done - tock
                for key, value in values.items():
                    sums[key] = sums.get(key, 0.0) + value
                count += 1
                bar.update(1)
                if step % self.log_every == 0 or step == self.steps:
                    last_metrics = {key: value / count for key, value in sums.items()}
                    row = {"step": step, "wall_seconds": round(time.perf_counter() - started, 3),
                           "data_seconds": round(interval_data, 4), "step_seconds": round(interval_step, 4),
                           **last_metrics}
                    rows.append(row)
                    self._write_log(rows)
                    if writer is not None:
                        _write_scalars(writer, step, {**last_metrics, "data_seconds": interval_data,
                                                      "step_seconds": interval_step})
                    bar.set_postfix({key: f"{value:.4g}" for key, value in last_metrics.items()})
                    sums, count, interval_data, interval_step = {}, 0, 0.0, 0.0
                if self.sample_every and self.sample_callback is not None and step % self.sample_every == 0:
                    self._draw_sample(step)
                if step % self.checkpoint_every == 0 and step < self.steps:
                    self.save_checkpoint(step, last_metrics)
        except KeyboardInterrupt:
            if step > start_step:
                self.save_checkpoint(step, last_metrics)
            raise
        finally:
            bar.close()
            if executor is not None:
                for future in pending.values():
                    future.cancel()
                executor.shutdown(wait=True)
            if writer is not None:
                writer.close()
        if count:
            last_metrics = {key: value / count for key, value in sums.items()}
        if step > start_step:
            self.save_checkpoint(step, last_metrics)
            if self.sample_callback is not None and self.sample_every and step % self.sample_every != 0:
                self._draw_sample(step)
        if step == self.steps and getattr(self.optimizer, "use_ema", False):
            self.optimizer.finalize_variable_values(self.model.trainable_variables)
        return TrainingSummary(start_step=start_step, final_step=step, metrics=last_metrics,
                               loader_samples_per_second=(samples / data_seconds if samples and data_seconds > 0
                                                          else None),
                               model_samples_per_second=(samples / step_seconds if samples and step_seconds > 0
                                                         else None))

    def _draw_sample(self, step: int) -> None:
        if not self.writes_files:
            return
        folder = self.run_dir / "samples"
        folder.mkdir(parents=True, exist_ok=True)
        self.sample_callback(self.model, step, folder / f"step_{step:08d}.png")
