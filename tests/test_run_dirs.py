"""Run directories: each method's run_dir module writes, reads and validates its files; method_of tells them apart."""

from __future__ import annotations

import json

import numpy as np
import pytest

from paz6d.aae import run_dir as aae_run
from paz6d.aae.codebook import Codebook
from paz6d.aae.run_dir import AAERunDir
from paz6d.keypointnet import run_dir as keypointnet_run
from paz6d.keypointnet.run_dir import KeypointNetRunDir
from paz6d.methods import get, methods
from paz6d.probabilistic_keypoints import run_dir as probabilistic_run
from paz6d.probabilistic_keypoints.run_dir import ProbabilisticKeypointsRunDir
from paz6d.run_dir import RunDir
from paz6d.run_dirs import RUN_DIR_MODULES, is_run_dir, method_of

HULL = np.array([[x, y, z] for x in (-0.04, 0.04) for y in (-0.03, 0.03) for z in (-0.02, 0.02)])


def write_aae_run(folder):
    AAERunDir.write_config(folder, {"crop_size": 16, "padding": 1.2, "latent_size": 8}, folder / "mesh.ply", 0.001,
                           3, None)
    aae_run.write_object(folder, HULL, HULL * 0.9, 0.1, HULL)
    codebook = Codebook(np.eye(2, 8), np.stack([np.eye(3)] * 2), np.array([[0.0, 0, 10, 10]] * 2),
                        np.diag([100.0, 100.0, 1.0]), 0.5)
    codebook.save(aae_run.codebook_path(folder))
    AAERunDir.model_path(folder).write_bytes(b"model")
    return folder


def write_keypointnet_run(folder):
    KeypointNetRunDir.write_config(folder, {"input_size": 32, "margin": 1.25, "downsample": 2, "mode": "supervised"})
    keypointnet_run.write_keypoints(folder, HULL, np.ones(8, bool), "farthest-point")
    keypointnet_run.write_object(folder, 0.1, HULL)
    KeypointNetRunDir.model_path(folder).write_bytes(b"model")
    return folder


def write_probabilistic_run(folder):
    ProbabilisticKeypointsRunDir.write_config(folder, {"input_size": 32, "margin": 1.25, "downsample": 2})
    probabilistic_run.write_keypoints(folder, HULL, 1.5, HULL)
    ProbabilisticKeypointsRunDir.model_path(folder).write_bytes(b"model")
    return folder


def test_aae_run_directory_round_trip(tmp_path):
    folder = write_aae_run(tmp_path / "aae")
    config = AAERunDir.read_config(folder)
    assert config["config"] == {"crop_size": 16, "padding": 1.2, "latent_size": 8}
    assert (config["mesh_scale"], config["seed"], config["dataset"]) == (0.001, 3, None)
    assert config["mesh"] == str((folder / "mesh.ply").resolve())
    geometry = aae_run.read_object(folder)
    np.testing.assert_array_equal(geometry["hull_points"], HULL)
    np.testing.assert_array_equal(geometry["surface_points"], HULL * 0.9)
    assert geometry["diameter"] == 0.1
    assert len(aae_run.read_codebook(folder)) == 2
    assert AAERunDir.validate(folder) == folder
    assert is_run_dir(folder, "aae") and not is_run_dir(folder, "keypointnet")


def test_aae_run_directory_errors_name_the_file(tmp_path):
    folder = write_aae_run(tmp_path / "aae")
    with pytest.raises(ValueError, match="not a directory"):
        AAERunDir.read_config(tmp_path / "absent")
    config = AAERunDir.config_path(folder)
    config.write_text(json.dumps({"config": {"crop_size": 16}, "mesh": "m", "mesh_scale": 1, "seed": 0}))
    with pytest.raises(ValueError, match=r"config.json: missing key\(s\) \['config.padding'\]"):
        AAERunDir.read_config(folder)
    config.write_text("{not json")
    with pytest.raises(ValueError, match="config.json: invalid JSON"):
        AAERunDir.validate(folder)
    np.savez(aae_run.object_path(folder), hull_points=HULL, diameter=0.1)
    with pytest.raises(ValueError, match=r"object.npz: missing key\(s\) \['surface_points', 'vertices'\]"):
        aae_run.read_object(folder)
    aae_run.object_path(folder).write_bytes(b"corrupt")
    with pytest.raises(ValueError, match="object.npz: not a readable .npz"):
        aae_run.read_object(folder)
    aae_run.codebook_path(folder).unlink()
    with pytest.raises(ValueError, match="codebook.npz: missing; is .* an AAE run directory"):
        aae_run.read_codebook(folder)
    with pytest.raises(ValueError, match=r"config: missing key\(s\) \['padding'\]"):
        AAERunDir.write_config(folder, {"crop_size": 16}, "mesh.ply", 1.0, 0, None)


def test_keypointnet_run_directory_round_trip_and_errors(tmp_path):
    folder = write_keypointnet_run(tmp_path / "keypointnet")
    assert KeypointNetRunDir.read_config(folder)["mode"] == "supervised"
    points, usable = KeypointNetRunDir.read_keypoints(folder)
    np.testing.assert_array_equal(points, HULL)
    assert usable.all()
    np.testing.assert_array_equal(keypointnet_run.read_object(folder)["hull_points"], HULL)
    assert KeypointNetRunDir.validate(folder) == folder
    KeypointNetRunDir.config_path(folder).write_text(json.dumps({"input_size": 32}))
    with pytest.raises(ValueError, match=r"config.json: missing field\(s\) \['margin', 'downsample'\]"):
        KeypointNetRunDir.validate(folder)
    KeypointNetRunDir.config_path(folder).write_text("[1, 2]")
    with pytest.raises(ValueError, match="config.json: expected a JSON object"):
        KeypointNetRunDir.read_config(folder)
    KeypointNetRunDir.model_path(folder).unlink()
    with pytest.raises(ValueError, match="model.keras: file not found"):
        KeypointNetRunDir.validate(folder)
    with pytest.raises(ValueError, match=r"config: missing key\(s\) \['downsample'\]"):
        KeypointNetRunDir.write_config(folder, {"input_size": 32, "margin": 1.25})


def test_method_of_tells_the_run_directories_apart(tmp_path):
    assert method_of(write_aae_run(tmp_path / "aae")) == "aae"
    assert method_of(write_keypointnet_run(tmp_path / "keypointnet")) == "keypointnet"
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"is not a run directory of any method \(expected the files of exactly "
                                         r"one: aae: config.json \+ codebook.npz; keypointnet: config.json \+ "
                                         r"keypoints.json"):
        method_of(tmp_path / "empty")
    with pytest.raises(ValueError, match="not a directory"):
        method_of(tmp_path / "absent")
    both = write_keypointnet_run(tmp_path / "aae")
    with pytest.raises(ValueError, match="matches several methods"):
        method_of(both)


def test_keypointnet_and_probabilistic_keypoints_runs_are_told_apart_and_refused_by_the_other(tmp_path, capsys):
    """Both keep the same crop settings in config.json; their keypoints files (keypoints.json,
    gaussian_keypoints.json) tell them apart, and each refuses a run of the other."""
    from paz6d.cli import main

    keypointnet = write_keypointnet_run(tmp_path / "keypointnet")
    probabilistic = write_probabilistic_run(tmp_path / "probabilistic")
    assert KeypointNetRunDir.read_config(probabilistic) == ProbabilisticKeypointsRunDir.read_config(probabilistic)
    assert method_of(keypointnet) == "keypointnet" and method_of(probabilistic) == "probabilistic-keypoints"
    assert KeypointNetRunDir.validate(keypointnet) == keypointnet
    assert ProbabilisticKeypointsRunDir.validate(probabilistic) == probabilistic
    assert ProbabilisticKeypointsRunDir.read_keypoints(probabilistic)[1] == 1.5
    with pytest.raises(ValueError, match=r"gaussian_keypoints.json: file not found \(is .* a probabilistic-keypoints "):
        ProbabilisticKeypointsRunDir.validate(keypointnet)
    with pytest.raises(ValueError, match=r"/keypoints.json: file not found \(is .* a KeypointNet run directory"):
        KeypointNetRunDir.validate(probabilistic)
    (tmp_path / "set").mkdir()
    for run, other in ((keypointnet, "probabilistic-keypoints"), (probabilistic, "keypointnet")):
        assert main(["estimate", "--run", f"1={run}", "--method", other, "--dataset", str(tmp_path / "set"),
                     "--out", str(tmp_path / "out.csv"), "--no-progress"]) == 2
        assert f"--method: {run} is a {method_of(run)} run directory" in capsys.readouterr().err
    (keypointnet / probabilistic_run.KEYPOINTS_FILE).write_bytes((probabilistic / probabilistic_run.KEYPOINTS_FILE)
                                                                  .read_bytes())
    with pytest.raises(ValueError, match="matches several methods"):  # both keypoints files: neither is assumed
        method_of(keypointnet)


@pytest.mark.parametrize("method", sorted(RUN_DIR_MODULES))
def test_each_method_is_recognised_by_its_own_marker_files_only(tmp_path, method):
    for name in get(method).run_dir.MARKER_FILES:
        (tmp_path / name).write_text("{}")
    assert method_of(tmp_path) == method
    assert [other for other in RUN_DIR_MODULES if is_run_dir(tmp_path, other)] == [method]
    assert [record.name for record in methods() if record.run_dir.is_run_dir(tmp_path)] == [method]


def test_the_registry_lists_every_method_once_with_its_run_directory_class():
    records = methods()
    assert [record.name for record in records] == list(RUN_DIR_MODULES)
    for record in records:
        assert issubclass(record.run_dir, RunDir) and record.run_dir.__module__ == RUN_DIR_MODULES[record.name].__name__
    assert [record.name for record in methods("pose")] == ["aae", "keypointnet", "hrnet", "probabilistic-keypoints"]
    assert get("keypoints") is get("keypointnet")


def test_a_run_described_by_one_file_is_marked_by_it_and_opened_to_its_description(tmp_path):
    from paz6d.run_dir import DescribedRunDir

    class TinyRunDir(DescribedRunDir):
        KIND = "a tiny"
        DESCRIPTION_FILE = "tiny.json"

        @classmethod
        def read_description(cls, run_dir):
            return json.loads((run_dir / cls.DESCRIPTION_FILE).read_text())

    assert TinyRunDir.MARKER_FILES == ("tiny.json",) and TinyRunDir.REQUIRED_FILES == ("tiny.json", "model.keras")
    (tmp_path / "tiny.json").write_text('{"side": 3}')
    with pytest.raises(ValueError, match=r"model.keras: file not found \(is .* a tiny run directory\?\)"):
        TinyRunDir.validate(tmp_path)
    (tmp_path / "model.keras").write_bytes(b"")
    assert TinyRunDir.is_run_dir(tmp_path) and TinyRunDir.validate(tmp_path) == {"side": 3}


def test_run_dir_base_reads_settings_metrics_and_the_training_mesh(tmp_path):
    class Tiny(RunDir):
        KIND = "a tiny"
        MARKER_FILES = REQUIRED_FILES = ("tiny.json",)

    assert Tiny.read_config(tmp_path) is None and Tiny.read_metrics(tmp_path) is None
    assert Tiny.training_mesh(tmp_path) is None and not Tiny.is_run_dir(tmp_path)
    with pytest.raises(ValueError, match=r"tiny.json: file not found \(is .* a tiny run directory\?\)"):
        Tiny.validate(tmp_path)
    Tiny.write_config(tmp_path / "run", {"mesh_path": str(tmp_path / "obj_000007.ply"), "seed": 1})
    Tiny.write_metrics(tmp_path / "run", {"loss": 0.5})
    assert Tiny.read_config(tmp_path / "run")["seed"] == 1 and Tiny.read_metrics(tmp_path / "run") == {"loss": 0.5}
    assert Tiny.training_mesh(tmp_path / "run") == (tmp_path / "obj_000007.ply", 1.0)  # scale defaults to 1
    with pytest.raises(ValueError, match=r"config.json: mesh_path '.*obj_000007.ply' is not a file"):
        Tiny.surface_points(tmp_path / "run")
    (tmp_path / "run" / "metrics.json").write_text("[1]")
    with pytest.raises(ValueError, match="metrics.json: expected a JSON object"):
        Tiny.read_metrics(tmp_path / "run")
    aae = write_aae_run(tmp_path / "aae")
    assert AAERunDir.training_mesh(aae) == ((aae / "mesh.ply").resolve(), 0.001)
    keypointnet = write_keypointnet_run(tmp_path / "keypointnet")
    assert KeypointNetRunDir.training_mesh(keypointnet) is None  # the config names no mesh


@pytest.mark.parametrize("method", sorted(RUN_DIR_MODULES))
def test_opening_a_run_directory_checks_its_config_through_the_methods_hook(tmp_path, method):
    class Checked(get(method).run_dir):
        @classmethod
        def check_config(cls, config, path):
            raise ValueError(f"{path}: field 'steps' checked by the hook")

    for name in Checked.REQUIRED_FILES:
        (tmp_path / name).write_bytes(b"not read before config.json")
    (tmp_path / "config.json").write_text(json.dumps({"input_size": 32, "margin": 1.25, "downsample": 2}))
    with pytest.raises(ValueError, match="config.json: field 'steps' checked by the hook"):
        Checked.validate(tmp_path)  # before the method's own files, which are not readable here
    with pytest.raises(ValueError, match="config.json: field 'steps' checked by the hook"):
        Checked.read_config(tmp_path)  # what a resumed training reads


SETTINGS_METHODS = ("hrnet", "keypointnet", "probabilistic-keypoints", "segmentation", "ssd", "stn")


def test_the_methods_with_typed_settings_name_them_on_their_run_directory():
    assert sorted(method.name for method in methods() if method.run_dir.SETTINGS is not None) == list(SETTINGS_METHODS)


@pytest.mark.parametrize("method", SETTINGS_METHODS)
def test_opening_a_run_directory_checks_its_recorded_settings(tmp_path, method):
    run_dir = get(method).run_dir
    for name in run_dir.REQUIRED_FILES:
        (tmp_path / name).write_bytes(b"not read before config.json")
    base = {"input_size": 32, "margin": 1.25, "downsample": 2, "mesh_path": "m.ply", "seed": 0, "config": "quick"}
    good = run_dir.SETTINGS().to_dict()
    (tmp_path / "config.json").write_text(json.dumps({**base, "settings": good}))
    assert run_dir.read_config(tmp_path)["settings"] == good
    numeric = next(name for name, value in good.items() if type(value) in (int, float))
    for bad, expected in (({**good, numeric: -1e300}, numeric), ({**good, "unknown_field": 1}, "unknown_field"),
                          ([1, 2], "settings")):
        (tmp_path / "config.json").write_text(json.dumps({**base, "settings": bad}))
        with pytest.raises(ValueError, match=rf"config.json: settings: .*{expected}"):
            run_dir.validate(tmp_path)  # opening the run for inference, before its model is read


def test_a_resumed_run_is_opened_with_its_config_and_trainer_files_checked(tmp_path):
    from paz6d.run_dirs import OWNER_FILE, run_output

    run = write_aae_run(tmp_path / "run")
    config = json.loads(AAERunDir.config_path(run).read_text())
    AAERunDir.config_path(run).write_text(json.dumps({**config, "config": {**config["config"], "crop_size": -16}}))
    with pytest.raises(ValueError, match=r"config.json: config: AAEConfig.crop_size: expected a positive multiple "
                                         r"of 2\*\*len\(filters\) = 16 pixels, got -16"):
        with run_output(run, "aae"):
            pass
    AAERunDir.config_path(run).write_text(json.dumps(config))
    (run / "log.csv").write_text("step,loss\n10,0.5\nten,0.4\n")
    with pytest.raises(ValueError, match="log.csv: line 3"):
        with run_output(run, "aae"):
            pass
    assert not (run / OWNER_FILE).exists()  # refused before the folder is claimed
    (run / "log.csv").unlink()
    with run_output(run, "aae"):
        assert (run / OWNER_FILE).is_file()


def test_run_output_claims_a_folder_resumes_its_own_and_refuses_others(tmp_path):
    from paz6d.run_dirs import OWNER_FILE, run_output

    run = tmp_path / "run"
    with run_output(run, "ssd"):
        (run / "detector.json").write_text("{}")
    assert json.loads((run / OWNER_FILE).read_text()) == {"method": "ssd"}
    with run_output(run, "ssd"):  # its own run: resumed
        pass
    with pytest.raises(ValueError, match="--out: .* is an output folder of ssd, not emotion"):
        with run_output(run, "emotion"):
            raise AssertionError("not reached")
    legacy = write_aae_run(tmp_path / "legacy")  # no owner file: its marker files tell
    with pytest.raises(ValueError, match="output folder of aae, not keypointnet"):
        with run_output(legacy, "keypointnet"):
            pass
    with run_output(legacy, "aae"):
        pass
    assert (legacy / OWNER_FILE).is_file()


def test_a_failed_command_leaves_no_claim(tmp_path):
    from paz6d.run_dirs import run_output

    fresh, empty = tmp_path / "fresh", tmp_path / "empty"
    empty.mkdir()
    for folder in (fresh, empty):
        with pytest.raises(ValueError, match="bad flag"):
            with run_output(folder, "aae"):
                raise ValueError("bad flag")
    assert not fresh.exists() and list(empty.iterdir()) == []
    with run_output(empty, "keypointnet"):  # nobody owns it
        pass


def test_run_output_refuses_data_sets_symlinks_inputs_and_a_bad_owner_file(tmp_path):
    from paz6d.run_dirs import OWNER_FILE, run_output

    dataset = tmp_path / "bop"
    (dataset / "test" / "000000").mkdir(parents=True)
    (dataset / "test" / "000000" / "scene_gt.json").write_text("{}")
    for folder in (dataset, dataset / "test", dataset / "test" / "000000"):
        with pytest.raises(ValueError, match="holds a BOP data set"):
            with run_output(folder, "ssd"):
                pass
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(ValueError, match="symbolic link"):
        with run_output(tmp_path / "link", "ssd"):
            pass
    images = tmp_path / "images"
    images.mkdir()
    with pytest.raises(ValueError, match="is also --images"):
        with run_output(tmp_path / "images", "aae", {"--images": images}):
            pass
    odd = tmp_path / "odd"
    odd.mkdir()
    (odd / OWNER_FILE).write_text("[1]")
    with pytest.raises(ValueError, match=OWNER_FILE):
        with run_output(odd, "ssd"):
            pass
    assert not (tmp_path / "elsewhere").exists() and (odd / OWNER_FILE).read_text() == "[1]"


def test_keypoints_that_could_not_be_lifted_are_written_with_a_null_error(tmp_path):
    error = np.array([0.5, np.nan, 1.5, np.inf, 0.1, 0.2, 0.3, 0.4])
    keypointnet_run.write_keypoints(tmp_path, HULL, np.isfinite(error), "triangulated", error)
    data = json.loads((tmp_path / keypointnet_run.KEYPOINTS_FILE).read_text())
    assert data["error"] == [0.5, None, 1.5, None, 0.1, 0.2, 0.3, 0.4]
    points, usable = KeypointNetRunDir.read_keypoints(tmp_path)
    assert usable.tolist() == np.isfinite(error).tolist() and np.allclose(points, HULL)
