"""Running a network over a batch of inputs, a fixed number of inputs per call."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from paz6d.abstract.processor import Processor


def predict_in_batches(function: Callable, inputs, batch_size: int = 32) -> dict[str, np.ndarray] | np.ndarray:
    """Outputs of ``function`` on ``inputs`` ``(B, ...)`` (cast to float32), ``batch_size`` inputs per call.

    ``function`` returns an array or a dict of arrays whose first axis is the batch; the
    results of all calls are concatenated along it (numpy).
    """
    if int(batch_size) <= 0:
        raise ValueError(f"batch_size: expected a positive number of inputs per call, got {batch_size}")
    parts: dict[str, list] = {}
    arrays: list[np.ndarray] = []
    for start in range(0, len(inputs), batch_size):
        output = function(np.asarray(inputs[start:start + batch_size], dtype=np.float32))
        if isinstance(output, dict):
            for name, value in output.items():
                parts.setdefault(name, []).append(np.asarray(value))
        else:
            arrays.append(np.asarray(output))
    if arrays:
        return np.concatenate(arrays)
    return {name: np.concatenate(values) for name, values in parts.items()}


class Predict(Processor):
    """``inputs (B, ...) or a list of B arrays -> outputs`` of a network function (see :func:`predict_in_batches`).

    Args:
        function: e.g. a compiled inference function of a Keras model.
        batch_size: inputs per call.
    """

    def __init__(self, function: Callable, batch_size: int = 32, name: str | None = None):
        super().__init__(name)
        self.function, self.batch_size = function, int(batch_size)

    def call(self, inputs) -> dict[str, np.ndarray] | np.ndarray:
        return predict_in_batches(self.function, np.stack(inputs) if isinstance(inputs, list) else inputs,
                                  self.batch_size)
