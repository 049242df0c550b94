"""PNG plots of a BOP evaluation: recall vs threshold per error type, ADD/ADD-S accuracy curves.

Figures are drawn on matplotlib's Agg canvas (no display, no pyplot state) and written atomically
(temporary file, then ``os.replace``); matplotlib is imported inside the functions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from paz6d.backend.files import new_figure, save_figure_atomically

from evaluation.bop import BopEvaluation, MetricRecalls

_AXIS_LABELS = {"mssd": "threshold (fraction of the object diameter)", "mspd": "threshold (px at 640 px width)",
                "vsd": "correctness threshold theta (mean over tau)", "add": "threshold (fraction of the diameter)"}
_TITLES = {"mssd": "MSSD", "mspd": "MSPD", "vsd": "VSD", "add": "ADD(-S)"}


def _curve(metric: MetricRecalls, name: str, taus: int) -> tuple[np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """x values, overall recalls and per-object recalls (VSD averaged over its taus)."""
    if name != "vsd":
        return metric.thresholds, metric.recalls, metric.object_recalls
    thetas = metric.thresholds.reshape(taus, -1)[0]
    mean = metric.recalls.reshape(taus, -1).mean(axis=0)
    objects = {obj_id: values.reshape(taus, -1).mean(axis=0) for obj_id, values in metric.object_recalls.items()}
    return thetas, mean, objects


def plot_recall_curve(evaluation: BopEvaluation, name: str, path: str | Path) -> Path:
    """Writes the recall-vs-threshold curve of metric ``name`` (all instances and each object)."""
    metric = evaluation.metrics[name]
    x, overall, objects = _curve(metric, name, len(evaluation.settings.vsd_taus))
    figure = new_figure(7, 5)
    axes = figure.add_subplot(1, 1, 1)
    marker = "o" if len(x) > 1 else "s"
    for obj_id, values in sorted(objects.items()):
        axes.plot(x, values, marker=marker, markersize=3, linewidth=1, alpha=0.6, label=f"object {obj_id}")
    label = f"all ({'recall' if name == 'add' else 'AR'} {metric.average:.3f})"
    axes.plot(x, overall, marker=marker, color="black", linewidth=2.5, label=label)
    axes.set_xlabel(_AXIS_LABELS[name])
    axes.set_ylabel("recall")
    axes.set_ylim(0.0, 1.02)
    axes.set_title(f"{_TITLES[name]} recall vs threshold")
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=7, ncol=2, loc="lower right")
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def plot_accuracy_curves(evaluation: BopEvaluation, path: str | Path) -> Path:
    """Writes the YCB-Video accuracy-threshold curves of ADD, ADD-S and ADD(-S) with their AUCs."""
    limit = evaluation.settings.auc_max_threshold
    thresholds = np.linspace(0.0, limit, 201)
    figure = new_figure(7, 5)
    axes = figure.add_subplot(1, 1, 1)
    for label, errors in evaluation.auc_errors.items():
        accuracy = (errors[None, :] <= thresholds[:, None]).mean(axis=1) if errors.size else np.zeros_like(thresholds)
        axes.plot(thresholds, accuracy, linewidth=2, label=f"{label} (AUC {evaluation.aucs[label]:.3f})")
    axes.set_xlabel("threshold (mm)")
    axes.set_ylabel("accuracy")
    axes.set_xlim(0.0, limit)
    axes.set_ylim(0.0, 1.02)
    axes.set_title("ADD / ADD-S accuracy vs threshold")
    axes.grid(True, alpha=0.3)
    axes.legend(loc="lower right")
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def plot_evaluation(evaluation: BopEvaluation, folder: str | Path) -> list[Path]:
    """Writes ``recall_<metric>.png`` for each computed metric and ``accuracy_add.png`` (with ADD)."""
    folder = Path(folder)
    paths = [plot_recall_curve(evaluation, name, folder / f"recall_{name}.png") for name in evaluation.metrics]
    if evaluation.auc_errors:
        paths.append(plot_accuracy_curves(evaluation, folder / "accuracy_add.png"))
    return paths
