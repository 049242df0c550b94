"""``python -m paz6d.benchmark.results``: docs/results.md from report JSON files; the LM-O report is the one
``paz6d.benchmark.lmo.write_report`` writes (its stages' score files faked), the demo's is built like
``paz6d demo``'s."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from paz6d.benchmark import lmo, results
from paz6d.benchmark.lmo import Benchmark, BenchmarkSettings

TINY = BenchmarkSettings(images=6, backgrounds=3, detector_steps=4, aae_steps=4, aae_in_plane=4,
                         keypointnet_steps=4, keypointnet_views=8, workers=1, aae_views=12, detector_input_size=128,
                         validation_images=3, aae_lr_drop_steps=1)


def _scores(mssd: float, mspd: float) -> dict:
    """A ``paz6d evaluate bop`` summary of objects 1 (2 instances) and 5 (2 instances)."""
    return {"AR_MSSD": mssd, "AR_MSPD": mspd, "ADD(-S)_recall": 0.125, "counts": {"gt_instances": 4},
            "per_object": {"1": {"instances": 2, "AR_MSSD": mssd - 0.1, "AR_MSPD": mspd - 0.1},
                           "5": {"instances": 2, "AR_MSSD": mssd + 0.1, "AR_MSPD": mspd + 0.1}}}


@pytest.fixture
def lmo_report(tmp_path, monkeypatch) -> Path:
    """``report.json`` of a quick benchmark of objects 1 and 5, written by the benchmark's own report stage."""
    data = tmp_path / "lmo"
    (data / "models").mkdir(parents=True)
    (data / "test").mkdir()
    for obj_id in (1, 5):
        (data / "models" / f"obj_{obj_id:06d}.ply").write_text("ply\n")
    job = Benchmark(out=tmp_path / "bench", lmo=data, quick=True, settings=TINY, progress=False)
    (job.out / "results").mkdir(parents=True)
    for index, condition in enumerate(lmo.CONDITIONS):
        job.result(condition, "_scores.json").write_text(json.dumps(_scores(0.2 + 0.25 * index, 0.4)))
    coco = {"stat_names": ["AP", "AP50", "AP75"], "stats": [0.2524, 0.5, 0.125], "per_class_ap": {}}
    (job.out / "results" / "detector_coco.json").write_text(json.dumps(coco))
    monkeypatch.setattr(lmo, "_overlays", lambda job, condition: [])
    lmo.write_report(job, {"detector": 90.0, "pose/obj_000001": 30.0})
    return job.out / "report.json"


def test_lmo_report_becomes_the_command_the_scores_and_the_per_object_table(lmo_report):
    page = results.results_page([lmo_report], cpu="test CPU (2 cores)")
    assert "## LM-O benchmark (quick)" in page
    assert ("`paz6d benchmark lmo --quick --method aae --aae-steps 4 --aae-lr-drop-steps 1 --aae-crop-box obj "
            "--detector-backbone none --detector-input-size 128 --neutral-distractors 0.0 --aae-encoder-backbone none "
            "--out OUT`") in page
    assert "CPU: test CPU (2 cores)" in page and "Total stage time 2.0 min" in page
    # mean of AR_MSSD 0.2 and AR_MSPD 0.4; held-out synthetic images: 0.7 and 0.4
    assert "| aae | gt_visible_boxes | 4 | 0.200 | 0.400 | **0.300** | 0.125 |" in page
    assert "| aae | synthetic_gt_visible_boxes | 4 | 0.700 | 0.400 | **0.550** | 0.125 |" in page
    assert "| aae | detections | 0.325 | 0.525 |" in page  # per object: (0.35 + 0.3) / 2, (0.55 + 0.5) / 2
    assert "AP 0.252, AP50 0.500, AP75 0.125" in page
    assert page.count("| aae | ") == 4 + 2  # four conditions, then the two real ones per object


def test_the_page_lists_reports_in_the_order_given_and_names_its_own_command(lmo_report, tmp_path):
    demo = tmp_path / "demo" / "report.json"
    demo.parent.mkdir()
    demo.write_text(json.dumps(
        {"metrics": {"metric": "ADD", "count": 40, "recall_0.1d": 0.875, "auc_10cm": 0.5,
                     "rotation_error_deg": {"median": 3.456, "below_5": 0.6, "below_10": 0.8},
                     "translation_error_m": {"median": 0.0123}, "failures": 1},
         "training": {"steps": 3000}, "config": {}, "seconds_per_estimate": 0.0215, "test_images": 200,
         "scene_crops": 0.0, "timings": {"total_seconds": 1200.0}, "cpu_count": 2}))
    out = tmp_path / "docs" / "results.md"
    assert results.main([str(demo), str(lmo_report), "--out", str(out), "--cpu", "X"]) == 0
    page = out.read_text()
    assert page.index("## End-to-end demo") < page.index("## LM-O benchmark")
    assert f"`python -m paz6d.benchmark.results {demo} {lmo_report} --out docs/results.md`" in page
    assert "`paz6d demo --test-images 200 --steps 3000 --out OUT`" in page
    for row in ("| ADD recall @ 0.1 d | 0.875 |", "| median rotation error [deg] | 3.46 |",
                "| median translation error [mm] | 12.3 |", "| inference per object [ms] | 21.5 |",
                "| total time [min] | 20.0 |", "| no estimate | 1 of 40 |"):
        assert row in page


def test_a_mixed_label_is_spelled_as_object_method_flags(lmo_report):
    report = json.loads(lmo_report.read_text())
    command = results.lmo_command(report, "aae+keypointnet_robust@8+keypointnet@5", lmo_report)
    assert command.startswith("paz6d benchmark lmo --quick --method aae --object-method 8=keypointnet_robust "
                              "--object-method 5=keypointnet ")
    with pytest.raises(results.ReportError, match="label 'aae\\+kp@x'"):
        results.lmo_command(report, "aae+kp@x", lmo_report)


def test_bad_reports_are_one_line_naming_the_file(lmo_report, tmp_path, capsys):
    unknown = tmp_path / "other.json"
    unknown.write_text(json.dumps({"benchmark": "ycb"}))
    assert results.main([str(unknown), "--out", str(tmp_path / "r.md")]) == 2
    assert f"{unknown}: not a report of `paz6d benchmark lmo`" in capsys.readouterr().err
    report = json.loads(lmo_report.read_text())
    del report["settings"]
    lmo_report.write_text(json.dumps(report))
    assert results.main([str(lmo_report), "--out", str(tmp_path / "r.md")]) == 2
    assert f"{lmo_report}: missing field settings" in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists()


def test_this_cpu_reads_the_model_name_and_counts_logical_cores(tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Test CPU @ 2.0GHz\n\nprocessor\t: 1\n"
                       "model name\t: Test CPU @ 2.0GHz\n")
    assert results.this_cpu(cpuinfo) == "Test CPU @ 2.0GHz (2 logical cores)"
    assert results.this_cpu(tmp_path / "missing") == "unknown CPU"
