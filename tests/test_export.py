"""``paz6d export`` and :mod:`paz6d.export`: tiny untrained AAE and SSD runs exported to SavedModel, TFLite
and ONNX give the Keras outputs, and pipelines with their network step replaced by an exported file
give the same poses and detections (the SSD's tests are marked slow: its conversion takes ~30 s)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from paz6d import cli
from paz6d.abstract.messages import Box2D
from paz6d.abstract.processor import KeyedStep
from paz6d.backend.camera import Camera

CLASS_NAMES = ["obj_000001", "obj_000002"]


@pytest.fixture(scope="module")
def ssd_run(tmp_path_factory) -> Path:
    """An SSD run directory (light network, 128 px input, random weights; the heads' kernels scaled up so
    that the outputs are of order 1, not the near-zero outputs of fresh heads)."""
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.ssd.model import build_ssd, save_ssd
    from paz6d.ssd.run_dir import SSDRunDir, write_detector

    import_keras().utils.set_random_seed(0)
    run = tmp_path_factory.mktemp("export") / "ssd"
    model, spec = build_ssd(len(CLASS_NAMES) + 1, "light", input_size=128, width=0.25)
    for weight in model.weights:
        if weight.path.startswith(("conf_", "loc_")) and weight.path.endswith("pointwise_kernel"):
            weight.assign(weight.numpy() * 1000)
    write_detector(run, "light", CLASS_NAMES, spec.to_dict())
    save_ssd(model, SSDRunDir.model_path(run))
    return run


@pytest.fixture(scope="module")
def aae_run(tmp_path_factory) -> Path:
    """An AAE run directory (16 px crops, 8-number codes, random weights) whose codebook holds the codes of
    40 random crops, each with its own rotation."""
    from scipy.spatial.transform import Rotation

    from paz6d.aae.codebook import Codebook
    from paz6d.aae.model import build_autoencoder, encode_function, encoder_of
    from paz6d.aae.run_dir import AAERunDir, codebook_path, write_object
    from paz6d.backend.files import save_keras_model_atomically
    from paz6d.backend.tensorflow_guard import import_keras

    import_keras().utils.set_random_seed(0)
    run = tmp_path_factory.mktemp("export") / "aae"
    model = build_autoencoder(16, 8, filters=(8, 16))
    hull = np.array([[x, y, z] for x in (-0.025, 0.025) for y in (-0.02, 0.02) for z in (-0.015, 0.015)])
    AAERunDir.write_config(run, {"crop_size": 16, "padding": 1.2, "latent_size": 8}, run / "mesh.ply", 1.0, 0, None)
    write_object(run, hull, hull * 0.9, 0.07, hull)
    crops = np.random.default_rng(1).uniform(0, 1, (40, 16, 16, 3)).astype(np.float32)
    codes = encode_function(encoder_of(model))(crops)
    codes /= np.linalg.norm(codes, axis=1, keepdims=True)
    Codebook(codes, Rotation.random(40, random_state=2).as_matrix(), np.tile([40.0, 40, 60, 60], (40, 1)),
             np.diag([100.0, 100.0, 1.0]), 0.5).save(codebook_path(run))
    save_keras_model_atomically(model, AAERunDir.model_path(run))
    return run


def onnx_available() -> None:
    """Skips the test when the ONNX converter cannot be imported here (the reason says why)."""
    from paz6d.export.formats import ExportError, onnx_modules

    try:
        onnx_modules()
        import onnxruntime  # noqa: F401
    except (ExportError, ImportError) as error:
        pytest.skip(f"ONNX export unavailable: {error}")


@pytest.fixture(scope="module")
def ssd_exports(ssd_run, tmp_path_factory) -> dict[str, Path]:
    """The SSD run's network exported as a SavedModel and a TFLite file (converted from it)."""
    from paz6d.export.formats import export
    from paz6d.export.networks import network_of

    folder = tmp_path_factory.mktemp("ssd_exports")
    model = network_of(ssd_run).model
    return {format: export(model, folder, format, folder) for format in ("saved_model", "tflite")}


@pytest.mark.slow  # the SSD's export and TFLite conversion take about 30 s
@pytest.mark.parametrize("format", ["saved_model", "tflite"])
def test_exported_ssd_gives_the_keras_outputs(format, ssd_run, ssd_exports):
    from paz6d.export.command import check_exported
    from paz6d.export.formats import load_exported
    from paz6d.export.networks import network_of

    network = network_of(ssd_run)
    assert network.method == "ssd" and network.step == "predict" and network.input_shape == (128, 128, 3)
    found = check_exported(network, load_exported(ssd_exports[format], format), 20, seed=0)
    assert set(found) == {"output"} and found["output"]["max_abs"] < 1e-4 and found["output"]["magnitude"] > 0.5


def test_export_command_writes_files_and_the_differences(aae_run, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["export", "--run", str(aae_run), "--format", "tflite", "saved_model", "--out", str(out)]) == 0
    report = json.loads((out / "export.json").read_text())
    assert report["method"] == "aae" and report["pipeline_step"] == "encode" and report["input_shape"] == [16, 16, 3]
    assert set(report["formats"]) == {"saved_model", "tflite"} and report["inputs"] == 20
    for format, entry in report["formats"].items():
        assert entry["passed"] and entry["max_difference"] < 1e-4 and entry["outputs"]["output"]["magnitude"] > 0.01
    assert (out / "model.tflite").stat().st_size > 1000 and (out / "saved_model" / "saved_model.pb").is_file()
    assert sorted(path.name for path in out.iterdir()) == ["export.json", "model.tflite", "saved_model"]
    assert "tflite: " in capsys.readouterr().out


def test_a_bfloat16_network_exports_as_its_float32_copy(tmp_path):
    from paz6d.aae.model import build_encoder
    from paz6d.export.command import TOLERANCE, check_exported
    from paz6d.export.formats import export, load_exported
    from paz6d.export.networks import Network, float32_copy
    from paz6d.methods import get

    encoder = build_encoder(16, 8, filters=(8, 16), compute_dtype="bfloat16")
    assert {layer.compute_dtype for layer in encoder.layers} >= {"bfloat16"}
    copy = float32_copy(encoder)
    assert {layer.compute_dtype for layer in copy.layers} == {"float32"} and float32_copy(copy) is copy
    crops = np.random.default_rng(0).uniform(0, 1, (4, 16, 16, 3)).astype(np.float32)
    np.testing.assert_allclose(copy(crops), encoder(crops), rtol=0.05, atol=0.05)  # bfloat16 rounding only
    network = Network("aae", copy, (16, 16, 3), get("aae").network.input_range, "encode")
    found = check_exported(network, load_exported(export(copy, tmp_path, "tflite", tmp_path), "tflite"), 20, seed=0)
    assert max(value["scaled"] for value in found.values()) < TOLERANCE


def test_a_failing_comparison_is_reported(aae_run, tmp_path, monkeypatch, capsys):
    """An exported model whose outputs are off fails the command, and export.json says by how much."""
    from paz6d.export import formats

    original = formats.TFLiteFunction.run
    monkeypatch.setattr(formats.TFLiteFunction, "run", lambda self, inputs: original(self, inputs) + 1e-3)
    assert cli.main(["export", "--run", str(aae_run), "--format", "tflite", "--out", str(tmp_path / "out")]) == 2
    assert "differ from the Keras model's by more than 0.0001: tflite 0.001" in capsys.readouterr().err
    entry = json.loads((tmp_path / "out" / "export.json").read_text())["formats"]["tflite"]
    assert not entry["passed"] and entry["max_difference"] == pytest.approx(1e-3, rel=0.05)


@pytest.mark.slow  # shares the SSD's export
def test_ssd_pipeline_with_the_tflite_network_detects_the_same(ssd_run, ssd_exports):
    """PAZ's hierarchy: the detector's ``predict`` step, replaced by name with the TFLite network, gives
    the same detections."""
    from paz6d.export.formats import TFLiteFunction
    from paz6d.pipelines import DetectSingleShot
    from paz6d.ssd.pipeline import PredictImage

    path = ssd_exports["tflite"]
    keras_detector = DetectSingleShot(ssd_run, score_threshold=0.0, max_detections=20)
    tflite_detector = DetectSingleShot(ssd_run, score_threshold=0.0, max_detections=20)
    replaced = tflite_detector.replace("predict", KeyedStep(PredictImage(TFLiteFunction(path)), "input", "output",
                                                            name="predict"))
    assert isinstance(replaced.processor, PredictImage) and tflite_detector.names == keras_detector.names
    image = np.random.default_rng(3).integers(0, 256, (48, 80, 3), dtype=np.uint8)
    expected, found = keras_detector(image), tflite_detector(image)
    assert len(found) == len(expected) == 20
    for a, b in zip(expected, found):
        assert a.class_name == b.class_name and a.score == pytest.approx(b.score, abs=1e-5)
        assert np.allclose(Box2D.coordinates_of(a), Box2D.coordinates_of(b), atol=1e-3)


def test_aae_pipeline_with_the_tflite_encoder_gives_the_same_poses(aae_run, tmp_path):
    from paz6d.aae.pipeline import EncodeCrops, ImplicitPose6D
    from paz6d.export.formats import TFLiteFunction, export
    from paz6d.export.networks import network_of

    path = export(network_of(aae_run).model, tmp_path, "tflite", tmp_path)
    camera = Camera(np.array([[100.0, 0, 40], [0, 100.0, 30], [0, 0, 1]]), 80, 60)
    keras_pose = ImplicitPose6D(aae_run, camera, refine=False)
    tflite_pose = ImplicitPose6D(aae_run, camera, refine=False)
    tflite_pose.replace("encode", KeyedStep(EncodeCrops(TFLiteFunction(path), 16), "crops", "codes", name="encode"))
    generator = np.random.default_rng(4)
    for _ in range(5):
        image = generator.integers(0, 256, (60, 80, 3), dtype=np.uint8)
        box = (20.0, 10.0, 20.0 + generator.uniform(15, 40), 10.0 + generator.uniform(15, 40))
        expected, found = keras_pose(image, box), tflite_pose(image, box)
        assert np.allclose(expected.rotation_matrix, found.rotation_matrix, atol=1e-6)
        assert np.allclose(expected.translation, found.translation, atol=1e-6)


def test_onnx_export_command(aae_run, tmp_path):
    onnx_available()
    out = tmp_path / "out"
    assert cli.main(["export", "--run", str(aae_run), "--format", "onnx", "--out", str(out)]) == 0
    entry = json.loads((out / "export.json").read_text())["formats"]["onnx"]
    assert entry["passed"] and entry["path"] == "model.onnx" and entry["max_difference"] < 1e-4


@pytest.mark.parametrize("argv, expect", [
    (["--run", "{tmp}", "--format", "tflite"], "is not a run directory of any method"),
    (["--run", "{tmp}/missing", "--format", "tflite"], "is not a directory"),
    (["--run", "{aae}", "--format", "tflite", "--inputs", "1"], "--inputs: expected at least 2"),
    (["--run", "{aae}", "--format", "tflite", "--out", "{aae}"], "--out: "),
    (["--run", "{broken}", "--format", "tflite"], "model.keras"),
])
def test_bad_input_exits_2_with_one_line(argv, expect, aae_run, tmp_path, capsys):
    broken = tmp_path / "broken"
    broken.mkdir()
    for path in aae_run.iterdir():
        (broken / path.name).write_bytes(path.read_bytes())
    (broken / "model.keras").write_bytes(b"not a model")
    argv = [part.format(tmp=tmp_path, aae=aae_run, broken=broken) for part in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    assert cli.main(["export", *argv]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("paz6d export: error: ") and expect in error, error
    assert not (tmp_path / "out").exists()


def tiny_network(method: str):
    """A small network of ``method`` as its pipeline runs it (random weights), and one input's shape."""
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.export.networks import Network
    from paz6d.faces.xception import mini_xception
    from paz6d.hrnet.model import OUTPUT_NAME, build_hrnet
    from paz6d.keypointnet.model import build_keypointnet
    from paz6d.methods import get
    from paz6d.probabilistic_keypoints.model import build_probabilistic_keypointnet
    from paz6d.segmentation.model import build_segmenter
    from paz6d.stn.model import build_classifier

    keras = import_keras()
    keras.utils.set_random_seed(0)
    if method == "keypointnet":
        model, shape = build_keypointnet(4, 32, 8, dilations=(1, 2)), (32, 32, 3)
    elif method == "probabilistic-keypoints":
        model, shape = build_probabilistic_keypointnet(4, 32, 8, dilations=(1, 2)), (32, 32, 3)
    elif method == "hrnet":
        full = build_hrnet(4, 32, widths=(8, 16, 32), stem_width=8)
        model, shape = keras.Model(full.input, full.output[OUTPUT_NAME]), (32, 32, 3)
    elif method == "segmentation":
        full = build_segmenter(2, 32, widths=(8, 16))
        model, shape = keras.Model(full.input, keras.layers.Activation("sigmoid")(full.output)), (32, 32, 3)
    elif method == "stn":
        model, shape = build_classifier(10, 48, True, filters=8), (48, 48, 1)
    else:
        model, shape = mini_xception((48, 48, 1), 7), (48, 48, 1)
    return Network(method, model, shape, get(method).network.input_range, None)


@pytest.mark.slow  # six networks, two conversions each: about a minute
@pytest.mark.parametrize("method", ["keypointnet", "probabilistic-keypoints", "hrnet", "segmentation", "stn",
                                    "emotion"])
def test_every_method_network_exports_to_tflite_and_onnx(method, tmp_path):
    from paz6d.export.command import TOLERANCE, check_exported
    from paz6d.export.formats import export, load_exported

    onnx_available()
    network = tiny_network(method)
    for format in ("tflite", "onnx"):
        found = check_exported(network, load_exported(export(network.model, tmp_path, format, tmp_path), format),
                               20, seed=0)
        assert max(value["scaled"] for value in found.values()) < TOLERANCE, (format, found)
        assert max(value["magnitude"] for value in found.values()) > 0.1


def test_an_emotion_run_is_recognised_and_its_network_loaded(tmp_path):
    from paz6d.backend.files import save_keras_model_atomically, write_json_atomically
    from paz6d.export.networks import network_of, run_method

    network = tiny_network("emotion")
    save_keras_model_atomically(network.model, tmp_path / "model.keras")
    with pytest.raises(ValueError, match="--run: .* is not a run directory of any method .*emotion: classes.json"):
        run_method(tmp_path)
    write_json_atomically(tmp_path / "classes.json", ["a", "b", "c", "d", "e", "f", "g"])
    assert run_method(tmp_path).name == "emotion"
    loaded = network_of(tmp_path)
    assert (loaded.method, loaded.input_shape, loaded.input_range, loaded.step) == ("emotion", (48, 48, 1),
                                                                                   (-1.0, 1.0), None)


@pytest.mark.slow  # two SSD conversions: about 30 s
def test_a_detector_of_any_image_size_exports_with_free_sides(tmp_path):
    from paz6d.backend.tensorflow_guard import import_keras
    from paz6d.export.formats import export, load_exported
    from paz6d.ssd.model import build_ssd

    onnx_available()
    import_keras().utils.set_random_seed(0)
    model, _ = build_ssd(3, "light", input_size=128, width=0.25, any_size=True)
    for weight in model.weights:
        if weight.path.startswith(("conf_", "loc_")) and weight.path.endswith("pointwise_kernel"):
            weight.assign(weight.numpy() * 1000)
    for format in ("tflite", "onnx"):
        runner = load_exported(export(model, tmp_path, format, tmp_path), format)
        for height, width in ((128, 128), (192, 256)):
            inputs = np.random.default_rng(height).uniform(-2.5, 2.5, (2, height, width, 3)).astype(np.float32)
            expected = np.asarray(model(inputs, training=False))
            assert np.abs(expected).max() > 0.5 and np.abs(runner(inputs) - expected).max() < 1e-4
