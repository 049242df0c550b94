"""``paz6d generate``: meshes in, BOP-format synthetic data set out.

Every flag is a field of :class:`data_gen.config.GenerationConfig` (what the images are) or of
:class:`data_gen.config.GenerationRun` (how they are rendered). Cheap to import: rendering
libraries load only inside :func:`run`.
"""

from __future__ import annotations

import argparse
import sys

from data_gen.config import GenerationConfig, GenerationRun, capped_workers
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``generate`` flags."""
    add_config_arguments(parser, GenerationConfig)
    add_config_arguments(parser.add_argument_group("execution"), GenerationRun)


def run(args: argparse.Namespace) -> int:
    """Generates the data set and prints a summary; bad input raises ``ValueError`` naming the flag."""
    from data_gen.generator import generate

    config = config_from_args(GenerationConfig, args)
    execution = config_from_args(GenerationRun, args)
    workers, message = capped_workers(execution.workers, execution.backend)
    if message:
        print(f"paz6d generate: {message}", file=sys.stderr)
    with flags_in_errors(GenerationConfig, GenerationRun):
        summary = generate(config, workers=workers, backend=execution.backend,
                           ray_address=execution.ray_address, show_progress=execution.progress)
    print(f"paz6d generate: {summary.images_total} images in {config.out} "
          f"({summary.images_rendered} rendered, {summary.images_skipped} already done), "
          f"{summary.files_written} files written in {summary.seconds:.1f} s, "
          f"{summary.images_per_second:.2f} images/s")
    return 0
