"""`paz6d benchmark lmo`: stage order, skip/resume logic, settings check and the report (stages mocked), and
(slow) one tiny real run of every stage on the shared LM-O data."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from paz6d.benchmark import lmo
from paz6d.benchmark.lmo import Benchmark, BenchmarkSettings, run_benchmark, score_table, stages
from paz6d.keypointnet.config import QUICK as KEYPOINT_QUICK, ROBUST as KEYPOINT_ROBUST

TINY = BenchmarkSettings(images=6, backgrounds=3, detector_steps=4, aae_steps=4, aae_in_plane=4,
                         keypointnet_steps=4, keypointnet_views=8, workers=1, aae_views=12, detector_input_size=128,
                         keypointnet_robust_steps=5, keypointnet_robust_views=9, validation_images=3)


#: the mocked estimate and evaluate stages of one run, in order
SCORING = ["estimate gt", "evaluate gt", "estimate detections", "evaluate detections", "estimate synthetic",
           "evaluate synthetic", "estimate synthetic_detections", "evaluate synthetic_detections"]


def _fake_lmo(root: Path, objects=(1, 5)) -> Path:
    (root / "models").mkdir(parents=True)
    for obj_id in objects:
        (root / "models" / f"obj_{obj_id:06d}.ply").write_text("ply\n")
    (root / "test").mkdir()
    return root


@pytest.fixture
def mocked(tmp_path, monkeypatch):
    """Every stage replaced by one that writes its outputs and records the call."""
    calls = []

    def touch(path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("{}") if path.suffix else path.mkdir(exist_ok=True)

    monkeypatch.setattr(lmo, "_stage_backgrounds", lambda job: (calls.append("backgrounds"),
                                                                 touch(job.out / "backgrounds"))[0] or {})
    monkeypatch.setattr(lmo, "_stage_synthetic", lambda job: (calls.append("synthetic"),
                                                               touch(job.out / "synthetic" / "camera.json"))[0] or {})
    monkeypatch.setattr(lmo, "_stage_validation", lambda job: (calls.append("validation"),
                                                                 touch(job.out / "validation" / "camera.json"))[0]
                        or {})
    monkeypatch.setattr(lmo, "_stage_detector", lambda job: (calls.append("detector"),
                                                              touch(job.out / "detector" / "model.keras"))[0] or {})
    monkeypatch.setattr(lmo, "_stage_pose", lambda job, obj_id: (calls.append(f"pose {obj_id}"),
                                                                  touch(job.pose_dir(obj_id)))[0] or {})

    def estimate(job, condition):
        calls.append(f"estimate {condition}")
        touch(job.result(condition, ".csv"))
        unusable = {"5": "keypoints.json: only 2 usable keypoints"} if job.method == "keypointnet" else {}
        return {"command": lmo._estimate_args(job, condition), "estimates": 3, "unusable": unusable}

    def evaluate(job, condition):
        calls.append(f"evaluate {condition}")
        scores = {"AR_MSSD": 0.2, "AR_MSPD": 0.4, "ADD(-S)_recall": 0.1, "counts": {"gt_instances": 4},
                  "per_object": {"1": {"instances": 2, "AR_MSSD": 0.1, "AR_MSPD": 0.3, "ADD(-S)_recall": 0.0},
                                 "5": {"instances": 2, "AR_MSSD": 0.3, "AR_MSPD": 0.5, "ADD(-S)_recall": 0.2}}}
        path = job.result(condition, "_scores.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(scores))
        return {}

    monkeypatch.setattr(lmo, "_stage_estimate", estimate)
    monkeypatch.setattr(lmo, "_stage_evaluate", evaluate)
    monkeypatch.setattr(lmo, "_stage_detection_ap", lambda job: (calls.append("detector ap"), touch(
        job.out / "results" / "detector_coco.json"))[0] or {})
    monkeypatch.setattr(lmo, "_overlays", lambda job, condition: [])
    monkeypatch.setattr("paz6d.backend.tensorflow_guard.import_tensorflow", lambda: None)
    return _fake_lmo(tmp_path / "lmo"), calls


def test_stages_run_in_order_once_and_a_rerun_skips_every_finished_one(mocked, tmp_path):
    data, calls = mocked
    job = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    assert [name for name, _, _ in stages(job)] == [
        "backgrounds", "synthetic", "validation", "detector", "pose/obj_000001", "pose/obj_000005", "estimate_aae_gt",
        "evaluate_aae_gt", "estimate_aae_detections", "evaluate_aae_detections", "estimate_aae_synthetic",
        "evaluate_aae_synthetic", "estimate_aae_synthetic_detections", "evaluate_aae_synthetic_detections",
        "detector_ap_aae"]
    report = run_benchmark(job)
    assert calls == ["backgrounds", "synthetic", "validation", "detector", "pose 1", "pose 5", *SCORING,
                     "detector ap"]
    assert sorted(report["methods"]["aae"]) == ["detections", "gt_visible_boxes", "synthetic_detections",
                                                "synthetic_gt_visible_boxes"]
    stored = json.loads((job.out / "report.json").read_text())
    assert stored == json.loads(json.dumps(report))
    assert stored["methods"]["aae"]["detections"]["mean_AR_MSSD_AR_MSPD"] == pytest.approx(0.3)
    assert ("| aae | detections | **all** | 4 | 0.200 | 0.400 | **0.300** | 0.100 |"
            in (job.out / "report.md").read_text())
    calls.clear()
    run_benchmark(job)
    assert calls == []  # everything was complete
    # a stage whose output went missing runs again, and only that one
    (job.out / "results" / "aae_gt.csv").unlink()
    run_benchmark(job)
    assert calls == ["estimate gt"]
    # a stage that crashed (no marker) runs again even though a partial output exists
    calls.clear()
    job.marker("detector").unlink()
    run_benchmark(job)
    assert calls == ["detector"]


def test_scores_made_with_another_estimate_command_are_made_again_and_the_models_kept(mocked, tmp_path):
    data, calls = mocked
    job = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    run_benchmark(job)
    calls.clear()
    for condition, recorded in (("gt", None), ("detections", ["estimate", "--flip"])):  # before commands were
        marker = job.marker(f"estimate_aae_{condition}")                                # recorded; other flags
        content = json.loads(marker.read_text())
        content["summary"].pop("command")
        if recorded:
            content["summary"]["command"] = recorded
        marker.write_text(json.dumps(content))
    run_benchmark(job)
    assert calls == ["estimate gt", "evaluate gt", "estimate detections", "evaluate detections", "detector ap"]
    calls.clear()
    run_benchmark(job)
    assert calls == []


def test_jobs_hand_the_unfinished_pose_trainings_to_side_by_side_processes_after_the_detector(mocked, tmp_path,
                                                                                       monkeypatch):
    data, calls = mocked
    handed = []

    def side_by_side(job, names):  # in place of the spawned processes: the (mocked) stages run here
        handed.append(list(names))
        calls.append("side by side")
        for name, function, _ in stages(job):
            if name in names:
                lmo._run_stage(job, name, function)

    monkeypatch.setattr(lmo, "_run_side_by_side", side_by_side)
    folder = dict(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    report = run_benchmark(Benchmark(**folder, jobs=2))
    assert handed == [["pose/obj_000001", "pose/obj_000005"]]
    assert calls[:4] == ["backgrounds", "synthetic", "validation", "detector"]
    assert calls[4:7] == ["side by side", "pose 1", "pose 5"] and calls[7:15] == SCORING
    assert report["jobs"] == 2 and report["run_wall_minutes"] >= 0
    assert "pose models 2 at a time" in (tmp_path / "bench" / "report.md").read_text()
    assert report["timings_seconds"].keys() >= {"detector", "pose/obj_000001", "pose/obj_000005"}

    # a resumed run hands over only what is unfinished; one training alone runs in this process
    lmo_marker = Benchmark(**folder).marker("pose/obj_000005")
    lmo_marker.unlink()
    calls.clear()
    run_benchmark(Benchmark(**folder, jobs=2))
    assert handed[1:] == [] and calls[0] == "pose 5"
    for name in ("pose/obj_000001", "pose/obj_000005"):
        Benchmark(**folder).marker(name).unlink()
    run_benchmark(Benchmark(**folder, jobs=2))
    assert handed[1:] == [["pose/obj_000001", "pose/obj_000005"]]
    report = run_benchmark(Benchmark(**folder))  # jobs=1: nothing is handed over
    assert len(handed) == 2 and report["jobs"] == 1
    assert "at a time" not in (tmp_path / "bench" / "report.md").read_text()
    for bad in (0, -1, 1.5):
        with pytest.raises(ValueError, match="jobs: expected a positive number of processes"):
            Benchmark(**folder, jobs=bad)


def test_keypointnet_reuses_the_data_and_detector_and_adds_its_scores_to_the_report(mocked, tmp_path):
    data, calls = mocked
    aae = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    run_benchmark(aae)
    calls.clear()
    keypointnet = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, method="keypointnet",
                            progress=False)
    assert keypointnet.pose_dir(5) == tmp_path / "bench" / "pose_keypointnet" / "obj_000005"
    report = run_benchmark(keypointnet)
    assert calls[:2] == ["pose 1", "pose 5"] and "detector" not in calls
    assert sorted(report["methods"]) == ["aae", "keypointnet"]
    assert "| keypointnet | gt_visible_boxes | 5 |" in score_table(report)
    assert report["not_estimated"] == {"aae": {}, "keypointnet": {"5": "keypoints.json: only 2 usable keypoints"}}
    assert ("- keypointnet, object 5: not estimated, scored as misses (keypoints.json: only 2 usable keypoints)"
            in (tmp_path / "bench" / "report.md").read_text())


def test_other_settings_in_the_same_folder_and_bad_input_are_refused(mocked, tmp_path):
    data, _ = mocked
    run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False))
    with pytest.raises(ValueError, match=r"other settings \(settings\.images \(6 there, 7 now\)"):
        run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, progress=False,
                                settings=replace(TINY, images=7)))
    with pytest.raises(ValueError, match="lmo: .*models not found"):
        Benchmark(out=tmp_path / "x", lmo=tmp_path / "none")
    with pytest.raises(ValueError, match=r"objects: \[9\] have no mesh"):
        Benchmark(out=tmp_path / "x", lmo=data, objects=(9,))
    with pytest.raises(ValueError, match="method: expected one of"):
        Benchmark(out=tmp_path / "x", lmo=data, method="pvnet")


def test_a_pose_method_per_object_reuses_the_other_models_and_reports_under_its_own_label(mocked, tmp_path):
    data, calls = mocked
    run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False))
    calls.clear()
    mixed = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False,
                      object_methods={5: "keypointnet_robust", 1: "aae"})
    assert mixed.object_methods == {5: "keypointnet_robust"} and mixed.label == "aae+keypointnet_robust@5"
    assert mixed.pose_dir(1) == tmp_path / "bench" / "pose" / "obj_000001"
    assert mixed.pose_dir(5) == tmp_path / "bench" / "pose_keypointnet_robust" / "obj_000005"
    assert [name for name, _, _ in stages(mixed)][4:7] == [
        "pose/obj_000001", "pose_keypointnet_robust/obj_000005", "estimate_aae+keypointnet_robust@5_gt"]
    assert {f"--run=1={mixed.pose_dir(1)}", f"--run=5={mixed.pose_dir(5)}"} <= set(lmo._estimate_args(mixed, "gt"))
    # the detections condition lets the detector see each frame's mirror image too (docs/ssd.md)
    detections, truth = lmo._estimate_args(mixed, "detections"), lmo._estimate_args(mixed, "gt")
    assert "--flip" in detections and "--flip" not in truth
    assert "--box-search" in detections and "--box-search" not in truth
    assert detections[detections.index("--poses-per-class") + 1] == "1" and "--poses-per-class" not in truth
    from paz6d.backend.viewpoints import ViewpointRange
    from paz6d.cli import build_parser
    from paz6d.estimate import viewpoint_range

    parsed = build_parser().parse_args(detections)  # the flags `paz6d estimate` runs with
    assert parsed.poses_per_class == 1 and parsed.box_search and parsed.flip
    # scored detections are kept down to 0.01: COCO AP and BOP's best-estimate rule rank them by score
    assert parsed.score_threshold == lmo.SCORED_DETECTION_THRESHOLD == 0.01 and "--score-threshold" not in truth
    # and their boxes are voted (box voting, chosen on the held-out synthetic images)
    assert parsed.vote_iou == lmo.SCORED_VOTE_IOU == 0.5 and "--vote-iou" not in truth
    # the held-out synthetic images with the detector's boxes: the same flags, scored on their visible-box targets
    synthetic = build_parser().parse_args(lmo._estimate_args(mixed, "synthetic_detections"))
    assert synthetic.detector == parsed.detector and synthetic.poses_per_class == 1 and synthetic.box_search
    assert synthetic.dataset == tmp_path / "bench" / "validation" and synthetic.targets_out is None
    assert lmo._targets(mixed, "synthetic_detections") == lmo._targets(mixed, "synthetic") == mixed.result(
        "synthetic", "_targets.json")
    assert lmo._targets(mixed, "detections") == mixed.result("detections", "_targets.json")
    # every condition's AAEs answer only with the training scenes' viewpoints (15-80 degrees up, rolled by at most
    # 30) widened by 15 degrees
    assert lmo.viewpoints(mixed) == ViewpointRange((0, 90), 45)
    for condition in lmo.CONDITIONS:
        flags = build_parser().parse_args(lmo._estimate_args(mixed, condition))
        assert viewpoint_range(flags) == ViewpointRange((0, 90), 45)
    report = run_benchmark(mixed)
    assert calls == ["pose 5", *SCORING, "detector ap"]
    assert sorted(report["methods"]) == ["aae", "aae+keypointnet_robust@5"]
    assert mixed.result("gt", ".csv") == tmp_path / "bench" / "results" / "aae+keypointnet_robust@5_gt.csv"
    assert "| aae+keypointnet_robust@5 | gt_visible_boxes | **all** |" in score_table(report)
    calls.clear()  # longer AAEs: the mix is scored again, its KeypointNet is not retrained
    run_benchmark(replace(mixed, aae_steps=9))
    assert calls == ["pose 1", *SCORING]
    with pytest.raises(ValueError, match=r"object_methods: objects \[9\] are not benchmarked"):
        Benchmark(out=tmp_path / "x", lmo=data, object_methods={9: "aae"})
    with pytest.raises(ValueError, match="object_methods: object 5: expected one of"):
        Benchmark(out=tmp_path / "x", lmo=data, object_methods={5: "pvnet"})


def test_more_aae_steps_extend_the_aaes_and_score_them_again_and_fewer_are_refused(mocked, tmp_path):
    data, calls = mocked
    run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False))
    calls.clear()
    longer = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False, aae_steps=9)
    assert longer.settings.aae_steps == 9
    run_benchmark(longer)
    assert calls == ["pose 1", "pose 5", *SCORING]
    assert json.loads((tmp_path / "bench" / "benchmark.json").read_text())["settings"]["aae_steps"] == 9
    calls.clear()
    run_benchmark(longer)
    assert calls == []
    with pytest.raises(ValueError, match=r"aae_steps: .* trained for 9 steps; expected at least that many"):
        run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False,
                                aae_steps=5))
    dropped = replace(TINY, aae_lr_drop_steps=2)
    run_benchmark(Benchmark(out=tmp_path / "drop", lmo=data, quick=True, settings=dropped, progress=False))
    # fewer steps also shorten the sizes' drop (2 -> 1); the error still says why, not "other settings"
    with pytest.raises(ValueError, match=r"trained for 4 steps; expected at least that many"):
        run_benchmark(Benchmark(out=tmp_path / "drop", lmo=data, quick=True, settings=dropped, progress=False,
                                aae_steps=2))
    with pytest.raises(ValueError, match=r"other settings \(settings\.\w+ \("):  # steps and another size: refused
        run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=replace(TINY, images=7),
                                progress=False, aae_steps=12))
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match=r"aae_steps: expected a number of training steps in 1\.\."):
            Benchmark(out=tmp_path / "x", lmo=data, aae_steps=bad)


def test_aae_learning_rate_drop_reaches_the_aae_and_folders_from_before_it_resume(mocked, tmp_path, monkeypatch):
    data, calls = mocked
    job = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False, aae_lr_drop_steps=3)
    assert job.settings.aae_lr_drop_steps == 3
    monkeypatch.undo()  # the real pose stage, with train_aae replaced: the AAE config it builds
    import paz6d.aae.train

    seen = {}
    monkeypatch.setattr(paz6d.aae.train, "train_aae", lambda mesh, run_dir, config, **kwargs: seen.update(
        steps=config.steps, lr_drop_steps=config.lr_drop_steps, crop_box=kwargs["crop_box"],
        encoder=config.encoder_backbone))
    lmo._stage_pose(job, 5)
    assert seen == {"steps": 4, "lr_drop_steps": 3, "crop_box": TINY.aae_crop_box, "encoder": "none"}
    lmo._stage_pose(replace(job, settings=replace(TINY, aae_crop_box="visib")), 5)
    assert seen["crop_box"] == "visib"
    lmo._stage_pose(replace(job, settings=replace(TINY, aae_encoder_backbone="efficientnet-lite0")), 5)
    assert seen["encoder"] == "efficientnet-lite0"
    with pytest.raises(ValueError, match="aae_encoder_backbone: expected one of"):
        replace(TINY, aae_encoder_backbone="resnet50")
    with pytest.raises(ValueError, match="crop_box: expected one of"):
        replace(TINY, aae_crop_box="whole")
    for bad, match in ((-1, "expected 0 or a number of steps"), (2.5, "expected 0 or a number of steps"),
                       (5, r"expected at most aae_steps \(4\)")):
        with pytest.raises(ValueError, match=f"aae_lr_drop_steps: {match}"):
            Benchmark(out=tmp_path / "x", lmo=data, settings=TINY, aae_lr_drop_steps=bad)


def test_the_detector_stage_trains_the_settings_backbone(tmp_path, monkeypatch):
    from paz6d.ssd import train

    data = _fake_lmo(tmp_path / "lmo")
    seen = []
    monkeypatch.setattr(train, "train_ssd", lambda training: seen.append(training) or {})
    for backbone in ("efficientnet-lite0", "none"):
        job = Benchmark(out=tmp_path / backbone, lmo=data, quick=True, settings=TINY, progress=False,
                        detector_backbone=backbone)
        lmo._stage_detector(job)
        assert seen[-1].backbone == backbone and seen[-1].steps == TINY.detector_steps
        assert seen[-1].input_size == TINY.detector_input_size
    with pytest.raises(ValueError, match="detector_backbone: expected one of"):
        replace(TINY, detector_backbone="resnet50")


def test_a_folder_written_before_the_learning_rate_drop_resumes_with_none(mocked, tmp_path):
    data, calls = mocked
    run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False))
    path = tmp_path / "bench" / "benchmark.json"
    stored = json.loads(path.read_text())
    for key in ("aae_lr_drop_steps", "keypointnet_robust_steps", "keypointnet_robust_views", "validation_images",
                "aae_crop_box", "detector_backbone", "neutral_distractors", "aae_encoder_backbone"):
        del stored["settings"][key]  # as written by the versions before these settings
    path.write_text(json.dumps(stored))
    calls.clear()
    settings = replace(TINY, keypointnet_robust_steps=None, keypointnet_robust_views=None, validation_images=60,
                       aae_crop_box="obj", detector_backbone="none")
    run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=settings, progress=False))
    assert calls == []
    with pytest.raises(ValueError, match=r"other settings \(settings\.\w+ \("):
        run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=settings, progress=False,
                                aae_lr_drop_steps=2))


def test_quick_and_full_sizes_and_the_generator_settings(tmp_path, shared_data):
    job = Benchmark(out=tmp_path / "b", lmo=shared_data / "bop_lmo", quick=True)
    assert job.settings == lmo.QUICK and len(job.objects) == 8
    config = lmo.generation_config(job)
    assert config.backgrounds == tmp_path / "b" / "backgrounds" and config.num_images == lmo.QUICK.images
    assert config.intrinsics == lmo.LMO_INTRINSICS and config.mesh_scale == 0.001 and len(config.meshes) == 8
    assert config.neutral_distractors == lmo.QUICK.neutral_distractors
    white = Benchmark(out=tmp_path / "b", lmo=shared_data / "bop_lmo", quick=True, neutral_distractors=0.3)
    assert lmo.generation_config(white).neutral_distractors == 0.3 == white.settings.neutral_distractors
    for bad in (1.5, -0.1, float("nan"), "0.3"):
        with pytest.raises(ValueError, match="neutral_distractors"):
            Benchmark(out=tmp_path / "b", lmo=shared_data / "bop_lmo", quick=True, neutral_distractors=bad)
    for bad in (416, 0, "448", 4096 * 64):
        with pytest.raises(ValueError, match="detector_input_size: expected"):
            Benchmark(out=tmp_path / "b", lmo=shared_data / "bop_lmo", quick=True, detector_input_size=bad)
    assert Benchmark(out=tmp_path / "b", lmo=shared_data / "bop_lmo").settings == lmo.FULL


def test_both_sizes_drop_the_aae_rate_at_the_end_and_fewer_steps_keep_its_share(tmp_path, shared_data):
    data = shared_data / "bop_lmo"
    assert (lmo.QUICK.aae_steps, lmo.QUICK.aae_lr_drop_steps) == (1000, 200)
    assert (lmo.FULL.aae_steps, lmo.FULL.aae_lr_drop_steps) == (5000, 500)
    short = Benchmark(out=tmp_path / "b", lmo=data, quick=True, aae_steps=50).settings
    assert (short.aae_steps, short.aae_lr_drop_steps) == (50, 10)  # a fifth of the run, as in the quick sizes
    assert Benchmark(out=tmp_path / "b", lmo=data, aae_steps=1000).settings.aae_lr_drop_steps == 100  # a tenth
    longer = Benchmark(out=tmp_path / "b", lmo=data, quick=True, aae_steps=1500).settings
    assert longer.aae_lr_drop_steps == 200  # kept, so a finished folder's AAEs can be extended
    with pytest.raises(ValueError, match=r"aae_lr_drop_steps: expected at most aae_steps \(50\)"):
        Benchmark(out=tmp_path / "b", lmo=data, quick=True, aae_steps=50, aae_lr_drop_steps=60)


def test_command_is_registered_and_light(tmp_path):
    from paz6d.cli import build_parser, main

    args = build_parser().parse_args(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--quick"])
    assert args.quick and args.method == "aae" and args.aae_steps is None
    assert build_parser().parse_args(["benchmark", "lmo", "--out", "b", "--aae-steps", "15000"]).aae_steps == 15000
    assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(tmp_path / "none")]) == 2


def test_command_passes_the_aae_schedule_on(mocked, tmp_path, monkeypatch):
    from paz6d.benchmark import command
    from paz6d.cli import main

    data, _ = mocked
    jobs = []
    monkeypatch.setattr(command, "run_benchmark", lambda job: jobs.append(job) or {"total_minutes": 0.0})
    assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(data), "--aae-steps", "12000",
                 "--aae-lr-drop-steps", "2000", "--no-progress"]) == 0
    assert (jobs[0].settings.aae_steps, jobs[0].settings.aae_lr_drop_steps) == (12000, 2000)
    assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(data), "--object-method",
                 "5=keypointnet_robust", "--object-method", "1=keypointnet", "--no-progress"]) == 0
    assert jobs[1].object_methods == {1: "keypointnet", 5: "keypointnet_robust"}
    assert jobs[1].jobs == 2  # side by side by default
    assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(data), "--jobs", "1",
                 "--no-progress"]) == 0
    assert jobs[2].jobs == 1 and jobs[2].settings.aae_crop_box == lmo.FULL.aae_crop_box
    for flag, value, setting in (("--aae-crop-box", "visib", {"aae_crop_box": "visib"}),
                                 ("--detector-backbone", "none", {"detector_backbone": "none"}),
                                 ("--neutral-distractors", "0.25", {"neutral_distractors": 0.25}),
                                 ("--aae-encoder-backbone", "none", {"aae_encoder_backbone": "none"}),
                                 ("--detector-input-size", "320", {"detector_input_size": 320})):
        assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(data), flag, value, "--quick",
                     "--no-progress"]) == 0
        assert jobs[-1].settings == replace(lmo.QUICK, **setting), flag
    assert len(jobs) == 8
    assert (lmo.QUICK.detector_input_size, lmo.FULL.detector_input_size) == (448, 640)
    assert lmo.QUICK.aae_encoder_backbone == "efficientnet-lite0" and lmo.FULL.aae_encoder_backbone == "none"
    assert (lmo.QUICK.neutral_distractors, lmo.FULL.neutral_distractors) == (0.3, 0.0)
    for bad in ("5", "x=aae", "5=aae 5=keypointnet"):
        assert main(["benchmark", "lmo", "--out", str(tmp_path / "b"), "--lmo", str(data), "--object-method",
                     *bad.split()]) == 2


@pytest.mark.slow
def test_every_real_stage_runs_on_the_shared_lmo_data_at_toy_size(tmp_path, shared_data):
    job = Benchmark(out=tmp_path / "bench", lmo=shared_data / "bop_lmo", quick=True, settings=TINY, objects=(5, 8),
                    progress=False, object_methods={8: "keypointnet_robust"}, jobs=2)  # pose models side by side
    report = run_benchmark(job)
    for condition in ("gt_visible_boxes", "detections", "synthetic_gt_visible_boxes", "synthetic_detections"):
        scores = report["methods"]["aae+keypointnet_robust@8"][condition]
        assert scores is not None and sorted(scores["per_object"]) == ["5", "8"]
        assert 0 <= scores["mean_AR_MSSD_AR_MSPD"] <= 1
    assert (job.out / "detector" / "model.keras").is_file() and (job.pose_dir(5) / "codebook.npz").is_file()
    assert json.loads((job.pose_dir(8) / "config.json").read_text())["config"] == "robust"
    assert len(list((job.out / "overlays" / "aae+keypointnet_robust@8_detections").glob("*.png"))) == 105  # one per
                                                                                                           # real frame
    assert (job.out / "overlays" / "aae+keypointnet_robust@8_gt.png").is_file() and (job.out / "report.md").is_file()


def test_keypointnet_stage_uses_the_orientation_network_for_half_turn_symmetric_objects(shared_data, tmp_path,
                                                                                         monkeypatch):
    jobs = {}
    monkeypatch.setattr(lmo, "train_keypointnet", lambda job: jobs.setdefault(job.mesh.stem, job) and {})
    bench = Benchmark(out=tmp_path / "bench", lmo=shared_data / "bop_lmo", quick=True, settings=TINY,
                      method="keypointnet")
    robust = replace(bench, method="aae", object_methods={1: "keypointnet_robust"})
    for job, obj_id in ((bench, 5), (bench, 10), (bench, 11), (robust, 1)):
        lmo._stage_pose(job, obj_id)
    assert {stem: job.orientation_network for stem, job in jobs.items()} == {
        "obj_000005": False, "obj_000010": True, "obj_000011": True, "obj_000001": False}
    assert {stem: (job.config, job.model_config) for stem, job in jobs.items() if stem in (
        "obj_000005", "obj_000001")} == {"obj_000005": ("quick", KEYPOINT_QUICK.replace(steps=4, views=8)),
                                         "obj_000001": ("robust", KEYPOINT_ROBUST.replace(steps=5, views=9))}
    assert jobs["obj_000001"].out == tmp_path / "bench" / "pose_keypointnet_robust" / "obj_000001"
    full = Benchmark(out=tmp_path / "full", lmo=shared_data / "bop_lmo", object_methods={8: "keypointnet_robust"})
    lmo._stage_pose(full, 8)  # the robust preset at its own length
    assert jobs["obj_000008"].model_config == KEYPOINT_ROBUST  # 10,000 steps, 4,000 views
    assert abs(jobs["obj_000010"].symmetry().symmetry[0, 0] + 1.0) < 1e-3  # the eggbox's half turn about z


def _scores(per_object: dict[str, tuple[int, float, float]]) -> dict:
    return {"per_object": {obj_id: {"instances": n, "AR_MSSD": mssd, "AR_MSPD": mspd}
                           for obj_id, (n, mssd, mspd) in per_object.items()}}


def test_the_method_pick_uses_only_the_synthetic_scores_and_pools_the_real_ones_by_instances():
    report = {"object_methods": {"aae": {"1": "aae", "5": "aae"},
                                 "aae+keypointnet_robust@5": {"1": "aae", "5": "keypointnet_robust"}},
              "methods": {"aae": {"gt_visible_boxes": _scores({"1": (2, 0.4, 0.6), "5": (6, 0.0, 0.2)}),
                                  "detections": None,
                                  "synthetic_gt_visible_boxes": _scores({"1": (9, 0.8, 0.9), "5": (9, 0.1, 0.3)})},
                          "aae+keypointnet_robust@5": {
                              "gt_visible_boxes": _scores({"1": (2, 0.4, 0.6), "5": (6, 0.3, 0.5)}),
                              "detections": _scores({"1": (2, 0.1, 0.2), "5": (6, 0.0, 0.1)}),
                              "synthetic_gt_visible_boxes": _scores({"1": (9, 0.8, 0.9), "5": (9, 0.6, 0.7)})}}}
    pick = lmo.method_pick(report)
    assert pick["methods"] == {"1": "aae", "5": "keypointnet_robust"}
    assert pick["validation"]["5"] == {"aae": pytest.approx(0.2), "keypointnet_robust": pytest.approx(0.65)}
    gt = pick["real"]["gt_visible_boxes"]
    # pooled over the 8 instances as `paz6d evaluate bop` pools them: (2 * 0.4 + 6 * 0.3) / 8, (2 * 0.6 + 6 * 0.5) / 8
    assert (gt["AR_MSSD"], gt["AR_MSPD"]) == (pytest.approx(0.325), pytest.approx(0.525))
    assert gt["mean"] == pytest.approx(0.425) and gt["per_object"] == {"1": 0.5, "5": 0.4}
    assert pick["real"]["detections"]["mean"] == pytest.approx((2 * 0.15 + 6 * 0.05) / 8)
    # a tie goes to the first method name; a real condition an object lacks is None; the most common pick is the base
    report["methods"]["aae+keypointnet_robust@5"]["synthetic_gt_visible_boxes"] = _scores({"1": (9, 0.8, 0.9),
                                                                                          "5": (9, 0.1, 0.3)})
    report["methods"]["aae"]["detections"] = report["methods"]["aae+keypointnet_robust@5"]["detections"]
    pick = lmo.method_pick(report)
    assert pick["methods"]["5"] == "aae" and pick["method"] == "aae" and pick["object_methods"] == {}
    report["methods"]["aae"]["detections"] = None
    assert lmo.method_pick(report)["real"]["detections"] is None
    # one method per object: nothing to pick; reports from before the per-object methods were stored: skipped
    one = {"object_methods": {"aae": {"1": "aae"}}, "methods": {"aae": report["methods"]["aae"]}}
    assert lmo.method_pick(one) is None
    assert lmo.method_pick({"methods": report["methods"]}) is None


def test_the_report_picks_a_method_per_object_once_two_were_scored(mocked, tmp_path, monkeypatch):
    data, _ = mocked
    evaluate = lmo._stage_evaluate

    def by_method(job, condition):  # the robust KeypointNet is better on object 5's synthetic images only
        evaluate(job, condition)
        path = job.result(condition, "_scores.json")
        scores = json.loads(path.read_text())
        if condition == "synthetic" and job.method_of(5) == "keypointnet_robust":
            scores["per_object"]["5"].update(AR_MSSD=0.9, AR_MSPD=0.9)
        path.write_text(json.dumps(scores))
        return {}

    monkeypatch.setattr(lmo, "_stage_evaluate", by_method)
    report = run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False))
    assert report["method_pick"] is None
    assert "picked on the held-out" not in (tmp_path / "bench" / "report.md").read_text()
    report = run_benchmark(Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False,
                                     method="keypointnet_robust"))
    assert report["object_methods"]["keypointnet_robust"] == {"1": "keypointnet_robust", "5": "keypointnet_robust"}
    assert report["method_pick"]["methods"] == {"1": "aae", "5": "keypointnet_robust"}
    text = (tmp_path / "bench" / "report.md").read_text()
    assert "| 5 | aae 0.400, keypointnet_robust 0.900 | keypointnet_robust | 0.400 | 0.400 |" in text
    assert "`paz6d benchmark lmo --method aae --object-method 5=keypointnet_robust`" in text


def test_a_model_scored_under_two_labels_counts_with_the_label_scored_last():
    older, newer = _scores({"1": (2, 0.1, 0.1)}), _scores({"1": (2, 0.7, 0.9)})
    rows = {"aae": {"gt_visible_boxes": older, "synthetic_gt_visible_boxes": _scores({"1": (9, 0.5, 0.5)})},
            "keypointnet_robust@1": {"gt_visible_boxes": _scores({"1": (2, 0.0, 0.0)}),
                                     "synthetic_gt_visible_boxes": _scores({"1": (9, 0.1, 0.1)})},
            "aae+x": {"gt_visible_boxes": newer, "synthetic_gt_visible_boxes": _scores({"1": (9, 0.5, 0.5)})}}
    methods_of = {"aae": {"1": "aae"}, "keypointnet_robust@1": {"1": "keypointnet_robust"}, "aae+x": {"1": "aae"}}
    pick = lmo.method_pick({"object_methods": methods_of, "methods": rows})
    assert pick["real"]["gt_visible_boxes"]["per_object"] == {"1": pytest.approx(0.8)}
    reordered = {label: methods_of[label] for label in ("aae+x", "keypointnet_robust@1", "aae")}
    pick = lmo.method_pick({"object_methods": reordered, "methods": rows})
    assert pick["real"]["gt_visible_boxes"]["per_object"] == {"1": pytest.approx(0.1)}


def test_longer_aaes_drop_the_stale_rows_of_every_label_with_an_aae(mocked, tmp_path):
    data, _ = mocked
    folder = dict(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    run_benchmark(Benchmark(**folder))
    run_benchmark(Benchmark(**folder, method="keypointnet_robust"))
    report = run_benchmark(Benchmark(**folder, object_methods={5: "keypointnet_robust"}))
    assert list(report["methods"]) == ["aae", "keypointnet_robust", "aae+keypointnet_robust@5"]
    report = run_benchmark(Benchmark(**folder))  # scored again (nothing to run): its row moves last
    assert list(report["methods"]) == ["keypointnet_robust", "aae+keypointnet_robust@5", "aae"]
    report = run_benchmark(Benchmark(**folder, object_methods={5: "keypointnet_robust"}, aae_steps=9))
    assert list(report["methods"]) == ["keypointnet_robust", "aae+keypointnet_robust@5"]  # "aae": not re-scored
    assert list(report["object_methods"]) == list(report["not_estimated"]) == list(report["methods"])
    assert "\n| aae | " not in (tmp_path / "bench" / "report.md").read_text()  # no score-table row of it
    # the AAE of object 5 is known from no scored label now; object 1's AAE and KeypointNet tie: the first name
    assert report["method_pick"]["methods"] == {"1": "aae", "5": "keypointnet_robust"}
