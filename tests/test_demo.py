"""The demo: the procedural object is asymmetric and written in BOP units; a toy-sized run of the whole
pipeline (generate -> train -> estimate -> score -> report/plots) works and its report is consistent."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from paz6d.assets.demo_object import make_demo_mesh, write_demo_object
from paz6d.backend.mesh import diameter, load_mesh


def test_demo_object_has_no_rotational_symmetry():
    """With distinct principal moments, a symmetry rotation must map principal axes onto themselves: only
    the three 180-degree turns about them are candidates, and none maps the surface onto itself."""
    mesh = make_demo_mesh()
    points = trimesh.sample.sample_surface_even(mesh, 3000, seed=0)[0]
    centred = points - points.mean(axis=0)
    moments, axes = np.linalg.eigh(centred.T @ centred / len(centred))
    assert np.min(np.diff(moments)) > 0.05 * moments.max()
    from scipy.spatial import cKDTree

    tree = cKDTree(centred)
    for axis in axes.T:
        flip = 2 * np.outer(axis, axis) - np.eye(3)  # 180 degrees about `axis`
        distances, _ = tree.query(centred @ flip.T)
        assert distances.mean() > 0.003  # metres; sampling spacing is ~1.5 mm


def test_demo_object_files_are_bop_millimetres(tmp_path):
    path = write_demo_object(tmp_path)
    info = json.loads((tmp_path / "models_info.json").read_text())["1"]
    metres = load_mesh(path, 0.001)
    assert info["diameter"] == pytest.approx(1000 * diameter(metres.vertices), rel=1e-6)  # PLY stores float32
    assert 0.08 < info["diameter"] / 1000 < 0.2
    assert metres.visual.vertex_colors.shape[0] == len(metres.vertices)
    assert len(np.unique(metres.visual.vertex_colors[:, :3], axis=0)) >= 10  # textured, not one flat colour


def test_demo_smoke_run(tmp_path):
    from paz6d.demo.aae_demo import run_demo
    from paz6d.aae.config import QUICK
    from paz6d.aae.config import Augmentation

    toy = replace(QUICK, crop_size=16, latent_size=16, filters=(8, 16), kernel_size=3, render_size=40, views=24,
                  in_plane=6, steps=20, batch_size=8, learning_rate=2e-3, bootstrap_fraction=0.25,
                  checkpoint_every=10, sample_every=10, log_every=5, augmentation=Augmentation())
    report = run_demo(tmp_path, toy, test_images=3, workers=0, grid_rows=2, train_images=4, scene_crops=0.5)
    for name in ("report.json", "recall_curves.png", "estimates_grid.png", "mesh/obj_000001.ply",
                 "mesh/models_info.json", "model/model.keras", "model/codebook.npz", "model/pairs.npz"):
        assert (tmp_path / name).is_file(), name
    # the AAE was trained on crops of the generated training scenes (seed 0), not of the test images
    stored_run = json.loads((tmp_path / "model" / "config.json").read_text())
    assert stored_run["dataset"] == str((tmp_path / "train_data").resolve())
    assert len(list((tmp_path / "train_data" / "train").glob("*/rgb/*"))) == 4
    assert report["train_images"] == 4 and report["scene_crops"] == 0.5
    stored = json.loads((tmp_path / "report.json").read_text())
    metrics = stored["metrics"]
    estimates = stored["estimates"]
    assert metrics["count"] == len(estimates) == report["metrics"]["count"] >= 1
    add = np.array([e["error_m"] for e in estimates])
    rotation = np.array([e["rotation_error_deg"] for e in estimates])
    assert metrics["metric"] == "ADD" and metrics["failures"] == 0
    assert metrics["recall_0.1d"] == pytest.approx(np.mean(add < 0.1 * metrics["diameter_m"]))
    assert metrics["rotation_error_deg"]["median"] == pytest.approx(np.median(rotation))
    assert sum(b["count"] for b in metrics["by_visible_fraction"].values()) == metrics["count"]
    # the stored ADD agrees with a direct computation from the stored poses and the mesh vertices
    vertices = load_mesh(tmp_path / "mesh" / "obj_000001.ply", 0.001).vertices
    first = estimates[0]
    T_est, T_gt = np.array(first["T_est"]), np.array(first["T_gt"])
    direct = np.mean(np.linalg.norm(vertices @ T_est[:3, :3].T + T_est[:3, 3] - vertices @ T_gt[:3, :3].T - T_gt[:3, 3],
                                    axis=1))
    assert first["error_m"] == pytest.approx(direct, rel=1e-9)
    # the model directory is an ImplicitPose6D run dir
    from paz6d.aae.pipeline import ImplicitPose6D

    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    assert ImplicitPose6D(tmp_path / "model", K).crop_size == 16
    # re-running the finished demo (as `paz6d demo` does, OOD check included) trains nothing: the
    # unmeasured throughput is written as null, not inf
    from paz6d.demo.command import DemoOptions, run_demos
    from paz6d.demo.ood_set import CONDITIONS

    again = run_demos(DemoOptions(out=tmp_path, test_images=3, workers=1, ood_images=2, train_images=4,
                                  scene_crops=0.5), toy)
    stored = json.loads((tmp_path / "report.json").read_text())
    assert again["training"]["steps"] == 20 and stored["training"]["model_samples_per_second"] is None
    assert stored["metrics"]["recall_0.1d"] == metrics["recall_0.1d"]
    # the report carries the out-of-distribution check of the AAE, every condition with a verdict
    check = stored["ood_check"]
    assert check["views"] == 2 and check["conditions"] == list(CONDITIONS) and list(check["models"]) == ["AAE"]
    aae = check["models"]["AAE"]
    assert aae["in_distribution_style"] == "clutter" and list(aae["conditions"]) == list(CONDITIONS[1:])
    for verdict in aae["conditions"].values():
        assert verdict["recall"] in (0.0, 0.5, 1.0) and isinstance(verdict["pass"], bool)
    assert aae["pass"] == all(verdict["pass"] for verdict in aae["conditions"].values())
    assert (tmp_path / "ood_check.png").is_file() and check["chart"] == str(tmp_path / "ood_check.png")


def test_demo_keypoints_option_runs_the_keypoint_demo_on_the_demo_mesh(tmp_path, monkeypatch):
    import paz6d.demo.aae_demo as demo
    import paz6d.demo.keypoint_demo as keypoint_demo
    import paz6d.demo.ood_check as ood_check
    from paz6d.cli import build_parser

    calls = {}
    mesh = tmp_path / "mesh" / "obj_000001.ply"
    def fake_run_demo(out, config, test_images, workers, platform, train_images, scene_crops):
        calls.setdefault("aae", (out, test_images, train_images, scene_crops))
        return {"files": {"mesh": str(mesh), "model": str(out / "model")}}

    monkeypatch.setattr(demo, "run_demo", fake_run_demo)
    monkeypatch.setattr(keypoint_demo, "run_keypoint_demo",
                        lambda out_dir, mesh_path,
                        **options: calls.setdefault("keypoints", (out_dir, mesh_path, options)))
    monkeypatch.setattr(ood_check, "run_check", lambda out, mesh_path, models, count, mesh_scale, workers:
                        calls.setdefault("ood", (models, count)) and {"chart": str(out / "ood_check.png")})
    args = build_parser().parse_args(["demo", "--out", str(tmp_path), "--test-images", "7", "--keypoints",
                                      "--ood-images", "5"])
    assert args._run(args) == 0
    out_dir, mesh_path, options = calls["keypoints"]
    assert out_dir == tmp_path / "keypoints" and mesh_path == mesh
    assert options["mesh_scale"] == 0.001 and options["test_images"] == 7 and options["config"] == "quick"
    assert calls["aae"][1:] == (7, 2000, 0.0)  # rendered views only by default
    models, count = calls["ood"]
    assert count == 5 and [(m.name, m.kind) for m in models] == [("AAE", "aae"), ("KeypointNet", "keypointnet")]
    assert models[1].run_dir == tmp_path / "keypoints" / "keypointnet_supervised"
    assert "ood_check" in json.loads((tmp_path / "report.json").read_text())
    calls.clear()
    args = build_parser().parse_args(["demo", "--out", str(tmp_path), "--keypoints", "--keypoint-config", "robust"])
    args._run(args)
    assert calls["keypoints"][2]["config"] == "robust"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["demo", "--keypoints", "--keypoint-config", "full"])
    (tmp_path / "plain").mkdir()
    args = build_parser().parse_args(["demo", "--out", str(tmp_path / "plain"), "--scene-crops", "0.25",
                                      "--train-images", "300"])
    calls.clear()
    args._run(args)
    assert "keypoints" not in calls and [m.name for m in calls["ood"][0]] == ["AAE"]
    assert calls["aae"][2:] == (300, 0.25)


def test_one_scorer_one_key_set_and_unmeasured_values_written_as_null(tmp_path, capsys):
    from paz6d.demo.report import pose_rows, print_rows, score_poses, write_report

    points = np.random.default_rng(0).uniform(-0.05, 0.05, (200, 3))
    T_gt = np.tile(np.eye(4), (3, 1, 1))
    T_gt[:, 2, 3] = 0.5
    shifted = T_gt[1].copy()
    shifted[2, 3] += 0.02  # 2 cm along z: ADD 0.02 m = 0.2 d
    scores = score_poses([T_gt[0], shifted, None], T_gt, points, diameter=0.1)
    metrics = scores.metrics
    assert metrics.keys() == score_poses([T_gt[0], shifted, None], T_gt, points, 0.1, symmetric=True).metrics.keys()
    assert metrics["metric"] == "ADD" and metrics["count"] == 3 and metrics["failures"] == 1
    assert metrics["recall_0.1d"] == pytest.approx(1 / 3) and metrics["z_error_m_median"] == pytest.approx(0.02)
    assert np.isinf(scores.errors_m[2]) and scores.errors_m[1] == pytest.approx(0.02)
    write_report(tmp_path / "report.json", {"metrics": metrics, "speed": float("inf")})
    stored = json.loads((tmp_path / "report.json").read_text())
    assert stored["speed"] is None and stored["metrics"]["translation_error_m"]["mean"] is None  # a miss: inf
    assert stored["metrics"]["translation_error_m"]["median"] == pytest.approx(0.02)
    print_rows(pose_rows(stored["metrics"], ", PnP"))
    assert "ADD recall @ 0.1 d, PnP" in capsys.readouterr().out


def test_the_demos_do_not_import_each_other():
    import subprocess
    import sys

    def demo_modules_after_importing(module: str) -> list[str]:
        code = f"import sys, {module}; print([m for m in sorted(sys.modules) if m.startswith('paz6d.demo.')])"
        return json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                         check=True).stdout.replace("'", '"'))

    assert demo_modules_after_importing("paz6d.demo.keypoint_demo") == ["paz6d.demo.keypoint_demo",
                                                                        "paz6d.demo.report"]
    assert demo_modules_after_importing("paz6d.demo.aae_demo") == ["paz6d.demo.aae_demo", "paz6d.demo.report"]
