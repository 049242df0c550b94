"""AdamW with a lower learning rate for some variables (a pretrained body fine-tuned more gently than the
new layers on it).

Adam divides each gradient by its running magnitude, so scaling the gradients of the pretrained
variables would leave their steps unchanged; the rate itself is scaled instead, per variable.
"""

from __future__ import annotations

from paz6d.backend.tensorflow_guard import import_keras

keras = import_keras()


class ScaledRateAdamW(keras.optimizers.AdamW):
    """``keras.optimizers.AdamW`` whose step for the variables in ``slow_variables`` uses ``rate_factor``
    times the learning rate (weight decay is applied at the full rate, as AdamW does for every variable).

    Args:
        slow_variables: the variables stepped at the lower rate.
        rate_factor: their learning rate as a fraction of the optimizer's, in ``(0, 1]``.
        **kwargs: ``keras.optimizers.AdamW``'s arguments.
    """

    def __init__(self, slow_variables=(), rate_factor: float = 0.1, **kwargs):
        super().__init__(**kwargs)
        if not 0.0 < float(rate_factor) <= 1.0:
            raise ValueError(f"rate_factor: expected a fraction of the learning rate in (0, 1], got {rate_factor}")
        self.rate_factor = float(rate_factor)
        self._slow_keys = {self._var_key(variable) for variable in slow_variables}

    def update_step(self, gradient, variable, learning_rate):
        """AdamW's step, at ``rate_factor`` times ``learning_rate`` for the slow variables."""
        if self._var_key(variable) in self._slow_keys:
            learning_rate = learning_rate * self.rate_factor
        super().update_step(gradient, variable, learning_rate)
