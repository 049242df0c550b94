"""``docs/results.md``: the measured figures, written from the benchmarks' report JSON files.

Usage: ``python -m paz6d.benchmark.results REPORT.json [REPORT.json ...] --out docs/results.md [--cpu TEXT]``.

Each report is ``paz6d benchmark lmo``'s ``OUT/report.json`` (:func:`paz6d.benchmark.lmo.write_report`) or
``paz6d demo``'s ``OUT/report.json`` (:func:`paz6d.demo.aae_demo.run_demo`); its kind is recognised from its
keys. The page holds one section per report: the command that reproduces it, the CPU, and its figures, copied
from the report with three decimals, so no figure is typed twice by hand.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from paz6d.backend.files import load_json_object, write_text_atomically
from paz6d.cli_errors import EXPECTED_ERRORS, describe

#: ``paz6d benchmark lmo``'s conditions (``report.json`` keys) in the order of the page, with what they mean.
LMO_CONDITIONS = {
    "gt_visible_boxes": "real frames, ground-truth visible boxes",
    "detections": "real frames, the benchmark's detector's boxes",
    "synthetic_gt_visible_boxes": "held-out synthetic images, ground-truth visible boxes",
    "synthetic_detections": "held-out synthetic images, the detector's boxes",
}
#: Benchmark settings that have a ``paz6d benchmark lmo`` flag; they are spelled out in the command.
LMO_FLAGS = {"aae_steps": "--aae-steps", "aae_lr_drop_steps": "--aae-lr-drop-steps", "aae_crop_box": "--aae-crop-box",
             "detector_backbone": "--detector-backbone", "detector_input_size": "--detector-input-size",
             "neutral_distractors": "--neutral-distractors", "aae_encoder_backbone": "--aae-encoder-backbone"}


class ReportError(ValueError):
    """A report file that is neither kind of report, or lacks a field this page needs (names the file)."""


def cell(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    """A number in a Markdown table: ``value * scale`` with ``digits`` decimals, ``-`` when missing."""
    return "-" if value is None else f"{value * scale:.{digits}f}"


def mean_ar(summary: dict) -> float | None:
    """Mean of AR_MSSD and AR_MSPD (the benchmark's headline score), ``None`` when either is missing."""
    if summary.get("mean_AR_MSSD_AR_MSPD") is not None:
        return summary["mean_AR_MSSD_AR_MSPD"]
    if summary.get("AR_MSSD") is None or summary.get("AR_MSPD") is None:
        return None
    return 0.5 * (summary["AR_MSSD"] + summary["AR_MSPD"])


def report_kind(report: dict, path: Path) -> str:
    """``"lmo"`` (``paz6d benchmark lmo``) or ``"demo"`` (``paz6d demo``), from the report's keys."""
    if report.get("benchmark") == "lmo":
        return "lmo"
    if {"metrics", "training", "config"} <= set(report):
        return "demo"
    raise ReportError(f"{path}: not a report of `paz6d benchmark lmo` (key benchmark = 'lmo') or of `paz6d demo` "
                      f"(keys metrics, training, config)")


def _field(report: dict, path: Path, *keys: str):
    value = report
    for depth, key in enumerate(keys):
        if not isinstance(value, dict) or key not in value:
            raise ReportError(f"{path}: missing field {'.'.join(keys[:depth + 1])}")
        value = value[key]
    return value


def lmo_command(report: dict, label: str, path: Path) -> str:
    """The ``paz6d benchmark lmo`` command that scores ``label`` (``method`` then ``+method@obj_id`` per object
    that differs, as :attr:`paz6d.benchmark.lmo.Benchmark.label` names it) with the report's settings."""
    method, *others = label.split("+")
    parts = ["paz6d benchmark lmo"] + (["--quick"] if _field(report, path, "quick") else []) + [f"--method {method}"]
    for other in others:
        name, _, obj_id = other.partition("@")
        if not obj_id.isdigit() or not name:
            raise ReportError(f"{path}: methods: label {label!r} is not METHOD[+METHOD@OBJ_ID...]")
        parts.append(f"--object-method {obj_id}={name}")
    settings = _field(report, path, "settings")
    parts += [f"{flag} {settings[key]}" for key, flag in LMO_FLAGS.items() if settings.get(key) is not None]
    return " ".join(parts + ["--out OUT"])


def lmo_section(report: dict, path: Path, cpu: str) -> str:
    """The Markdown section of one ``paz6d benchmark lmo`` report: per method label and condition, the scores
    over all objects, then the real frames' mean AR per object, the detector's COCO AP and the stage time."""
    settings = _field(report, path, "settings")
    methods = _field(report, path, "methods")
    objects = [str(obj_id) for obj_id in _field(report, path, "objects")]
    size = "quick" if report.get("quick") else "full"
    lines = [f"## LM-O benchmark ({size}): `{path}`", "",
             "Synthetic training on the 8 LM-O meshes only, scored with `paz6d evaluate bop` "
             "(docs/real_photos.md). Commands (one per method label, into the same `OUT`):", ""]
    lines += [f"- `{label}`: `{lmo_command(report, label, path)}`" for label in methods]
    sizes = ", ".join(f"{key} {value}" for key, value in settings.items())
    lines += ["", f"Settings: {sizes}. CPU: {cpu}. Total stage time {cell(report.get('total_minutes'), digits=1)} "
              f"min.", "",
              "| method | boxes | instances | AR_MSSD | AR_MSPD | mean | ADD(-S) |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for label, conditions in methods.items():
        for condition in LMO_CONDITIONS:
            summary = (conditions or {}).get(condition)
            if summary is None:
                continue
            instances = summary.get("counts", {}).get("gt_instances", "-")
            lines.append(f"| {label} | {condition} | {instances} | {cell(summary.get('AR_MSSD'))} | "
                         f"{cell(summary.get('AR_MSPD'))} | **{cell(mean_ar(summary))}** | "
                         f"{cell(summary.get('ADD(-S)_recall'))} |")
    lines += ["", "Mean of AR_MSSD and AR_MSPD per object on the real frames:", "",
              "| method | boxes | " + " | ".join(f"obj {int(obj_id)}" for obj_id in objects) + " |",
              "|---|---|" + "---:|" * len(objects)]
    for label, conditions in methods.items():
        for condition in ("gt_visible_boxes", "detections"):
            summary = (conditions or {}).get(condition)
            if summary is None:
                continue
            per_object = summary.get("per_object", {})
            lines.append(f"| {label} | {condition} | "
                         + " | ".join(cell(mean_ar(per_object.get(obj_id, {}))) for obj_id in objects) + " |")
    coco = report.get("detector_coco")
    if coco:
        stats = dict(zip(_field(report, path, "detector_coco", "stat_names"),
                         _field(report, path, "detector_coco", "stats")))
        lines += ["", f"Detector on the real frames (`paz6d evaluate coco`): AP {cell(stats.get('AP'))}, "
                      f"AP50 {cell(stats.get('AP50'))}, AP75 {cell(stats.get('AP75'))}."]
    pick = report.get("method_pick")
    if pick:
        real = pick.get("real", {})
        choice = ", ".join(f"{int(obj_id)}: {method}" for obj_id, method in pick["methods"].items())
        lines += ["", f"Method per object picked on the held-out synthetic images ({choice}): on the real frames "
                      f"mean {cell((real.get('gt_visible_boxes') or {}).get('mean'))} with ground-truth visible "
                      f"boxes, {cell((real.get('detections') or {}).get('mean'))} with the detector's boxes."]
    return "\n".join(lines) + "\n"


def demo_section(report: dict, path: Path, cpu: str) -> str:
    """The Markdown section of one ``paz6d demo`` report: the AAE's scores on the held-out synthetic images."""
    metrics = _field(report, path, "metrics")
    rotation = metrics.get("rotation_error_deg", {})
    options = [f"--test-images {_field(report, path, 'test_images')}",
               f"--steps {_field(report, path, 'training', 'steps')}"]
    if report.get("scene_crops"):
        options += [f"--scene-crops {report['scene_crops']}", f"--train-images {report.get('train_images')}"]
    metric = metrics.get("metric", "ADD")
    rows = [("test instances", str(metrics.get("count", "-"))),
            (f"{metric} recall @ 0.1 d", cell(metrics.get("recall_0.1d"))),
            (f"{metric} AUC (0-10 cm)", cell(metrics.get("auc_10cm"))),
            ("median rotation error [deg]", cell(rotation.get("median"), digits=2)),
            ("rotation error < 5 / 10 deg", f"{cell(rotation.get('below_5'))} / {cell(rotation.get('below_10'))}"),
            ("median translation error [mm]", cell(metrics.get("translation_error_m", {}).get("median"), 1000, 1)),
            ("no estimate", f"{metrics.get('failures', '-')} of {metrics.get('count', '-')}"),
            ("inference per object [ms]", cell(report.get("seconds_per_estimate"), 1000, 1)),
            ("total time [min]", cell(report.get("timings", {}).get("total_seconds"), 1 / 60, 1))]
    lines = [f"## End-to-end demo: `{path}`", "",
             f"`paz6d demo {' '.join(options)} --out OUT` (docs/aae.md). CPU: {cpu}.", "",
             "| figure | value |", "|---|---:|"] + [f"| {name} | {value} |" for name, value in rows]
    return "\n".join(lines) + "\n"


def this_cpu(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """This machine's CPU model and logical core count, e.g. ``"Intel(R) Xeon(R) ... (2 logical cores)"``."""
    try:
        lines = Path(cpuinfo).read_text().splitlines()
    except OSError:
        return "unknown CPU"
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    cores = sum(line.startswith("processor") for line in lines)
    return f"{models[0] if models else 'unknown CPU'} ({cores} logical cores)"


def results_page(paths: Sequence[Path], cpu: str | None = None) -> str:
    """The whole ``docs/results.md``: a header, then one section per report, in the order given.

    Args:
        paths: report JSON files.
        cpu: the CPU the reports were measured on (default: the report's ``cpu`` field, else this machine's).
    """
    sections = []
    for path in map(Path, paths):
        report = load_json_object(path)
        machine = cpu or report.get("cpu") or f"{this_cpu()}, the machine that wrote this page"
        kind = report_kind(report, path)
        sections.append((lmo_section if kind == "lmo" else demo_section)(report, path, machine))
    header = ["# Results", "",
              "The measured figures of the benchmarks, written by "
              "`python -m paz6d.benchmark.results " + " ".join(str(p) for p in paths) + " --out docs/results.md` "
              "from the reports those commands write; edit the reports' commands, not this page.", ""]
    return "\n".join(header) + "\n".join(sections)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: writes ``--out`` from the report files; a bad report prints one line and exits 2."""
    parser = argparse.ArgumentParser(prog="python -m paz6d.benchmark.results", description=__doc__.splitlines()[0])
    parser.add_argument("reports", nargs="+", type=Path, help="report.json files of paz6d benchmark lmo / paz6d demo")
    parser.add_argument("--out", type=Path, required=True, help="Markdown file to write (e.g. docs/results.md)")
    parser.add_argument("--cpu", default=None, help="the CPU the reports were measured on (default: the report's "
                                                    "cpu field, else this machine's)")
    args = parser.parse_args(argv)
    try:
        page = results_page(args.reports, args.cpu)
        write_text_atomically(args.out, page)
    except EXPECTED_ERRORS as error:
        print(f"{parser.prog}: error: {describe(error)}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
