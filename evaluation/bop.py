"""BOP Challenge 2019 evaluation of 6D localization results (average recall of VSD, MSSD, MSPD).

The protocol of the BOP toolkit (``scripts/eval_bop19_pose.py``, ``eval_calc_errors.py``,
``eval_calc_scores.py``, ``pose_matching.py``):

* Targets come from ``test_targets_bop19.json``. For each target ``(scene, image, object)`` only the
  ``inst_count`` estimates with the highest score are evaluated (stable order for equal scores).
* A ground-truth instance counts (is *valid*) when it is one of the ``inst_count`` most visible
  instances of a target (``visib_gt_min = -1``, the default of the toolkit's
  ``eval_bop19_pose.py``), or, with ``visib_gt_min >= 0``, when its object is a target of the image
  and its visible fraction is at least ``visib_gt_min`` (e.g. 0.1).
* For every error type and threshold, estimates are matched greedily in decreasing score to the
  still unmatched valid instance of the same object with the smallest error below the threshold
  (strictly). Recall = matched instances / valid instances.
* Thresholds: MSSD ``< tau * diameter`` and VSD ``< theta`` for tau, theta in {0.05, ..., 0.5} (VSD
  also over its misalignment tolerance tau * diameter in the same set, 100 recalls), MSPD
  ``< tau * 640 / width`` px for tau in {5, ..., 50}. AR of a metric = mean of its recalls;
  AR = mean of AR_VSD, AR_MSSD and AR_MSPD.

Besides the BOP scores: ADD(-S) recall (ADD, or ADI for objects with symmetries, < 0.1 diameter,
same matching) and the YCB-Video AUC of ADD / ADD-S / ADD(-S) over [0, 100] mm. All lengths are
millimetres, as read from the BOP files (``units="mm"``, see :mod:`paz6d.datasets.bop`); the
errors are exact (no BOP "spheres do not overlap -> inf" shortcut).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from evaluation import pose_errors
from evaluation.bop_data import BopEvaluationData
from paz6d.datasets.bop.results import PoseResults
from paz6d.datasets.bop.units import lengths_from_mm, mm_from_lengths

#: Error types with a BOP average recall, then the extra ADD(-S) group.
AR_METRICS = ("vsd", "mssd", "mspd")
METRICS = AR_METRICS + ("add",)
#: Thresholds of correctness for VSD (values) and MSSD (fractions of the diameter); VSD taus.
BOP_FRACTIONS = tuple(np.round(np.arange(0.05, 0.51, 0.05), 2))
#: MSPD thresholds in pixels for a 640 px wide image.
MSPD_PIXELS = tuple(float(value) for value in range(5, 51, 5))
#: Columns of the per-estimate errors (ERRORS.csv) and their units.
ERROR_COLUMNS = ("add", "adi", "mssd", "mspd", "re", "te", "proj")
ERROR_UNITS = {"add": "mm", "adi": "mm", "mssd": "mm", "mspd": "px", "re": "deg", "te": "mm", "proj": "px"}


@dataclass(frozen=True)
class BopSettings:
    """Parameters of the evaluation (BOP'19 defaults).

    Attributes:
        metrics: subset of :data:`METRICS` to compute.
        visib_gt_min: minimum visible fraction of a counted GT instance; -1 (the default, as the
            BOP toolkit's ``eval_bop19_pose.py``): the ``inst_count`` most visible instances of
            each target.
        vsd_delta: VSD visibility tolerance (mm; BOP uses 15 for LM-O and most data sets).
        vsd_taus: VSD misalignment tolerances (fractions of the diameter).
        correct_thresholds: correctness thresholds of VSD (values) and MSSD (fractions of the diameter).
        mspd_thresholds: MSPD thresholds (px at 640 px width).
        add_threshold: ADD(-S) threshold (fraction of the diameter).
        auc_max_threshold: upper end of the ADD/ADD-S accuracy-threshold curve (mm).
        workers: threads for the KD-tree queries of ADI (-1 = all cores).
    """

    metrics: tuple[str, ...] = METRICS
    visib_gt_min: float = -1.0
    vsd_delta: float = 15.0
    vsd_taus: tuple[float, ...] = BOP_FRACTIONS
    correct_thresholds: tuple[float, ...] = BOP_FRACTIONS
    mspd_thresholds: tuple[float, ...] = MSPD_PIXELS
    add_threshold: float = 0.1
    auc_max_threshold: float = 100.0
    workers: int = 1

    def __post_init__(self):
        unknown = sorted(set(self.metrics) - set(METRICS))
        if unknown or not self.metrics:
            raise ValueError(f"metrics: expected a non-empty subset of {list(METRICS)}, got {list(self.metrics)}")
        if not (self.visib_gt_min == -1 or 0 <= self.visib_gt_min <= 1):
            raise ValueError(f"visib_gt_min: expected a fraction in [0, 1] or -1, got {self.visib_gt_min}")
        for name in ("vsd_delta", "add_threshold", "auc_max_threshold"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected a positive value, got {getattr(self, name)}")
        if not (self.workers == -1 or self.workers >= 1):
            raise ValueError(f"workers: expected -1 (all cores) or a positive thread count, got {self.workers}")
        for name in ("vsd_taus", "correct_thresholds", "mspd_thresholds"):
            values = np.asarray(getattr(self, name), dtype=np.float64)
            if values.ndim != 1 or values.size == 0 or np.any(values <= 0):
                raise ValueError(f"{name}: expected a non-empty list of positive thresholds")


@dataclass
class EvaluationPairs:
    """Every (evaluated estimate, valid GT instance of the same object and image) pair.

    Attributes:
        estimate: ``(P,)`` row of the estimate in the results.
        gt: ``(P,)`` index of the instance in :attr:`BopEvaluation.gt_obj_ids` etc.
        group: ``(P,)`` target ``(scene, image, object)`` the pair belongs to.
        rank: ``(P,)`` position of the estimate in its target's score order (0 = best).
        errors: ``{name: (P,)}`` errors (see :data:`ERROR_UNITS`), ``"vsd": (P, T)`` per tau.
    """

    estimate: np.ndarray
    gt: np.ndarray
    group: np.ndarray
    rank: np.ndarray
    errors: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.estimate)


@dataclass
class MetricRecalls:
    """Recalls of one error type at each threshold column.

    Attributes:
        thresholds: ``(C,)`` threshold of each column (VSD: ``(taus x thetas)`` flattened, tau major).
        recalls: ``(C,)`` recall over all valid GT instances.
        object_recalls: ``{obj_id: (C,)}`` recall over the instances of each object.
    """

    thresholds: np.ndarray
    recalls: np.ndarray
    object_recalls: dict[int, np.ndarray]

    @property
    def average(self) -> float:
        return float(np.mean(self.recalls))

    def object_averages(self) -> dict[int, float]:
        return {obj_id: float(np.mean(values)) for obj_id, values in self.object_recalls.items()}


@dataclass
class BopEvaluation:
    """Everything :func:`evaluate` computed.

    Attributes:
        settings: the parameters used.
        gt_keys: ``(G, 3)`` ``(scene_id, im_id, gt index in scene_gt)`` of each valid instance.
        gt_obj_ids: ``(G,)`` object of each valid instance.
        pairs: the evaluated pairs and their errors.
        report_pairs: ``(R,)`` pair indices pairing each evaluated estimate with one instance
            (greedy by score, nearest translation, no threshold): the rows of ERRORS.csv and the
            assignment behind the ADD/ADD-S AUCs.
        metrics: ``{name: MetricRecalls}`` for the computed ``vsd``/``mssd``/``mspd``/``add``.
        aucs: ``{"ADD": ..., "ADD-S": ..., "ADD(-S)": ...}`` AUCs in [0, 1] (with ``add``).
        auc_errors: ``{name: (G,)}`` error behind each AUC per valid instance (inf = missed).
        counts: numbers of targets, instances and estimates.
        skipped_metrics: ``{name: reason}`` for metrics left out.
    """

    settings: BopSettings
    gt_keys: np.ndarray
    gt_obj_ids: np.ndarray
    pairs: EvaluationPairs
    report_pairs: np.ndarray
    metrics: dict[str, MetricRecalls]
    aucs: dict[str, float]
    auc_errors: dict[str, np.ndarray]
    counts: dict[str, int]
    skipped_metrics: dict[str, str] = field(default_factory=dict)

    @property
    def average_recalls(self) -> dict[str, float]:
        """``{"AR_VSD": ..., "AR_MSSD": ..., "AR_MSPD": ...}`` for the computed ones, plus ``"AR"``
        (their mean) when all three were computed."""
        values = {f"AR_{name.upper()}": self.metrics[name].average for name in AR_METRICS if name in self.metrics}
        if len(values) == len(AR_METRICS):
            values["AR"] = float(np.mean(list(values.values())))
        return values

    @property
    def add_recall(self) -> float | None:
        """ADD(-S) < ``add_threshold`` * diameter recall (``None`` when ``add`` was not computed)."""
        return self.metrics["add"].average if "add" in self.metrics else None

    def to_dict(self) -> dict:
        """JSON-safe summary: ARs, ADD(-S) recall, AUCs, per-object recalls, curves and counts."""
        objects = {}
        for obj_id in sorted(set(self.gt_obj_ids.tolist())):
            entry = {"instances": int(np.count_nonzero(self.gt_obj_ids == obj_id))}
            for name, metric in self.metrics.items():
                key = "ADD(-S)_recall" if name == "add" else f"AR_{name.upper()}"
                entry[key] = metric.object_averages().get(obj_id)
            objects[str(obj_id)] = entry
        summary = dict(self.average_recalls)
        if "add" in self.metrics:
            summary["ADD(-S)_recall"] = self.add_recall
            summary.update({f"AUC_{name}": value for name, value in self.aucs.items()})
        curves = {name: {"thresholds": metric.thresholds.tolist(), "recalls": metric.recalls.tolist()}
                  for name, metric in self.metrics.items()}
        settings = self.settings
        return {**summary,
                "per_object": objects,
                "recall_curves": curves,
                "counts": dict(self.counts),
                "skipped_metrics": dict(self.skipped_metrics),
                "settings": {"metrics": list(settings.metrics), "visib_gt_min": settings.visib_gt_min,
                             "vsd_delta_mm": settings.vsd_delta, "vsd_taus": list(settings.vsd_taus),
                             "correct_thresholds": list(settings.correct_thresholds),
                             "mspd_thresholds_px_at_640": list(settings.mspd_thresholds),
                             "add_threshold": settings.add_threshold,
                             "auc_max_threshold_mm": settings.auc_max_threshold},
                "units": {"errors": ERROR_UNITS, "lengths": "mm"}}

    def error_rows(self) -> list[dict]:
        """One dict per reported pair: ``scene_id, im_id, obj_id, score`` and the errors
        (:data:`ERROR_COLUMNS`, ``None`` when not computed), ordered by scene, image, object, rank."""
        rows = []
        for pair in self.report_pairs:
            scene_id, im_id, _ = self.gt_keys[self.pairs.gt[pair]]
            row = {"scene_id": int(scene_id), "im_id": int(im_id), "obj_id": int(self.gt_obj_ids[self.pairs.gt[pair]]),
                   "estimate": int(self.pairs.estimate[pair])}
            for name in ERROR_COLUMNS:
                values = self.pairs.errors.get(name)
                row[name] = None if values is None else float(values[pair])
            rows.append(row)
        return rows


def valid_ground_truth(data: BopEvaluationData, visib_gt_min: float) -> tuple[np.ndarray, np.ndarray]:
    """The GT instances that count: ``(G, 3)`` keys ``(scene_id, im_id, gt index)`` and ``(G,)`` objects.

    With ``visib_gt_min >= 0`` an instance counts when its object is a target of the image and
    ``visib_fract >= visib_gt_min``; with -1, the ``inst_count`` most visible instances of each
    target count (BOP toolkit's rule, stable order for equal fractions).
    """
    targets: dict[tuple[int, int], dict[int, int]] = {}
    for target in data.targets:
        targets.setdefault((target.scene_id, target.im_id), {})[target.obj_id] = target.inst_count
    keys, objects = [], []
    for (scene_id, im_id), image_targets in sorted(targets.items()):
        image = data.images[(scene_id, im_id)]
        if visib_gt_min >= 0:
            chosen = [index for index, obj_id in enumerate(image.obj_ids)
                      if int(obj_id) in image_targets and image.visib_fract[index] >= visib_gt_min]
        else:
            remaining = dict(image_targets)
            chosen = []
            for index in np.argsort(-image.visib_fract, kind="stable"):
                obj_id = int(image.obj_ids[index])
                if remaining.get(obj_id, 0) > 0:
                    chosen.append(int(index))
                    remaining[obj_id] -= 1
            chosen.sort()
        for index in chosen:
            keys.append((scene_id, im_id, index))
            objects.append(int(image.obj_ids[index]))
    return np.array(keys, dtype=np.int64).reshape(-1, 3), np.array(objects, dtype=np.int64)


def select_estimates(data: BopEvaluationData, results: PoseResults) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The estimates BOP evaluates: per target the ``inst_count`` highest scores (stable).

    Returns:
        ``(estimates, targets, ranks)``: ``(S,)`` result rows, ``(S,)`` index of their target in
        ``data.targets`` and ``(S,)`` position in the target's score order.
    """
    by_key: dict[tuple[int, int, int], list[int]] = {}
    for row, key in enumerate(zip(results.scene_ids.tolist(), results.im_ids.tolist(), results.obj_ids.tolist())):
        by_key.setdefault(key, []).append(row)
    estimates, owners, ranks = [], [], []
    for target_index, target in enumerate(data.targets):
        rows = np.array(by_key.get((target.scene_id, target.im_id, target.obj_id), []), dtype=np.int64)
        if rows.size == 0:
            continue
        order = rows[np.argsort(-results.scores[rows], kind="stable")][:target.inst_count]
        estimates.extend(order.tolist())
        owners.extend([target_index] * len(order))
        ranks.extend(range(len(order)))
    return (np.array(estimates, dtype=np.int64), np.array(owners, dtype=np.int64), np.array(ranks, dtype=np.int64))


def build_pairs(data: BopEvaluationData, results: PoseResults, gt_keys: np.ndarray,
                gt_obj_ids: np.ndarray) -> EvaluationPairs:
    """Pairs every evaluated estimate with every valid instance of its object in its image,
    sorted by target, then estimate rank, then GT index (the order of greedy matching)."""
    estimates, owners, ranks = select_estimates(data, results)
    instances: dict[tuple[int, int, int], list[int]] = {}
    for gt, (scene_id, im_id, _) in enumerate(gt_keys.tolist()):
        instances.setdefault((scene_id, im_id, int(gt_obj_ids[gt])), []).append(gt)
    pair_estimates, pair_gts, pair_groups, pair_ranks = [], [], [], []
    for estimate, owner, rank in zip(estimates.tolist(), owners.tolist(), ranks.tolist()):
        target = data.targets[owner]
        for gt in instances.get((target.scene_id, target.im_id, target.obj_id), []):
            pair_estimates.append(estimate)
            pair_gts.append(gt)
            pair_groups.append(owner)
            pair_ranks.append(rank)
    pairs = EvaluationPairs(np.array(pair_estimates, dtype=np.int64), np.array(pair_gts, dtype=np.int64),
                            np.array(pair_groups, dtype=np.int64), np.array(pair_ranks, dtype=np.int64))
    order = np.lexsort((pairs.gt, pairs.rank, pairs.group))
    return EvaluationPairs(pairs.estimate[order], pairs.gt[order], pairs.group[order], pairs.rank[order])


def greedy_match(pairs: EvaluationPairs, errors: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """BOP's greedy matching, for several threshold columns at once.

    In each target group, estimates are taken in rank order; each is matched to the still
    unmatched instance with the smallest error strictly below the column's threshold (the first
    one in GT order among equal errors).

    Args:
        pairs: pairs sorted by group, rank and GT (as :func:`build_pairs` returns them).
        errors: ``(P, C)`` error of each pair in each column (or ``(P,)`` for every column).
        thresholds: ``(C,)`` threshold of each column.

    Returns:
        ``(P, C)`` bool: the pair is a match in that column.
    """
    thresholds = np.asarray(thresholds, dtype=np.float64).ravel()
    errors = np.asarray(errors, dtype=np.float64)
    errors = errors[:, None] if errors.ndim == 1 else errors  # (P,): the same errors in every column
    errors = np.broadcast_to(errors, (len(errors), len(thresholds)))
    below = errors < thresholds
    matched = np.zeros_like(below)
    if len(pairs) == 0:
        return matched
    starts = np.flatnonzero(np.r_[True, pairs.group[1:] != pairs.group[:-1]])
    ends = np.r_[starts[1:], len(pairs)]
    single = (ends - starts) == 1
    matched[starts[single]] = below[starts[single]]
    for start, end in zip(starts[~single], ends[~single]):
        gts = pairs.gt[start:end]
        local_gt = np.unique(gts, return_inverse=True)[1]
        taken = np.zeros((len(thresholds), local_gt.max() + 1), dtype=bool)
        ranks = pairs.rank[start:end]
        boundaries = np.flatnonzero(np.r_[True, ranks[1:] != ranks[:-1], True])
        columns = np.arange(len(thresholds))
        for first, last in zip(boundaries[:-1], boundaries[1:]):
            rows = np.arange(start + first, start + last)
            candidates = below[rows].T & ~taken[:, local_gt[first:last]]
            masked = np.where(candidates, errors[rows].T, np.inf)
            best = np.argmin(masked, axis=1)
            hit = candidates[columns, best]
            matched[rows[best[hit]], columns[hit]] = True
            taken[columns[hit], local_gt[first:last][best[hit]]] = True
    return matched


def _recalls(matched: np.ndarray, pairs: EvaluationPairs, gt_obj_ids: np.ndarray,
             thresholds: np.ndarray) -> MetricRecalls:
    counts = np.bincount(gt_obj_ids, minlength=1) if len(gt_obj_ids) else np.zeros(1)
    total = len(gt_obj_ids)
    recalls = matched.sum(axis=0) / total if total else np.zeros(matched.shape[1])
    matched_objects = gt_obj_ids[pairs.gt] if len(pairs) else np.zeros(0, dtype=np.int64)
    object_recalls = {}
    for obj_id in np.unique(gt_obj_ids):
        rows = matched_objects == obj_id
        object_recalls[int(obj_id)] = matched[rows].sum(axis=0) / counts[obj_id]
    return MetricRecalls(np.asarray(thresholds, dtype=np.float64), np.asarray(recalls, dtype=np.float64),
                         object_recalls)


def report_pairing(pairs: EvaluationPairs) -> np.ndarray:
    """Pairs each evaluated estimate with one instance: greedy by score, smallest translation
    error, no threshold. Returns the chosen pair indices (sorted)."""
    chosen = greedy_match(pairs, pairs.errors["te"], np.array([np.inf]))[:, 0]
    return np.flatnonzero(chosen)


def _pose_arrays(data: BopEvaluationData, results: PoseResults, pairs: EvaluationPairs, gt_keys: np.ndarray,
                 rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    T_est = results.T_model2cam[pairs.estimate[rows]]
    T_gt = np.empty((len(rows), 4, 4))
    K = np.empty((len(rows), 3, 3))
    for out, gt in enumerate(pairs.gt[rows]):
        scene_id, im_id, index = gt_keys[gt]
        image = data.images[(int(scene_id), int(im_id))]
        T_gt[out] = image.T_model2cam[index]
        K[out] = image.K
    return T_est, T_gt, K


def compute_errors(data: BopEvaluationData, results: PoseResults, pairs: EvaluationPairs, gt_keys: np.ndarray,
                   gt_obj_ids: np.ndarray, settings: BopSettings, renderer=None, progress: bool = False) -> None:
    """Fills ``pairs.errors`` with the errors the settings' metrics need (mm, px, deg).

    ``re``, ``te`` and ``proj`` are always computed (they are cheap); ``add`` gives ``add`` and
    ``adi``; ``vsd`` renders depth with ``renderer`` (a :class:`renderers.Renderer` of the data
    set's image size, created when ``None``).
    """
    count = len(pairs)
    errors = {name: np.full(count, np.nan) for name in ("re", "te", "proj")}
    metrics = set(settings.metrics)
    for name in ("mssd", "mspd"):
        if name in metrics:
            errors[name] = np.full(count, np.nan)
    if "add" in metrics:
        errors["add"] = np.full(count, np.nan)
        errors["adi"] = np.full(count, np.nan)
    objects = gt_obj_ids[pairs.gt] if count else np.zeros(0, dtype=np.int64)
    for obj_id in tqdm(np.unique(objects).tolist(), desc="pose errors", unit="object", disable=not progress):
        rows = np.flatnonzero(objects == obj_id)
        model = data.object_model(obj_id)
        T_est, T_gt, K = _pose_arrays(data, results, pairs, gt_keys, rows)
        errors["re"][rows] = pose_errors.rotation_error_deg(T_est[:, :3, :3], T_gt[:, :3, :3])
        errors["te"][rows] = pose_errors.translation_error(T_est[:, :3, 3], T_gt[:, :3, 3])
        errors["proj"][rows] = pose_errors.projection_error(T_est, T_gt, model.points, K)
        if "mssd" in metrics:
            errors["mssd"][rows] = pose_errors.mssd_error(T_est, T_gt, model.points, model.symmetries)
        if "mspd" in metrics:
            errors["mspd"][rows] = pose_errors.mspd_error(T_est, T_gt, model.points, K, model.symmetries)
        if "add" in metrics:
            errors["add"][rows] = pose_errors.add_error(T_est, T_gt, model.points)
            errors["adi"][rows] = pose_errors.adi_error(T_est, T_gt, model.points, tree=model.tree,
                                                        workers=settings.workers)
    if "vsd" in metrics:
        errors["vsd"] = _vsd_errors(data, results, pairs, gt_keys, gt_obj_ids, settings, renderer, progress)
    pairs.errors = errors


def _render_depth_mm(renderer, data: BopEvaluationData, obj_id: int, T_mm: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Rendered depth (mm) of the error mesh; a rounded (not exactly orthonormal) rotation, as BOP
    ground truth stores them, is rendered with its nearest rotation (the renderer needs a rigid pose).
    The renderer works in metres: the pose and the depth cross units here, through the BOP unit converters."""
    T = T_mm.copy()
    T[:3, 3] = lengths_from_mm(T[:3, 3], "m")
    if np.abs(T[:3, :3].T @ T[:3, :3] - np.eye(3)).max() > 1e-9:
        left, _, right = np.linalg.svd(T[:3, :3])
        T[:3, :3] = left @ right
    depth = renderer.render(K, [(data.render_mesh(obj_id), T)], rgb=False, masks=False).depth
    return mm_from_lengths(depth, "m")


def _vsd_errors(data: BopEvaluationData, results: PoseResults, pairs: EvaluationPairs, gt_keys: np.ndarray,
                gt_obj_ids: np.ndarray, settings: BopSettings, renderer, progress: bool) -> np.ndarray:
    """``(P, T)`` VSD of each pair for each tau; each estimate and instance is rendered once."""
    taus = np.asarray(settings.vsd_taus, dtype=np.float64)
    errors = np.full((len(pairs), len(taus)), np.nan)
    own_renderer = renderer is None
    if own_renderer:
        from renderers import Renderer

        renderer = Renderer(data.width, data.height, antialias="none")
    try:
        images = gt_keys[pairs.gt, :2] if len(pairs) else np.zeros((0, 2), dtype=np.int64)
        keys = np.unique(images, axis=0)
        for scene_id, im_id in tqdm(keys.tolist(), desc="VSD", unit="image", disable=not progress):
            rows = np.flatnonzero((images[:, 0] == scene_id) & (images[:, 1] == im_id))
            image = data.images[(scene_id, im_id)]
            depth_test = data.read_depth(scene_id, im_id)
            est_depths, gt_depths = {}, {}
            for row in rows:
                estimate, gt = int(pairs.estimate[row]), int(pairs.gt[row])
                obj_id = int(gt_obj_ids[gt])
                if estimate not in est_depths:
                    est_depths[estimate] = _render_depth_mm(renderer, data, obj_id, results.T_model2cam[estimate],
                                                            image.K)
                if gt not in gt_depths:
                    gt_depths[gt] = _render_depth_mm(renderer, data, obj_id, image.T_model2cam[gt_keys[gt, 2]], image.K)
                errors[row] = pose_errors.vsd_error(depth_test, est_depths[estimate], gt_depths[gt], image.K,
                                                    settings.vsd_delta, taus, data.diameters[obj_id])
    finally:
        if own_renderer:
            renderer.close()
    return errors


def _metric_columns(name: str, settings: BopSettings, pairs: EvaluationPairs, data: BopEvaluationData,
                    gt_obj_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P, C)`` normalized errors and ``(C,)`` thresholds of one metric."""
    objects = gt_obj_ids[pairs.gt] if len(pairs) else np.zeros(0, dtype=np.int64)
    diameters = np.array([data.diameters[int(obj_id)] for obj_id in objects])
    if name == "vsd":
        taus = len(settings.vsd_taus)
        thetas = np.asarray(settings.correct_thresholds, dtype=np.float64)
        errors = np.repeat(pairs.errors["vsd"].reshape(len(pairs), taus), len(thetas), axis=1)
        return errors, np.tile(thetas, taus)
    if name == "mssd":
        return pairs.errors["mssd"] / diameters, np.asarray(settings.correct_thresholds, dtype=np.float64)
    if name == "mspd":
        return pairs.errors["mspd"] * (640.0 / data.width), np.asarray(settings.mspd_thresholds, dtype=np.float64)
    symmetric = np.array([data.object_model(int(obj_id)).is_symmetric for obj_id in objects], dtype=bool)
    errors = np.where(symmetric, pairs.errors["adi"], pairs.errors["add"]) if len(pairs) else np.zeros(0)
    return errors / diameters, np.array([settings.add_threshold])


def evaluate(data: BopEvaluationData, results: PoseResults, settings: BopSettings = BopSettings(),
             renderer=None, progress: bool = False) -> BopEvaluation:
    """Scores ``results`` on ``data`` with the BOP'19 protocol (see the module docstring).

    Args:
        data: ground truth, targets and models (:func:`evaluation.bop_data.load_evaluation_data`).
        results: estimates in millimetres (:func:`paz6d.datasets.bop.read_pose_results` with
            ``units="mm"``).
        settings: metrics and thresholds.
        renderer: depth renderer for VSD (created and closed here when ``None``).
        progress: show tqdm progress bars.

    Raises:
        ValueError: ``results`` were read in metres.
    """
    if results.units != "mm":
        raise ValueError(f"results: expected translations in millimetres (read_pose_results(..., units='mm')), "
                         f"got units={results.units!r}")
    gt_keys, gt_obj_ids = valid_ground_truth(data, settings.visib_gt_min)
    pairs = build_pairs(data, results, gt_keys, gt_obj_ids)
    compute_errors(data, results, pairs, gt_keys, gt_obj_ids, settings, renderer, progress)
    metrics = {}
    for name in settings.metrics:
        errors, thresholds = _metric_columns(name, settings, pairs, data, gt_obj_ids)
        matched = greedy_match(pairs, errors, thresholds)
        metrics[name] = _recalls(matched, pairs, gt_obj_ids, thresholds)
    report = report_pairing(pairs)
    aucs, auc_errors = {}, {}
    if "add" in settings.metrics:
        symmetric = np.array([data.object_model(int(obj_id)).is_symmetric for obj_id in gt_obj_ids], dtype=bool)
        for label, source in (("ADD", "add"), ("ADD-S", "adi"), ("ADD(-S)", None)):
            per_gt = np.full(len(gt_obj_ids), np.inf)
            if source is None:
                per_gt = np.where(symmetric, auc_errors["ADD-S"], auc_errors["ADD"])
            else:
                per_gt[pairs.gt[report]] = pairs.errors[source][report]
            auc_errors[label] = per_gt
            aucs[label] = pose_errors.accuracy_auc(per_gt, settings.auc_max_threshold)
    paired = int(np.unique(pairs.estimate).size)
    counts = {"targets": len(data.targets), "gt_instances": len(gt_obj_ids), "estimates_read": len(results),
              "estimates_skipped_invalid": len(results.skipped), "estimates_paired": paired,
              "estimates_not_evaluated": len(results) - paired, "pairs": len(pairs)}
    return BopEvaluation(settings, gt_keys, gt_obj_ids, pairs, report, metrics, aucs, auc_errors, counts)
