"""``paz6d evaluate bop``: BOP'19 average recall (VSD, MSSD, MSPD) and ADD(-S) of a results CSV.

Example:
    paz6d evaluate bop --dataset lmo --split test --results results_lmo-test.csv \
        --metrics mssd,mspd,add --out scores.json --errors errors.csv --plots plots/

Without ``--metrics`` every metric is computed except VSD when the data set has no depth images
(a warning is printed and ``skipped_metrics`` in the JSON says why); asking for ``vsd`` explicitly
on such a data set is an error. The JSON and CSV are written atomically. Heavy modules are
imported inside :func:`run`.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from paz6d.backend.files import write_csv_atomically, write_json_atomically
from paz6d.backend.paths import check_output_file, check_output_folder, check_outputs_apart, check_plain_name
from paz6d.cli_errors import shorten
from paz6d.datasets.bop.results import read_pose_results

METRIC_NAMES = ("vsd", "mssd", "mspd", "add")
SKIPPED_ROWS_IN_JSON = 100


def _metrics(text: str) -> tuple[str, ...]:
    names = tuple(dict.fromkeys(part.strip().lower() for part in text.split(",") if part.strip()))
    unknown = [name for name in names if name not in METRIC_NAMES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of {','.join(METRIC_NAMES)}, got {text!r}")
    return names


def _visibility(text: str) -> float:
    value = float(text)
    if not (value == -1 or 0.0 <= value <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1] or -1, got {text}")
    return value


def _positive_millimetres(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of millimetres, got {text}")
    return value


def _workers(text: str) -> int:
    value = int(text)
    if value == 0 or value < -1:
        raise argparse.ArgumentTypeError(f"expected a positive number of threads or -1 (all cores), got {text}")
    return value


def check_arguments(args: argparse.Namespace) -> None:
    """Checks names and output paths before any file is read (bad ones raise ``ValueError`` naming the flag)."""
    check_plain_name(args.split, "--split")
    check_outputs_apart({"--out": args.out, "--errors": args.errors},
                        {"--results": args.results, "--targets": args.targets})
    check_output_file(args.out, "--out")
    if args.errors is not None:
        check_output_file(args.errors, "--errors")
    if args.plots is not None:
        check_output_folder(args.plots, "--plots")


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``evaluate bop`` arguments to ``parser``."""
    parser.description = ("BOP Challenge 2019 evaluation of 6D pose estimates: AR_VSD, AR_MSSD, AR_MSPD, AR, "
                          "ADD(-S) recall and ADD/ADD-S AUC, per object.")
    parser.add_argument("--dataset", required=True, type=Path,
                        help="BOP data set folder (camera.json, models[_eval]/, <split>/<scene>/)")
    parser.add_argument("--split", default="test", help="split folder (default: test)")
    parser.add_argument("--results", required=True, type=Path,
                        help="results CSV: scene_id,im_id,obj_id,score,R,t,time (R row-major, t in mm)")
    parser.add_argument("--targets", type=Path, help="targets JSON (default: <dataset>/test_targets_bop19.json)")
    parser.add_argument("--metrics", type=_metrics,
                        help="comma-separated subset of vsd,mssd,mspd,add (default: all; vsd only with depth images)")
    parser.add_argument("--out", required=True, type=Path, help="output JSON with the scores")
    parser.add_argument("--errors", type=Path, help="output CSV with the errors of each evaluated estimate")
    parser.add_argument("--plots", type=Path, help="folder for PNG recall-vs-threshold plots")
    parser.add_argument("--skip-invalid", action="store_true",
                        help="skip malformed/unknown rows of the results CSV (counted in the JSON) instead of failing")
    parser.add_argument("--visib-gt-min", type=_visibility, default=-1.0,
                        help="GT instances that count: -1 (default, as the BOP toolkit's eval_bop19_pose.py) = "
                             "the inst_count most visible of each target; a fraction such as 0.1 = every "
                             "instance of a target object at least that visible")
    parser.add_argument("--vsd-delta", type=_positive_millimetres, default=15.0,
                        help="VSD visibility tolerance in mm (default 15)")
    parser.add_argument("--workers", type=_workers, default=1,
                        help="threads for the ADD-S search (-1 = all cores; results do not depend on it)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True,
                        help="progress bars (default: --progress)")


def _choose_metrics(requested: tuple[str, ...] | None, data) -> tuple[tuple[str, ...], dict[str, str]]:
    """The metrics to run and the ones skipped (with the reason)."""
    images = sorted({(target.scene_id, target.im_id) for target in data.targets})
    missing = [key for key in images if data.depth_path(*key) is None]
    if requested is None:
        if not missing:
            return METRIC_NAMES, {}
        scene_id, im_id = missing[0]
        reason = (f"no depth images ({len(missing)} of {len(images)} target images lack one, e.g. "
                  f"{data.scene_folder(scene_id) / 'depth' / f'{im_id:06d}.png'}); VSD needs depth")
        print(f"warning: skipping VSD: {reason}; AR (the mean of the three) is not reported", file=sys.stderr)
        return tuple(name for name in METRIC_NAMES if name != "vsd"), {"vsd": reason}
    if "vsd" in requested and missing:
        scene_id, im_id = missing[0]
        raise ValueError(f"--metrics vsd: VSD needs depth images, but {len(missing)} of {len(images)} target "
                         f"images have none (e.g. {data.scene_folder(scene_id) / 'depth' / f'{im_id:06d}.png'}); "
                         "drop vsd from --metrics")
    return requested, {}


def write_errors_csv(evaluation, results, path: Path) -> Path:
    """Writes ERRORS.csv atomically: one row per evaluated estimate paired with a GT instance."""
    from evaluation.bop import ERROR_COLUMNS


    rows = ([row["scene_id"], row["im_id"], row["obj_id"], repr(float(results.scores[row["estimate"]]))]
            + ["" if row[name] is None else repr(row[name]) for name in ERROR_COLUMNS]
            for row in evaluation.error_rows())
    return write_csv_atomically(path, ("scene_id", "im_id", "obj_id", "score") + ERROR_COLUMNS, rows)


def _format(value) -> str:
    return "-" if value is None else f"{value:.3f}"


def print_table(evaluation, title: str) -> None:
    """Prints per-object and overall scores."""
    summary = evaluation.to_dict()
    columns = [key for key in ("AR_VSD", "AR_MSSD", "AR_MSPD", "ADD(-S)_recall") if key in summary]
    print(title)
    print(f"  {'object':>8s} {'GT':>6s} " + " ".join(f"{column:>14s}" for column in columns))
    for obj_id, entry in summary["per_object"].items():
        print(f"  {obj_id:>8s} {entry['instances']:6d} " + " ".join(f"{_format(entry.get(c)):>14s}" for c in columns))
    print(f"  {'all':>8s} {summary['counts']['gt_instances']:6d} "
          + " ".join(f"{_format(summary.get(c)):>14s}" for c in columns))
    if "AR" in summary:
        print(f"  AR (mean of AR_VSD, AR_MSSD, AR_MSPD) = {summary['AR']:.4f}")
    aucs = [key for key in summary if key.startswith("AUC_")]
    if aucs:
        limit = evaluation.settings.auc_max_threshold
        print(f"  AUC over 0-{limit:g} mm: " + ", ".join(f"{key[4:]} {summary[key]:.4f}" for key in aucs))
    for name, reason in evaluation.skipped_metrics.items():
        print(f"  skipped {name}: {reason}")


def run(args: argparse.Namespace) -> int:
    """Evaluates, prints the table and writes the JSON (and CSV/plots when asked).

    Raises:
        ValueError: bad data set files, targets or results rows (file and line named), or VSD
            requested without depth images.
    """
    from evaluation import bop
    from evaluation.bop_data import load_evaluation_data

    check_arguments(args)
    data = load_evaluation_data(args.dataset, args.split, args.targets)
    metrics, skipped_metrics = _choose_metrics(args.metrics, data)
    settings = bop.BopSettings(metrics=metrics, visib_gt_min=args.visib_gt_min, vsd_delta=args.vsd_delta,
                               workers=args.workers)
    results = read_pose_results(args.results, object_ids=data.object_ids, image_ids=data.images.keys(),
                                skip_invalid=args.skip_invalid, units="mm")
    if results.skipped:
        print(f"warning: skipped {len(results.skipped)} invalid rows of {args.results} "
              f"(first: line {results.skipped[0][0]}: {shorten(results.skipped[0][1], 300)})", file=sys.stderr)
    note = None
    if len(results) == 0:
        note = (f"no estimates in {args.results}" + (f" (all {len(results.skipped)} rows skipped as invalid)"
                                                       if results.skipped else "") + ": every target scores 0")
        print(f"note: {note}", file=sys.stderr)
    evaluation = bop.evaluate(data, results, settings, progress=args.progress)
    evaluation.skipped_metrics.update(skipped_metrics)
    print_table(evaluation, f"BOP'19 evaluation of {args.results} on {args.dataset}/{args.split} "
                            f"({len(data.targets)} targets, {len(results)} estimates read, "
                            f"{len(results.skipped)} skipped)")
    summary = {"dataset": str(args.dataset), "split": args.split, "results": str(args.results),
               "targets": str(args.targets) if args.targets else None, "models": str(data.models_folder),
               **evaluation.to_dict(), **({"note": note} if note else {}),
               "skipped_rows": [{"line": line, "reason": reason}
                                for line, reason in results.skipped[:SKIPPED_ROWS_IN_JSON]]}
    write_json_atomically(args.out, summary, indent=2)
    print(f"wrote {args.out}")
    if args.errors is not None:
        print(f"wrote {write_errors_csv(evaluation, results, args.errors)}")
    if args.plots is not None:
        from evaluation import pose_plots

        for path in pose_plots.plot_evaluation(evaluation, args.plots):
            print(f"wrote {path}")
    return 0
