"""``paz6d evaluate {coco,voc,bop}``: score detections or poses, print a table, write JSON (+ PNG plots).

Examples:
    paz6d evaluate coco --gt instances.json --results detections.json --iou-type segm --out coco.json
    paz6d evaluate voc --annotations Annotations/ --detections results/ --iou 0.5 --method 11point \
        --out voc.json --plots plots/

The JSON is written atomically (temporary file, then ``os.replace``). The COCO and VOC scorers are
imported when their subcommand runs (the BOP one imports its heavy parts inside ``run``), and
matplotlib loads only when plots are drawn, so building the parser stays cheap.

Scoring multiplies small (3x3, 4x4) matrices: OpenBLAS's thread pool, started when numpy loads,
would only cost CPU time (0.1-0.25 s per process on 2 cores), so this module asks for one BLAS
thread before numpy is imported. A value already set in the environment is kept.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

from evaluation import bop_cli  # noqa: E402
from paz6d.backend.files import finite_or_none, write_json_atomically  # noqa: E402
from paz6d.backend.paths import check_output_file, check_output_folder, check_outputs_apart  # noqa: E402


def _iou_threshold(text: str) -> float:
    value = float(text)
    if not (0.0 < value <= 1.0):
        raise argparse.ArgumentTypeError(f"expected an IoU threshold in (0, 1], got {text}")
    return value


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``coco``, ``voc`` and ``bop`` subcommands to ``parser``."""
    subparsers = parser.add_subparsers(dest="evaluate_command", required=True)

    coco = subparsers.add_parser("coco", help="COCO mAP (bbox or segm), same numbers as pycocotools",
                                 description="COCO detection/segmentation mAP with the 12-number summary.")
    coco.add_argument("--gt", required=True, type=Path, help="COCO ground-truth JSON (instances_*.json)")
    coco.add_argument("--results", required=True, type=Path, help="COCO results JSON (list of detections)")
    coco.add_argument("--iou-type", choices=("bbox", "segm"), default="bbox", help="box or mask IoU")
    coco.add_argument("--out", required=True, type=Path, help="output JSON (stats + per-class AP)")
    coco.add_argument("--plots", type=Path, help="directory for PNG precision-recall and per-class AP plots")
    coco.add_argument("--errors", action="store_true",
                      help="also break down each class's best-scoring detections (as many as it has objects) into "
                           "correct, duplicate, localization, other-class and background errors, and its recall at "
                           "IoU 0.5 at any score, and what each object is called (the class of its best-scoring "
                           "detection at IoU 0.5; with --plots also as coco_<iou-type>_confusion.png; boxes only)")

    voc = subparsers.add_parser("voc", help="PASCAL VOC AP (11-point or all-point)",
                                description="PASCAL VOC AP per class and mAP from XML/text annotations.")
    voc.add_argument("--annotations", required=True, type=Path,
                     help="directory of VOC XML files or text files '<class> <4 box numbers>' (one per image)")
    voc.add_argument("--detections", required=True, type=Path,
                     help="directory of per-image '<class> <score> <box>' files or devkit "
                          "comp<N>_det_<set>_<class>.txt files")
    voc.add_argument("--iou", type=_iou_threshold, default=0.5, help="IoU threshold for a true positive")
    voc.add_argument("--method", choices=("11point", "allpoint"), default="allpoint",
                     help="11point = VOC2007, allpoint = VOC2010+")
    voc.add_argument("--box-format", choices=("xyxy", "xywh"), default="xyxy", help="box format of text files")
    voc.add_argument("--plus-one", action=argparse.BooleanOptionalAction, default=True,
                     help="box areas with the VOC '+1 pixel' convention; --no-plus-one: continuous coordinates "
                          "(x2 - x1) (default: --plus-one)")
    voc.add_argument("--class-names", type=Path, help="file with one class name per line to map integer class ids")
    voc.add_argument("--layout", choices=("auto", "per_image", "per_class"), default="auto",
                     help="detection file layout (auto-detected from file names by default)")
    voc.add_argument("--out", required=True, type=Path, help="output JSON (per-class AP + mAP)")
    voc.add_argument("--plots", type=Path, help="directory for PNG precision-recall plots")

    bop_cli.configure(subparsers.add_parser("bop", help="BOP 6D pose evaluation"))


def _run_coco(args: argparse.Namespace) -> int:
    from evaluation import coco, detection_plots

    if args.errors:  # both files are needed again for the breakdown: read them once
        truth, detections = coco.read_files(args.gt, args.results)
        evaluation = coco.evaluate(truth, detections, args.iou_type)
    else:
        evaluation = coco.evaluate_files(args.gt, args.results, args.iou_type)
    per_class = evaluation.per_category_ap()
    print(f"COCO {args.iou_type} evaluation of {args.results} against {args.gt}")
    for name, value in zip(coco.STAT_NAMES, evaluation.stats):
        print(f"  {name:<10s} {value:7.3f}")
    print(f"  {'class':<24s} {'AP':>7s}")
    for name, value in per_class.items():
        print(f"  {name:<24s} {'-' if value is None else f'{value:.3f}':>7s}")
    report = {"iou_type": args.iou_type, "ground_truth": str(args.gt), "results": str(args.results),
              "stat_names": list(coco.STAT_NAMES), "stats": [float(v) for v in evaluation.stats],
              "per_class_ap": per_class}
    if args.errors:
        from evaluation.detection_errors import detection_errors

        errors = detection_errors(truth, detections)
        print(errors.table())
        report["errors"] = errors.to_dict()
    write_json_atomically(args.out, report, indent=2)
    print(f"wrote {args.out}")
    if args.plots is not None:
        paths = detection_plots.plot_coco(evaluation, args.plots)
        if args.errors:
            paths.append(detection_plots.plot_confusion(errors, args.plots / f"coco_{args.iou_type}_confusion.png",
                                                        "What each object is called"))
        for path in paths:
            print(f"wrote {path}")
    return 0


def _run_voc(args: argparse.Namespace) -> int:
    from evaluation import detection_plots, voc

    names = voc.read_class_names(args.class_names) if args.class_names is not None else None
    evaluation = voc.evaluate_directories(args.annotations, args.detections, args.iou, args.method, args.box_format,
                                          args.plus_one, names, args.layout)
    print(f"VOC AP ({args.method}, IoU >= {args.iou:g}, {'+1 pixel' if args.plus_one else 'continuous'} areas)")
    print(f"  {'class':<20s} {'AP':>8s} {'GT':>6s} {'dets':>6s} {'TP':>6s} {'FP':>6s}")
    per_class = {}
    for name, result in evaluation.per_class.items():
        ap = finite_or_none(result.average_precision)
        print(f"  {name:<20s} {'-' if ap is None else f'{ap:.4f}':>8s} {result.ground_truth_count:6d} "
              f"{result.detection_count:6d} {result.true_positives:6d} {result.false_positives:6d}")
        per_class[name] = {"ap": ap, "ground_truth": result.ground_truth_count,
                           "detections": result.detection_count, "true_positives": result.true_positives,
                           "false_positives": result.false_positives}
    mean = finite_or_none(evaluation.mean_average_precision)
    print(f"  {'mAP':<20s} {'-' if mean is None else f'{mean:.4f}':>8s}")
    write_json_atomically(args.out, {"annotations": str(args.annotations), "detections": str(args.detections),
                       "iou_threshold": args.iou, "method": args.method, "box_format": args.box_format,
                       "plus_one": args.plus_one, "per_class": per_class, "mAP": mean}, indent=2)
    print(f"wrote {args.out}")
    if args.plots is not None:
        for path in detection_plots.plot_voc(evaluation, args.plots):
            print(f"wrote {path}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Runs the subcommand chosen in ``args`` (from a parser set up by :func:`configure`).

    Raises:
        ValueError: for malformed input files, naming the file (and line or entry).
    """
    if args.evaluate_command in ("coco", "voc"):  # bop checks its own flags first
        inputs = {"--gt": args.gt, "--results": args.results} if args.evaluate_command == "coco" else \
            {"--class-names": args.class_names}
        check_outputs_apart({"--out": args.out}, inputs)
        check_output_file(args.out, "--out")
        if args.plots is not None:
            check_output_folder(args.plots, "--plots")
    if args.evaluate_command == "coco":
        return _run_coco(args)
    if args.evaluate_command == "voc":
        return _run_voc(args)
    if args.evaluate_command == "bop":
        return bop_cli.run(args)
    raise ValueError(f"evaluate: unknown subcommand {args.evaluate_command!r}")
