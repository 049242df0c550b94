"""SSD's multibox loss as a Keras loss: smooth L1 on matched priors + softmax cross-entropy with hard
negative mining.

Layouts (:mod:`paz6d.ssd.model`): ``y_true (B, P, 4 + C)`` holds the encoded offsets of each prior's
matched box and a one-hot class (column ``4`` is the background: a prior whose background entry is 1
is a negative); ``y_pred (B, P, 4 + C)`` holds predicted offsets and class logits.

For each image with ``n`` positives, the negatives with the largest cross-entropy are kept, at most
``neg_pos_ratio * max(n, 1)`` of them (an image without objects still trains its background). With
``N`` the positives of the whole batch (at least 1)::

    classification = (sum of cross-entropy over positives and kept negatives) / N
    localization   = (sum over positives of smooth L1 summed over the 4 offsets) / N
    loss           = classification + alpha * localization

``smooth_l1(x) = 0.5 x^2`` for ``|x| < 1``, else ``|x| - 0.5``.
"""

from __future__ import annotations

from paz6d.backend.tensorflow_guard import import_keras, import_tensorflow

tf = import_tensorflow()
keras = import_keras()


def multibox_terms(y_true, y_pred, neg_pos_ratio: float = 3.0) -> dict:
    """The loss terms of a batch: ``classification``, ``localization`` (both divided by the batch's
    positives) and ``positives`` (their count), scalar tensors."""
    y_true = tf.cast(y_true, tf.float32)
    y_pred = tf.cast(y_pred, tf.float32)
    positive = 1.0 - y_true[..., 4]
    cross_entropy = tf.nn.softmax_cross_entropy_with_logits(labels=y_true[..., 4:], logits=y_pred[..., 4:])
    difference = tf.abs(y_true[..., :4] - y_pred[..., :4])
    smooth_l1 = tf.reduce_sum(tf.where(difference < 1.0, 0.5 * difference ** 2, difference - 0.5), axis=-1)

    positives_per_image = tf.reduce_sum(positive, axis=1)
    priors = tf.cast(tf.shape(positive)[1], tf.float32)
    negatives_per_image = tf.minimum(neg_pos_ratio * tf.maximum(positives_per_image, 1.0),
                                     priors - positives_per_image)
    negative_loss = tf.where(positive > 0, -1.0, cross_entropy)  # positives rank last
    ranks = tf.argsort(tf.argsort(negative_loss, axis=1, direction="DESCENDING", stable=True), axis=1, stable=True)
    hard_negative = tf.cast(tf.cast(ranks, tf.float32) < negatives_per_image[:, None], tf.float32) * (1.0 - positive)

    count = tf.maximum(tf.reduce_sum(positive), 1.0)
    classification = tf.reduce_sum(cross_entropy * (positive + hard_negative)) / count
    localization = tf.reduce_sum(smooth_l1 * positive) / count
    return {"classification": classification, "localization": localization, "positives": tf.reduce_sum(positive)}


@keras.saving.register_keras_serializable(package="paz6d")
class MultiboxLoss(keras.losses.Loss):
    """``classification + alpha * localization`` (see the module docstring) as a Keras loss.

    The loss is normalised by the positives of the whole batch, as in the paper, so every sample
    carries the batch's value (Keras' mean over the batch returns it unchanged).

    Args:
        neg_pos_ratio: negatives kept per positive (3 in the paper).
        alpha: weight of the localization term (1 in the paper).
    """

    def __init__(self, neg_pos_ratio: float = 3.0, alpha: float = 1.0, name: str = "multibox_loss", **kwargs):
        super().__init__(name=name, **kwargs)
        if not neg_pos_ratio > 0 or not alpha >= 0:
            raise ValueError(f"neg_pos_ratio/alpha: expected > 0 and >= 0, got {neg_pos_ratio}, {alpha}")
        self.neg_pos_ratio, self.alpha = float(neg_pos_ratio), float(alpha)

    def call(self, y_true, y_pred):
        terms = multibox_terms(y_true, y_pred, self.neg_pos_ratio)
        total = terms["classification"] + self.alpha * terms["localization"]
        return tf.fill(tf.shape(y_pred)[:1], total)

    def get_config(self):
        return {**super().get_config(), "neg_pos_ratio": self.neg_pos_ratio, "alpha": self.alpha}
