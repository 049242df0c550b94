"""``paz6d train emotion``: flags from :class:`~paz6d.faces.emotion_config.EmotionTraining` and the command.

Light on purpose: building the parser imports only this module and the settings; the trainer
(:mod:`paz6d.faces.emotion_train`, with OpenCV, the augmentation and TensorFlow) is imported when
the command runs.
"""

from __future__ import annotations

import argparse

from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors
from paz6d.run_dirs import training_output
from paz6d.faces.emotion_config import EmotionTraining


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d train emotion`` flags (the fields of :class:`EmotionTraining`)."""
    add_config_arguments(parser, EmotionTraining)


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d train emotion``; bad input raises ``ValueError`` naming the flag."""
    from paz6d.faces.emotion_train import train_emotion  # here: the trainer loads OpenCV and TensorFlow

    job = config_from_args(EmotionTraining, args)
    with flags_in_errors(EmotionTraining), training_output(job, "emotion"):
        train_emotion(job)
    return 0
