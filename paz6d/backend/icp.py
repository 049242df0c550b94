"""Depth refinement of a pose: ICP (open3d) of an object's depth points onto its model points.

An RGB-only pose is good in the image plane and poor along the viewing ray (its distance comes from the
object's apparent size). :func:`refine_pose_icp` corrects it with a depth image (metres, 0 = no data):

1. **region**: the pixels of ``mask`` (else ``box``) that have depth, back-projected to camera points;
2. **ray shift**: the model points visible under the pose (a point z-buffer) are compared with the depth
   at their pixels; the most common difference (a mode, so the table behind the object and occluders in
   front of it do not pull) moves the pose along the ray through its origin;
3. **gate**: only region points within ``gate × diameter`` of the shifted model are kept;
4. **ICP**: scene points onto the model, point-to-plane (or point-to-point), at the thresholds
   ``scales × diameter`` in turn, each started from the last;
5. **checks**: the fitness (fraction of kept points within ``fitness_distance × diameter`` of the refined
   model's points) and the
   *agreement* (of the refined model's visible points that the depth does not occlude, the fraction whose
   depth matches; a depth seen *behind* the model surface contradicts the pose) must reach their minimums.

A refinement that fails any step returns the input pose with ``accepted=False`` and the reason.
open3d is imported only when a refinement runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from paz6d.backend.camera import project_points, unproject
from paz6d.backend.checks import as_camera_matrix, as_points, check_depth
from paz6d.backend.transform import apply, as_pose_matrix, invert

ICP_METHODS = ("point_to_plane", "point_to_point")
#: The checks a refinement can fail, in the order they run (:attr:`ICPResult.check`).
CHECKS = ("depth_in_region", "depth_near_pose", "points_near_model", "in_front", "fitness", "visible_points",
          "agreement")


@dataclass(frozen=True)
class ICPSettings:
    """Settings of :func:`refine_pose_icp`; lengths are fractions of the object's diameter.

    Attributes:
        method: ``"point_to_plane"`` (model normals estimated by open3d) or ``"point_to_point"``.
        scales: ICP correspondence thresholds, coarse to fine (× diameter).
        max_iterations: ICP iterations per threshold.
        gate: region points farther than this from the ray-shifted model are dropped (× diameter).
        mode_width: half-width of the window in which the ray shift's mode is counted (× diameter).
        max_ray_shift: largest ray shift, as a fraction of the pose's distance ``t_z``.
        agreement_tolerance: a visible model point agrees with the depth within this (× diameter).
        fitness_distance: a kept point fits the refined model within this distance of a model point
            (× diameter; above the spacing of the model points).
        min_points: fewest region points near the model (and visible model points with depth) to refine.
        min_fitness: smallest accepted ICP fitness.
        min_agreement: smallest accepted agreement (see the module docstring).
        max_points: region points kept for ICP (an even subsample above it).
    """

    method: str = "point_to_plane"
    scales: tuple[float, ...] = (0.1, 0.04, 0.02)
    max_iterations: int = 30
    gate: float = 0.2
    mode_width: float = 0.05
    max_ray_shift: float = 0.3
    agreement_tolerance: float = 0.03
    fitness_distance: float = 0.05
    min_points: int = 30
    min_fitness: float = 0.8
    min_agreement: float = 0.8
    max_points: int = 5000

    def __post_init__(self):
        if self.method not in ICP_METHODS:
            raise ValueError(f"method: expected one of {list(ICP_METHODS)}, got {self.method!r}")
        if not self.scales or any(not np.isfinite(s) or s <= 0 for s in self.scales):
            raise ValueError(f"scales: expected positive thresholds (× diameter), got {self.scales}")
        for name in ("gate", "mode_width", "max_ray_shift", "agreement_tolerance", "fitness_distance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name}: expected a positive number, got {value}")
        for name in ("min_fitness", "min_agreement"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}: expected a fraction in [0, 1], got {getattr(self, name)}")
        for name, minimum in (("max_iterations", 1), ("min_points", 3), ("max_points", 10)):
            if int(getattr(self, name)) < minimum:
                raise ValueError(f"{name}: expected an integer >= {minimum}, got {getattr(self, name)}")


@dataclass(frozen=True)
class ICPResult:
    """What :func:`refine_pose_icp` found.

    Attributes:
        T_model2cam: ``(4, 4)`` refined pose (metres), or the input pose when not ``accepted``.
        accepted: every check passed.
        fitness: fraction of the ICP points within ``fitness_distance`` of the refined model (0 when ICP did
            not run).
        rmse: RMS distance of those points to their nearest model point, metres (``inf`` when none).
        agreement: see the module docstring (0 when not measured).
        ray_shift: depth change (metres, along z) of the ray shift before ICP.
        points: region points used by ICP.
        check: the check that rejected it (:data:`CHECKS`; empty when accepted).
        reason: why, in words (empty when accepted).
    """

    T_model2cam: np.ndarray
    accepted: bool
    fitness: float = 0.0
    rmse: float = float("inf")
    agreement: float = 0.0
    ray_shift: float = 0.0
    points: int = 0
    check: str = ""
    reason: str = ""


def region_of(shape: tuple[int, int], box=None, mask=None) -> np.ndarray:
    """``(H, W)`` bool: ``mask`` itself, else the pixels of ``box`` (``(x_min, y_min, x_max, y_max)``, pixel
    ``i`` covers ``[i, i + 1)``, clipped to the image)."""
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != tuple(shape):
            raise ValueError(f"mask: expected shape {tuple(shape)} (the depth image's), got {mask.shape}")
        return mask.astype(bool)
    if box is None:
        raise ValueError("box/mask: expected the object's box or mask (the depth region to use)")
    box = np.asarray(box, dtype=np.float64).reshape(-1)
    if box.shape != (4,) or not np.all(np.isfinite(box)) or box[2] <= box[0] or box[3] <= box[1]:
        raise ValueError(f"box: expected finite (x_min, y_min, x_max, y_max) with positive size, got {box.tolist()}")
    region = np.zeros(shape, dtype=bool)
    x0, y0 = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
    x1, y1 = min(int(np.ceil(box[2])), shape[1]), min(int(np.ceil(box[3])), shape[0])
    region[y0:y1, x0:x1] = True
    return region


def visible_points(points_cam, K, shape: tuple[int, int], tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(M, 2)`` (int ``col, row``) and depths ``(M,)`` of the points ``(N, 3)`` that project into the
    image and lie within ``tolerance`` (metres) of the nearest point at their z-buffer cell.

    The cell side (pixels) is chosen so that about two points fall in each cell of the projected area, so a
    sparse point set still hides the surfaces behind it.
    """
    points_cam = np.asarray(points_cam, dtype=np.float64)
    in_front = points_cam[:, 2] > 0
    pixels = project_points(points_cam[in_front], K)
    depths = points_cam[in_front, 2]
    columns, rows = np.floor(pixels[:, 0] + 0.5).astype(np.int64), np.floor(pixels[:, 1] + 0.5).astype(np.int64)
    inside = (columns >= 0) & (columns < shape[1]) & (rows >= 0) & (rows < shape[0])
    columns, rows, depths = columns[inside], rows[inside], depths[inside]
    if len(depths) == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    area = max(float(np.ptp(columns) + 1) * float(np.ptp(rows) + 1), 1.0)
    cell = max(1, int(np.ceil(np.sqrt(4.0 * area / len(depths)))))
    cell_ids = (rows // cell) * (shape[1] // cell + 1) + columns // cell
    nearest = np.full(int(cell_ids.max()) + 1, np.inf)
    np.minimum.at(nearest, cell_ids, depths)
    keep = depths <= nearest[cell_ids] + tolerance
    return np.stack([columns[keep], rows[keep]], axis=-1), depths[keep]


def _mode(values: np.ndarray, half_width: float) -> float:
    """The mode of ``values``: the mean of the densest window of ``± half_width`` around one of them."""
    ordered = np.sort(values)
    counts = np.searchsorted(ordered, ordered + half_width, "right") - np.searchsorted(ordered, ordered - half_width)
    centre = ordered[int(np.argmax(counts))]
    return float(ordered[np.abs(ordered - centre) <= half_width].mean())


def _depth_differences(T, model_points, depth, K, region, tolerance) -> tuple[np.ndarray, np.ndarray]:
    """Observed minus model depth ``(M,)`` at the visible model points with depth, and whether each lies in
    the region."""
    pixels, depths = visible_points(apply(T, model_points), K, depth.shape, tolerance)
    observed = depth[pixels[:, 1], pixels[:, 0]].astype(np.float64)
    has_depth = observed > 0
    return (observed - depths)[has_depth], region[pixels[:, 1], pixels[:, 0]][has_depth]


def agreement_of(T, model_points, depth, K, tolerance: float) -> tuple[float, int]:
    """``(agreement, count)``: of the model points visible under ``T`` whose pixel has depth and is not
    occluded (depth in front by more than ``tolerance`` metres), the fraction whose depth is within
    ``tolerance``; ``count`` is how many were compared."""
    differences, _ = _depth_differences(T, model_points, depth, K, np.ones(depth.shape, bool), tolerance)
    compared = differences[differences >= -tolerance]
    if len(compared) == 0:
        return 0.0, 0
    return float(np.mean(compared <= tolerance)), len(compared)


def _shift_along_ray(T: np.ndarray, dz: float) -> np.ndarray:
    """``T`` with its translation scaled so that ``t_z`` changes by ``dz`` (the origin stays on its ray)."""
    shifted = T.copy()
    shifted[:3, 3] *= (T[2, 3] + dz) / T[2, 3]
    return shifted


class ICPModel:
    """The model side of the refinement for one object, built once and reused for every pose and image: its
    surface points, diameter, KD-tree and open3d point cloud (normals estimated at the first point-to-plane
    refinement).

    Args:
        model_points: ``(N, 3)`` points on the object's surface, metres, model frame (uniform samples).
        diameter: the object's diameter, metres (the unit of the settings' lengths).
    """

    def __init__(self, model_points, diameter: float):
        self.points = as_points(model_points, "model_points", dimension=3, min_count=10)
        if not np.isfinite(diameter) or diameter <= 0:
            raise ValueError(f"diameter: expected a positive length in metres, got {diameter}")
        self.diameter = float(diameter)

    @cached_property
    def tree(self):
        """``scipy.spatial.cKDTree`` of :attr:`points`."""
        from scipy.spatial import cKDTree  # here: scipy.spatial costs ~0.2 s to import

        return cKDTree(self.points)

    @cached_property
    def _cloud(self):
        import open3d as o3d

        return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points))

    def cloud(self, normals: bool):
        """The open3d point cloud of :attr:`points`, with normals (radius 0.1 diameter) when ``normals``."""
        import open3d as o3d

        if normals and not self._cloud.has_normals():
            self._cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.1 * self.diameter, max_nn=30))
        return self._cloud

    def refine(self, T_model2cam, depth, K, box=None, mask=None, settings: ICPSettings | None = None) -> ICPResult:
        """See :func:`refine_pose_icp`."""
        import open3d as o3d
        from scipy.spatial import cKDTree

        settings = settings or ICPSettings()
        T_input = as_pose_matrix(T_model2cam, "T_model2cam")
        if T_input[2, 3] <= 0:
            raise ValueError(f"T_model2cam: expected the object in front of the camera (t_z > 0), got t_z = "
                             f"{T_input[2, 3]}")
        depth = check_depth(depth)
        K = as_camera_matrix(K)
        model_points, diameter = self.points, self.diameter
        region = region_of(depth.shape, box, mask)

        def rejected(check: str, reason: str, **fields) -> ICPResult:
            return ICPResult(T_input.copy(), False, check=check, reason=reason, **fields)

        rows, columns = np.nonzero(region & (depth > 0))
        if len(rows) < settings.min_points:
            return rejected("depth_in_region", f"{len(rows)} depth pixels in the object's region (at least "
                                               f"{settings.min_points} needed)")
        tolerance = settings.agreement_tolerance * diameter
        differences, in_region = _depth_differences(T_input, model_points, depth, K, region, tolerance)
        limit = settings.max_ray_shift * T_input[2, 3]
        differences = differences[in_region & (np.abs(differences) <= limit)]
        if len(differences) < settings.min_points:
            return rejected("depth_near_pose", f"{len(differences)} visible model points have depth within "
                                               f"{limit:.3f} m of the pose (at least {settings.min_points} needed)")
        ray_shift = _mode(differences, settings.mode_width * diameter)
        T_start = _shift_along_ray(T_input, ray_shift)

        scene = unproject(np.stack([columns, rows], axis=-1).astype(np.float64), depth[rows, columns], K)
        distances, _ = cKDTree(apply(T_start, model_points)).query(scene,
                                                                   distance_upper_bound=settings.gate * diameter)
        scene = scene[np.isfinite(distances)]
        if len(scene) < settings.min_points:
            return rejected("points_near_model", f"{len(scene)} depth points within {settings.gate} diameters of "
                                                 f"the model (at least {settings.min_points} needed)",
                            ray_shift=ray_shift)
        if len(scene) > settings.max_points:
            scene = scene[np.linspace(0, len(scene) - 1, settings.max_points).round().astype(np.int64)]

        source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scene))
        point_to_plane = settings.method == "point_to_plane"
        target = self.cloud(normals=point_to_plane)
        estimation = (o3d.pipelines.registration.TransformationEstimationPointToPlane() if point_to_plane
                      else o3d.pipelines.registration.TransformationEstimationPointToPoint())
        criteria = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=settings.max_iterations)
        T_cam2model = invert(T_start)
        for scale in settings.scales:
            T_cam2model = np.asarray(o3d.pipelines.registration.registration_icp(
                source, target, scale * diameter, T_cam2model, estimation, criteria).transformation)
        T_refined = invert(T_cam2model)
        distances, _ = self.tree.query(apply(T_cam2model, scene),
                                       distance_upper_bound=settings.fitness_distance * diameter)
        inliers = distances[np.isfinite(distances)]
        fitness = len(inliers) / len(scene)
        rmse = float(np.sqrt(np.mean(inliers ** 2))) if len(inliers) else float("inf")
        agreement, compared = agreement_of(T_refined, model_points, depth, K, tolerance)
        fields = dict(fitness=fitness, rmse=rmse, agreement=agreement, ray_shift=ray_shift, points=len(scene))
        if T_refined[2, 3] <= 0:
            return rejected("in_front", "ICP moved the object behind the camera", **fields)
        if fitness < settings.min_fitness:
            return rejected("fitness", f"fitness {fitness:.2f} below {settings.min_fitness}", **fields)
        if compared < settings.min_points:
            return rejected("visible_points", f"{compared} visible model points have depth to compare (at least "
                                              f"{settings.min_points} needed)", **fields)
        if agreement < settings.min_agreement:
            return rejected("agreement", f"agreement {agreement:.2f} below {settings.min_agreement} (the depth "
                                         f"lies behind the refined model's surface)", **fields)
        return ICPResult(T_refined, True, **fields)


def refine_pose_icp(T_model2cam, depth, K, model_points, diameter: float, box=None, mask=None,
                    settings: ICPSettings | None = None) -> ICPResult:
    """Refines a pose with a depth image (see the module docstring for the steps and checks); to refine
    many poses of one object, build its :class:`ICPModel` once and call :meth:`ICPModel.refine`.

    Args:
        T_model2cam: ``(4, 4)`` starting pose, metres (OpenCV camera frame).
        depth: ``(H, W)`` metres, 0 = no data (checked: finite, non-negative).
        K: ``(3, 3)`` intrinsics of the depth image (registered to the RGB image).
        model_points: ``(N, 3)`` points on the object's surface, metres, model frame (uniform samples).
        diameter: the object's diameter, metres (the unit of the settings' lengths).
        box: ``(x_min, y_min, x_max, y_max)`` pixels of the object, used when ``mask`` is ``None``.
        mask: ``(H, W)`` bool region of the object (e.g. its visible mask).
        settings: :class:`ICPSettings` (default: the defaults).
    Returns:
        :class:`ICPResult`; when rejected its ``T_model2cam`` is the input pose.
    """
    return ICPModel(model_points, diameter).refine(T_model2cam, depth, K, box, mask, settings)
