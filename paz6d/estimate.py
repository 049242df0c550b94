"""``paz6d estimate``: run a trained pose model on a BOP data set and write a BOP results CSV.

The model gets each annotated instance of one object with its ground-truth 2D box (the setting of
the AAE paper's and our demo's evaluations; no detector involved), and the estimates are written in
the BOP'19 results format that ``paz6d evaluate bop`` scores::

    paz6d estimate --run runs/aae_lmo5 --dataset ../shared/data/bop_lmo --object-id 5 --out lmo5.csv
    paz6d evaluate bop --dataset ../shared/data/bop_lmo --results lmo5.csv --metrics mssd,mspd,add \\
        --out lmo5.json

Images without an RGB file are skipped (reported), as are instances below ``--min-visible``.
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

import numpy as np

from paz6d.backend.paths import check_output_file, check_outputs_apart, check_plain_name
from paz6d.aae.codebook import Codebook
from paz6d.keypointnet import run_dir as keypointnet_run_dir
from paz6d.datasets.bop import Target, write_pose_results, write_targets
from paz6d.datasets.bop.targets import TARGET_MIN_VISIBLE_FRACTION

METHODS = ("aae", "keypoints")
#: ``--method`` value -> the method name of its run directories (:func:`paz6d.run_dirs.method_of`).
RUN_METHODS = {"aae": "aae", "keypoints": "keypointnet"}
_OBJECT_MESH = re.compile(r"^obj_(\d+)$")
BOXES = {"obj": "bbox_obj", "visib": "bbox_visib"}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--run", type=Path, required=True, help="run directory of `paz6d train aae|keypointnet`")
    parser.add_argument("--method", choices=METHODS, default="aae", help="model type of --run")
    parser.add_argument("--dataset", type=Path, required=True, help="BOP data set folder")
    parser.add_argument("--split", default="test", help="split folder of --dataset")
    parser.add_argument("--object-id", type=int, required=True, help="object the model was trained for")
    parser.add_argument("--out", type=Path, required=True, help="results CSV to write")
    parser.add_argument("--box", choices=sorted(BOXES), default="obj",
                        help="ground-truth box given to the model: of the whole projected object (obj) or of "
                             "its visible part (visib, what a detector would see)")
    parser.add_argument("--targets-out", type=Path, default=None,
                        help="also write the BOP'19 targets of the images estimated (for `evaluate bop --targets` "
                             "when only some images of the split have RGB files)")
    parser.add_argument("--min-visible", type=float, default=TARGET_MIN_VISIBLE_FRACTION,
                        help=f"skip instances whose visible fraction is below this (default "
                             f"{TARGET_MIN_VISIBLE_FRACTION}, as BOP'19 targets)")


def _estimator(method: str, run_dir: Path):
    """The method's pipeline, loaded once; each image's camera is given per call."""
    if method == "aae":
        from paz6d.aae.pipeline import ImplicitPose6D

        return ImplicitPose6D(run_dir)
    from paz6d.keypointnet.pipeline import KeypointPose6D

    return KeypointPose6D(run_dir)


def estimate_dataset(run_dir: Path, method: str, dataset: Path, split: str, obj_id: int, box: str = "obj",
                     min_visible: float = TARGET_MIN_VISIBLE_FRACTION, progress: bool = True) -> dict:
    """Estimates the pose of every visible-enough instance of ``obj_id`` from its ground-truth box.

    Returns:
        ``{"scene_ids", "im_ids", "rotations" (E, 3, 3), "translations" (E, 3) metres, "seconds" (E,),
        "targets" (BOP'19 :class:`Target` of the estimated images), "skipped_images", "failed"}``; an
        estimate that fails (e.g. PnP with too few keypoints) is counted in ``failed`` and left out
        (BOP scores a missing estimate as a miss).
    """
    from tqdm.auto import tqdm

    from paz6d.datasets.bop.reader import BOPDataset  # here: the image reader loads OpenCV, which `--help` does not need

    if box not in BOXES:
        raise ValueError(f"box: expected one of {sorted(BOXES)}, got {box!r}")
    data = BOPDataset(dataset, split=split)
    estimator = None  # loaded at the first instance to estimate
    found = {"scene_ids": [], "im_ids": [], "rotations": [], "translations": [], "seconds": []}
    skipped_images, failed, targets = 0, 0, []
    for sample in tqdm(data, desc=f"estimate obj {obj_id}", unit="image", disable=not progress, dynamic_ncols=True):
        instances = [instance for instance in sample.objects if instance.obj_id == obj_id
                     and (instance.info or {}).get("visib_fract", 1.0) >= min_visible]
        if not instances:
            continue
        if sample.image is None:
            skipped_images += 1
            continue
        targets.append(Target(sample.scene_id, sample.im_id, obj_id, len(instances)))
        if estimator is None:
            estimator = _estimator(method, run_dir)
        for instance in instances:
            if not instance.info or BOXES[box] not in instance.info:
                raise ValueError(f"{dataset}: scene {sample.scene_id} image {sample.im_id} has no {BOXES[box]} in "
                                 f"scene_gt_info.json (needed for the ground-truth box)")
            x, y, width, height = instance.info[BOXES[box]]
            started = time.perf_counter()
            try:
                pose = estimator(sample.image, (float(x), float(y), float(x + width), float(y + height)),
                                 camera=sample.camera)
            except ValueError:
                pose = None
            if pose is None:
                failed += 1
                continue
            T = pose.to_matrix()
            found["scene_ids"].append(sample.scene_id)
            found["im_ids"].append(sample.im_id)
            found["rotations"].append(T[:3, :3])
            found["translations"].append(T[:3, 3])
            found["seconds"].append(time.perf_counter() - started)
    result = {name: np.asarray(values) for name, values in found.items()}
    result.update(targets=targets, skipped_images=skipped_images, failed=failed)
    return result


def run_object_id(run_dir: Path, method: str) -> int | None:
    """The BOP object id a run directory was trained on, from its mesh's ``obj_XXXXXX`` file name
    (``None`` when the mesh is named otherwise, e.g. a mesh given with ``--mesh``).

    Reads the run's files through its method's ``run_dir`` module, so a corrupt or incomplete run
    directory fails here, naming the file, before any image is read.
    """
    if method == "aae":
        from paz6d.aae import run_dir as aae_run_dir

        mesh = aae_run_dir.read_config(run_dir)["mesh"]
        aae_run_dir.read_object(run_dir)
        Codebook.load(aae_run_dir.codebook_path(run_dir))
    else:
        mesh = keypointnet_run_dir.read_config(run_dir).get("mesh_path")
        keypointnet_run_dir.read_keypoints(run_dir)
    match = _OBJECT_MESH.match(Path(str(mesh)).stem) if mesh else None
    return int(match.group(1)) if match else None


def check_arguments(args: argparse.Namespace) -> None:
    """Checks every flag, the run directory (its method, its files, its object) and the output paths
    before any image is read; bad input raises ``ValueError`` naming the flag or file."""
    from paz6d.run_dirs import method_of

    check_plain_name(args.split, "--split")
    if args.object_id < 1:
        raise ValueError(f"--object-id: expected a BOP object id (a positive integer), got {args.object_id}")
    if not 0.0 <= args.min_visible <= 1.0:
        raise ValueError(f"--min-visible: expected a visible fraction in [0, 1], got {args.min_visible}")
    check_outputs_apart({"--out": args.out, "--targets-out": args.targets_out}, {})
    check_output_file(args.out, "--out")
    if args.targets_out is not None:
        check_output_file(args.targets_out, "--targets-out")
    if not args.run.is_dir():
        raise ValueError(f"--run: {args.run} is not a directory")
    method = method_of(args.run)
    if method != RUN_METHODS[args.method]:
        wanted = next(name for name, value in RUN_METHODS.items() if value == method)
        raise ValueError(f"--method: {args.run} is a {method} run directory; use --method {wanted}")
    trained_on = run_object_id(args.run, args.method)
    if trained_on is not None and trained_on != args.object_id:
        raise ValueError(f"--object-id: {args.run} was trained on object {trained_on}, not {args.object_id}")


def run(args: argparse.Namespace) -> int:
    from paz6d.backend.tensorflow_guard import import_tensorflow

    check_arguments(args)
    import_tensorflow()
    found = estimate_dataset(args.run, args.method, args.dataset, args.split, args.object_id, args.box,
                             args.min_visible)
    count = len(found["im_ids"])
    if count == 0 and found["failed"] == 0:
        raise ValueError(f"{args.dataset}: no instance of object {args.object_id} with an RGB image and visible "
                         f"fraction >= {args.min_visible} in split {args.split!r}")
    if count == 0:
        raise ValueError(f"every estimate failed ({found['failed']} instances of object {args.object_id}); "
                         f"{args.out} not written (is {args.run} a model of this object and data set?)")
    write_pose_results(args.out, found["scene_ids"], found["im_ids"], np.full(count, args.object_id),
                       np.ones(count), found["rotations"].reshape(-1, 3, 3), found["translations"].reshape(-1, 3),
                       found["seconds"], units="m")
    if args.targets_out is not None:
        write_targets(args.targets_out, found["targets"])
    print(f"wrote {args.out}: {count} estimates of object {args.object_id} ({found['failed']} failed, "
          f"{found['skipped_images']} images without RGB skipped)")
    return 0
