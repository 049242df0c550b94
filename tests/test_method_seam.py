"""The method seam: a method is one record (paz6d.method.Method) in one registry (paz6d.methods).

The test writes a small pose method and a small detector in this file (their RunDir subclasses, their
pipelines and their records), registers them, and runs them through ``paz6d estimate`` (the CLI's main),
``DetectAndEstimatePose6D`` and ``paz6d export`` without any other file knowing them. The pose method's
rule: the object sits on the ray through the box centre at the distance its run directory names (or the
depth image's value there), with the rotation its run directory names; so every expected pose is computed
here from the ground-truth boxes and K alone. Its run directory holds a network (a Keras model) that its
pipeline runs: normalised image coordinates ``(x, y)`` to the translation ``distance * (x, y, 1)``.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Pose6D
from paz6d.backend.camera import as_camera
from paz6d.backend.files import load_run_json, save_keras_model_atomically
from paz6d.method import Method, NetworkSpec
from paz6d.methods import get, method_of, methods, register, registered
from paz6d.run_dir import RunDir

K = np.array([[400.0, 0.0, 79.5], [0.0, 400.0, 59.5], [0.0, 0.0, 1.0]])
WIDTH, HEIGHT = 160, 120
ROTATION_VECTOR = [0.2, -0.4, 0.1]
DISTANCE = 0.6  # metres
#: (scene image id, [x, y, width, height] of the object's box), one object (id 5) per image
BOXES = {0: [30, 20, 40, 30], 1: [90, 50, 50, 44]}


# ------------------------------------------------------------------------------------------ the new method
class BoxRayRunDir(RunDir):
    """Run directory of the ``box-ray`` method: ``box_ray.json`` holds ``rotation_vector`` (3,) and
    ``distance`` (metres); ``model.keras`` the network ``(B, 2) -> (B, 3)`` translations (metres);
    ``config.json`` the training mesh (``mesh_path``)."""

    KIND = "a box-ray"
    MARKER_FILES = ("box_ray.json",)
    REQUIRED_FILES = ("box_ray.json", RunDir.MODEL_FILE)

    @classmethod
    def read_rule(cls, run_dir) -> dict:
        return load_run_json(Path(run_dir) / "box_ray.json", ("rotation_vector", "distance"), cls.KIND)

    @classmethod
    def read_network(cls, run_dir):
        from paz6d.backend.tensorflow_guard import load_keras_model

        return load_keras_model(cls.model_path(cls.check_files(run_dir)))

    @classmethod
    def validate(cls, run_dir) -> Path:
        run_dir = cls.check_files(run_dir)
        cls.read_rule(run_dir)
        return run_dir


class BoxRayPose6D:
    """``(image, box, *, camera=None, depth=None) -> Pose6D``: the fixed rule of the module docstring."""

    def __init__(self, run_dir, camera=None, class_name: str | None = None):
        rule = BoxRayRunDir.read_rule(run_dir)
        self.rotation = Rotation.from_rotvec(rule["rotation_vector"]).as_matrix()
        self.network = BoxRayRunDir.read_network(run_dir)
        self.camera, self.class_name = camera, class_name
        self.model_points = np.zeros((1, 3))

    def __call__(self, image, box, *, camera=None, depth=None) -> Pose6D:
        camera = as_camera(self.camera if camera is None else camera, image.shape[1], image.shape[0])
        x_min, y_min, x_max, y_max = Box2D.coordinates_of(box)
        u, v = (x_min + x_max) / 2 - 0.5, (y_min + y_max) / 2 - 0.5  # pixel-centre coordinates
        x, y, _ = np.linalg.solve(camera.K, [u, v, 1.0])
        translation = np.asarray(self.network(np.array([[x, y]], np.float32)), np.float64)[0]
        if depth is not None:
            translation *= float(depth[int(round(v)), int(round(u))]) / translation[2]
        return Pose6D.from_rotation_matrix(self.rotation, translation, class_name=self.class_name)


def load_box_ray(run_dir, camera=None, class_name=None):
    return BoxRayPose6D(run_dir, camera, class_name)


BOX_RAY = Method("box-ray", "box-ray", BoxRayRunDir, load_box_ray,
                 network=NetworkSpec(BoxRayRunDir.read_network, (-1.0, 1.0), step=None))


def translation_network(distance: float):
    """The box-ray network: ``(B, 2)`` normalised image coordinates -> ``(B, 3)`` translations at ``distance``."""
    from paz6d.backend.tensorflow_guard import import_keras

    keras = import_keras()
    inputs, layer = keras.Input((2,)), keras.layers.Dense(3, name="translation")
    model = keras.Model(inputs, layer(inputs))
    layer.set_weights([np.array([[distance, 0, 0], [0, distance, 0]]), np.array([0, 0, distance])])
    return model


# ------------------------------------------------------------------------------------------ a new detector
class ListedBoxesRunDir(RunDir):
    """Run directory of the ``listed-boxes`` detector: ``listed_boxes.json`` holds ``class_names`` and
    ``boxes`` ``[[x_min, y_min, x_max, y_max, score, class_name], ...]`` found in every image."""

    KIND = "a listed-boxes"
    MARKER_FILES = ("listed_boxes.json",)
    REQUIRED_FILES = ("listed_boxes.json",)
    MESH_FIELDS = None

    @classmethod
    def class_names(cls, run_dir) -> tuple[str, ...]:
        return tuple(load_run_json(Path(run_dir) / "listed_boxes.json", ("class_names",), cls.KIND)["class_names"])


class ListedBoxes:
    def __init__(self, run_dir, score_threshold: float = 0.3, flip: bool = False):
        listed = load_run_json(Path(run_dir) / "listed_boxes.json", ("class_names", "boxes"), "a listed-boxes")
        self.class_names = tuple(listed["class_names"])
        self.boxes = [Box2D(*box[:4], box[4], box[5]) for box in listed["boxes"] if box[4] >= score_threshold]

    def __call__(self, image) -> list[Box2D]:
        return list(self.boxes)


LISTED_BOXES = Method("listed-boxes", "listed-boxes", ListedBoxesRunDir, ListedBoxes, task="detection",
                      options=("score_threshold", "flip"))


# ------------------------------------------------------------------------------------------ data
def expected_pose(box_xywh, distance: float = DISTANCE) -> np.ndarray:
    x, y, width, height = box_xywh
    u, v = x + width / 2 - 0.5, y + height / 2 - 0.5
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(ROTATION_VECTOR).as_matrix()
    T[:3, 3] = distance * np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0])
    return T


@pytest.fixture
def runs(tmp_path):
    """A BOP split of two images with object 5 in each, a box-ray run trained on ``obj_000005.ply`` and a
    listed-boxes detector that finds the box of image 1 (and a distractor of another class)."""
    scene = tmp_path / "set" / "test" / "000001"
    (scene / "rgb").mkdir(parents=True)
    (tmp_path / "set" / "camera.json").write_text(json.dumps(
        {"cx": K[0, 2], "cy": K[1, 2], "fx": K[0, 0], "fy": K[1, 1], "width": WIDTH, "height": HEIGHT,
         "depth_scale": 1.0}))
    cameras, truth, info = {}, {}, {}
    for im_id, box in BOXES.items():
        cv2.imwrite(str(scene / "rgb" / f"{im_id:06d}.png"), np.full((HEIGHT, WIDTH, 3), 90, np.uint8))
        cameras[str(im_id)] = {"cam_K": K.ravel().tolist(), "depth_scale": 1.0}
        T = expected_pose(box)
        truth[str(im_id)] = [{"obj_id": 5, "cam_R_m2c": T[:3, :3].ravel().tolist(),
                              "cam_t_m2c": (1000 * T[:3, 3]).tolist()}]
        info[str(im_id)] = [{"bbox_obj": box, "bbox_visib": box, "px_count_all": 100, "px_count_valid": 100,
                             "px_count_visib": 100, "visib_fract": 1.0}]
    for name, data in (("scene_camera", cameras), ("scene_gt", truth), ("scene_gt_info", info)):
        (scene / f"{name}.json").write_text(json.dumps(data))
    pose = tmp_path / "box_ray_run"
    pose.mkdir()
    (pose / "box_ray.json").write_text(json.dumps({"rotation_vector": ROTATION_VECTOR, "distance": DISTANCE}))
    save_keras_model_atomically(translation_network(DISTANCE), BoxRayRunDir.model_path(pose))
    BoxRayRunDir.write_config(pose, {"mesh_path": str(tmp_path / "obj_000005.ply"), "mesh_scale": 0.001})
    detector = tmp_path / "listed_boxes_run"
    detector.mkdir()
    x, y, width, height = BOXES[1]
    (detector / "listed_boxes.json").write_text(json.dumps({
        "class_names": ["obj_000005", "obj_000009"],
        "boxes": [[x, y, x + width, y + height, 0.8, "obj_000005"], [0, 0, 20, 20, 0.6, "obj_000009"]]}))
    return {"set": tmp_path / "set", "pose": pose, "detector": detector}


# ------------------------------------------------------------------------------------------ tests
def test_a_registered_method_is_found_by_its_files_and_loaded_by_its_record(runs):
    with pytest.raises(ValueError, match="is not a run directory of any method"):
        method_of(runs["pose"])
    with registered(BOX_RAY), registered(LISTED_BOXES):
        assert method_of(runs["pose"]) is BOX_RAY and get("box-ray") is BOX_RAY
        assert method_of(runs["detector"]) is LISTED_BOXES
        assert BOX_RAY in methods("pose") and LISTED_BOXES in methods("detection")
        assert BoxRayRunDir.training_mesh(runs["pose"]) == (runs["set"].parent / "obj_000005.ply", 0.001)
        pipeline = BOX_RAY.load(runs["pose"], camera=K, class_name="obj_000005", keypoint_crops=3, viewpoints=None)
        assert isinstance(pipeline, BoxRayPose6D)  # options of other methods are left out
        with pytest.raises(ValueError, match="names .'box-ray'. are taken"):
            register(BOX_RAY)
    assert BOX_RAY not in methods() and LISTED_BOXES not in methods()
    with pytest.raises(ValueError, match="expected one of .*got 'box-ray'"):
        get("box-ray")


def test_a_method_record_is_checked_where_it_is_made():
    with pytest.raises(ValueError, match="task: expected one of"):
        Method("x", "x", BoxRayRunDir, load_box_ray, task="tracking")
    with pytest.raises(ValueError, match="run_dir: expected a RunDir subclass"):
        Method("x", "x", dict, load_box_ray)
    with pytest.raises(ValueError, match="names no MARKER_FILES"):
        Method("x", "x", RunDir, load_box_ray)
    with pytest.raises(ValueError, match="network: expected a paz6d.method.NetworkSpec"):
        Method("x", "x", BoxRayRunDir, load_box_ray, network=BoxRayRunDir.read_network)
    with pytest.raises(ValueError, match="input_range: expected .low, high. with low < high"):
        NetworkSpec(BoxRayRunDir.read_network, (1.0, 0.0))


def test_a_network_of_any_input_size_needs_the_size_to_export_at(tmp_path):
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.export.networks import network_of

    keras = import_keras()
    inputs = keras.Input((None, None, 3))
    save_keras_model_atomically(keras.Model(inputs, keras.layers.Conv2D(2, 3)(inputs)), tmp_path / "model.keras")
    (tmp_path / "box_ray.json").write_text("{}")
    free = Method("box-ray", "box-ray", BoxRayRunDir, load_box_ray,
                  network=NetworkSpec(BoxRayRunDir.read_network, (0.0, 1.0)))
    with registered(free), pytest.raises(ValueError, match="takes inputs of any size .* gives no input_size"):
        network_of(tmp_path)
    sized = Method("box-ray", "box-ray", BoxRayRunDir, load_box_ray,
                   network=NetworkSpec(BoxRayRunDir.read_network, (0.0, 1.0), input_size=lambda run_dir: 24))
    with registered(sized):
        assert network_of(tmp_path).input_shape == (24, 24, 3)


def test_paz6d_estimate_runs_a_registered_method_with_ground_truth_and_detector_boxes(runs, tmp_path):
    from paz6d.cli import main
    from paz6d.datasets.bop import read_pose_results

    with registered(BOX_RAY), registered(LISTED_BOXES):
        truth_csv, detector_csv = tmp_path / "truth.csv", tmp_path / "detector.csv"
        assert main(["estimate", "--run", str(runs["pose"]), "--dataset", str(runs["set"]), "--out", str(truth_csv),
                     "--no-progress"]) == 0  # the object id comes from the run's mesh name
        assert main(["estimate", "--run", f"5={runs['pose']}", "--detector", str(runs["detector"]),
                     "--dataset", str(runs["set"]), "--out", str(detector_csv), "--no-progress"]) == 0
    results = read_pose_results(truth_csv)
    assert results.im_ids.tolist() == [0, 1] and results.obj_ids.tolist() == [5, 5]
    for im_id, T in zip(results.im_ids, results.T_model2cam):
        np.testing.assert_allclose(T, expected_pose(BOXES[int(im_id)]), atol=1e-6)  # mm in the CSV: 6 digits
    results = read_pose_results(detector_csv)
    assert results.im_ids.tolist() == [0, 1] and results.scores.tolist() == [0.8, 0.8]
    for T in results.T_model2cam:  # the detector finds image 1's box in every image
        np.testing.assert_allclose(T, expected_pose(BOXES[1]), atol=1e-6)
    detections = json.loads((tmp_path / "detector_detections.json").read_text())
    assert sorted(entry["category_id"] for entry in detections) == [5, 5, 9, 9]


def test_detect_and_estimate_loads_registered_methods_from_their_run_directories(runs):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D, MissingPoseModelWarning

    image = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    with registered(BOX_RAY), registered(LISTED_BOXES):
        pipeline = DetectAndEstimatePose6D.from_run_dirs(runs["detector"], {5: runs["pose"]}, K)
    with pytest.warns(MissingPoseModelWarning, match="class 'obj_000009' has no pose model"):
        (box, pose), = pipeline(image)
    assert box.class_name == pose.class_name == "obj_000005"
    np.testing.assert_allclose(pose.to_matrix(), expected_pose(BOXES[1]), atol=1e-6)  # a float32 network
    depth = np.full((HEIGHT, WIDTH), 0.9, np.float32)  # the depth image reaches the pose pipeline
    with pytest.warns(MissingPoseModelWarning):
        (_, pose), = pipeline(image, depth=depth)
    np.testing.assert_allclose(pose.to_matrix(), expected_pose(BOXES[1], distance=0.9), atol=1e-6)
    assert pipeline.draw(image, [(box, pose)]).shape == image.shape


def test_paz6d_export_writes_the_network_of_a_registered_method(runs, tmp_path, capsys):
    from paz6d.cli import main
    from paz6d.export.formats import TFLiteFunction

    out = tmp_path / "export"
    with registered(BOX_RAY), registered(LISTED_BOXES):
        assert main(["export", "--run", str(runs["pose"]), "--format", "tflite", "--out", str(out)]) == 0
        assert main(["export", "--run", str(runs["detector"]), "--format", "tflite",
                     "--out", str(tmp_path / "none")]) == 2
    assert "is a listed-boxes run directory, whose method has no network to export" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    report = json.loads((out / "export.json").read_text())
    assert (report["method"], report["pipeline_step"], report["input_shape"], report["input_range"]) == \
        ("box-ray", None, [2], [-1.0, 1.0])
    assert report["formats"]["tflite"]["passed"] and report["formats"]["tflite"]["outputs"]["output"]["magnitude"] > 0.5
    xy = np.array([[0.1, -0.2], [0.0, 0.3]], np.float32)
    np.testing.assert_allclose(TFLiteFunction(out / "model.tflite")(xy), DISTANCE * np.c_[xy, [1, 1]], atol=1e-6)


def test_the_benchmark_trains_pose_models_of_registered_pose_methods():
    from paz6d.benchmark.lmo import METHODS, POSE_MODELS

    assert METHODS == tuple(POSE_MODELS) and len({model.folder for model in POSE_MODELS.values()}) == len(METHODS)
    assert all(get(model.method).task == "pose" for model in POSE_MODELS.values())
