"""Frame sources (paz6d.video.frames) and the video writer (paz6d.video.video_file), against OpenCV."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from paz6d.backend.files import TEMPORARY_PREFIX
from paz6d.video.frames import FrameSizeError, FrameSourceError, device_index, open_frames
from paz6d.backend.image import save_image
from paz6d.video.video_file import VideoFileWriter


def random_frames(count: int = 6, size: tuple[int, int] = (64, 48), seed: int = 0) -> list[np.ndarray]:
    generator = np.random.default_rng(seed)
    return [generator.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8) for _ in range(count)]


def test_lossless_video_round_trip_keeps_every_pixel_and_timestamp(tmp_path):
    frames = random_frames()
    with VideoFileWriter(tmp_path / "clip.mkv", 10.0, (64, 48)) as writer:
        for image in frames:
            writer.write(image)
    assert writer.frames == 6 and not list(tmp_path.glob(TEMPORARY_PREFIX + "*"))
    with open_frames(tmp_path / "clip.mkv", size=(64, 48)) as source:
        read = list(source)
        assert (source.kind, source.fps, source.size, source.count) == ("video", 10.0, (64, 48), 6)
    assert [frame.index for frame in read] == list(range(6))
    np.testing.assert_allclose([frame.timestamp_s for frame in read], np.arange(6) / 10.0, atol=1e-9)
    for frame, image in zip(read, frames):
        np.testing.assert_array_equal(frame.image, image)  # RGB in, RGB out (the writer and reader convert BGR)


def test_mp4_round_trip_is_close_and_decodes_as_opencv_does(tmp_path):
    image = np.zeros((48, 64, 3), np.uint8)
    image[:, :32] = (200, 30, 30)  # red left half: a swapped channel order would show
    with VideoFileWriter(tmp_path / "clip.mp4", 5.0, (64, 48)) as writer:
        for _ in range(3):
            writer.write(image)
    with open_frames(str(tmp_path / "clip.mp4")) as source:
        read = [frame.image for frame in source]
    assert len(read) == 3
    capture = cv2.VideoCapture(str(tmp_path / "clip.mp4"))
    ok, bgr = capture.read()
    capture.release()
    np.testing.assert_array_equal(read[0], cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    assert np.abs(read[0].astype(int) - image).mean() < 3.0
    assert read[0][24, 10, 0] > 150 and read[0][24, 10, 2] < 80


def test_a_folder_is_read_in_name_order_with_timestamps_from_fps(tmp_path):
    frames = random_frames(3)
    for name, image in zip(("b.png", "a.png", "c.jpg"), frames):
        save_image(tmp_path / name, image)
    (tmp_path / "notes.txt").write_text("not an image")
    with open_frames(tmp_path, fps=4.0) as source:
        read = list(source)
        assert (source.kind, source.count, source.fps) == ("folder", 3, 4.0)
    np.testing.assert_array_equal(read[0].image, frames[1])
    np.testing.assert_array_equal(read[1].image, frames[0])
    assert [frame.timestamp_s for frame in read] == [0.0, 0.25, 0.5]


def test_bad_sources_give_clear_errors(tmp_path):
    with pytest.raises(FrameSourceError, match="no such video file"):
        open_frames(tmp_path / "none.mp4")
    (tmp_path / "bad.mp4").write_bytes(b"garbage" * 100)
    with pytest.raises(FrameSourceError, match="bad.mp4: cannot open the video"):
        open_frames(tmp_path / "bad.mp4")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FrameSourceError, match="no image file"):
        open_frames(tmp_path / "empty")
    with pytest.raises(FrameSourceError, match="device 97: the camera device does not open"):
        open_frames(97)
    with pytest.raises(FrameSourceError, match="device 96"):
        open_frames("96")
    with pytest.raises(ValueError, match="fps"):
        open_frames(tmp_path, fps=0)
    with pytest.raises(FrameSourceError, match="input: empty"):
        open_frames("")


def test_frames_of_another_size_than_the_camera_are_refused(tmp_path):
    save_image(tmp_path / "a.png", random_frames(1)[0])
    with pytest.raises(FrameSizeError, match="a.png: frame 0 is 64x48 pixels, expected 640x480"):
        open_frames(tmp_path, size=(640, 480))
    save_image(tmp_path / "b.png", random_frames(1, (32, 48))[0])
    with open_frames(tmp_path) as source, pytest.raises(FrameSizeError, match="b.png: frame 1 is 32x48"):
        list(source)


def test_device_index_and_writer_errors(tmp_path):
    assert device_index(0) == 0 and device_index("12") == 12
    assert device_index("clip.mp4") is None and device_index("-1") is None and device_index(True) is None
    with pytest.raises(ValueError, match="ending in"):
        VideoFileWriter(tmp_path / "clip.gif", 10, (64, 48))
    with pytest.raises(ValueError, match="64x48"):
        with VideoFileWriter(tmp_path / "clip.mp4", 10, (64, 48)) as writer:
            writer.write(np.zeros((10, 10, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []  # nothing left behind


def test_estimate_folder_frames_number_the_sorted_images_and_undistort_them_with_the_camera(tmp_path, monkeypatch):
    from paz6d.backend.camera import Camera
    from paz6d.split_estimation import FolderFrames

    first, second = random_frames(2)
    save_image(tmp_path / "b.png", second)
    save_image(tmp_path / "a.png", first)
    K = np.array([[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]])
    dist = np.array([0.3, -0.1, 0.01, 0.0, 0.0])
    frames = FolderFrames(tmp_path, Camera(K, 64, 48, dist))
    found = list(frames)
    assert [(frame.scene_id, frame.im_id, frame.name) for frame in found] == [(0, 0, "a.png"), (0, 1, "b.png")]
    assert frames.undistorted and frames.count == 2 and frames.skipped == 0
    assert all(frame.camera.distortion is None and np.array_equal(frame.camera.K, K) for frame in found)
    for frame, image in zip(found, (first, second)):
        np.testing.assert_array_equal(frame.image, cv2.undistort(image, K, dist))
        assert not np.array_equal(frame.image, image)
    plain = list(FolderFrames(tmp_path, Camera(K, 64, 48)))
    np.testing.assert_array_equal(plain[1].image, second)
    with pytest.raises(FrameSizeError, match="a.png: frame 0 is 64x48 pixels, expected 32x24"):
        FolderFrames(tmp_path, Camera(K, 32, 24))
    save_image(tmp_path / "7" / "c.png", first)  # a folder named with digits is a folder, not camera device 7
    monkeypatch.chdir(tmp_path)
    assert [frame.name for frame in FolderFrames(Path("7"), Camera(K, 64, 48))] == ["c.png"]
