"""``paz6d demo``: the README's end-to-end job (AAE, :mod:`paz6d.demo.aae_demo`); ``--keypoints`` adds
KeypointNet on the same object (:mod:`paz6d.demo.keypoint_demo`); then every trained pose model goes
through the out-of-distribution check (:mod:`paz6d.demo.ood_check`), written into ``OUT/report.json``
(``ood_check``) and ``OUT/ood_check.png``. Each flag is a field of :class:`DemoOptions`. Cheap to
import: the demos load TensorFlow and the renderers when they run.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from pathlib import Path

from paz6d.aae.config import QUICK
from paz6d.backend.paths import check_output_folder
from paz6d.cli_options import add_config_arguments, config_from_args, flags_in_errors, option
from paz6d.datasets.bop.units import MM_PER_M
from paz6d.demo.report import write_report
from renderers.platform import PLATFORMS


@dataclass(frozen=True)
class DemoOptions:
    """One ``paz6d demo`` run."""

    out: Path = option(Path("demo_output"), "output folder (re-run to resume)")
    test_images: int = option(200, "held-out synthetic test images")
    scene_crops: float = option(0.0, "share of the AAE's training inputs cut from --train-images generated training "
                                     "scenes (real occlusion by the generator's occluders; 0: rendered views only, no "
                                     "training scenes; measured in docs/aae.md)")
    train_images: int = option(2000, "training scenes generated when --scene-crops > 0")
    steps: int | None = option(None, "AAE training steps (default: the quick config's)")
    workers: int = option(2, "rendering processes")
    platform: str | None = option(None, "OpenGL platform of the renderers (default: auto)", choices=PLATFORMS)
    keypoints: bool = option(False, "also train and score KeypointNet (supervised, --keypoint-config) on the same "
                                    "object into OUT/keypoints")
    keypoint_config: str = option("quick", "KeypointNet config of --keypoints: quick (~13 more minutes on 2 CPU "
                                           "cores; fails the out-of-distribution check) or robust (~25 minutes; "
                                           "passes it)", choices=("quick", "robust"))
    ood_images: int = option(200, "held-out views of the out-of-distribution check (each scored under every condition)")

    def __post_init__(self):
        if self.steps is not None and self.steps <= 0:
            raise ValueError(f"steps: expected a positive number of steps, got {self.steps}")
        if self.workers < 1:
            raise ValueError(f"workers: expected a positive number of rendering processes, got {self.workers}")
        if self.test_images < 1:
            raise ValueError(f"test_images: expected a positive number of images, got {self.test_images}")
        if not 0.0 <= self.scene_crops <= 1.0:
            raise ValueError(f"scene_crops: expected a share in [0, 1], got {self.scene_crops}")
        if self.scene_crops > 0 and self.train_images < 1:
            raise ValueError(f"train_images: expected a positive number of images, got {self.train_images}")
        if self.ood_images < 1:
            raise ValueError(f"ood_images: expected a positive number of views, got {self.ood_images}")


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d demo`` flags (the fields of :class:`DemoOptions`)."""
    add_config_arguments(parser, DemoOptions)


def run_demos(options: DemoOptions, config=QUICK, keypoint_settings=None) -> dict:
    """The AAE demo with ``config``, KeypointNet's when ``options.keypoints`` (``keypoint_settings``: a
    :class:`~paz6d.keypointnet.config.KeypointConfig` replacing its preset), then the OOD check of every
    model, added to the AAE demo's report (``OUT/report.json``, key ``ood_check``); returns that report."""
    from paz6d.demo import aae_demo, keypoint_demo, ood_check  # here: they load OpenCV, the renderers, TensorFlow

    out = Path(options.out)
    report = aae_demo.run_demo(out, config, options.test_images, options.workers, options.platform,
                               train_images=options.train_images, scene_crops=options.scene_crops)
    mesh = Path(report["files"]["mesh"])
    models = [ood_check.PoseModel("AAE", "aae", Path(report["files"]["model"]))]
    if options.keypoints:
        keypoint_out = out / "keypoints"
        keypoint_demo.run_keypoint_demo(keypoint_out, mesh, mesh_scale=1.0 / MM_PER_M, test_images=options.test_images,
                                        workers=options.workers, settings=keypoint_settings,
                                        config=options.keypoint_config)
        models.append(ood_check.PoseModel("KeypointNet", "keypointnet",
                                          keypoint_demo.mode_run_dir(keypoint_out, "supervised")))
    print(f"\n== out-of-distribution check ({options.ood_images} views, {len(models)} models)", flush=True)
    report["ood_check"] = ood_check.run_check(out, mesh, models, options.ood_images, 1.0 / MM_PER_M,
                                              workers=options.workers)
    write_report(out / "report.json", report)
    print(f"\nreport: {out / 'report.json'} (ood_check); chart: {report['ood_check']['chart']}")
    return report


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d demo``."""
    options = config_from_args(DemoOptions, args)
    config = QUICK if options.steps is None else replace(QUICK, steps=options.steps)
    with flags_in_errors(DemoOptions):
        check_output_folder(options.out, "out")
        run_demos(options, config)
    return 0
