"""paz6d.video: the JSON-lines stream (records), VideoPlayer over videos and folders, and ``paz6d run``."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import skimage.data

from paz6d import cli
from paz6d.abstract import Box2D, Keypoints2D, Keypoints3D, Pose6D
from paz6d.backend.camera import Camera
from paz6d.backend.camera_file import write_camera_json
from paz6d.backend.files import TEMPORARY_PREFIX
from paz6d.video.frames import open_frames
from paz6d.backend.image import save_image
from paz6d.video.video_file import VideoFileWriter
from paz6d.faces.haar import HaarCascadeDetector
from paz6d.faces.head_pose import HeadDetection
from paz6d.video.player import VideoPlayer, latency_summary
from paz6d.video.records import FrameRecord, read_records, record_line, result_entries

SIZE = (160, 120)
K = np.array([[150.0, 0.0, 80.0], [0.0, 150.0, 60.0], [0.0, 0.0, 1.0]])


def astronaut_frames(count: int = 4) -> list[np.ndarray]:
    """The astronaut's face moving across a 160 x 120 window (half-size image)."""
    image = cv2.resize(skimage.data.astronaut(), (256, 256), interpolation=cv2.INTER_AREA)
    return [np.ascontiguousarray(image[10 + 4 * i:10 + 4 * i + SIZE[1], 30 + 6 * i:30 + 6 * i + SIZE[0]])
            for i in range(count)]


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A lossless video of :func:`astronaut_frames` at 10 frames/s, and a folder of the same frames."""
    root = tmp_path_factory.mktemp("clip")
    frames = astronaut_frames()
    with VideoFileWriter(root / "clip.mkv", 10.0, SIZE) as writer:
        for index, image in enumerate(frames):
            writer.write(image)
            save_image(root / "frames" / f"{index:04d}.png", image)
    return root


def test_records_round_trip_every_message_through_from_dict():
    pose = Pose6D.from_rotation_vector([0.1, -0.2, 0.3], [0.01, 0.02, 0.5], "obj_000001", 0.8)
    box = Box2D(10.5, 20.0, 30.25, 44.0, 0.9, "obj_000001")
    keypoints = Keypoints2D(np.array([[1.5, 2.0], [3.0, 4.25]]), np.array([0.5, 1.0]), "face")
    points = Keypoints3D(np.array([[0.1, 0.2, 0.3]]))
    head = HeadDetection(pose, box, keypoints, 1.25)
    record = FrameRecord(7, 0.7, 12.5, result_entries([(box, pose), (box, "happy", np.array([0.25, 0.75])),
                                                       head, points, {"custom": 3}]))
    line = record_line(record)
    back = FrameRecord.from_dict(json.loads(line))
    assert (back.frame, back.timestamp_s, back.latency_ms) == (7, 0.7, 12.5)
    assert back.results[0] == {"box": box, "pose": pose}
    assert back.results[1] == {"box": box, "label": "happy", "scores": [0.25, 0.75]}
    assert back.results[2] == {"pose": pose, "box": box, "landmarks": keypoints, "reprojection_error": 1.25}
    assert back.results[3] == {"keypoints3d": points} and back.results[4] == {"custom": 3}
    assert json.loads(line)["results"][0]["pose"]["type"] == "Pose6D"
    assert "file" not in json.loads(line)
    named = FrameRecord.from_dict(json.loads(record_line(FrameRecord(1, 0.0, 1.0, [{"box": box}], "000012.png"))))
    assert named.file == "000012.png" and named.results == [{"box": box}]
    assert result_entries(None) == [] and result_entries([(box, box)]) == [{"box": box, "box_1": box}]


def test_records_file_errors_name_the_line(tmp_path):
    path = tmp_path / "frames.jsonl"
    path.write_text(record_line(FrameRecord(0, 0.0, 1.0, [])) + "\n" + '{"frame": 1}\n')
    with pytest.raises(ValueError, match=r"frames.jsonl: line 2: not a frame record.*timestamp_s"):
        list(read_records(path))


def test_latency_summary_matches_numpy():
    values = np.random.default_rng(0).uniform(0.001, 0.1, 37)
    summary = latency_summary(values)
    assert summary["median"] == round(float(np.median(values)) * 1000, 3)
    ordered = np.sort(values) * 1000
    rank = 0.95 * (len(values) - 1)  # linear interpolation between the neighbouring order statistics
    low = int(np.floor(rank))
    assert summary["p95"] == pytest.approx(ordered[low] + (rank - low) * (ordered[low + 1] - ordered[low]), abs=1e-3)
    assert latency_summary([])["median"] is None


def test_a_folder_and_a_video_give_identical_messages(clip, tmp_path):
    detector = HaarCascadeDetector()
    summaries = {}
    for name, spec in (("video", clip / "clip.mkv"), ("folder", clip / "frames")):
        with open_frames(spec, fps=10.0, size=SIZE) as source:
            summaries[name] = VideoPlayer(detector, source).run(tmp_path / name / "annotated.mp4",
                                                                tmp_path / name / "frames.jsonl")
    video, folder = (list(read_records(tmp_path / name / "frames.jsonl")) for name in ("video", "folder"))
    assert len(video) == len(folder) == 4 == summaries["video"]["frames"]
    assert [r.results for r in video] == [r.results for r in folder]
    assert [r.timestamp_s for r in video] == [r.timestamp_s for r in folder] == [0.0, 0.1, 0.2, 0.3]
    assert [r.file for r in folder] == ["0000.png", "0001.png", "0002.png", "0003.png"]
    assert all(r.file is None for r in video)
    expected = [detector(image) for image in astronaut_frames()]  # the detector on the frames themselves
    assert [[entry["box"] for entry in record.results] for record in video] == expected
    assert all(len(boxes) == 1 for boxes in expected)  # one face per frame: the comparison is not vacuous


def test_player_draws_with_the_pipelines_drawing_and_keeps_frames_on_ctrl_c(clip, tmp_path):
    calls = []

    def pipeline(image):
        calls.append(image)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return [Box2D(10, 10, 60, 50, 0.5, "thing")]

    def draw(image, output):
        canvas = image.copy()
        for box in output:
            canvas[int(box.y_min):int(box.y_max), int(box.x_min):int(box.x_max)] = (255, 0, 255)
        return canvas

    with open_frames(clip / "frames") as source:
        summary = VideoPlayer(pipeline, source, draw).run(tmp_path / "a.mkv", tmp_path / "frames.jsonl")
    assert summary["stopped"] == "interrupted" and summary["frames"] == 2
    assert [record.frame for record in read_records(tmp_path / "frames.jsonl")] == [0, 1]
    with open_frames(tmp_path / "a.mkv") as source:
        written = [frame.image for frame in source]
    assert len(written) == 2
    assert (written[0][10:50, 10:60] == (255, 0, 255)).all()
    np.testing.assert_array_equal(written[1][60:], astronaut_frames()[1][60:])  # the rest of the frame untouched
    assert not list(tmp_path.glob(TEMPORARY_PREFIX + "*"))


def test_a_failing_pipeline_leaves_no_output_and_distortion_is_removed_first(clip, tmp_path):
    with open_frames(clip / "frames") as source, pytest.raises(ValueError, match="boom"):
        VideoPlayer(lambda image: (_ for _ in ()).throw(ValueError("boom")), source).run(
            tmp_path / "a.mp4", tmp_path / "frames.jsonl")
    assert list(tmp_path.iterdir()) == []
    camera = Camera(K, *SIZE, distortion=[-0.3, 0.1, 0.0, 0.0, 0.0])
    seen = []
    with open_frames(clip / "frames") as source:
        player = VideoPlayer(lambda image: seen.append(image) or [], source, undistort=camera)
        list(player.play(max_frames=2))
    assert len(seen) == 2
    np.testing.assert_array_equal(seen[1], cv2.undistort(astronaut_frames()[1], K, camera.distortion))


def run_cli(capsys, *argv) -> tuple[int, str]:
    code = cli.main([str(part) for part in argv])
    return code, capsys.readouterr().err


def test_paz6d_run_end_to_end_on_a_video(clip, tmp_path, capsys):
    camera = write_camera_json(tmp_path / "camera.json", Camera(K, *SIZE))
    out = tmp_path / "out"
    code, err = run_cli(capsys, "run", "--input", clip / "clip.mkv", "--camera", camera, "--faces", "haar",
                        "--out", out, "--no-progress", "--max-frames", "3")
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["input"]["kind"] == "video" and summary["pipeline"] == "faces haar"
    assert summary["latency_ms"]["p95"] >= summary["latency_ms"]["median"] > 0 and summary["fps"] > 0
    records = list(read_records(out / "frames.jsonl"))
    assert [record.frame for record in records] == [0, 1, 2]
    assert all(isinstance(entry["box"], Box2D) for record in records for entry in record.results)
    with open_frames(out / "annotated.mp4") as source:
        assert (source.size, len(list(source))) == (SIZE, 3)


@pytest.mark.parametrize("change, expect", [
    (lambda paths: ["--input", paths["tmp"] / "bad.mp4"], "bad.mp4: cannot open the video"),
    (lambda paths: ["--input", "97"], "device 97: the camera device does not open"),
    (lambda paths: ["--camera", paths["big_camera"]], "frame 0 is 160x120 pixels, expected 640x480"),
    (lambda paths: ["--camera", paths["bad_camera"]], "camera.json: missing field 'fx'"),
    (lambda paths: ["--out", paths["frames"]], "--out"),
    (lambda paths: ["--faces", "head-pose", "--camera", None], "--camera: --faces head-pose needs"),
    (lambda paths: ["--faces", None, "--run", "1=x"], "--detector or --faces"),
    (lambda paths: ["--fps", "0"], "--fps"),
])
def test_paz6d_run_refuses_bad_input_in_one_line(clip, tmp_path, capsys, change, expect):
    (tmp_path / "bad.mp4").write_bytes(b"not a video" * 50)
    big = write_camera_json(tmp_path / "big" / "camera.json", Camera(K, 640, 480))
    bad = tmp_path / "bad" / "camera.json"
    bad.parent.mkdir()
    bad.write_text(json.dumps({"fy": 1.0, "cx": 1.0, "cy": 1.0, "width": 160, "height": 120}))
    paths = {"tmp": tmp_path, "big_camera": big, "bad_camera": bad, "frames": clip / "frames"}
    flags = {"--input": clip / "frames", "--camera": write_camera_json(tmp_path / "camera.json", Camera(K, *SIZE)),
             "--faces": "haar", "--out": tmp_path / "out"}
    changed = change(paths)
    flags.update(dict(zip(changed[::2], changed[1::2])))
    argv = [part for flag, value in flags.items() if value is not None for part in (flag, value)]
    code, err = run_cli(capsys, "run", *argv, "--no-progress")
    assert code == 2 and expect in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists() and sorted(p.name for p in (clip / "frames").iterdir())[-1] == "0003.png"


def test_detect_and_estimate_poses_through_the_player_with_its_own_drawing(clip, tmp_path):
    from paz6d.detect_and_estimate import DetectAndEstimatePose6D

    pose = Pose6D.from_rotation_vector([0.3, 0.2, 0.1], [0.0, 0.0, 0.5])
    box = Box2D(50, 30, 110, 90, 0.9, "obj_000001")
    cube = (np.array([[x, y, z] for x in (-0.03, 0.03) for y in (-0.03, 0.03) for z in (-0.03, 0.03)]),
            np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))
    pipeline = DetectAndEstimatePose6D(lambda image: [box], {1: lambda image, box, camera=None: pose},
                                       Camera(K, *SIZE), meshes={1: cube})
    with open_frames(clip / "frames") as source:
        summary = VideoPlayer(pipeline, source).run(tmp_path / "a.mkv", tmp_path / "frames.jsonl")
    assert summary["frames"] == 4
    records = list(read_records(tmp_path / "frames.jsonl"))
    expected = Pose6D(pose.quaternion, pose.translation, "obj_000001", pose.score)
    assert all(record.results == [{"box": box, "pose": expected}] for record in records)
    with open_frames(tmp_path / "a.mkv") as source:
        first = next(iter(source)).image
    np.testing.assert_array_equal(first, pipeline.draw(astronaut_frames()[0], [(box, expected)]))
    centre = np.rint(Camera(K, *SIZE).project(pose.translation[None])[0]).astype(int)  # the axes start there
    assert not np.array_equal(first[centre[1] - 2:centre[1] + 3, centre[0] - 2:centre[0] + 3],
                              astronaut_frames()[0][centre[1] - 2:centre[1] + 3, centre[0] - 2:centre[0] + 3])


def test_smoothing_as_the_players_transform_gives_the_smoothers_poses(clip, tmp_path):
    from paz6d.video.smoothing import PoseSmoother

    generator = np.random.default_rng(1)
    poses = [Pose6D.from_rotation_vector(generator.normal(0, 0.02, 3), [0.0, 0.0, 0.5] + generator.normal(0, 0.003, 3),
                                         "obj_000001") for _ in range(4)]
    calls = iter(poses)
    with open_frames(clip / "frames", fps=10.0) as source:
        VideoPlayer(lambda image: [next(calls)], source, transform=PoseSmoother(0.4)).run(
            records=tmp_path / "frames.jsonl")
    reference = PoseSmoother(0.4)
    expected = [reference([pose], frame)[0] for pose, frame in
                zip(poses, (type("F", (), {"timestamp_s": i / 10.0}) for i in range(4)))]
    written = [record.results[0]["pose"] for record in read_records(tmp_path / "frames.jsonl")]
    assert written == expected and written[0] == poses[0] and written[1] != poses[1]


def test_poses_of_the_stream_as_a_bop_results_csv(tmp_path):
    from paz6d.datasets.bop import read_pose_results
    from paz6d.video.bop_results import write_bop_results

    first = Pose6D.from_rotation_vector([0.1, 0.2, 0.3], [0.01, -0.02, 0.6], "obj_000005", 0.7)
    second = Pose6D.from_rotation_vector([-0.3, 0.0, 1.0], [0.05, 0.0, 0.9], "obj_000008", 0.4)
    head = Pose6D.from_rotation_vector([0, 0, 0], [0, 0, 0.5], "head")
    records = [FrameRecord(0, 0.0, 25.0, [{"box": Box2D(0, 0, 5, 5, 0.9, "obj_000005"), "pose": first}], "000012.png"),
               FrameRecord(1, 0.1, 50.0, [{"pose": second}, {"pose": head}], "000020.png"),
               FrameRecord(2, 0.2, 10.0, [{"pose": second}])]
    assert write_bop_results(records, tmp_path / "results.csv", 2) == 3
    results = read_pose_results(tmp_path / "results.csv")
    assert results.scene_ids.tolist() == [2, 2, 2] and results.im_ids.tolist() == [12, 20, 2]
    assert results.obj_ids.tolist() == [5, 8, 8] and results.scores.tolist() == [0.9, 0.4, 0.4]
    np.testing.assert_allclose(results.times, [0.025, 0.05, 0.01])
    np.testing.assert_allclose(results.rotations, [first.rotation_matrix, second.rotation_matrix,
                                                   second.rotation_matrix], atol=1e-12)
    np.testing.assert_allclose(results.translations, [first.translation, second.translation, second.translation],
                               atol=1e-12)
    with pytest.raises(ValueError, match="same image id 12"):
        write_bop_results([records[0], FrameRecord(5, 0.5, 1.0, [], "12.jpg")], tmp_path / "again.csv", 2)


def test_show_needs_a_display(clip, tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with open_frames(clip / "frames") as source, pytest.raises(ValueError, match="show: no display"):
        VideoPlayer(lambda image: [], source).run(tmp_path / "a.mp4", show=True)
    assert list(tmp_path.iterdir()) == []


def test_paz6d_run_show_without_a_display_fails_before_any_output(clip, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, err = run_cli(capsys, "run", "--input", clip / "frames", "--faces", "haar", "--show", "--out",
                        tmp_path / "out", "--no-progress")
    assert code == 2 and "--show: no display" in err and not (tmp_path / "out").exists()


def test_paz6d_run_streams_the_json_lines_to_standard_output(clip, tmp_path, capsys):
    code = cli.main(["run", "--input", str(clip / "frames"), "--faces", "haar", "--stream", "--out",
                     str(tmp_path / "out"), "--no-progress"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out == (tmp_path / "out" / "frames.jsonl").read_text()  # the lines as they were done
    assert [json.loads(line)["frame"] for line in captured.out.splitlines()] == [0, 1, 2, 3]
    assert "4 frames" in captured.err


def test_max_frames_reads_no_frame_beyond_the_last(tmp_path):
    for index, image in enumerate(astronaut_frames(3)):
        save_image(tmp_path / f"{index}.png", image)
    (tmp_path / "3.png").write_bytes(b"not an image")  # read only if the player went one frame too far
    with open_frames(tmp_path) as source:
        assert [frame.index for frame, _, _ in VideoPlayer(lambda image: [], source).play(max_frames=3)] == [0, 1, 2]
