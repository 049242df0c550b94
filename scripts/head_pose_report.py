"""Head-pose rotation errors of ``HeadPose6D`` on warped copies of scikit-image's astronaut photograph.

Usage: ``python scripts/head_pose_report.py [--out docs/images]``.

The true head pose of the photograph is unknown, but warps with a known camera motion give exact
relative ground truth: rotating the image by ``phi`` about the principal point is a camera roll
by ``-phi``; warping with ``K' R K^-1`` onto a larger canvas is a camera rotation ``R`` (yaw about
y, pitch about x). The estimate on the warped image must equal ``R @ R_original``; the error is
the angle of the residual rotation. Writes ``head_pose_errors.json`` and ``head_pose_axes.png``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import cv2
import numpy as np
import skimage.data
from tqdm import tqdm

from paz6d.backend.camera import Camera
from paz6d.faces.head_pose import HeadPose6D, draw_axes, yaw_pitch_roll_degrees

FOCAL = 512.0
CAMERA = Camera([[FOCAL, 0, 255.5], [0, FOCAL, 255.5], [0, 0, 1]], 512, 512)
WIDE_CAMERA = Camera([[FOCAL, 0, 511.5], [0, FOCAL, 511.5], [0, 0, 1]], 1024, 1024)
ROLLS = tuple(range(-45, 50, 5))
CAMERA_ANGLES = (-20, -15, -10, -5, 5, 10, 15, 20)


def rotation_error_degrees(R_estimated: np.ndarray, R_expected: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(cv2.Rodrigues(R_expected.T @ R_estimated)[0])))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    args = parser.parse_args()
    image = skimage.data.astronaut()
    estimator, wide_estimator = HeadPose6D(CAMERA), HeadPose6D(WIDE_CAMERA, detection_angles=(0.0,))
    reference = estimator.detect(image)[0].pose
    R_reference = reference.rotation_matrix
    results = {"reference_yaw_pitch_roll_degrees": yaw_pitch_roll_degrees(reference).tolist(),
               "reference_translation_m": reference.translation.tolist(), "roll": [], "yaw": [], "pitch": []}
    tiles = []
    for phi in tqdm(ROLLS, desc="roll"):
        rotation = cv2.getRotationMatrix2D((255.5, 255.5), float(phi), 1.0)
        rotated = cv2.warpAffine(image, rotation, (512, 512), borderMode=cv2.BORDER_REPLICATE)
        detections = estimator.detect(rotated)
        R_camera = cv2.Rodrigues(np.array([0.0, 0.0, -np.radians(phi)]))[0]
        error = rotation_error_degrees(detections[0].pose.rotation_matrix, R_camera @ R_reference) if detections \
            else None
        results["roll"].append({"degrees": phi, "faces": len(detections), "error_degrees": error})
        if phi in (-45, -20, 0, 30) and detections:
            tiles.append(draw_axes(rotated, detections[0].pose, CAMERA))
    for axis, name in ((1, "yaw"), (0, "pitch")):
        for angle in tqdm(CAMERA_ANGLES, desc=name):
            rotation_vector = np.zeros(3)
            rotation_vector[axis] = np.radians(angle)
            R_camera = cv2.Rodrigues(rotation_vector)[0]
            warped = cv2.warpPerspective(image, WIDE_CAMERA.K @ R_camera @ np.linalg.inv(CAMERA.K), (1024, 1024))
            detections = wide_estimator.detect(warped)
            error = rotation_error_degrees(detections[0].pose.rotation_matrix, R_camera @ R_reference) \
                if detections else None
            results[name].append({"degrees": angle, "faces": len(detections), "error_degrees": error})
    args.out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out / "head_pose_axes.png"),
                cv2.cvtColor(np.hstack([cv2.resize(tile, (256, 256), interpolation=cv2.INTER_AREA) for tile in tiles]),
                             cv2.COLOR_RGB2BGR))
    temporary = args.out / "head_pose_errors.json.tmp"
    temporary.write_text(json.dumps(results, indent=2) + "\n")
    os.replace(temporary, args.out / "head_pose_errors.json")
    print("reference yaw/pitch/roll (deg):", np.round(results["reference_yaw_pitch_roll_degrees"], 2))
    for name in ("roll", "yaw", "pitch"):
        errors = [row["error_degrees"] for row in results[name] if row["error_degrees"] is not None]
        missed = [row["degrees"] for row in results[name] if row["error_degrees"] is None]
        print(f"{name}: {len(errors)} warps, error mean {np.mean(errors):.2f} deg, max {np.max(errors):.2f} deg"
              + (f", no face at {missed}" if missed else ""))
        print("   " + ", ".join(f"{row['degrees']}: {row['error_degrees']:.2f}" for row in results[name]
                                if row["error_degrees"] is not None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
