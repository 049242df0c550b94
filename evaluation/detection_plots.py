"""PNG plots of detection results: precision-recall curves, per-class AP bars and what each object is called.

Figures are drawn with matplotlib's Agg canvas (no display, no pyplot state) and written
atomically (temporary file, then ``os.replace``). matplotlib is imported inside the functions so
importing this module stays cheap.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from paz6d.backend.files import new_figure, save_figure_atomically

from evaluation.coco import RECALL_THRESHOLDS, CocoEvaluation
from evaluation.detection_errors import DetectionErrors
from evaluation.voc import VocEvaluation


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "class"


def plot_precision_recall(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: str | Path, title: str) -> Path:
    """Writes one PNG with a precision-recall curve per entry.

    Args:
        curves: label -> (recall (N,), precision (N,)).
        path: output PNG file.
        title: figure title.

    Returns:
        The written path.
    """
    figure = new_figure(7, 5.5)
    axes = figure.add_subplot(1, 1, 1)
    for label, (recall, precision) in curves.items():
        axes.plot(recall, precision, label=label, linewidth=1.5)
    axes.set_xlim(0.0, 1.0)
    axes.set_ylim(0.0, 1.02)
    axes.set_xlabel("recall")
    axes.set_ylabel("precision")
    axes.set_title(title)
    axes.grid(True, alpha=0.3)
    if curves:
        axes.legend(loc="lower left", fontsize="small", ncol=2 if len(curves) > 10 else 1)
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def plot_average_precision_bars(values: dict[str, float | None], path: str | Path, title: str) -> Path:
    """Writes a horizontal bar chart of AP per class (classes without a value are drawn as gaps)."""
    names = list(values)
    heights = [np.nan if values[n] is None else values[n] for n in names]
    figure = new_figure(7, max(3.0, 0.22 * len(names) + 1.2))
    axes = figure.add_subplot(1, 1, 1)
    axes.barh(np.arange(len(names)), np.nan_to_num(heights, nan=0.0), color="tab:blue")
    axes.set_yticks(np.arange(len(names)), names, fontsize="small")
    axes.invert_yaxis()
    axes.set_xlim(0.0, 1.0)
    axes.set_xlabel("AP")
    axes.set_title(title)
    axes.grid(True, axis="x", alpha=0.3)
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def plot_confusion(errors: DetectionErrors, path: str | Path, title: str) -> Path:
    """Writes a heat map of ``errors.confusion``: rows are the objects' categories, columns the category of
    their best-scoring detection at IoU >= 0.5 (last: none); cells are shares of the row, with counts."""
    counts = errors.confusion
    shares = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
    figure = new_figure(max(5.0, 0.6 * counts.shape[1] + 2.5), max(3.0, 0.45 * counts.shape[0] + 1.8))
    axes = figure.add_subplot(1, 1, 1)
    image = axes.imshow(shares, cmap="Blues", vmin=0.0, vmax=1.0, aspect="auto")
    for (row, column), count in np.ndenumerate(counts):
        if count:
            axes.text(column, row, str(count), ha="center", va="center", fontsize="small",
                      color="white" if shares[row, column] > 0.6 else "black")
    axes.set_xticks(np.arange(counts.shape[1]), errors.called_names, rotation=45, ha="right", fontsize="small")
    axes.set_yticks(np.arange(counts.shape[0]), errors.category_names, fontsize="small")
    axes.set_xlabel("called (best-scoring detection at IoU >= 0.5)")
    axes.set_ylabel("object")
    axes.set_title(title)
    figure.colorbar(image, ax=axes, label="share of the objects")
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def plot_coco(evaluation: CocoEvaluation, directory: str | Path) -> list[Path]:
    """COCO plots: mean precision-recall curves (IoU .50, .75, .50:.95) and per-class AP.

    Returns:
        Paths of ``coco_<iou_type>_pr.png`` and ``coco_<iou_type>_ap_per_class.png``.
    """
    directory = Path(directory)
    curves = {}
    for label, threshold in (("IoU=.50", 0.5), ("IoU=.75", 0.75), ("IoU=.50:.95", None)):
        curves[label] = (RECALL_THRESHOLDS, evaluation.precision_curve(threshold))
    stats = evaluation.stats_dict()
    title = f"COCO {evaluation.iou_type}: AP={stats['AP']:.3f} AP50={stats['AP50']:.3f} AP75={stats['AP75']:.3f}"
    return [plot_precision_recall(curves, directory / f"coco_{evaluation.iou_type}_pr.png", title),
            plot_average_precision_bars(evaluation.per_category_ap(),
                                        directory / f"coco_{evaluation.iou_type}_ap_per_class.png",
                                        f"COCO {evaluation.iou_type}: AP@[.50:.95] per class")]


def plot_voc(evaluation: VocEvaluation, directory: str | Path) -> list[Path]:
    """VOC plots: one precision-recall PNG per class, all classes together, and AP bars.

    Returns:
        Paths of ``voc_pr_<class>.png`` files, ``voc_pr_all.png`` and ``voc_ap_per_class.png``.
    """
    directory = Path(directory)
    settings = f"IoU>={evaluation.iou_threshold:g}, {evaluation.method}"
    written = []
    curves = {}
    for name, result in evaluation.per_class.items():
        if np.isnan(result.average_precision):
            continue
        curves[f"{name} ({result.average_precision:.3f})"] = (result.recall, result.precision)
        envelope = np.maximum.accumulate(result.precision[::-1])[::-1]
        written.append(plot_precision_recall({name: (result.recall, result.precision),
                                              "interpolated (monotone envelope)": (result.recall, envelope)},
                                             directory / f"voc_pr_{_safe_name(name)}.png",
                                             f"{name}: AP={result.average_precision:.4f} ({settings})"))
    written.append(plot_precision_recall(curves, directory / "voc_pr_all.png",
                                         f"VOC mAP={evaluation.mean_average_precision:.4f} ({settings})"))
    values = {name: (None if np.isnan(r.average_precision) else r.average_precision)
              for name, r in evaluation.per_class.items()}
    written.append(plot_average_precision_bars(values, directory / "voc_ap_per_class.png",
                                               f"VOC AP per class ({settings})"))
    return written
