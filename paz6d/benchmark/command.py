"""``paz6d benchmark lmo``: the real-data benchmark of :mod:`paz6d.benchmark.lmo` (flags: :class:`LmoOptions`).

Light on purpose: building the parser imports only this module and :mod:`paz6d.benchmark.lmo`, whose
stages load TensorFlow and the renderers when they run.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from paz6d.benchmark.lmo import DEFAULT_LMO, METHODS, Benchmark, run_benchmark
from paz6d.backbones import BACKBONES
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors, option
from paz6d.datasets.bop.fields import BOX_FIELDS
from paz6d.run_dirs import run_output


@dataclass(frozen=True)
class LmoOptions:
    """One ``paz6d benchmark lmo`` run."""

    out: Path = option(help="output folder (detector/, pose/obj_XXXXXX/, results/, overlays/, report.json); "
                            "re-run the same command to resume")
    quick: bool = option(False, "the quick sizes (about 1.5 h on a 2-core CPU, docs/results.md) instead of the full "
                                "ones (~3 h)")
    method: str = option("aae", "pose model per object (keypointnet runs go to OUT/pose_<method>/)",
                         choices=METHODS)
    object_method: tuple[str, ...] = option((), "OBJ_ID=METHOD: this object's pose model instead of --method's "
                                                "(repeatable), e.g. 8=keypointnet_robust", metavar="OBJ_ID=METHOD")
    lmo: Path = option(DEFAULT_LMO, "LM-O BOP folder: its models/ train everything, its test/ RGB frames are scored")
    seed: int = option(0, "seed of the synthetic data and of every training run")
    aae_steps: int | None = option(None, "AAE training steps (default: 1,000 quick, 5,000 full); a larger number "
                                         "on a finished --out resumes its AAEs and scores them again")
    aae_lr_drop_steps: int | None = option(None, "the last this many AAE steps at a tenth of the learning rate "
                                                 "(default: 200 quick, 500 full; the same share of a smaller "
                                                 "--aae-steps); with a larger --aae-steps on a finished --out the "
                                                 "drop moves to the new end")
    aae_crop_box: str | None = option(None, "the box the AAEs' scene crops are cut around: obj (whole object) or "
                                            "visib (visible part, as at test time) (default: the sizes' own, "
                                            "docs/real_photos.md)", choices=tuple(sorted(BOX_FIELDS)))
    detector_backbone: str | None = option(None, "the detector's body: efficientnet-lite0 (pretrained on ImageNet, "
                                                 "docs/backbones.md) or none (the light network from scratch) "
                                                 "(default: the sizes' own)", choices=BACKBONES)
    detector_input_size: int | None = option(None, "the detector's square input side in pixels, a multiple of 64 "
                                                   "(default: the sizes' own: 448 quick, 640 full; docs/backbones.md)")
    neutral_distractors: float | None = option(None, "share of the synthetic images' distractors coloured white "
                                                     "to mid grey, hard negatives for the white objects (default: "
                                                     "the sizes' own: 0.3 quick, 0 full)")
    aae_encoder_backbone: str | None = option(None, "the AAEs' encoder body: none (trained from scratch) or "
                                                    "efficientnet-lite0 (pretrained on ImageNet, frozen; "
                                                    "docs/aae.md) (default: the sizes' own: efficientnet-lite0 "
                                                    "quick, none full)", choices=BACKBONES)
    jobs: int = option(2, "pose models trained side by side, each in its own process with its share of the CPU "
                          "cores (measured in docs/real_photos.md)")
    progress: bool = option(True, "progress bars")


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d benchmark lmo`` flags (the fields of :class:`LmoOptions`)."""
    add_config_arguments(parser, LmoOptions)


def parse_object_methods(values: tuple[str, ...]) -> dict[int, str]:
    """``{obj_id: method}`` of ``--object-method OBJ_ID=METHOD`` values."""
    found = {}
    for value in values:
        obj_id, _, method = value.partition("=")
        if not obj_id.strip().isdigit() or not method:
            raise ValueError(f"object_method: expected OBJ_ID=METHOD (e.g. 8=keypointnet_robust), got {value!r}")
        if int(obj_id) in found:
            raise ValueError(f"object_method: object {int(obj_id)} given twice")
        found[int(obj_id)] = method
    return found


def run(args: argparse.Namespace) -> int:
    """Runs (or resumes) the benchmark."""
    options = config_from_args(LmoOptions, args)
    with flags_in_errors(LmoOptions), run_output(options.out, "benchmark lmo", {"--lmo": options.lmo}):
        job = Benchmark(out=options.out, lmo=options.lmo, quick=options.quick, method=options.method,
                        progress=options.progress, seed=options.seed, aae_steps=options.aae_steps,
                        aae_lr_drop_steps=options.aae_lr_drop_steps, aae_crop_box=options.aae_crop_box,
                        detector_backbone=options.detector_backbone, detector_input_size=options.detector_input_size,
                        neutral_distractors=options.neutral_distractors,
                        aae_encoder_backbone=options.aae_encoder_backbone,
                        object_methods=parse_object_methods(options.object_method), jobs=options.jobs)
        report = run_benchmark(job)
    print(f"wrote {Path(options.out) / 'report.json'} and {Path(options.out) / 'report.md'} "
          f"({report['total_minutes']:.1f} min of stages)")
    return 0
