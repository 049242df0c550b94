"""`paz6d estimate --depth` end to end on a tiny generated BOP set: the depth PNGs (millimetres × depth_scale)
are read in metres and every pose is refined by ICP; missing, wrong-sized and NaN depth images fail clearly,
naming the file; `DetectAndEstimatePose6D` passes a depth image on to its pose models.

The AAE run is a toy (two training steps): its rotations are not what is tested. Its ``pose_from_codebook``
step is replaced by one that returns the ground-truth pose moved 3 cm along the viewing ray and turned by 3
degrees (an RGB pose's typical error), so the test measures what the depth step adds.
"""

from __future__ import annotations

import shutil
from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.backend.tensorflow_guard import import_tensorflow

import_tensorflow()  # before any renderer in this process

from paz6d.abstract import Box2D, KeyedStep, Pose6D  # noqa: E402
from paz6d.aae.config import QUICK, Augmentation  # noqa: E402
from paz6d.assets.demo_object import write_demo_object  # noqa: E402
from paz6d.cli import main  # noqa: E402

TOY = replace(QUICK, crop_size=16, latent_size=8, filters=(4, 8), kernel_size=3, render_size=32, views=8, in_plane=2,
              steps=2, batch_size=4, checkpoint_every=2, sample_every=2, log_every=1, augmentation=Augmentation())
DEPTH_ERROR = 0.03  # metres along the ray


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A toy AAE run of the demo object and a 3-image generated BOP set of it (one instance per image)."""
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate
    from paz6d.aae.train import train_aae

    root = tmp_path_factory.mktemp("estimate_depth")
    mesh = write_demo_object(root / "mesh")
    train_aae(mesh, root / "run", TOY, mesh_scale=0.001, seed=3, workers=0, progress=False)
    generate(GenerationConfig(meshes=(mesh,), out=root / "set", num_images=3, width=160, height=120, seed=5,
                              split="test", mesh_scale=0.001, objects_per_image=(1, 1), distractors=0,
                              occluder_probability=0.0, distance=(0.5, 0.6)), workers=1, show_progress=False)
    return root


def _truth(dataset):
    """``{ground-truth box (rounded): T_model2cam}`` of every instance, and the list of poses."""
    from paz6d.datasets.bop import BOPDataset

    truth = {}
    for sample in BOPDataset(dataset, "test"):
        for instance in sample.objects:
            x, y, width, height = instance.info["bbox_obj"]
            truth[(round(float(x)), round(float(y)), round(float(x + width)), round(float(y + height)))] = \
                instance.T_model2cam
    return truth


class TruthWithRGBError:
    """A ``pose_from_codebook`` step: the ground-truth pose of the box, DEPTH_ERROR farther along its ray and
    turned by 3 degrees."""

    def __init__(self, truth):
        self.truth = truth

    def __call__(self, indices, similarities, rotations, box, camera):
        T = self.truth[tuple(int(round(value)) for value in box)].copy()
        T[:3, 3] *= (T[2, 3] + DEPTH_ERROR) / T[2, 3]
        T[:3, :3] = Rotation.from_rotvec([0.0, 0.05, 0.0]).as_matrix() @ T[:3, :3]
        return [Pose6D.from_matrix(T)]


@pytest.fixture
def rgb_error_estimator(world, monkeypatch):
    from paz6d import split_estimation as module

    real, truth = module._estimator, _truth(world / "set")

    def estimator(run_dir, **options):
        pipeline = real(run_dir, **options)
        pipeline.replace("pose_from_codebook", KeyedStep(
            TruthWithRGBError(truth), ("indices", "similarities", "rotations", "boxes", "cameras"), "candidates",
            "pose_from_codebook", per_sample=True))
        return pipeline

    monkeypatch.setattr(module, "_estimator", estimator)
    return truth


def _translation_errors(results, truth) -> np.ndarray:
    from paz6d.datasets.bop import read_pose_results

    estimates = read_pose_results(results)
    return np.array([min(np.linalg.norm(t - T[:3, 3]) for T in truth.values()) for t in estimates.translations])


def test_estimate_with_depth_removes_the_depth_error(world, tmp_path, rgb_error_estimator, capsys):
    flags = ["estimate", "--run", f"1={world / 'run'}", "--dataset", str(world / "set"), "--no-progress"]
    assert main([*flags, "--out", str(tmp_path / "rgb.csv")]) == 0
    assert main([*flags, "--out", str(tmp_path / "depth.csv"), "--depth"]) == 0
    assert "depth refinement (ICP): 3 of 3 accepted" in capsys.readouterr().out
    rgb, depth = (_translation_errors(tmp_path / name, rgb_error_estimator) for name in ("rgb.csv", "depth.csv"))
    assert len(rgb) == len(depth) == 3
    assert np.all((rgb > DEPTH_ERROR) & (rgb < 1.1 * DEPTH_ERROR)), rgb  # 3 cm along rays near the optical axis
    assert np.all(depth < 0.002), depth


def _copy_set(world, tmp_path):
    dataset = tmp_path / "set"
    shutil.copytree(world / "set", dataset)
    return dataset, dataset / "test" / "000000" / "depth"


def test_estimate_with_depth_names_a_missing_wrong_sized_or_nan_depth_file(world, tmp_path, capsys):
    dataset, folder = _copy_set(world, tmp_path)
    flags = ["estimate", "--run", f"1={world / 'run'}", "--dataset", str(dataset), "--no-progress", "--depth",
             "--out", str(tmp_path / "out.csv")]
    (folder / "000001.png").unlink()
    assert main(flags) == 2
    assert f"{folder / '000001.png'}: depth image not found (--depth needs one per image)" in capsys.readouterr().err
    cv2.imwrite(str(folder / "000001.png"), np.full((60, 80), 5000, np.uint16))
    assert main(flags) == 2
    assert (f"{folder / '000001.png'}: depth image is 80x60 pixels, expected 160x120 (the RGB image's size)"
            in capsys.readouterr().err)
    (folder / "000001.png").unlink()
    cv2.imwrite(str(folder / "000001.tif"), np.full((120, 160), np.nan, np.float32))
    assert main(flags) == 2
    assert f"{folder / '000001.tif'}: 19200 NaN or infinite depth values" in capsys.readouterr().err
    assert not (tmp_path / "out.csv").exists()


def test_detect_and_estimate_passes_the_depth_image_to_the_pose_models():
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D

    seen = []

    def estimator(image, box, camera=None, depth=None):
        seen.append(depth)
        return Pose6D.from_rotation_vector([0.0, 0.0, 0.0], [0.0, 0.0, 0.5])

    def detector(image):
        return [Box2D(2, 2, 10, 10, 0.9, "obj_000001")]

    pipeline = DetectAndEstimatePose6D(detector, {1: estimator}, np.array([[50.0, 0, 10], [0, 50.0, 8], [0, 0, 1]]))
    image, depth = np.zeros((16, 20, 3), np.uint8), np.full((16, 20), 0.5, np.float32)
    assert len(pipeline(image)) == 1 and seen == [None]
    assert len(pipeline(image, depth=depth)) == 1 and np.array_equal(seen[-1], depth)
    with pytest.raises(ValueError, match=r"depth: depth image is 10x8 pixels, expected 20x16"):
        pipeline(image, depth=depth[:8, :10])


def test_keypoint_pipeline_refines_with_depth_on_points_sampled_from_the_run_mesh(world, tmp_path):
    """KeypointPose6D's ``refine_with_depth`` step (there from construction: a call does not change the steps)
    samples the run's mesh (config.json mesh_path) at the first depth image and undoes a depth error; without
    mesh_path the error names config.json.
    The untrained network's PnP step is replaced by one returning the pose with a depth error."""
    import json

    from test_depth_refinement import raycast_depth

    from paz6d.backend.camera import Camera, transform_and_project
    from paz6d.backend.mesh import load_mesh
    from paz6d.keypointnet import model as kp
    from paz6d.keypointnet.pipeline import KeypointPose6D
    from paz6d.keypointnet.run_dir import write_keypoints

    mesh_path = next((world / "mesh").glob("*.ply"))
    run = tmp_path / "keypoint_run"
    run.mkdir()
    kp.save_keypointnet(kp.build_keypointnet(8, 32, 4, 2, (1,)), run / "model.keras")  # untrained: not used here
    config = {"input_size": 32, "margin": 1.25, "downsample": 2, "mesh_path": str(mesh_path), "mesh_scale": 0.001}
    (run / "config.json").write_text(json.dumps(config))
    cube = np.array([[x, y, z] for x in (-0.04, 0.04) for y in (-0.03, 0.03) for z in (-0.02, 0.02)])
    write_keypoints(run, cube, np.ones(8, bool), "farthest-point")
    K = np.array([[500.0, 0, 159.5], [0, 500.0, 119.5], [0, 0, 1]])
    camera = Camera(K, 320, 240)

    def estimator_with_pnp_pose(pose: Pose6D) -> KeypointPose6D:
        estimator = KeypointPose6D(run, camera)
        estimator.replace("solve_pnp", KeyedStep(lambda keypoints, window, camera: pose,
                                                 ("keypoints", "windows", "cameras"), "poses", "solve_pnp",
                                                 per_sample=True))
        return estimator

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, 0.5, -0.2]).as_matrix()
    T[:3, 3] = [0.0, 0.01, 0.55]
    mesh = load_mesh(mesh_path, 0.001)
    depth = raycast_depth([(mesh, T)], K, 320, 240)
    pixels = transform_and_project(np.asarray(mesh.vertices), T, K)
    box = Box2D(*pixels.min(axis=0), *(pixels.max(axis=0) + 1))
    far = T.copy()
    far[:3, 3] *= 1.06  # 3.3 cm along the ray
    image = np.zeros((240, 320, 3), np.uint8)
    estimator = estimator_with_pnp_pose(Pose6D.from_matrix(far))
    steps = estimator.names
    assert steps[-2:] == ["solve_pnp", "refine_with_depth"]
    assert estimator(image, box) == Pose6D.from_matrix(far)  # without depth: the pose of the PnP step
    assert estimator["refine_with_depth"].processor.statistics["refinements"] == 0
    refined = estimator(image, box, depth=depth)
    assert estimator.names == steps
    assert np.linalg.norm(refined.translation - T[:3, 3]) < 0.001
    assert estimator["refine_with_depth"].processor.statistics["accepted"] == 1
    del config["mesh_path"]
    (run / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"config.json: mesh_path None is not a file; depth refinement samples"):
        estimator_with_pnp_pose(Pose6D.from_matrix(far))(image, box, depth=depth)
