"""``paz6d calibrate``: a camera's intrinsics and lens distortion from images of a chessboard or a ChArUco board.

Writes into ``--out``:

* ``camera.json``: the camera file that ``--camera`` reads (:mod:`paz6d.backend.camera_file`: the BOP
  fields ``fx, fy, cx, cy, width, height, depth_scale`` plus ``dist`` in OpenCV's order and ``rms_px``);
* ``corners.png``: every image with the corners found drawn (images without a board labelled in red);
* ``calibration.json``: the board, the images used and skipped, each view's RMS error and the standard
  deviations of the estimates.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from paz6d.backend.files import write_json_atomically
from paz6d.backend.paths import check_output_folder

#: Image files read from ``--images``.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
CAMERA_FILE = "camera.json"
CORNERS_FILE = "corners.png"
REPORT_FILE = "calibration.json"


def configure(parser: argparse.ArgumentParser) -> None:
    """Adds the ``paz6d calibrate`` flags."""
    parser.add_argument("--images", type=Path, required=True, help="folder of board images (all of one size)")
    board = parser.add_mutually_exclusive_group(required=True)
    board.add_argument("--chessboard", metavar="COLSxROWS",
                       help="a chessboard with COLSxROWS inner corners (where four squares meet), e.g. 9x6")
    board.add_argument("--charuco", metavar="COLSxROWS",
                       help="a ChArUco board of COLSxROWS squares (OpenCV's cv2.aruco.CharucoBoard), e.g. 7x5")
    parser.add_argument("--square-size", type=float, required=True, help="side of one square (metres)")
    parser.add_argument("--marker-size", type=float, help="ChArUco: side of one ArUco marker (metres)")
    parser.add_argument("--dictionary", default="DICT_4X4_50",
                        help="ChArUco: the ArUco dictionary, an OpenCV name (default: DICT_4X4_50)")
    parser.add_argument("--legacy-charuco", action="store_true",
                        help="ChArUco: the marker layout of OpenCV before 4.6 (boards with an even number of rows)")
    parser.add_argument("--min-views", type=int, default=5,
                        help="fewest images with a board found for a calibration (default 5; at least 3)")
    parser.add_argument("--fix-k3", action="store_true",
                        help="keep the distortion coefficient k3 at 0 (a lens with mild distortion, few views)")
    parser.add_argument("--depth-scale", type=float, default=1.0,
                        help="depth_scale written to camera.json: millimetres per depth unit (default 1.0)")
    parser.add_argument("--out", type=Path, required=True,
                        help="output folder: camera.json, corners.png, calibration.json")


def _board(args: argparse.Namespace):
    from paz6d.backend.calibration import CalibrationError, CharucoBoard, Chessboard, parse_board_size

    if args.chessboard is not None:
        if args.marker_size is not None:
            raise CalibrationError("--marker-size: only a ChArUco board (--charuco) has markers")
        return Chessboard(*parse_board_size(args.chessboard, "--chessboard", 3), args.square_size)
    if args.marker_size is None:
        raise CalibrationError("--marker-size: required with --charuco (side of one ArUco marker, metres)")
    columns, rows = parse_board_size(args.charuco, "--charuco", 3)
    return CharucoBoard(columns, rows, args.square_size, args.marker_size, args.dictionary, args.legacy_charuco)


def image_files(folder: Path) -> list[Path]:
    """The image files of ``folder``, sorted by name.

    Raises:
        ValueError: not a folder, or no image in it.
    """
    if not folder.is_dir():
        raise ValueError(f"--images: {folder} is not a folder")
    files = sorted(path for path in folder.iterdir() if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file())
    if not files:
        raise ValueError(f"--images: no image file ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    return files


def run(args: argparse.Namespace) -> int:
    """Runs ``paz6d calibrate``; bad input raises ``ValueError`` naming the flag or file."""
    import cv2

    from paz6d.backend.calibration import CalibrationError, calibrate, corner_grid
    from paz6d.backend.camera_file import write_camera_json
    from paz6d.backend.image import load_image, save_image

    board = _board(args)
    if args.min_views < 3:
        raise CalibrationError(f"--min-views: expected at least 3, got {args.min_views}")
    if not (np.isfinite(args.depth_scale) and args.depth_scale > 0):
        raise CalibrationError(f"--depth-scale: expected a positive number, got {args.depth_scale}")
    check_output_folder(args.out, "--out")
    files = image_files(args.images)
    images, views, size = [], [], None
    for path in files:
        image = load_image(path)
        if size is None:
            size = (image.shape[1], image.shape[0])
        elif (image.shape[1], image.shape[0]) != size:
            raise CalibrationError(f"{path}: image is {image.shape[1]}x{image.shape[0]} pixels, but {files[0].name} "
                                   f"is {size[0]}x{size[1]}; all calibration images must be of one size")
        images.append(image)
        views.append(board.detect(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)))
    used = [index for index, view in enumerate(views) if view is not None]
    if len(used) < args.min_views:
        raise CalibrationError(f"--images: the board ({board.name}) was found in {len(used)} of {len(files)} images "
                               f"in {args.images}, fewer than --min-views {args.min_views}; check the board flags "
                               "(inner corners for --chessboard, squares for --charuco) or add images")
    result = calibrate([views[index] for index in used], size, fix_k3=args.fix_k3)
    view_rms = dict(zip(used, result.view_rms_px))
    labels = [f"{path.name}: " + (f"{view_rms[index]:.3f} px" if index in view_rms else "no board")
              for index, path in enumerate(files)]
    args.out.mkdir(parents=True, exist_ok=True)
    camera_path = write_camera_json(args.out / CAMERA_FILE, result.camera, dist=result.dist, rms=result.rms_px,
                                    depth_scale=args.depth_scale)
    save_image(args.out / CORNERS_FILE, corner_grid(images, views, board, labels))
    K = result.camera.K
    write_json_atomically(args.out / REPORT_FILE, {
        "board": board.to_dict(), "image_size": list(size), "rms_px": result.rms_px,
        "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
        "dist": result.dist.tolist(),
        "std": result.std_intrinsics, "fix_k3": bool(args.fix_k3),
        "views": [{"file": files[index].name, "corners": len(views[index].image_points),
                   "rms_px": float(view_rms[index])} for index in used],
        "skipped": [path.name for index, path in enumerate(files) if index not in view_rms]}, indent=2)
    print(f"calibrated from {len(used)} of {len(files)} images ({board.name}): RMS re-projection error "
          f"{result.rms_px:.4f} px; fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f} px; "
          f"dist {np.array2string(result.dist, precision=5, separator=', ')}")
    print(f"wrote {camera_path}, {args.out / CORNERS_FILE} and {args.out / REPORT_FILE}")
    return 0
