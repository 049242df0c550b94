"""``paz6d calibrate`` and :mod:`paz6d.backend.calibration`: boards rendered at a known ``K`` and distortion
(:mod:`board_renders`) give that camera back."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from board_renders import DIST_TRUE, K_TRUE, SIZE, board_poses, chessboard_texture, render_board
from paz6d import cli
from paz6d.backend.calibration import CalibrationError, CharucoBoard, Chessboard, calibrate, parse_board_size
from paz6d.backend.camera import Camera
from paz6d.backend.camera_file import read_camera_json
from paz6d.backend.image import save_image

CHESSBOARD = Chessboard(9, 6, 0.025)
CHARUCO = CharucoBoard(7, 5, 0.04, 0.03, "DICT_4X4_50")


def chessboard_renders(count: int, seed: int) -> list[np.ndarray]:
    pixels_per_square = 60
    texture = chessboard_texture(CHESSBOARD.columns, CHESSBOARD.rows, pixels_per_square)
    width, height = (side / pixels_per_square * CHESSBOARD.square_size for side in texture.shape[::-1])
    return [render_board(texture, width, R, t) for R, t in board_poses(count, width, height, seed)]


def charuco_renders(count: int, seed: int) -> list[np.ndarray]:
    pixels_per_square, margin = 80, 40
    texture = CHARUCO.board().generateImage((CHARUCO.columns * pixels_per_square + 2 * margin,
                                             CHARUCO.rows * pixels_per_square + 2 * margin), marginSize=margin,
                                            borderBits=1)
    width, height = (side / pixels_per_square * CHARUCO.square_size for side in texture.shape[::-1])
    return [render_board(texture, width, R, t) for R, t in board_poses(count, width, height, seed)]


@pytest.fixture(scope="module")
def chessboard_images() -> list[np.ndarray]:
    return chessboard_renders(12, seed=1)


def grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def assert_recovers_the_camera(K: np.ndarray, dist: np.ndarray, views) -> None:
    """fx, fy, cx, cy within 0.5 %, and the fitted lens's distortion (the shift that undistorting
    gives each pixel where a corner was seen) within 0.2 px of the true lens's."""
    for (row, column), name in zip(((0, 0), (1, 1), (0, 2), (1, 2)), ("fx", "fy", "cx", "cy")):
        assert K[row, column] == pytest.approx(K_TRUE[row, column], rel=0.005), name
    pixels = np.concatenate([view.image_points for view in views]).astype(np.float64)
    true_shift = Camera(K_TRUE, *SIZE, DIST_TRUE).undistort_points(pixels) - pixels
    fitted_shift = Camera(K, *SIZE, dist).undistort_points(pixels) - pixels
    assert np.abs(true_shift).max() > 5  # the lens moves the corners by several pixels
    assert np.abs(fitted_shift - true_shift).max() < 0.2


def test_chessboard_renders_give_back_the_camera(chessboard_images):
    views = [CHESSBOARD.detect(grey(image)) for image in chessboard_images]
    assert all(view is not None for view in views)
    result = calibrate(views, SIZE)
    assert_recovers_the_camera(result.camera.K, result.dist, views)
    assert result.rms_px < 0.1 and result.view_rms_px.shape == (12,)
    assert result.std_intrinsics["fx"] < 1.0


def test_subpixel_refinement_beats_the_raw_corners(chessboard_images):
    """Corners refined by cv2.cornerSubPix lie closer to the true projections than OpenCV's raw detections."""
    image = grey(chessboard_images[0])
    _, raw = cv2.findChessboardCorners(image, (9, 6), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    refined = CHESSBOARD.detect(image).image_points
    # the board's own pose from the refined corners is the oracle for both (the renders know K and dist)
    ok, rvec, tvec = cv2.solvePnP(CHESSBOARD.object_points(), refined, K_TRUE, DIST_TRUE)
    truth = cv2.projectPoints(CHESSBOARD.object_points(), rvec, tvec, K_TRUE, DIST_TRUE)[0].reshape(-1, 2)
    assert ok
    assert np.abs(refined - truth).max() < 0.1 < np.abs(raw.reshape(-1, 2) - truth).max()


def test_charuco_renders_give_back_the_camera():
    views = [CHARUCO.detect(grey(image)) for image in charuco_renders(12, seed=2)]
    assert all(view is not None and len(view.ids) == 24 for view in views)
    result = calibrate(views, SIZE)
    assert_recovers_the_camera(result.camera.K, result.dist, views)
    assert result.rms_px < 0.15


def test_no_board_in_a_blank_image():
    blank = np.full((SIZE[1], SIZE[0]), 128, np.uint8)
    assert CHESSBOARD.detect(blank) is None and CHARUCO.detect(blank) is None


def test_calibrate_command_writes_the_camera_file_and_corner_picture(chessboard_images, tmp_path, capsys):
    folder = tmp_path / "images"
    write_images(folder, chessboard_images)
    save_image(folder / "99_blank.png", np.full((SIZE[1], SIZE[0], 3), 200, np.uint8))
    out = tmp_path / "out"
    assert cli.main(["calibrate", "--images", str(folder), "--chessboard", "9x6", "--square-size", "0.025",
                     "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    camera = read_camera_json(out / "camera.json")
    views = [CHESSBOARD.detect(grey(image)) for image in chessboard_images]
    assert_recovers_the_camera(camera.K, camera.distortion, views)
    data = json.loads((out / "camera.json").read_text())
    assert set(data) == {"fx", "fy", "cx", "cy", "width", "height", "depth_scale", "dist", "rms_px"}
    assert (data["width"], data["height"]) == SIZE and len(data["dist"]) == 5 and data["rms_px"] < 0.1
    assert f"{data['rms_px']:.4f} px" in printed and "12 of 13 images" in printed
    report = json.loads((out / "calibration.json").read_text())
    assert report["skipped"] == ["99_blank.png"] and len(report["views"]) == 12
    view_rms = np.array([view["rms_px"] for view in report["views"]])
    corners = np.array([view["corners"] for view in report["views"]])
    assert np.sqrt(np.sum(view_rms ** 2 * corners) / corners.sum()) == pytest.approx(data["rms_px"], rel=1e-6)
    picture = cv2.imread(str(out / "corners.png"))
    assert picture.shape == (4 * 240, 4 * 320, 3)  # 13 tiles of 320 x 240 in rows of 4
    tile = picture[:240, :320].astype(int)
    assert (np.abs(tile[..., 0] - tile[..., 2]) > 100).sum() > 100  # coloured corner marks on a grey render


def write_images(folder, images) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    for index, image in enumerate(images):
        save_image(folder / f"{index:02d}.png", image)
    return str(folder)


@pytest.mark.parametrize("name, argv, expect", [
    ("no-images", ["--images", "{empty}", "--chessboard", "9x6"], "--images: no image file"),
    ("not-a-folder", ["--images", "{tmp}/missing", "--chessboard", "9x6"], "is not a folder"),
    ("no-board", ["--images", "{blank}", "--chessboard", "9x6"], "was found in 0 of 3 images"),
    ("too-few", ["--images", "{two}", "--chessboard", "9x6"], "was found in 2 of 2 images"),
    ("sizes", ["--images", "{mixed}", "--chessboard", "9x6"], "all calibration images must be of one size"),
    ("board-spec", ["--images", "{two}", "--chessboard", "9by6"], "--chessboard: expected COLSxROWS"),
    ("board-small", ["--images", "{two}", "--chessboard", "2x6"], "--chessboard: expected COLSxROWS"),
    ("square", ["--images", "{two}", "--chessboard", "9x6", "--square-size", "-1"], "--square-size: expected a pos"),
    ("marker-without-charuco", ["--images", "{two}", "--chessboard", "9x6", "--marker-size", "0.01"],
     "--marker-size: only a ChArUco"),
    ("charuco-without-marker", ["--images", "{two}", "--charuco", "7x5"], "--marker-size: required with --charuco"),
    ("marker-too-big", ["--images", "{two}", "--charuco", "7x5", "--marker-size", "0.05"],
     "--marker-size: expected less than --square-size"),
    ("dictionary", ["--images", "{two}", "--charuco", "7x5", "--marker-size", "0.01", "--dictionary", "DICT_9X9"],
     "--dictionary: unknown ArUco dictionary"),
    ("dictionary-small", ["--images", "{two}", "--charuco", "15x15", "--marker-size", "0.01"],
     "DICT_4X4_50 has 50 markers"),
    ("min-views", ["--images", "{two}", "--chessboard", "9x6", "--min-views", "2"], "--min-views: expected at least 3"),
    ("corrupt-image", ["--images", "{corrupt}", "--chessboard", "9x6"], "could not decode image"),
])
def test_bad_input_exits_2_with_one_line(name, argv, expect, chessboard_images, tmp_path, capsys):
    folders = {"tmp": str(tmp_path), "empty": str(tmp_path / "empty"),
               "blank": write_images(tmp_path / "blank", [np.full((48, 64, 3), 128, np.uint8)] * 3),
               "two": write_images(tmp_path / "two", chessboard_images[:2]),
               "mixed": write_images(tmp_path / "mixed", [chessboard_images[0], chessboard_images[1][:400]])}
    (tmp_path / "empty").mkdir()
    write_images(tmp_path / "corrupt", chessboard_images[:1])
    (tmp_path / "corrupt" / "01.png").write_bytes(b"not a png")
    folders["corrupt"] = str(tmp_path / "corrupt")
    argv = [part.format(**folders) for part in argv]
    if "--square-size" not in argv:
        argv += ["--square-size", "0.025"]
    assert cli.main(["calibrate", *argv, "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("paz6d calibrate: error: ") and expect in error, error
    assert not (tmp_path / "out").exists()


def test_parse_board_size():
    assert parse_board_size(" 9X6 ", "--chessboard", 3) == (9, 6)
    with pytest.raises(CalibrationError, match="at least 3"):
        parse_board_size("9x2", "--chessboard", 3)
