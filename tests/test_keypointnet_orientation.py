"""KeypointNet's orientation network for half-turn symmetric objects: charts, canonical poses, the
symmetric demo object, the network with a forced or predicted chart, and a tiny training run."""

import csv
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from scipy.spatial import cKDTree

from paz6d.backend.tensorflow_guard import import_tensorflow
from paz6d.keypointnet import orientation as ko
from paz6d.keypointnet.config import QUICK

import_tensorflow()  # the renderer shares this process with TensorFlow (workers=0)

TINY = QUICK.replace(num_keypoints=6, input_size=32, filters=8, downsample=2, dilations=(1, 2), views=24,
                     validation_views=8, lift_views=8, pairs=4, learning_rate=3e-3, checkpoint_every=20,
                     sample_every=20)
seeds = st.integers(0, 2**32 - 1)


def half_turn(axis, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A half turn about ``axis`` followed by ``translation``."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.pi * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
    T[:3, 3] = translation
    return T


def random_poses(seed: int, count: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (count, 1, 1))
    T[:, :3, :3] = Rotation.random(count, random_state=seed).as_matrix()
    T[:, :3, 3] = rng.uniform([-0.1, -0.1, 0.5], [0.1, 0.1, 1.0], (count, 3))
    return T


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_chart_axis_is_flipped_by_the_half_turn(seed):
    rng = np.random.default_rng(seed)
    symmetry = half_turn(rng.normal(size=3), rng.normal(size=3) * 0.01)
    a = ko.chart_axis(symmetry)
    assert np.isclose(np.linalg.norm(a), 1.0)
    assert np.allclose(symmetry[:3, :3] @ a, -a, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_both_equivalent_poses_get_the_same_chart_and_the_same_canonical_pose(seed):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    symmetry = half_turn(axis, np.cross(axis, rng.normal(size=3)) * 0.01)
    assert np.allclose(symmetry @ symmetry, np.eye(4))
    a = ko.chart_axis(symmetry)
    T = random_poses(seed, 16)
    flipped = T @ symmetry
    charts = ko.chart_targets(T, a)
    assert np.array_equal(charts, ko.chart_targets(flipped, a))
    d = ko.axis_in_camera(T, a)
    assert np.all(np.abs(d[np.arange(16), charts]) >= 1 / np.sqrt(3) - 1e-9)  # the largest of three components
    for chart_choice in (charts, (charts + 1) % 3):
        canonical = ko.canonical_poses(T, chart_choice, symmetry, a)
        assert np.allclose(canonical, ko.canonical_poses(flipped, chart_choice, symmetry, a), atol=1e-9)
        assert np.all(ko.axis_in_camera(canonical, a)[np.arange(16), chart_choice] >= -1e-12)
        for one, original, other in zip(canonical, T, flipped):  # one of the two equivalent poses
            assert np.allclose(one, original) or np.allclose(one, other)


def test_training_charts_are_the_true_chart_or_a_safe_other_one():
    a = np.array([0.0, 1.0, 0.0])
    T = random_poses(1, 400)
    targets = ko.chart_targets(T, a)
    assert np.array_equal(ko.training_charts(T, a, np.random.default_rng(0), 0.0), targets)
    charts = ko.training_charts(T, a, np.random.default_rng(0), 1.0)
    d = np.abs(ko.axis_in_camera(T, a))
    changed = charts != targets
    assert 0.3 < changed.mean() < 1.0  # views without a safe alternative keep their chart
    assert np.all(d[changed, charts[changed]] >= ko.SAFE_COMPONENT)
    unchanged = np.flatnonzero(~changed)
    assert all(sorted(d[view])[1] < ko.SAFE_COMPONENT for view in unchanged)
    assert np.array_equal(ko.one_hot(np.array([2, 0])), [[0, 0, 1], [1, 0, 0]])


def test_only_a_single_half_turn_is_accepted():
    assert np.allclose(ko.half_turn_symmetry(half_turn([0, 0, 1])[None], "x"), half_turn([0, 0, 1]))
    with pytest.raises(ValueError, match="obj 3: the orientation network handles exactly one discrete symmetry.*got 0"):
        ko.half_turn_symmetry(np.zeros((0, 4, 4)), "obj 3")
    with pytest.raises(ValueError, match="got 2"):
        ko.half_turn_symmetry(np.stack([half_turn([0, 0, 1]), half_turn([1, 0, 0])]), "obj 3")
    quarter = np.eye(4)
    quarter[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    with pytest.raises(ValueError, match="needs a half-turn symmetry .180 degrees., got a rotation of 90.0"):
        ko.half_turn_symmetry(quarter[None], "obj 3")
    assert ko.is_single_half_turn(half_turn([0, 0, 1])[None]) and ko.is_single_half_turn(half_turn([1, 0, 0]).ravel())
    assert not ko.is_single_half_turn(np.zeros((0, 4, 4))) and not ko.is_single_half_turn(quarter[None])
    assert not ko.is_single_half_turn(np.stack([half_turn([0, 0, 1]), half_turn([1, 0, 0])]))


def test_symmetric_demo_object_maps_onto_itself_by_its_half_turn_only(tmp_path):
    from paz6d.assets.demo_object import HALF_TURN_Z, make_symmetric_demo_mesh, write_symmetric_demo_object

    mesh = make_symmetric_demo_mesh()
    vertices = np.asarray(mesh.vertices)
    tree = cKDTree(vertices)
    assert tree.query(vertices @ HALF_TURN_Z[:3, :3].T)[0].max() < 1e-9  # metres
    centres, colours = mesh.triangles_center, np.asarray(mesh.visual.face_colors)
    distance, index = cKDTree(centres).query(centres @ HALF_TURN_Z[:3, :3].T)
    assert distance.max() < 1e-9 and np.array_equal(colours[index], colours)  # the colours too
    for other in (half_turn([1, 0, 0]), half_turn([0, 1, 0])):
        assert tree.query(vertices @ other[:3, :3].T)[0].max() > 1e-2
    ply = write_symmetric_demo_object(tmp_path)
    assert np.allclose(ko.mesh_symmetry(ply, 1e-3), HALF_TURN_Z)
    info = json.loads((tmp_path / "models_info.json").read_text())
    assert np.allclose(np.reshape(info["1"]["symmetries_discrete"][0], (4, 4)), HALF_TURN_Z)


def test_mesh_symmetry_errors_name_the_file(tmp_path):
    from paz6d.assets.demo_object import write_demo_object

    ply = write_demo_object(tmp_path / "asymmetric")
    with pytest.raises(ValueError, match="models_info.json: object 1: .*exactly one discrete symmetry.*got 0"):
        ko.mesh_symmetry(ply, 1e-3)
    renamed = tmp_path / "asymmetric" / "part.ply"
    renamed.write_bytes(ply.read_bytes())
    with pytest.raises(ValueError, match="part.ply: .*BOP model named obj_XXXXXX.ply"):
        ko.mesh_symmetry(renamed, 1e-3)
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    (lonely / "obj_000001.ply").write_bytes(ply.read_bytes())
    with pytest.raises(ValueError, match="lonely/models_info.json: not found"):
        ko.mesh_symmetry(lonely / "obj_000001.ply", 1e-3)
    # translations follow the mesh scale (models_info is in the mesh file's millimetres)
    info = {"1": {"diameter": 100.0, "symmetries_discrete": [half_turn([0, 0, 1], [4.0, 0, 0]).ravel().tolist()]}}
    (lonely / "models_info.json").write_text(json.dumps(info))
    assert np.isclose(ko.mesh_symmetry(lonely / "obj_000001.ply", 1e-3)[0, 3], 0.004)


def test_network_uses_its_own_chart_unless_one_is_forced(tmp_path):
    from paz6d.keypointnet import model as kp

    tf = kp.tf
    model, forcing = kp.build_keypointnet(5, 32, 8, 2, (1, 2), context_stride=8, orientation=True)
    assert kp.has_orientation(model) and len(forcing.inputs) == 2
    model.get_layer("chart").embedding.assign(np.random.default_rng(1).normal(size=(3, 8)))
    images = tf.constant(np.random.default_rng(0).uniform(0, 255, (4, 32, 32, 3)), tf.float32)
    outputs = model(images)
    assert outputs["chart_logits"].shape == (4, 3) and outputs["uv"].shape == (4, 5, 2)
    chart = outputs["chart"].numpy()
    assert np.array_equal(chart, ko.one_hot(np.argmax(outputs["chart_logits"].numpy(), axis=1)))
    same = forcing([images, tf.constant(chart)])
    assert np.allclose(same["uv"], outputs["uv"]) and np.allclose(same["chart_logits"], outputs["chart_logits"])
    other = forcing([images, tf.constant(np.roll(chart, 1, axis=1))])
    assert np.abs(other["uv"] - outputs["uv"]).max() > 1e-3
    path = kp.save_keypointnet(model, tmp_path / "model.keras")
    loaded = kp.load_keypointnet(path)
    assert np.array_equal(loaded(images)["uv"], outputs["uv"]) and kp.has_orientation(loaded)
    assert not kp.has_orientation(kp.build_keypointnet(5, 32, 8, 2, (1, 2)))


def _losses(run_dir):
    with open(run_dir / "log.csv") as handle:
        return [row for row in csv.DictReader(handle)]


def test_tiny_orientation_training_writes_a_run_the_pipeline_loads(tmp_path):
    from paz6d.assets.demo_object import write_demo_object, write_symmetric_demo_object
    from paz6d.keypointnet.config import KeypointTraining
    from paz6d.keypointnet.pipeline import KeypointPose6D
    from paz6d.keypointnet.train import train_keypointnet

    mesh = write_symmetric_demo_object(tmp_path / "mesh")
    job = KeypointTraining(tmp_path / "run", mesh, mesh_scale=1e-3, mode="discovery", seed=0, workers=0, steps=40,
                           progress=False, settings=TINY, orientation_network=True)
    summary = train_keypointnet(job)
    rows = _losses(job.out)
    orientation = [float(row["orientation"]) for row in rows]
    assert len(rows) == 4 and orientation[-1] < orientation[0]
    assert 0.0 <= summary["chart_accuracy"] <= 1.0
    config = json.loads((job.out / "config.json").read_text())
    assert np.allclose(config["orientation"]["symmetry"], np.diag([-1.0, -1.0, 1.0, 1.0]))
    from paz6d.keypointnet.run_dir import write_keypoints

    write_keypoints(job.out, np.random.default_rng(0).normal(0, 0.03, (6, 3)), np.ones(6, bool), "test")
    K = np.array([[150.0, 0.0, 79.5], [0.0, 150.0, 59.5], [0.0, 0.0, 1.0]])
    image = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    assert len(KeypointPose6D(job.out, K, depth_from_box=True).detect(image, (60, 40, 100, 80))) == 6
    with pytest.raises(ValueError, match="different run .orientation="):
        train_keypointnet(KeypointTraining(job.out, mesh, mesh_scale=1e-3, mode="discovery", workers=0, steps=50,
                                           progress=False, settings=TINY))
    asymmetric = write_demo_object(tmp_path / "asymmetric")
    with pytest.raises(ValueError, match="models_info.json: object 1: .*exactly one discrete symmetry"):
        KeypointTraining(tmp_path / "other", asymmetric, mesh_scale=1e-3, mode="discovery", orientation_network=True)


def test_orientation_flag_on_the_command_line(tmp_path, capsys):
    import argparse

    from paz6d.cli import main
    from paz6d.keypointnet.command import configure

    parser = argparse.ArgumentParser()
    configure(parser)
    assert parser.parse_args(["--mesh", "m.ply", "--out", "r", "--orientation-network"]).orientation_network
    assert not parser.parse_args(["--mesh", "m.ply", "--out", "r"]).orientation_network
    from paz6d.assets.demo_object import write_demo_object

    ply = write_demo_object(tmp_path / "mesh")
    assert main(["train", "keypointnet", "--mesh", str(ply), "--out", str(tmp_path / "r"),
                 "--orientation-network"]) == 2
    assert "exactly one discrete symmetry" in capsys.readouterr().err
