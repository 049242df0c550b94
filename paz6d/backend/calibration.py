"""Camera calibration from images of a planar board: a chessboard or a ChArUco board (OpenCV).

A board is found in each image (:meth:`Chessboard.detect`, :meth:`CharucoBoard.detect`), its corners
refined to sub-pixel accuracy, and :func:`calibrate` fits the intrinsics ``K`` and OpenCV's distortion
``[k1, k2, p1, p2, k3]`` to all views (``cv2.calibrateCameraExtended``). Board sizes and squares are
in metres; the scale does not change ``K`` (it moves only the board poses).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import cv2
import numpy as np

from paz6d.backend.camera import Camera

#: Fewest corners a ChArUco view needs to count (and not all on one line).
MIN_CHARUCO_CORNERS = 6
#: Sub-pixel refinement stops after this many iterations or a move below this many pixels.
SUBPIXEL_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)


class CalibrationError(ValueError):
    """Bad board specification or images that cannot calibrate a camera (the message says which)."""


def parse_board_size(text: str, flag: str, minimum: int) -> tuple[int, int]:
    """``"COLSxROWS"`` -> ``(cols, rows)``, each at least ``minimum``.

    Raises:
        CalibrationError: naming ``flag`` and the expected form.
    """
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(text))
    if match is None or min(int(match.group(1)), int(match.group(2))) < minimum:
        raise CalibrationError(f"{flag}: expected COLSxROWS with whole numbers of at least {minimum} "
                               f"(e.g. 9x6), got {str(text)[:40]!r}")
    return int(match.group(1)), int(match.group(2))


def _positive(value: float, flag: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise CalibrationError(f"{flag}: expected a positive length in metres, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class BoardView:
    """A board found in one image.

    Attributes:
        image_points: ``(N, 2)`` float32 refined corner pixels.
        object_points: ``(N, 3)`` float32 the same corners on the board (metres, ``z = 0``).
        ids: ``(N,)`` corner ids (ChArUco) or ``None`` (chessboard: all corners, in row order).
    """

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray | None = None


def _subpixel_window(points: np.ndarray, columns: int) -> int:
    """Half side (px) of the sub-pixel search window: 40 % of the closest corner spacing along a row,
    between 2 and 11 px, so the window never reaches the next corner."""
    grid = points.reshape(-1, columns, 2)
    spacing = np.linalg.norm(np.diff(grid, axis=1), axis=-1).min() if columns > 1 else 10.0
    return int(np.clip(0.4 * spacing, 2, 11))


@dataclass(frozen=True)
class Chessboard:
    """A chessboard of ``columns x rows`` inner corners and squares of ``square_size`` metres."""

    columns: int
    rows: int
    square_size: float

    def __post_init__(self):
        if min(self.columns, self.rows) < 3:
            raise CalibrationError(f"--chessboard: expected at least 3x3 inner corners, got {self.columns}x{self.rows}")
        _positive(self.square_size, "--square-size")

    @property
    def name(self) -> str:
        return f"chessboard {self.columns}x{self.rows} inner corners, {self.square_size} m squares"

    def object_points(self) -> np.ndarray:
        """``(columns * rows, 3)`` float32 corner positions (metres), row by row."""
        x, y = np.meshgrid(np.arange(self.columns), np.arange(self.rows))
        points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=-1) * self.square_size
        return points.astype(np.float32)

    def to_dict(self) -> dict:
        return {"type": "chessboard", "columns": self.columns, "rows": self.rows, "square_size": self.square_size}

    def detect(self, grey: np.ndarray) -> BoardView | None:
        """The board in a ``uint8 (H, W)`` image with sub-pixel corners (``cv2.cornerSubPix``), or ``None``."""
        size = (self.columns, self.rows)
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(grey, size, flags=flags)
        if not found:
            return None
        half = _subpixel_window(corners.reshape(-1, 2), self.columns)
        corners = cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), SUBPIXEL_CRITERIA)
        return BoardView(corners.reshape(-1, 2).astype(np.float32), self.object_points())

    def draw(self, image: np.ndarray, view: BoardView, scale: float) -> None:
        """Draws ``view``'s corners, scaled by ``scale``, on ``image`` (in place)."""
        corners = (view.image_points * scale).reshape(-1, 1, 2).astype(np.float32)
        cv2.drawChessboardCorners(image, (self.columns, self.rows), corners, True)


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board of ``columns x rows`` squares (``square_size`` metres) with ArUco markers of
    ``marker_size`` metres from the OpenCV dictionary ``dictionary`` (e.g. ``"DICT_4X4_50"``);
    ``legacy``: the layout of OpenCV before 4.6 for boards with an even number of rows."""

    columns: int
    rows: int
    square_size: float
    marker_size: float
    dictionary: str = "DICT_4X4_50"
    legacy: bool = False

    def __post_init__(self):
        if min(self.columns, self.rows) < 3:
            raise CalibrationError(f"--charuco: expected at least 3x3 squares, got {self.columns}x{self.rows}")
        square = _positive(self.square_size, "--square-size")
        if not _positive(self.marker_size, "--marker-size") < square:
            raise CalibrationError(f"--marker-size: expected less than --square-size ({square} m), "
                                   f"got {self.marker_size}")
        names = sorted(name for name in dir(cv2.aruco) if name.startswith("DICT_"))
        if self.dictionary not in names:
            raise CalibrationError(f"--dictionary: unknown ArUco dictionary {str(self.dictionary)[:40]!r}; "
                                   f"expected one of {', '.join(names)}")
        markers = self.columns * self.rows // 2
        available = self._dictionary().bytesList.shape[0]
        if markers > available:
            raise CalibrationError(f"--dictionary: {self.dictionary} has {available} markers, a "
                                   f"{self.columns}x{self.rows} board needs {markers}")

    def _dictionary(self):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    @property
    def name(self) -> str:
        return (f"ChArUco {self.columns}x{self.rows} squares, {self.square_size} m squares, "
                f"{self.marker_size} m markers, {self.dictionary}")

    def to_dict(self) -> dict:
        return {"type": "charuco", "columns": self.columns, "rows": self.rows, "square_size": self.square_size,
                "marker_size": self.marker_size, "dictionary": self.dictionary, "legacy": self.legacy}

    def board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board (``generateImage`` draws it for printing)."""
        board = cv2.aruco.CharucoBoard((self.columns, self.rows), self.square_size, self.marker_size,
                                       self._dictionary())
        board.setLegacyPattern(self.legacy)
        return board

    def detect(self, grey: np.ndarray) -> BoardView | None:
        """The board's visible corners in a ``uint8 (H, W)`` image, or ``None`` with fewer than
        :data:`MIN_CHARUCO_CORNERS` or all on one line. Corners are interpolated from the markers by a
        local homography and refined with ``cv2.cornerSubPix`` (OpenCV's ``CharucoDetector``)."""
        board = self.board()
        corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(grey)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        ids = ids.ravel().astype(np.int32)
        object_points = board.getChessboardCorners()[ids].astype(np.float32)
        flat = object_points[:, :2] - object_points[:, :2].mean(axis=0)
        if np.linalg.svd(flat, compute_uv=False)[1] < 1e-3 * self.square_size:
            return None
        return BoardView(corners.reshape(-1, 2).astype(np.float32), object_points, ids)

    def draw(self, image: np.ndarray, view: BoardView, scale: float) -> None:
        """Draws ``view``'s corners, scaled by ``scale``, on ``image`` (in place)."""
        corners = (view.image_points * scale).reshape(-1, 1, 2).astype(np.float32)
        cv2.aruco.drawDetectedCornersCharuco(image, corners, None, (255, 0, 0))


@dataclass(frozen=True)
class Calibration:
    """A calibrated camera.

    Attributes:
        camera: ``K``, image size and distortion.
        dist: ``(5,)`` OpenCV distortion ``[k1, k2, p1, p2, k3]`` (also when all zero).
        rms_px: root-mean-square re-projection error over all corners (pixels).
        view_rms_px: ``(V,)`` the same per view.
        std_intrinsics: standard deviations of ``fx, fy, cx, cy`` (px) and of each ``dist`` coefficient.
    """

    camera: Camera
    dist: np.ndarray
    rms_px: float
    view_rms_px: np.ndarray
    std_intrinsics: dict[str, float]


def calibrate(views: list[BoardView], image_size: tuple[int, int], fix_k3: bool = False) -> Calibration:
    """Fits ``K`` and distortion to board views of images of ``image_size = (width, height)`` pixels.

    Args:
        views: at least 3 views (more views at varied tilts give better estimates).
        fix_k3: keep ``k3 = 0`` (lenses with mild distortion; fewer views needed).
    Raises:
        CalibrationError: fewer than 3 views.
    """
    if len(views) < 3:
        raise CalibrationError(f"calibration needs at least 3 views of the board, got {len(views)}")
    object_points = [view.object_points.reshape(-1, 1, 3) for view in views]
    image_points = [view.image_points.reshape(-1, 1, 2) for view in views]
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs, std_intrinsic, _, view_errors = cv2.calibrateCameraExtended(
        object_points, image_points, tuple(int(v) for v in image_size), None, None, flags=flags, criteria=criteria)
    dist = np.asarray(dist, dtype=np.float64).ravel()[:5]
    std = np.asarray(std_intrinsic, dtype=np.float64).ravel()
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    camera = Camera(K, image_size[0], image_size[1], dist)
    return Calibration(camera, dist, float(rms), np.asarray(view_errors, dtype=np.float64).ravel(),
                       {name: float(value) for name, value in zip(names, std)})


def corner_grid(images: list[np.ndarray], views: list[BoardView | None], board: Chessboard | CharucoBoard,
                labels: list[str], tile_width: int = 320) -> np.ndarray:
    """One ``uint8`` RGB picture of all images side by side (``tile_width`` px each, in rows of
    ``ceil(sqrt(n))``), the detected corners drawn, each labelled (``labels``); an image without a board
    is labelled so in red.

    Args:
        images: ``uint8 (H, W, 3)`` RGB images.
        views: the board found in each image, or ``None``.
    """
    tiles = []
    for image, view, label in zip(images, views, labels):
        scale = tile_width / image.shape[1]
        tile = cv2.resize(image, (tile_width, max(1, round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        if view is not None:
            board.draw(tile, view, scale)
        color = (255, 255, 255) if view is not None else (255, 40, 40)
        for thickness, ink in ((3, (0, 0, 0)), (1, color)):
            cv2.putText(tile, label, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, ink, thickness, cv2.LINE_AA)
        tiles.append(tile)
    columns = math.ceil(math.sqrt(len(tiles)))
    height = max(tile.shape[0] for tile in tiles)
    canvas = np.zeros((height * math.ceil(len(tiles) / columns), tile_width * columns, 3), np.uint8)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        canvas[row * height:row * height + tile.shape[0], column * tile_width:(column + 1) * tile_width] = tile
    return canvas
