"""Board images seen by a camera of known ``K`` and distortion, for checking ``paz6d calibrate`` end to end.

Writes ``--count`` PNGs of a chessboard (9x6 inner corners, 25 mm squares) or a ChArUco board (7x5 squares,
40 mm squares, 30 mm DICT_4X4_50 markers) at random tilts, made as the tests make them
(``tests/board_renders.py``: a 640 x 480 camera with fx 610, fy 604, cx 327.5, cy 236.5 px and barrel
distortion), and ``truth.json`` with that camera. Then::

    paz6d calibrate --images DIR --chessboard 9x6 --square-size 0.025 --out calib/
    paz6d calibrate --images DIR --charuco 7x5 --square-size 0.04 --marker-size 0.03 --out calib/

Run: ``.venv/bin/python scripts/render_calibration_boards.py --board chessboard --count 12 --seed 1 --out DIR``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))

from board_renders import DIST_TRUE, K_TRUE, SIZE, board_poses, chessboard_texture, render_board  # noqa: E402

from paz6d.backend.calibration import CharucoBoard  # noqa: E402
from paz6d.backend.files import write_json_atomically  # noqa: E402
from paz6d.backend.image import save_image  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--board", choices=("chessboard", "charuco"), default="chessboard")
    parser.add_argument("--count", type=int, default=12)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if args.board == "chessboard":
        pixels_per_square, square = 60, 0.025
        texture = chessboard_texture(9, 6, pixels_per_square)
    else:
        pixels_per_square, square = 80, 0.04
        board = CharucoBoard(7, 5, square, 0.03)
        texture = board.board().generateImage((7 * pixels_per_square + 80, 5 * pixels_per_square + 80),
                                              marginSize=40, borderBits=1)
    width, height = (side / pixels_per_square * square for side in texture.shape[::-1])
    args.out.mkdir(parents=True, exist_ok=True)
    for index, (R, t) in enumerate(board_poses(args.count, width, height, args.seed)):
        save_image(args.out / f"{args.board}_{index:03d}.png", render_board(texture, width, R, t))
    write_json_atomically(args.out / "truth.json", {"fx": K_TRUE[0, 0], "fy": K_TRUE[1, 1], "cx": K_TRUE[0, 2],
                                                    "cy": K_TRUE[1, 2], "width": SIZE[0], "height": SIZE[1],
                                                    "dist": DIST_TRUE.tolist()}, indent=2)
    print(f"wrote {args.count} {args.board} images and truth.json to {args.out}")


if __name__ == "__main__":
    main()
