"""The demo's out-of-distribution check: does each pose model keep >= :data:`MIN_RETENTION` of its
in-distribution ADD recall on backgrounds and a light set-up that its training never used?

Every model is scored (ADD recall at 0.1 d, from the ground-truth boxes) on the same held-out views of
the demo object (:mod:`paz6d.demo.ood_set`) under each condition of
:data:`~paz6d.demo.ood_set.CONDITIONS`; the reference is the same views over the model's own training
background style (:meth:`PoseModel.training_style`). The report (:func:`check_summary`), per model::

    in_distribution_style   the training background style of the reference images
    in_distribution_recall  ADD recall @ 0.1 d on the reference images
    conditions              {condition: {recall, retention (= recall / in_distribution_recall), pass}}
    min_retention           the lowest retention (None when the reference recall is 0 or unmeasured)
    pass                    every condition retains >= min_retention_required

Written into the demo's ``report.json`` (key ``ood_check``), printed as a table and drawn as a bar
chart (``ood_check.png``). Inference only: no model is trained here.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from paz6d.backend.files import finite_or_none, new_figure, save_figure_atomically
from paz6d.demo.keypoint_demo import evaluate_keypoint_pose
from paz6d.demo.ood_set import CONDITIONS, IN_DISTRIBUTION, OODViews
from paz6d.demo.report import number, print_rows, score_poses

#: The check passes when every OOD recall is at least this fraction of the in-distribution recall.
MIN_RETENTION = 0.9
#: Floating-point slack of the retention comparison.
RATIO_TOLERANCE = 1e-9
#: Seed of the OOD views: shared with no training, validation or test set of the demo.
OOD_SEED = 2_000_029
#: Training background style of the AAE: it composites its inputs over a ``"clutter"``
#: :class:`~paz6d.synthesis.backgrounds.BackgroundBank` (:mod:`paz6d.aae.augment`). KeypointNet's is the
#: style of :data:`paz6d.keypointnet.views.BACKGROUND`.
AAE_TRAINING_STYLE = "clutter"
MODEL_KINDS = ("aae", "keypointnet")
OOD_CONDITIONS = CONDITIONS[1:]


@dataclass(frozen=True)
class PoseModel:
    """One model of the check: ``kind`` (one of :data:`MODEL_KINDS`) and its run directory."""

    name: str
    kind: str
    run_dir: Path

    def __post_init__(self):
        if self.kind not in MODEL_KINDS:
            raise ValueError(f"{self.name}: kind: expected one of {MODEL_KINDS}, got {self.kind!r}")

    def training_style(self) -> str:
        """The background style this kind of model is trained on."""
        if self.kind == "keypointnet":
            from paz6d.keypointnet.views import BACKGROUND

            return BACKGROUND.style
        return AAE_TRAINING_STYLE

    def scorer(self, views: OODViews, camera, points: np.ndarray, object_diameter: float):
        """``images (V, H, W, 3) -> ADD recall @ 0.1 d`` of this model on ``views``' poses and boxes
        (the model is loaded once)."""
        if self.kind == "aae":
            from paz6d.aae.pipeline import ImplicitPose6D

            estimator = ImplicitPose6D(self.run_dir, camera)

            def aae_recall(images: np.ndarray) -> float | None:
                poses = [estimator(image, box).to_matrix() for image, box in zip(images, views.boxes)]
                return score_poses(poses, views.T_model2cam, points, object_diameter).metrics["recall_0.1d"]

            return aae_recall
        from paz6d.keypointnet.views import TestImages

        def keypointnet_recall(images: np.ndarray) -> float | None:
            test = TestImages(images=images, boxes=views.boxes, T_model2cam=views.T_model2cam, masks=views.masks)
            return evaluate_keypoint_pose(self.run_dir, test, points, object_diameter, camera)[0]["recall_0.1d"]

        return keypointnet_recall


def retention_verdict(in_distribution: float | None, recall: float | None,
                      min_retention: float = MIN_RETENTION) -> dict:
    """``{recall, retention, pass}`` of one condition: ``retention = recall / in_distribution``;
    it passes when ``retention >= min_retention`` (up to :data:`RATIO_TOLERANCE`, so that 0.72 / 0.8
    passes 0.9). An unmeasured recall, or a reference recall of 0 (nothing to retain), gives
    ``retention None`` and fails."""
    in_distribution, recall = finite_or_none(in_distribution), finite_or_none(recall)
    retention = None if in_distribution is None or recall is None or in_distribution <= 0 else recall / in_distribution
    return {"recall": recall, "retention": retention,
            "pass": retention is not None and retention >= min_retention - RATIO_TOLERANCE}


def check_summary(style: str, recalls: dict[str, float | None], min_retention: float = MIN_RETENTION) -> dict:
    """The report of one model (keys in the module doc) from its ``recalls`` per condition
    (:data:`~paz6d.demo.ood_set.CONDITIONS`, the in-distribution one included)."""
    missing = [condition for condition in CONDITIONS if condition not in recalls]
    if missing:
        raise ValueError(f"recalls: expected a recall for every condition {CONDITIONS}, missing {missing}")
    reference = finite_or_none(recalls[IN_DISTRIBUTION])
    conditions = {condition: retention_verdict(reference, recalls[condition], min_retention)
                  for condition in OOD_CONDITIONS}
    retentions = [verdict["retention"] for verdict in conditions.values()]
    return {"in_distribution_style": style, "in_distribution_recall": reference, "conditions": conditions,
            "min_retention": None if None in retentions else min(retentions),
            "min_retention_required": min_retention,
            "pass": all(verdict["pass"] for verdict in conditions.values())}


def evaluate_models(models: list[PoseModel], views: OODViews, camera, points: np.ndarray, object_diameter: float,
                    min_retention: float = MIN_RETENTION, progress: bool = True) -> dict:
    """``{model name: check_summary}`` of every model on every condition of ``views``.

    Args:
        camera: the :class:`~paz6d.backend.camera.Camera` of the views.
        points: ``(P, 3)`` model points in metres; object_diameter: in metres.
    """
    from tqdm.auto import tqdm

    results = {}
    with tqdm(total=len(models) * len(CONDITIONS), desc="OOD check", unit="condition", disable=not progress,
              dynamic_ncols=True) as bar:
        for model in models:
            style, recall = model.training_style(), model.scorer(views, camera, points, object_diameter)
            recalls = {}
            for condition in CONDITIONS:
                bar.set_postfix_str(f"{model.name}, {condition}")
                recalls[condition] = recall(views.images(condition, style))
                bar.update()
            results[model.name] = check_summary(style, recalls, min_retention)
    return results


def check_rows(results: dict) -> list[tuple[str, str]]:
    """Table rows: per model, the in-distribution recall, then each condition's recall, retention and
    verdict, then the model's verdict."""
    rows = []
    for name, result in results.items():
        rows.append((f"{name}: ADD recall, in-distribution ({result['in_distribution_style']})",
                     number(result["in_distribution_recall"], 100, " %")))
        for condition, verdict in result["conditions"].items():
            rows.append((f"  {condition}: recall / retention",
                         f"{number(verdict['recall'], 100, ' %')} / {number(verdict['retention'], 100, ' %')}  "
                         f"{'PASS' if verdict['pass'] else 'FAIL'}"))
        rows.append((f"{name}: OOD check (>= {100 * result['min_retention_required']:.0f} % retained)",
                     "PASS" if result["pass"] else "FAIL"))
    return rows


def plot_check(path: str | Path, results: dict) -> Path:
    """Bar chart: ADD recall per condition for every model, the in-distribution bar first, a dashed
    line at the pass level (``min_retention`` × in-distribution recall) and PASS/FAIL over each OOD bar."""
    figure = new_figure(max(6.0, 1.6 * len(CONDITIONS) * max(1, len(results)) ** 0.5), 4.2, dpi=110)
    axis = figure.add_subplot()
    width = 0.8 / max(1, len(results))
    positions = np.arange(len(CONDITIONS))
    for number_of_model, (name, result) in enumerate(results.items()):
        offsets = positions - 0.4 + width * (number_of_model + 0.5)
        recalls = [result["in_distribution_recall"]] + [result["conditions"][c]["recall"] for c in OOD_CONDITIONS]
        bars = axis.bar(offsets, [0.0 if value is None else value for value in recalls], width, label=name)
        reference = result["in_distribution_recall"]
        if reference is not None:
            axis.hlines(result["min_retention_required"] * reference, offsets[0] - width / 2, offsets[-1] + width / 2,
                        colors=bars.patches[0].get_facecolor(), linestyles="--", linewidth=1)
        for offset, condition in zip(offsets[1:], OOD_CONDITIONS):
            verdict = result["conditions"][condition]
            axis.text(offset, (verdict["recall"] or 0.0) + 0.01, "PASS" if verdict["pass"] else "FAIL",
                      ha="center", va="bottom", fontsize=7, rotation=90)
    axis.set_xticks(positions, CONDITIONS, fontsize=8)
    axis.set_ylim(0, 1.15)
    axis.set_ylabel("ADD recall @ 0.1 d")
    axis.set_title("out-of-distribution check (dashed: pass level, 90 % of in-distribution)"
                   if len(results) else "out-of-distribution check", fontsize=9)
    axis.grid(axis="y", alpha=0.3)
    axis.legend(fontsize=8, loc="upper right")
    figure.tight_layout()
    return save_figure_atomically(figure, path)


def run_check(out: str | Path, mesh_path: str | Path, models: list[PoseModel], count: int = 200,
              mesh_scale: float = 1.0, seed: int = OOD_SEED, workers: int = 2, progress: bool = True) -> dict:
    """Renders ``count`` OOD views of the mesh, scores every model, prints the table and writes
    ``out/ood_check.png``; returns ``{"views", "seed", "conditions", "models": {...}, "seconds", "chart"}``
    (the ``ood_check`` entry of the demo report)."""
    from paz6d.backend.mesh import diameter, load_mesh
    from paz6d.demo.ood_set import render_ood_views
    from paz6d.keypointnet.views import ViewSampling

    if not models:
        raise ValueError("models: expected at least one pose model to check")
    started = time.perf_counter()
    sampling = ViewSampling()
    points = np.asarray(load_mesh(mesh_path, mesh_scale).vertices)
    views = render_ood_views(mesh_path, count, seed, sampling, mesh_scale, workers, progress=progress)
    results = evaluate_models(models, views, sampling.camera, points, diameter(points), progress=progress)
    chart = plot_check(Path(out) / "ood_check.png", results)
    print_rows(check_rows(results))
    return {"views": int(count), "seed": int(seed), "conditions": list(CONDITIONS), "models": results,
            "seconds": round(time.perf_counter() - started, 1), "chart": str(chart)}
