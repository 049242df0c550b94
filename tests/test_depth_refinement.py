"""Depth refinement (ICP, open3d): a known perturbation of a pose is undone against a ray-cast depth image,
depth that does not show the object is refused (the input pose kept), bad depth images fail clearly, and
`paz6d estimate --depth` reads BOP depth files (millimetres) and refines the poses end to end.

Depth images are ray-cast with open3d's RaycastingScene (no GL) from the demo object (an asymmetric composite of
boxes and a cylinder), standing in front of a table plane.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Pose6D
from paz6d.assets.demo_object import make_demo_mesh
from paz6d.backend.camera import Camera, project_points
from paz6d.backend.checks import check_depth
from paz6d.backend.icp import ICPSettings, agreement_of, refine_pose_icp
from paz6d.backend.mesh import diameter, sample_points
from paz6d.processors.refine import RefineWithDepth

K = np.array([[500.0, 0.0, 159.5], [0.0, 500.0, 119.5], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 320, 240


def raycast_depth(meshes_and_poses, K, width: int, height: int) -> np.ndarray:
    """``(H, W)`` float32 z-depth (metres, 0 = no hit) of trimesh meshes posed by ``T_model2cam``, one ray per
    pixel centre (OpenCV camera)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    for mesh, T in meshes_and_poses:
        vertices = (np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
        scene.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    columns, rows = np.meshgrid(np.arange(width), np.arange(height))
    directions = np.stack([(columns - K[0, 2]) / K[0, 0], (rows - K[1, 2]) / K[1, 1], np.ones((height, width))], -1)
    rays = np.concatenate([np.zeros_like(directions), directions], axis=-1).astype(np.float32)
    hits = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # in units of the direction, whose z is 1
    return np.where(np.isfinite(hits), hits, 0.0).astype(np.float32)


def translated(mesh, offset):
    T = np.eye(4)
    T[:3, 3] = offset
    return mesh, T


@pytest.fixture(scope="module")
def scene():
    """The demo object 0.6 m away, a table 10 cm behind it and a plate occluding part of it."""
    import trimesh

    mesh = make_demo_mesh()
    T_true = np.eye(4)
    T_true[:3, :3] = Rotation.from_rotvec([0.5, -0.4, 0.9]).as_matrix()
    T_true[:3, 3] = [0.01, -0.02, 0.6]
    table = translated(trimesh.creation.box((1.0, 1.0, 0.01)), [0.0, 0.0, 0.7])
    plate = translated(trimesh.creation.box((0.03, 0.2, 0.005)), [0.03, -0.02, 0.5])  # 10 cm in front
    points = sample_points(mesh, 2000, seed=0)
    pixels = project_points(points @ T_true[:3, :3].T + T_true[:3, 3], K)
    box = np.concatenate([pixels.min(axis=0), pixels.max(axis=0) + 1.0])
    return {"mesh": mesh, "T": T_true, "points": points, "diameter": diameter(np.asarray(mesh.vertices)),
            "box": box, "depth": raycast_depth([(mesh, T_true), table], K, WIDTH, HEIGHT),
            "occluded": raycast_depth([(mesh, T_true), table, plate], K, WIDTH, HEIGHT),
            "table": table}


def perturbed(T, rotation_vector, offset) -> np.ndarray:
    result = T.copy()
    result[:3, :3] = Rotation.from_rotvec(rotation_vector).as_matrix() @ T[:3, :3]
    result[:3, 3] += offset
    return result


def errors(T, T_true) -> tuple[float, float]:
    """(rotation error in degrees, translation error in metres)."""
    angle = np.degrees(Rotation.from_matrix(T[:3, :3].T @ T_true[:3, :3]).magnitude())
    return float(angle), float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


@pytest.mark.parametrize("rotation_vector, offset", [
    ([0.0, 0.0, 0.0], [0.004, -0.003, 0.05]),      # translation only: the depth error of an RGB pose (5 cm)
    ([0.0, 0.0, 0.0], [0.0, 0.0, -0.08]),           # 8 cm too near
    ([0.07, -0.05, 0.05], [0.004, 0.003, -0.03]),   # about 5 degrees and 3 cm
])
@pytest.mark.parametrize("depth_key", ["depth", "occluded"])
def test_icp_undoes_a_known_perturbation(scene, rotation_vector, offset, depth_key):
    start = perturbed(scene["T"], rotation_vector, offset)
    result = refine_pose_icp(start, scene[depth_key], K, scene["points"], scene["diameter"], box=scene["box"])
    assert result.accepted, result.reason
    angle, distance = errors(result.T_model2cam, scene["T"])
    assert angle < 0.5 and distance < 0.001, (angle, distance)
    assert abs(result.ray_shift + offset[2]) < 0.01  # the shift along the ray removed the depth error first
    assert result.fitness >= 0.5 and result.agreement >= 0.9 and result.rmse < 0.003
    before = errors(start, scene["T"])
    assert before[1] > 0.02


def test_point_to_point_icp_and_a_mask_region(scene):
    start = perturbed(scene["T"], [0.03, 0.02, -0.04], [0.002, 0.0, 0.04])
    mask = (scene["depth"] > 0) & (scene["depth"] < 0.66)  # the object's pixels (the table is at 0.695 m)
    result = refine_pose_icp(start, scene["depth"], K, scene["points"], scene["diameter"], mask=mask,
                             settings=ICPSettings(method="point_to_point", scales=(0.1, 0.04, 0.02, 0.01),
                                                  max_iterations=60))
    assert result.accepted, result.reason
    angle, distance = errors(result.T_model2cam, scene["T"])
    assert angle < 1.0 and distance < 0.002, (angle, distance)


def test_depth_without_the_object_is_refused_and_the_input_pose_kept(scene):
    start = perturbed(scene["T"], [0.02, 0.0, 0.0], [0.0, 0.0, 0.03])
    wall = raycast_depth([translated(scene["table"][0], [0.0, 0.0, 0.63])], K, WIDTH, HEIGHT)  # a wall, no object
    noise = np.random.default_rng(0).uniform(0.3, 1.2, (HEIGHT, WIDTH)).astype(np.float32)
    far = raycast_depth([translated(scene["mesh"], [0.0, 0.0, 2.0])], K, WIDTH, HEIGHT)  # the object, 1.4 m away
    for name, depth, check in (("empty", np.zeros((HEIGHT, WIDTH), np.float32), "depth_in_region"),
                               ("wall", wall, "fitness"), ("noise", noise, "fitness"), ("far", far, "depth_near_pose")):
        result = refine_pose_icp(start, depth, K, scene["points"], scene["diameter"], box=scene["box"])
        assert not result.accepted and result.check == check, (name, result.reason)
        assert np.array_equal(result.T_model2cam, start), name


def test_agreement_counts_depth_seen_behind_the_model_as_a_contradiction_and_ignores_occlusion(scene):
    tolerance = 0.03 * scene["diameter"]
    agreement, compared = agreement_of(scene["T"], scene["points"], scene["depth"], K, tolerance)
    assert agreement > 0.9 and compared > 300
    nearer = perturbed(scene["T"], [0.0, 0.0, 0.0], [0.0, 0.0, -0.03])  # in front of what the depth shows
    assert agreement_of(nearer, scene["points"], scene["depth"], K, tolerance)[0] < 0.1
    farther = perturbed(scene["T"], [0.0, 0.0, 0.0], [0.0, 0.0, 0.2])  # behind the table: all of it occluded
    assert agreement_of(farther, scene["points"], scene["depth"], K, tolerance)[1] == 0
    occluded_agreement, occluded_compared = agreement_of(scene["T"], scene["points"], scene["occluded"], K, tolerance)
    assert occluded_agreement > 0.9 and occluded_compared < compared  # the plate hides points, contradicts none


def test_refine_step_picks_the_accepted_candidate_and_counts_its_work(scene):
    step = RefineWithDepth(lambda: scene["points"])  # points loaded lazily, diameter computed from them
    camera = Camera(K, WIDTH, HEIGHT)
    good = Pose6D.from_matrix(perturbed(scene["T"], [0.0, 0.0, 0.0], [0.0, 0.0, 0.04]), "obj", 0.7)
    wrong = Pose6D.from_matrix(perturbed(scene["T"], [0.0, 0.0, 0.0], [0.25, 0.0, 0.0]), "obj", 0.9)
    assert step([wrong, good], None, scene["box"], camera) is wrong  # no depth: the first candidate as it is
    refined = step([wrong, good], scene["depth"], Box2D(*scene["box"]), camera)
    assert errors(refined.to_matrix(), scene["T"])[1] < 0.001 and refined.score == 0.7
    assert step.statistics["refinements"] == 2 and step.statistics["accepted"] == 1
    assert sum(step.statistics["rejected"].values()) == 1 and step.statistics["seconds"] > 0
    assert abs(step.diameter - scene["diameter"]) < 0.01
    kept = step(wrong, np.zeros((HEIGHT, WIDTH), np.float32), scene["box"], camera)
    assert kept == wrong  # refused: the input pose itself
    model = step.icp_model  # the object's KD-tree and point cloud (with normals) are built once, then reused
    assert model.cloud(normals=True).has_normals() and model.tree.n == len(scene["points"])
    step([wrong, good], scene["depth"], scene["box"], camera)
    assert step.icp_model is model and step.statistics["refinements"] == 5


def test_bad_depth_images_raise_clear_errors(scene):
    step = RefineWithDepth(scene["points"], scene["diameter"])
    camera, pose = Camera(K, WIDTH, HEIGHT), Pose6D.from_matrix(scene["T"])
    with pytest.raises(ValueError, match=r"depth: depth image is 160x120 pixels, expected 320x240"):
        step(pose, scene["depth"][::2, ::2], scene["box"], camera)
    with pytest.raises(ValueError, match=r"depth: 1 NaN or infinite depth values"):
        step(pose, _with_nan(scene["depth"]), scene["box"], camera)
    with pytest.raises(ValueError, match=r"scene_0001.png: negative depth values"):
        check_depth(-scene["depth"], "scene_0001.png")
    with pytest.raises(ValueError, match=r"depth: expected a depth image of shape \(H, W\)"):
        check_depth(np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match="box/mask"):
        refine_pose_icp(scene["T"], scene["depth"], K, scene["points"], scene["diameter"])
    with pytest.raises(ValueError, match="method"):
        ICPSettings(method="plane")
    with pytest.raises(ValueError, match=r"t_z > 0"):
        refine_pose_icp(perturbed(scene["T"], [0, 0, 0], [0, 0, -1.0]), scene["depth"], K, scene["points"],
                        scene["diameter"], box=scene["box"])


def _with_nan(depth: np.ndarray) -> np.ndarray:
    result = depth.copy()
    result[10, 20] = np.nan
    return result
