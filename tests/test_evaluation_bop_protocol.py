"""BOP'19 protocol on hand-made data sets with known answers: top-k selection, visibility rule,
greedy matching, symmetries, thresholds, VSD from rendered depth, and the ``evaluate bop`` CLI."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

from evaluation import bop
from evaluation.bop_data import load_evaluation_data
from paz6d.cli import main
from paz6d.datasets.bop.results import read_pose_results, write_pose_results

SIDE = 100.0  # mm
DIAMETER = SIDE * np.sqrt(2.0)
FX = 500.0
FLIP_Z = np.diag([-1.0, -1.0, 1.0, 1.0])  # 180 degrees about z: a symmetry of the square plate


def plate() -> trimesh.Trimesh:
    half = SIDE / 2
    return trimesh.Trimesh(vertices=[[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]],
                           faces=[[0, 1, 2], [0, 2, 3]], process=False)


def pose(x: float, y: float, z: float = 1000.0, T_extra: np.ndarray | None = None) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T if T_extra is None else T @ T_extra


def write_dataset(root: Path, meshes: dict[int, trimesh.Trimesh], diameters: dict[int, float],
                  symmetric: set[int], images: dict[int, list[tuple[int, np.ndarray, float]]],
                  targets: list[tuple[int, int, int]], depth: dict[int, np.ndarray] | None = None,
                  width: int = 640, height: int = 480) -> Path:
    """Writes a one-scene BOP data set: images = {im_id: [(obj_id, T (mm), visib_fract), ...]},
    targets = [(im_id, obj_id, inst_count)], depth = {im_id: depth in mm} (stored in 0.1 mm)."""
    (root / "models_eval").mkdir(parents=True)
    info = {}
    for obj_id, mesh in meshes.items():
        mesh.export(root / "models_eval" / f"obj_{obj_id:06d}.ply")
        info[str(obj_id)] = {"diameter": diameters[obj_id]}
        if obj_id in symmetric:
            info[str(obj_id)]["symmetries_discrete"] = [FLIP_Z.ravel().tolist()]
    (root / "models_eval" / "models_info.json").write_text(json.dumps(info))
    (root / "camera.json").write_text(json.dumps({"fx": FX, "fy": FX, "cx": width / 2 - 0.5, "cy": height / 2 - 0.5,
                                                  "width": width, "height": height, "depth_scale": 0.1}))
    scene = root / "test" / "000001"
    scene.mkdir(parents=True)
    K = [FX, 0.0, width / 2 - 0.5, 0.0, FX, height / 2 - 0.5, 0.0, 0.0, 1.0]
    gt, camera, gt_info = {}, {}, {}
    for im_id, instances in images.items():
        gt[str(im_id)] = [{"obj_id": obj_id, "cam_R_m2c": T[:3, :3].ravel().tolist(), "cam_t_m2c": T[:3, 3].tolist()}
                          for obj_id, T, _ in instances]
        camera[str(im_id)] = {"cam_K": K, "depth_scale": 0.1}
        gt_info[str(im_id)] = [{"bbox_obj": [0, 0, 1, 1], "bbox_visib": [0, 0, 1, 1], "px_count_all": 1,
                                "px_count_valid": 1, "px_count_visib": 1, "visib_fract": visib}
                               for _, _, visib in instances]
    (scene / "scene_gt.json").write_text(json.dumps(gt))
    (scene / "scene_camera.json").write_text(json.dumps(camera))
    (scene / "scene_gt_info.json").write_text(json.dumps(gt_info))
    (root / "test_targets_bop19.json").write_text(json.dumps(
        [{"scene_id": 1, "im_id": im_id, "obj_id": obj_id, "inst_count": count} for im_id, obj_id, count in targets]))
    if depth:
        (scene / "depth").mkdir()
        for im_id, depth_mm in depth.items():
            cv2.imwrite(str(scene / "depth" / f"{im_id:06d}.png"), np.round(depth_mm * 10).astype(np.uint16))
    return root


def write_results(path: Path, estimates: list[tuple[int, int, float, np.ndarray]]) -> Path:
    """estimates = [(im_id, obj_id, score, T (mm)), ...] of scene 1."""
    T = np.array([estimate[3] for estimate in estimates])
    return write_pose_results(path, [1] * len(estimates), [e[0] for e in estimates], [e[1] for e in estimates],
                              [e[2] for e in estimates], T[:, :3, :3], T[:, :3, 3], units="mm")


# Shifts along x (fractions of the diameter): a plate facing the camera at 1000 mm then has
# MSSD = ADD = shift (mm) and MSPD = FX * shift / 1000 px exactly.
SHIFTS = {"e1": 0.12, "e2": 0.33, "e5": 0.60, "e6": 0.04}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    A, B, C = pose(-150, 0), pose(150, 0), pose(0, 120)
    images = {1: [(1, A, 0.9), (1, B, 0.5), (2, C, 0.05)], 2: [(1, pose(0, 0), 1.0)], 3: [(1, pose(0, -50), 0.8)]}
    targets = [(1, 1, 2), (1, 2, 1), (2, 1, 1), (3, 1, 1)]
    write_dataset(root / "data", {1: plate(), 2: plate()}, {1: DIAMETER, 2: DIAMETER}, {2}, images, targets)
    shift = {name: value * DIAMETER for name, value in SHIFTS.items()}
    estimates = [
        (1, 1, 0.9, pose(-150 + shift["e1"], 0)),   # e1 -> A
        (1, 1, 0.8, pose(150 + shift["e2"], 0)),    # e2 -> B
        (1, 1, 0.1, pose(150, 0)),                  # e3: exact B, but only inst_count = 2 estimates count
        (1, 2, 0.7, pose(0, 120, T_extra=FLIP_Z)),  # e4: symmetric pose of C (C has visib 0.05)
        (2, 1, 0.5, pose(shift["e5"], 0)),          # e5
        (3, 1, 0.6, pose(shift["e6"], -50)),        # e6
        (2, 2, 0.9, pose(0, 0)),                    # not a target: ignored
    ]
    results_path = write_results(root / "results.csv", estimates)
    return root / "data", results_path


def evaluate_tiny(tiny, **settings):
    data = load_evaluation_data(tiny[0])
    results = read_pose_results(tiny[1], object_ids=data.object_ids, image_ids=data.images.keys(), units="mm")
    return bop.evaluate(data, results, bop.BopSettings(metrics=("mssd", "mspd", "add"), **settings))


def test_average_recalls_of_the_hand_made_case(tiny):
    evaluation = evaluate_tiny(tiny, visib_gt_min=0.1)
    # 4 counted instances (C is 5 % visible). MSSD < t*d for t in 0.05..0.5: e1 (0.12) 8 thresholds,
    # e2 (0.33) 4, e5 (0.6) none, e6 (0.04) all 10 -> 22 / 40.
    assert evaluation.counts["gt_instances"] == 4
    assert evaluation.metrics["mssd"].average == pytest.approx(22 / 40, abs=1e-12)
    # MSPD = 0.5 * shift px < 5..50 px: e1 8.49 px -> 9, e2 23.3 -> 6, e5 42.4 -> 2, e6 2.83 -> 10.
    assert evaluation.metrics["mspd"].average == pytest.approx(27 / 40, abs=1e-12)
    assert evaluation.add_recall == pytest.approx(1 / 4, abs=1e-12)
    assert evaluation.metrics["mssd"].object_averages() == {1: pytest.approx(22 / 40)}
    np.testing.assert_allclose(evaluation.metrics["mssd"].recalls, np.array([1, 1, 2, 2, 2, 2, 3, 3, 3, 3]) / 4)
    # AUC over 0-100 mm of ADD (= shift) and ADD-S (a 4-corner plate shifted by s > 50 mm has
    # ADI = (s + (100 - s)) / 2 = 50 mm).
    shifts = np.array([SHIFTS[name] for name in ("e1", "e2", "e5", "e6")]) * DIAMETER
    adi = np.where(shifts > 50, 50.0, shifts)
    assert evaluation.aucs["ADD"] == pytest.approx(np.mean(1 - shifts / 100), abs=1e-12)
    assert evaluation.aucs["ADD-S"] == pytest.approx(np.mean(1 - adi / 100), abs=1e-12)
    assert evaluation.aucs["ADD(-S)"] == pytest.approx(evaluation.aucs["ADD"], abs=1e-12)
    assert "AR" not in evaluation.average_recalls  # VSD not computed


def test_most_visible_rule_counts_the_barely_visible_symmetric_instance(tiny):
    evaluation = evaluate_tiny(tiny, visib_gt_min=-1)
    assert evaluation.counts["gt_instances"] == 5
    # e4 matches C through the symmetry: MSSD = MSPD = ADI = 0, ADD = the plate's diagonal.
    assert evaluation.metrics["mssd"].average == pytest.approx(32 / 50, abs=1e-12)
    assert evaluation.metrics["mspd"].average == pytest.approx(37 / 50, abs=1e-12)
    assert evaluation.add_recall == pytest.approx(2 / 5, abs=1e-12)
    assert evaluation.metrics["mssd"].object_averages()[2] == 1.0
    rows = {(row["im_id"], row["obj_id"]): row for row in evaluation.error_rows()}
    assert rows[(1, 2)]["mssd"] == pytest.approx(0, abs=1e-9) and rows[(1, 2)]["adi"] == pytest.approx(0, abs=1e-9)
    assert rows[(1, 2)]["add"] == pytest.approx(DIAMETER) and rows[(1, 2)]["re"] == pytest.approx(180.0)


def test_results_order_does_not_change_the_scores(tiny, tmp_path):
    data = load_evaluation_data(tiny[0])
    results = read_pose_results(tiny[1], units="mm")
    reversed_path = tmp_path / "reversed.csv"
    with open(tiny[1]) as file:
        lines = file.read().splitlines()
    reversed_path.write_text("\n".join([lines[0]] + lines[:0:-1]) + "\n")
    settings = bop.BopSettings(metrics=("mssd", "mspd", "add"))
    first = bop.evaluate(data, results, settings).to_dict()
    second = bop.evaluate(data, read_pose_results(reversed_path, units="mm"), settings).to_dict()
    assert first == second


def test_results_read_in_metres_are_rejected(tiny):
    data = load_evaluation_data(tiny[0])
    with pytest.raises(ValueError, match="results: expected translations in millimetres"):
        bop.evaluate(data, read_pose_results(tiny[1]), bop.BopSettings(metrics=("mssd",)))


def reference_match(errors: dict[int, dict[int, float]], scores: dict[int, float], top: int, threshold: float):
    """Literal BOP greedy matching for one target: {estimate: gt} (estimates by decreasing score,
    stable; each takes the unmatched GT with the smallest error below the threshold)."""
    order = sorted(errors, key=lambda estimate: -scores[estimate])[:top]
    taken, matches = set(), {}
    for estimate in order:
        best, best_error = None, threshold
        for gt in sorted(errors[estimate]):
            if gt not in taken and errors[estimate][gt] < best_error:
                best, best_error = gt, errors[estimate][gt]
        if best is not None:
            taken.add(best)
            matches[estimate] = best
    return matches


def test_greedy_matching_equals_the_literal_loop_on_random_groups():
    generator = np.random.default_rng(5)
    thresholds = np.array([0.1, 0.25, 0.5, 0.75, np.inf])
    for _ in range(200):
        groups = generator.integers(1, 4)
        estimate_rows, gt_rows, group_rows, rank_rows, error_rows = [], [], [], [], []
        expected = []
        next_estimate = next_gt = 0
        for group in range(groups):
            estimates = list(range(next_estimate, next_estimate + generator.integers(1, 5)))
            gts = list(range(next_gt, next_gt + generator.integers(1, 5)))
            next_estimate, next_gt = estimates[-1] + 1, gts[-1] + 1
            scores = {e: float(generator.choice([0.2, 0.5, 0.9])) for e in estimates}  # ties on purpose
            errors = {e: {g: float(np.round(generator.random(), 1)) for g in gts} for e in estimates}
            top = int(generator.integers(1, len(estimates) + 1))
            order = sorted(estimates, key=lambda e: -scores[e])[:top]
            for rank, estimate in enumerate(order):
                for gt in gts:
                    estimate_rows.append(estimate)
                    gt_rows.append(gt)
                    group_rows.append(group)
                    rank_rows.append(rank)
                    error_rows.append(errors[estimate][gt])
            expected.append((errors, scores, top))
        pairs = bop.EvaluationPairs(np.array(estimate_rows), np.array(gt_rows), np.array(group_rows),
                                    np.array(rank_rows))
        matched = bop.greedy_match(pairs, np.array(error_rows), thresholds)
        for column, threshold in enumerate(thresholds):
            ours = {(int(pairs.estimate[row]), int(pairs.gt[row])) for row in np.flatnonzero(matched[:, column])}
            reference = set()
            for errors, scores, top in expected:
                reference |= set(reference_match(errors, scores, top, threshold).items())
            assert ours == reference


def test_cli_writes_json_errors_and_plots(tiny, tmp_path, capsys):
    out, errors_csv, plots = tmp_path / "out.json", tmp_path / "errors.csv", tmp_path / "plots"
    code = main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(tiny[1]), "--out", str(out),
                 "--errors", str(errors_csv), "--plots", str(plots), "--no-progress"])
    assert code == 0
    captured = capsys.readouterr()
    assert "skipping VSD" in captured.err and "AR_MSSD" in captured.out
    summary = json.loads(out.read_text())
    # Default: the BOP toolkit's rule (visib_gt_min -1), which also counts the 5 % visible instance C.
    assert summary["settings"]["visib_gt_min"] == -1 and summary["counts"]["gt_instances"] == 5
    assert summary["AR_MSSD"] == pytest.approx(32 / 50) and summary["AR_MSPD"] == pytest.approx(37 / 50)
    assert "AR" not in summary and "AR_VSD" not in summary and "vsd" in summary["skipped_metrics"]
    assert summary["ADD(-S)_recall"] == pytest.approx(0.4)
    assert summary["per_object"]["1"]["AR_MSSD"] == pytest.approx(22 / 40)
    with open(errors_csv) as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == ["scene_id", "im_id", "obj_id", "score", "add", "adi", "mssd", "mspd", "re", "te", "proj"]
    assert [(row["im_id"], row["score"]) for row in rows] == [("1", "0.9"), ("1", "0.8"), ("1", "0.7"), ("2", "0.5"),
                                                             ("3", "0.6")]
    assert float(rows[1]["mssd"]) == pytest.approx(SHIFTS["e2"] * DIAMETER, abs=1e-9)
    assert float(rows[1]["mspd"]) == pytest.approx(FX * SHIFTS["e2"] * DIAMETER / 1000, abs=1e-9)
    assert sorted(path.name for path in plots.iterdir()) == ["accuracy_add.png", "recall_add.png",
                                                            "recall_mspd.png", "recall_mssd.png"]
    assert all(path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for path in plots.iterdir())
    assert main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(tiny[1]), "--out", str(out),
                 "--visib-gt-min", "0.1", "--metrics", "mssd,mspd", "--no-progress"]) == 0
    summary = json.loads(out.read_text())
    assert summary["counts"]["gt_instances"] == 4 and summary["AR_MSSD"] == pytest.approx(22 / 40)


def test_cli_rejects_vsd_without_depth_and_bad_rows(tiny, tmp_path, capsys):
    out = tmp_path / "out.json"
    code = main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(tiny[1]), "--out", str(out),
                 "--metrics", "vsd,mssd", "--no-progress"])
    assert code == 2 and "VSD needs depth images" in capsys.readouterr().err and not out.exists()
    broken = tmp_path / "broken.csv"
    broken.write_text(tiny[1].read_text() + "1,1,1,0.5,1 0 0 0 1 0 0 0 1,0 0 nan,-1\n"
                      "1,1,9,0.5,1 0 0 0 1 0 0 0 1,0 0 1,-1\n")
    code = main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(broken), "--out", str(out),
                 "--metrics", "mssd", "--no-progress"])
    assert code == 2 and f"{broken}:9: field 't'" in capsys.readouterr().err
    code = main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(broken), "--out", str(out),
                 "--metrics", "mssd", "--skip-invalid", "--no-progress"])
    assert code == 0
    summary = json.loads(out.read_text())
    assert summary["counts"]["estimates_skipped_invalid"] == 2
    assert [row["line"] for row in summary["skipped_rows"]] == [9, 10]
    assert "unknown object id 9" in summary["skipped_rows"][1]["reason"]
    assert summary["AR_MSSD"] == pytest.approx(32 / 50)


def test_cli_rejects_a_targets_file_listing_a_target_twice(tiny, tmp_path, capsys):
    # Counted twice, the instances of image 2 would give recalls above 1.
    targets = json.loads((tiny[0] / "test_targets_bop19.json").read_text())
    duplicated = tmp_path / "targets.json"
    duplicated.write_text(json.dumps(targets + [targets[2]]))
    out = tmp_path / "out.json"
    assert main(["evaluate", "bop", "--dataset", str(tiny[0]), "--results", str(tiny[1]), "--targets", str(duplicated),
                 "--out", str(out), "--no-progress"]) == 2
    assert f"{duplicated}: target 4 repeats target 2: scene 1, image 2, object 1" in capsys.readouterr().err
    assert not out.exists()


# --- VSD through the protocol, with depth images rendered from the ground truth ------------------

@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    renderers = pytest.importorskip("renderers")
    width, height = 160, 120
    try:
        renderer = renderers.Renderer(width, height, antialias="none")
    except renderers.PlatformUnavailableError as error:
        pytest.skip(f"no offscreen OpenGL: {error}")
    box_mm = trimesh.creation.box((60.0, 40.0, 30.0))
    box_m = box_mm.copy()
    box_m.apply_scale(0.001)
    diameter = float(np.sqrt(60.0**2 + 40.0**2 + 30.0**2))
    K = np.array([[FX / 4, 0, width / 2 - 0.5], [0, FX / 4, height / 2 - 0.5], [0, 0, 1]])
    rotation = trimesh.transformations.rotation_matrix(0.5, [1.0, 1.0, 0.0])
    poses = {1: pose(-40, 10, 600, rotation), 2: pose(30, -15, 650, rotation)}
    depth = {}
    with renderer:
        for im_id, T in poses.items():
            T_m = T.copy()
            T_m[:3, 3] /= 1000
            depth[im_id] = renderer.render(K, [(box_m, T_m)], rgb=False, masks=False).depth.astype(np.float64) * 1000
    root = tmp_path_factory.mktemp("vsd")
    for T in poses.values():  # stored rounded, as BOP ground truth is (not exactly orthonormal)
        T[:3, :3] = np.round(T[:3, :3], 3)
    assert max(np.abs(T[:3, :3].T @ T[:3, :3] - np.eye(3)).max() for T in poses.values()) > 1e-4
    images = {im_id: [(1, T, 1.0)] for im_id, T in poses.items()}
    write_dataset(root / "data", {1: box_mm}, {1: diameter}, set(), images, [(1, 1, 1), (2, 1, 1)], depth,
                  width, height)
    return root, poses, diameter


def test_vsd_average_recall_from_dataset_depth(rendered, capsys):
    root, poses, diameter = rendered
    exact = write_results(root / "exact.csv", [(im_id, 1, 0.5, T) for im_id, T in poses.items()])
    out = root / "exact.json"
    assert main(["evaluate", "bop", "--dataset", str(root / "data"), "--results", str(exact), "--out", str(out),
                 "--no-progress"]) == 0
    summary = json.loads(out.read_text())
    assert summary["AR_VSD"] == 1.0 and summary["AR"] == 1.0 and summary["skipped_metrics"] == {}
    # Second image: the estimate is moved sideways by 1.5 diameters, so the silhouettes do not
    # overlap (VSD = 1 at every tau): half of the targets are found at every threshold.
    far = dict(poses)
    far[2] = poses[2] @ pose(1.5 * diameter, 0, 0)
    moved = write_results(root / "moved.csv", [(im_id, 1, 0.5, T) for im_id, T in far.items()])
    out = root / "moved.json"
    assert main(["evaluate", "bop", "--dataset", str(root / "data"), "--results", str(moved), "--out", str(out),
                 "--metrics", "vsd", "--no-progress"]) == 0
    summary = json.loads(out.read_text())
    assert summary["AR_VSD"] == 0.5 and "AR" not in summary
    assert summary["per_object"]["1"]["AR_VSD"] == 0.5
