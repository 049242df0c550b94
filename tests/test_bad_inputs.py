"""Bad input through every command and the Python API: a clear error naming the file or field (exit
code 2 on the command line), no traceback, no hang, nothing touched outside the output.

The command-line table lives in ``tests/bad_input_cases.py`` (also used by ``scripts/fuzz_inputs.py``);
each case runs ``paz6d.cli.main`` in this process on a small world of valid inputs built once.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

import bad_input_cases as cases

REPO = Path(__file__).resolve().parents[1]
CASES = cases.all_cases()


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> cases.World:
    return cases.build_world(tmp_path_factory.mktemp("bad_inputs") / "world")


def test_the_table_is_large_and_covers_every_command():
    assert len(CASES) >= 200
    commands = {" ".join(case.argv[:2]) if case.argv[0] in ("evaluate", "train") else case.argv[0] for case in CASES}
    assert {"generate", "estimate", "demo", "evaluate bop", "evaluate coco", "evaluate voc", "train aae",
            "train keypointnet", "train emotion"} <= commands


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_bad_input_is_reported_clearly(world, case):
    verdict = cases.run_case(world, case)
    assert not verdict.problems, f"{case.name} [{verdict.kind}]: " + "\n".join(verdict.problems)
    if case.code == 2:
        assert "error:" in verdict.outcome.stderr


# ------------------------------------------------------------------------------------------ a real process

@pytest.mark.parametrize("argv, expect", [
    (["evaluate", "bop", "--dataset", "{bop}", "--split", "../..", "--results", "{results}", "--out", "{out}"],
     "--split: expected a plain folder name"),
    (["evaluate", "bop", "--dataset", "{bop}", "--results", "{bad}", "--out", "{out}"], "not UTF-8"),
    (["generate", "--meshes", "{bad}", "--out", "{out}", "--num-images", "1"], "bad.ply"),
], ids=["split-outside", "results-not-utf8", "mesh-not-a-mesh"])
def test_a_real_process_prints_one_line_and_no_traceback(world, tmp_path, argv, expect):
    bad = tmp_path / ("bad.ply" if "generate" in argv else "bad.csv")
    bad.write_bytes(cases.NOT_UTF8)
    values = {"bop": world.bop, "results": world.results, "out": tmp_path / "out" / "scores.json", "bad": bad}
    result = subprocess.run([sys.executable, "-m", "paz6d", *[part.format(**values) for part in argv]],
                            capture_output=True, text=True, cwd=REPO, timeout=120,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert result.returncode == 2
    assert cases.TRACEBACK not in result.stderr
    assert expect in result.stderr
    assert result.stderr.strip().count("\n") == 0, result.stderr  # one line
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------------ the Python API

def _api_cases():
    from paz6d.abstract.messages import Pose6D
    from paz6d.backend import quaternion
    from paz6d.backend.boxes import check_box_in_image
    from paz6d.backend.files import load_json, load_npz
    from paz6d.backend.paths import check_output_file, check_output_folder, check_outputs, check_plain_name, path_inside
    from paz6d.backend.pnp import solve_pnp
    from paz6d.datasets.sample import Sample, check_sample
    from paz6d.faces.haar import HaarCascadeDetector
    from paz6d.processors.crops import SquareCrop
    from paz6d.ssd.pipeline import DetectSingleShot

    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    points = np.random.default_rng(0).uniform(-0.05, 0.05, (10, 3))
    pixels = points[:, :2] / (points[:, 2:] + 0.5) * 500 + [320, 240]
    image = np.zeros((48, 64, 3), np.uint8)
    return {
        "pnp-nan-distortion": (lambda: solve_pnp(points, pixels, K, distortion=[np.nan] * 5), "distortion"),
        "pnp-short-distortion": (lambda: solve_pnp(points, pixels, K, distortion=[0.1, 0.2]), "distortion"),
        "pnp-confidence-2": (lambda: solve_pnp(points, pixels, K, ransac=True, confidence=2), "confidence"),
        "pnp-negative-threshold": (lambda: solve_pnp(points, pixels, K, reprojection_threshold=-1),
                                   "reprojection_threshold"),
        "pnp-zero-iterations": (lambda: solve_pnp(points, pixels, K, ransac=True, iterations=0), "iterations"),
        "pnp-identical-pixels": (lambda: solve_pnp(points, np.ones((10, 2)), K), "points2d"),
        "pnp-nan-pixels": (lambda: solve_pnp(points, np.full((10, 2), np.nan), K), "points2d"),
        "pnp-bad-K": (lambda: solve_pnp(points, pixels, np.zeros((3, 3))), "K"),
        "haar-scale-inf": (lambda: HaarCascadeDetector(scale_factor=float("inf")), "scale_factor"),
        "haar-scale-nan": (lambda: HaarCascadeDetector(scale_factor=float("nan")), "scale_factor"),
        "haar-scale-one": (lambda: HaarCascadeDetector(scale_factor=1.0), "scale_factor"),
        "pose-score-nan": (lambda: Pose6D([0, 0, 0, 1], [0, 0, 1], score=float("nan")), "score"),
        "pose-score-text": (lambda: Pose6D([0, 0, 0, 1], [0, 0, 1], score="high"), "score"),
        "pose-translation-inf": (lambda: Pose6D([0, 0, 0, 1], [0, 0, np.inf]), "translation"),
        "slerp-nan": (lambda: quaternion.slerp([0, 0, 0, 1], [0, 0, 1, 0], float("nan")), "t"),
        "box-huge": (lambda: check_box_in_image([-1e9, -1e9, 1e9, 1e9], 64, 48), "larger than"),
        "box-outside": (lambda: check_box_in_image([100, 100, 120, 120], 64, 48), "outside"),
        "box-empty": (lambda: check_box_in_image([10, 10, 10, 20], 64, 48), "empty"),
        "crop-huge-box": (lambda: SquareCrop(1.2, 32)(image, [-1e9, -1e9, 1e9, 1e9]), "larger than"),
        "crop-nan-box": (lambda: SquareCrop(1.2, 32)(image, [np.nan, 0, 10, 10]), "box"),
        "plain-name-parent": (lambda: check_plain_name("..", "split"), "split"),
        "plain-name-path": (lambda: check_plain_name("a/../../b", "split"), "split"),
        "output-file-device": (lambda: check_output_file("/dev/null", "--out"), "--out"),
        "output-folder-file": (lambda: check_output_folder(__file__, "--plots"), "--plots"),
        "json-folder": (lambda: load_json(REPO / "tests"), "tests"),
        "npz-not-zip": (lambda: load_npz(__file__), "test_bad_inputs.py"),
        "detector-run-dir-none": (lambda: DetectSingleShot(None), "run_dir"),
        "detector-max-detections-inf": (lambda: DetectSingleShot("run", max_detections=float("inf")),
                                        "max_detections"),
        "detector-max-detections-fraction": (lambda: DetectSingleShot("run", max_detections=2.7), "max_detections"),
        "detector-score-threshold-text": (lambda: DetectSingleShot("run", score_threshold="0.5"), "score_threshold"),
        "detector-iou-threshold-nan": (lambda: DetectSingleShot("run", iou_threshold=float("nan")), "iou_threshold"),
        "path-inside-parent": (lambda: path_inside(REPO, "../../etc/passwd", "a.json: file_name"),
                               "a.json: file_name: expected a relative path inside"),
        "path-inside-absolute": (lambda: path_inside(REPO, "/etc/passwd", "a.xml, field <filename>"), "<filename>"),
        "outputs-over-an-input-file": (lambda: check_outputs({"--out": REPO / "README.md"}, {"--dataset": REPO}),
                                       "a file of --dataset"),
        "outputs-folder-is-a-data-set": (lambda: check_outputs({}, {}, {"--out": REPO / "tests" / "data" / "datasets"
                                                                        / "coco"}), "COCO data set"),
        "sample-nan-box": (lambda: check_sample(Sample(image, np.array([[np.nan, 0, 4, 4]]), np.zeros(1, int), ["a"],
                                                       source="a.json: image id 1")),
                           "a.json: image id 1, box 0"),
        "sample-box-off-image": (lambda: check_sample(Sample(image, np.array([[100.0, 0, 120, 4]]), np.zeros(1, int),
                                                             ["a"])), "entirely outside the 64 x 48 px image"),
        "sample-size-not-the-image": (lambda: check_sample(Sample(image, np.zeros((0, 4)), np.zeros(0, int), [],
                                                                  extras={"image_size": (640, 48)})),
                                      "says 640 x 48 px"),
    }


API_CASES = _api_cases()


@pytest.mark.parametrize("name", sorted(API_CASES))
def test_python_api_raises_value_errors_naming_the_argument(name):
    call, expect = API_CASES[name]
    started = time.perf_counter()
    with pytest.raises(ValueError, match=expect.replace("(", r"\(")):
        call()
    assert time.perf_counter() - started < 1.0


def test_huge_rotation_vectors_give_finite_rotations():
    from paz6d.backend import quaternion

    assert np.all(np.isfinite(quaternion.from_rotation_vector([1e300, 0, 0])))


def test_readers_name_file_and_field(tmp_path):
    from paz6d.datasets.bop import load_models_info, load_scene_gt, read_pose_results, read_targets

    path = tmp_path / "scene_gt.json"
    path.write_text(json.dumps({"0": [{"cam_R_m2c": [1, 0, 0, 0, 1, 0, 0, 0, 1], "cam_t_m2c": [0, 0, 1],
                                       "obj_id": 1.5}]}))
    with pytest.raises(ValueError, match="scene_gt.json: image 0, instance 0: field 'obj_id' must be an integer"):
        load_scene_gt(path)
    path = tmp_path / "models_info.json"
    path.write_text(json.dumps({"1": {"diameter": -3}}))
    with pytest.raises(ValueError, match="models_info.json: object 1: field 'diameter' must be a positive number"):
        load_models_info(path)
    path = tmp_path / "targets.json"
    path.write_text(json.dumps([{"scene_id": 0, "im_id": 0, "obj_id": 1, "inst_count": 1}] * 2))
    with pytest.raises(ValueError, match="targets.json: target 1 repeats target 0"):
        read_targets(path)
    path = tmp_path / "results.csv"
    path.write_bytes(b"scene_id,im_id,obj_id,score,R,t,time\n0,0,1," + b"9" * 5_000_000
                     + b",1 0 0 0 1 0 0 0 1,0 0 1,-1\n")
    with pytest.raises(ValueError, match="results.csv:2") as error:
        read_pose_results(path)
    assert len(str(error.value)) < 500  # the 5 MB value is not echoed


def test_messages_are_shortened():
    from paz6d.cli_errors import report

    line = report("evaluate bop", ValueError("x" * 5_000_000))
    assert len(line) < 1100 and line.startswith("paz6d evaluate bop: error: x")


def test_os_errors_name_the_file_and_the_disk_being_full():
    import errno

    from paz6d.cli_errors import describe

    assert describe(OSError(errno.ENOSPC, "No space left on device", "/data/out.json")) == \
        "/data/out.json: no space left on device"
    assert describe(IsADirectoryError(errno.EISDIR, "Is a directory", "scores.json")) == "scores.json: Is a directory"


# ------------------------------------------------------------------------------------------ behaviour

def test_generate_workers_are_capped_at_the_usable_cores(monkeypatch):
    from data_gen import config

    monkeypatch.setattr(config, "usable_cores", lambda: 2)
    assert config.capped_workers(64, "local") == (2, "--workers 64 capped at 2, the number of usable CPU cores")
    assert config.capped_workers(2, "local") == (2, None)
    assert config.capped_workers(64, "ray") == (64, None)  # Ray actors may run on other machines


def test_resume_remakes_deleted_empty_and_unrecorded_files(world, tmp_path):
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    config = GenerationConfig(meshes=(world.mesh,), out=tmp_path / "set", num_images=3, width=64, height=48,
                              split="test", seed=3, objects_per_image=(2, 2), images_per_scene=2)
    generate(config, show_progress=False)
    files = {path: path.read_bytes() for path in config.out.rglob("*") if path.is_file()}
    scene = config.out / "test" / "000000"
    (scene / "rgb" / "000000.png").unlink()
    (scene / "depth" / "000001.png").write_bytes(b"")
    (config.out / ".paz6d-generate" / "shards" / "test" / "000001" / "000000.json").write_text("{broken")
    summary = generate(config, show_progress=False)
    assert summary.images_rendered == 3
    assert {path: path.read_bytes() for path in config.out.rglob("*") if path.is_file()} == files
    assert generate(config, show_progress=False).images_rendered == 0


def test_an_empty_results_file_scores_zero_with_a_note(world, tmp_path):
    results = tmp_path / "results.csv"
    results.write_text("scene_id,im_id,obj_id,score,R,t,time\n")
    outcome = cases.run_cli(["evaluate", "bop", "--dataset", str(world.bop), "--results", str(results),
                             "--out", str(tmp_path / "scores.json"), "--metrics", "mssd,mspd,add", "--no-progress"])
    assert outcome.code == 0 and outcome.exception is None
    assert "no estimates" in outcome.stderr
    scores = json.loads((tmp_path / "scores.json").read_text())
    assert scores["AR_MSSD"] == 0 and scores["AR_MSPD"] == 0 and "no estimates" in scores["note"]


def test_estimate_fails_when_every_estimate_failed(world, tmp_path, monkeypatch):
    from paz6d import split_estimation

    monkeypatch.setattr(split_estimation, "_estimator",
                        lambda run_dir, **options: lambda image, box, camera: None)
    out = tmp_path / "results.csv"
    outcome = cases.run_cli(["estimate", "--run", str(world.aae_run), "--dataset", str(world.bop), "--split", "test",
                             "--object-id", "1", "--out", str(out)])
    assert outcome.code == 2 and outcome.exception is None
    assert "every estimate failed (4 instances of object 1)" in outcome.stderr
    assert not out.exists()


def test_evaluate_bop_does_not_read_outside_the_data_set(world, tmp_path):
    outside = world.root / "cases" / "outside-split"
    shutil.rmtree(outside, ignore_errors=True)
    outcome = cases.run_cli(["evaluate", "bop", "--dataset", str(world.bop), "--split", "../cases/outside-split",
                             "--results", str(world.results), "--out", str(tmp_path / "s.json")])
    assert outcome.code == 2 and "--split: expected a plain folder name" in outcome.stderr


def test_a_moved_data_set_resumes_when_its_inputs_moved_with_it(world, tmp_path):
    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    first = tmp_path / "first"
    first.mkdir()
    shutil.copy(world.mesh, first / "obj_000001.ply")
    settings = dict(num_images=1, width=64, height=48, seed=3, objects_per_image=(1, 1))
    generate(GenerationConfig(meshes=(first / "obj_000001.ply",), out=first / "set", **settings), show_progress=False)
    moved = tmp_path / "moved"
    first.rename(moved)
    config = GenerationConfig(meshes=(moved / "obj_000001.ply",), out=moved / "set", **settings)
    assert generate(config, show_progress=False).images_rendered == 0
    trimesh.creation.box((0.05, 0.04, 0.031)).export(moved / "obj_000001.ply")  # another object, same path
    with pytest.raises(ValueError, match="input_contents differ"):
        generate(config, show_progress=False)
