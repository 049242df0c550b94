"""Processor framework (Processor, SequentialProcessor, RandomProcessor, reseed) and the thin
processors of paz6d.processors, each checked against the backend function it wraps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, Keypoints2D, Pose6D, Processor, RandomProcessor, SequentialProcessor
from paz6d.abstract import random_processors, reseed
from paz6d.backend import boxes as boxes_backend
from paz6d.backend import camera as camera_backend
from paz6d.backend import image as image_backend
from paz6d.backend import keypoints as keypoints_backend
from paz6d.backend.camera import Camera
from paz6d.processors import boxes as box_processors
from paz6d.processors import image as image_processors
from paz6d.processors import keypoints as keypoint_processors
from paz6d.processors import pose as pose_processors

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


class AddOne(Processor):
    def call(self, x):
        return x + 1


class Scale(Processor):
    def __init__(self, factor, name=None):
        super().__init__(name)
        self.factor = factor

    def call(self, x):
        return x * self.factor


class Jitter(RandomProcessor):
    def call(self, x):
        return x + self.generator.random()


def double(x):
    return 2 * x


@pytest.fixture
def picture() -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (24, 32, 3), dtype=np.uint8)


def test_processor_names_and_call():
    assert AddOne()(1) == 2
    assert AddOne().name == "AddOne"
    step = Scale(3, name="triple")
    assert step.name == "triple" and repr(step) == "Scale(name='triple')"
    step.name = "thrice"
    assert step.name == "thrice"
    with pytest.raises(NotImplementedError, match="Processor must implement call"):
        Processor()(1)


def test_sequential_processor_list_operations():
    pipeline = SequentialProcessor([AddOne(), double])
    assert pipeline(3) == 8 and len(pipeline) == 2
    assert pipeline.add(Scale(10, "ten")) is pipeline
    assert pipeline(3) == 80
    pipeline.insert(0, Scale(-1, "negate"))
    assert pipeline(3) == (-3 + 1) * 2 * 10
    assert [type(step).__name__ for step in pipeline] == ["Scale", "AddOne", "function", "Scale"]
    assert pipeline[2] is double and pipeline[-1].name == "ten"
    sliced = pipeline[1:3]
    assert isinstance(sliced, SequentialProcessor) and sliced(3) == 8
    assert pipeline.remove("double") is double
    assert pipeline(3) == (-3 + 1) * 10
    assert pipeline.pop().name == "ten" and pipeline.pop(0).name == "negate"
    assert len(pipeline) == 1 and pipeline(3) == 4
    steps = pipeline.steps
    steps.append(double)
    assert len(pipeline) == 1  # steps is a copy
    assert "AddOne" in repr(pipeline)
    with pytest.raises(ValueError, match=r"name: no step named 'missing'; steps are \['AddOne'\]"):
        pipeline.remove("missing")
    with pytest.raises(ValueError, match="step: expected a callable"):
        pipeline.add(3)
    with pytest.raises(ValueError, match="step: expected a callable"):
        SequentialProcessor([AddOne(), "not callable"])
    pipeline.pop()
    with pytest.raises(IndexError, match="pop from an empty SequentialProcessor"):
        pipeline.pop()


def test_sequential_processor_nesting_and_arguments():
    inner = SequentialProcessor([AddOne(), AddOne()], name="add_two")
    outer = SequentialProcessor([lambda a, b: a * b, inner, double])
    assert outer(3, b=4) == (12 + 2) * 2
    assert outer.name == "SequentialProcessor" and inner.name == "add_two"
    assert outer.remove("add_two") is inner
    empty = SequentialProcessor()
    assert empty(5) == 5 and empty(1, 2) == (1, 2)


def test_random_processor_seeding_and_reseed():
    assert Jitter(seed=3)(0.0) == Jitter(seed=3)(0.0)
    assert Jitter(seed=3)(0.0) != Jitter(seed=4)(0.0)
    generator = np.random.default_rng(9)
    shared = Jitter(seed=generator)
    assert shared.generator is generator
    first, second, plain = Jitter(seed=1), Jitter(seed=1), AddOne()
    nested = SequentialProcessor([first, SequentialProcessor([plain, second]), double])
    found = random_processors(nested)
    assert found == [first, second]
    assert random_processors(SequentialProcessor([first, first])) == [first]
    reseed(nested, 42)
    value = nested(0.0)
    reseed(nested, 42)
    assert nested(0.0) == value
    reseed(nested, 43)
    assert nested(0.0) != value
    reseed(nested, 42)
    # the two processors get independent streams, not the same one
    assert first.generator.random() != second.generator.random()


def test_random_processors_found_inside_attributes():
    holder = pose_processors.PoseFromKeypoints(np.eye(3) + 0.1, K)
    assert random_processors(holder) == []
    flip = image_processors.RandomFlipLeftRight(seed=0)

    class Holder(Processor):
        def __init__(self):
            super().__init__()
            self.table = {"flip": flip, "others": [Jitter(seed=0)]}

        def call(self, x):
            return x

    found = random_processors(Holder())
    assert found[0] is flip and isinstance(found[1], Jitter)


def test_image_processors_wrap_the_backend(picture, tmp_path):
    path = image_backend.save_image(tmp_path / "picture.png", picture)
    np.testing.assert_array_equal(image_processors.LoadImage()(path), picture)
    assert image_processors.LoadImage(grayscale=True)(path).shape == (24, 32)
    np.testing.assert_array_equal(image_processors.ResizeImage((16, 12))(picture),
                                  cv2.resize(picture, (16, 12), interpolation=cv2.INTER_LINEAR))
    np.testing.assert_array_equal(image_processors.ConvertColorSpace("RGB", "BGR")(picture), picture[..., ::-1])
    normalized = image_processors.NormalizeImage(mean=[0.5] * 3, std=[0.25] * 3)(picture)
    assert normalized.dtype == np.float32
    np.testing.assert_allclose(normalized, (picture / 255.0 - 0.5) / 0.25, atol=1e-6)  # float32 rounding
    np.testing.assert_array_equal(image_processors.DenormalizeImage([0.5] * 3, [0.25] * 3)(normalized), picture)
    np.testing.assert_array_equal(image_processors.CropImage()(picture, [2.5, 3, 10, 7.2]), picture[3:8, 2:10])
    assert image_processors.PadToSquare(value=9)(picture).shape == (32, 32, 3)


@pytest.mark.parametrize("processor, backend, arguments", [
    (image_processors.RandomBrightness(20.0, seed=5), image_backend.random_brightness, (20.0,)),
    (image_processors.RandomContrast(0.6, 1.4, seed=5), image_backend.random_contrast, (0.6, 1.4)),
    (image_processors.RandomSaturation(0.6, 1.4, seed=5), image_backend.random_saturation, (0.6, 1.4)),
    (image_processors.RandomHue(30.0, seed=5), image_backend.random_hue, (30.0,)),
    (image_processors.RandomImageNoise(8.0, seed=5), image_backend.random_image_noise, (8.0,)),
])
def test_random_photometric_processors_use_their_generator(picture, processor, backend, arguments):
    expected = backend(picture, np.random.default_rng(5), *arguments)
    np.testing.assert_array_equal(processor(picture), expected)
    processor.reseed(5)
    np.testing.assert_array_equal(processor(picture), expected)
    later = [processor(picture) for _ in range(3)]  # the generator advances between calls
    assert not all(np.array_equal(output, expected) for output in later)


def test_random_gaussian_blur_probability(picture):
    never = image_processors.RandomGaussianBlur(probability=0.0, seed=0)
    assert never(picture) is picture
    always = image_processors.RandomGaussianBlur(kernel_sizes=(5,), probability=1.0, seed=0)
    np.testing.assert_array_equal(always(picture), cv2.GaussianBlur(picture, (5, 5), 0))


def test_random_flip_left_right_moves_boxes_with_the_image(picture):
    boxes = np.array([[2.0, 3.0, 10.0, 8.0, 7.0]])
    flipped, moved = image_processors.RandomFlipLeftRight(probability=1.0, seed=0)(picture, boxes)
    np.testing.assert_array_equal(flipped, picture[:, ::-1])
    np.testing.assert_array_equal(moved, [[22.0, 3.0, 30.0, 8.0, 7.0]])
    np.testing.assert_array_equal(image_backend.crop(flipped, moved[0, :4]),
                                  image_backend.crop(picture, boxes[0, :4])[:, ::-1])
    unchanged, same = image_processors.RandomFlipLeftRight(probability=0.0, seed=0)(picture, boxes)
    np.testing.assert_array_equal(unchanged, picture)
    np.testing.assert_array_equal(same, boxes)


def test_random_crop_keeps_boxes_whose_centre_is_inside(picture):
    boxes = np.array([[0.0, 0.0, 32.0, 24.0, 1.0], [0.0, 0.0, 2.0, 2.0, 2.0], [30.0, 22.0, 32.0, 24.0, 3.0]])
    for seed in range(10):
        window = image_backend.random_crop_box((32, 24), np.random.default_rng(seed))
        cropped, kept = image_processors.RandomCrop(seed=seed)(picture, boxes)
        np.testing.assert_array_equal(cropped, image_backend.crop(picture, window))
        centers = (boxes[:, :2] + boxes[:, 2:4]) / 2
        inside = np.all((centers >= window[:2]) & (centers < window[2:]), axis=1)
        np.testing.assert_array_equal(kept[:, 4], boxes[inside, 4])
        assert np.all(kept[:, :4] >= 0) and np.all(kept[:, [2, 3]] <= [cropped.shape[1], cropped.shape[0]])
        assert 1.0 in kept[:, 4]  # the full-image box always survives, clipped to the crop
        np.testing.assert_array_equal(kept[kept[:, 4] == 1.0, :4], [[0, 0, cropped.shape[1], cropped.shape[0]]])
    assert image_processors.RandomCrop(seed=0)(picture).ndim == 3
    with pytest.raises(ValueError, match=r"boxes: expected shape \(N, 4 \+ k\)"):
        image_processors.RandomCrop(seed=0)(picture, [1, 2, 3])


def test_blend_background_composites_over_a_background_patch(picture):
    background = np.full((50, 60, 3), 200, np.uint8)
    alpha = np.zeros((24, 32), bool)
    alpha[5:10, 5:10] = True
    blended = image_processors.BlendBackground([background], seed=0)(picture, alpha)
    np.testing.assert_array_equal(blended[alpha], picture[alpha])
    assert np.all(blended[~alpha] == 200)
    with pytest.raises(ValueError, match="backgrounds: expected at least one"):
        image_processors.BlendBackground([])


def test_box_processors_wrap_the_backend():
    boxes = np.array([[10.0, 20.0, 50.0, 60.0], [-5.0, 0.0, 700.0, 30.0]])
    np.testing.assert_array_equal(box_processors.ConvertBoxFormat("xyxy", "xywh")(boxes),
                                  boxes_backend.convert(boxes, "xyxy", "xywh"))
    normalized = box_processors.NormalizeBoxes((640, 480))(boxes)
    np.testing.assert_allclose(box_processors.DenormalizeBoxes((640, 480))(normalized), boxes)
    np.testing.assert_array_equal(box_processors.ClipBoxes((640, 480))(boxes)[1], [0, 0, 640, 30])
    kept_boxes, kept_scores, kept_ids = box_processors.NonMaximumSuppression(0.5, 0.1)(
        [[0, 0, 10, 10], [1, 1, 10, 10], [0, 0, 10, 10], [50, 50, 60, 60]], [0.9, 0.8, 0.7, 0.05], [0, 0, 1, 0])
    np.testing.assert_array_equal(kept_scores, [0.9, 0.7])
    np.testing.assert_array_equal(kept_ids, [0, 1])
    np.testing.assert_array_equal(kept_boxes, [[0, 0, 10, 10], [0, 0, 10, 10]])
    messages = box_processors.ToBoxes2D(["duck", "cat"])(kept_boxes, kept_scores, kept_ids)
    assert messages == [Box2D(0, 0, 10, 10, 0.9, "duck"), Box2D(0, 0, 10, 10, 0.7, "cat")]
    assert box_processors.ToBoxes2D()(boxes[:1]) == [Box2D(10, 20, 50, 60)]
    with pytest.raises(ValueError, match="class_ids: given without class_names"):
        box_processors.ToBoxes2D()(boxes, None, [0, 1])


def test_encode_and_decode_boxes_processors_round_trip():
    priors = boxes_backend.prior_boxes(300, [3], [100], [60], [150], [[2]])
    truth = np.array([[0.1, 0.1, 0.4, 0.5], [0.6, 0.5, 0.95, 0.9]])
    targets = box_processors.EncodeBoxes(priors, iou_threshold=0.4)(truth, [0, 4])
    assert targets.shape == (len(priors), 5)
    matched = boxes_backend.match(truth, priors, 0.4)
    np.testing.assert_array_equal(targets[:, 4], np.where(matched >= 0, np.array([1, 5])[matched], 0))
    decoded = box_processors.DecodeBoxes(priors)(targets[:, :4])
    positive = matched >= 0
    np.testing.assert_allclose(decoded[positive], truth[matched[positive]], atol=1e-12)
    with pytest.raises(ValueError, match="class_ids: expected 2 ids matching boxes, got 1"):
        box_processors.EncodeBoxes(priors)(truth, [0])


def test_keypoint_processors_wrap_the_backend():
    points = np.array([[0.0, 0.0], [31.0, 23.0], [10.5, 4.0]])
    normalized = keypoint_processors.NormalizeKeypoints((32, 24))(points)
    np.testing.assert_array_equal(normalized, keypoints_backend.normalize(points, (32, 24)))
    np.testing.assert_allclose(keypoint_processors.DenormalizeKeypoints((32, 24))(normalized), points)
    np.testing.assert_array_equal(keypoint_processors.FlipKeypointsLeftRight(32, [1, 0, 2])(points),
                                  [[0.0, 23.0], [31.0, 0.0], [20.5, 4.0]])
    message = keypoint_processors.ToKeypoints2D("face")(points, [1, 1, 0.5])
    assert message == Keypoints2D(points, [1, 1, 0.5], "face")


def test_pose_processors_solve_project_and_convert():
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation.as_matrix(), [0.02, -0.01, 0.7]
    model = np.random.default_rng(1).uniform(-0.05, 0.05, (12, 3))
    lens = Camera(K, 640, 480, [-0.1, 0.01, 0.0, 0.0, 0.0])
    pixels = pose_processors.ProjectPoints(lens)(model, T)
    np.testing.assert_allclose(pixels, camera_backend.transform_and_project(model, T, K, lens.distortion))
    pose = pose_processors.SolvePnP(lens, class_name="box")(model, pixels)
    np.testing.assert_allclose(pose.to_matrix(), T, atol=1e-8)
    assert pose.class_name == "box"
    np.testing.assert_allclose(pose_processors.ProjectPoints(K)(model, pose),
                               camera_backend.transform_and_project(model, T, K), atol=1e-6)
    camera_points = pose_processors.TransformPoints()(model, pose)
    np.testing.assert_allclose(pose_processors.ProjectPoints(K)(camera_points),
                               camera_backend.project_points(camera_points, K))
    from_keypoints = pose_processors.PoseFromKeypoints(model, lens)(pixels)
    np.testing.assert_allclose(from_keypoints.to_matrix(), T, atol=1e-8)
    to_pose = pose_processors.ToPose6D(class_name="box", score=0.5)
    reference = Pose6D(rotation.as_quat(), T[:3, 3], "box", 0.5)
    for encoding in (T, np.concatenate([rotation.as_quat(), T[:3, 3]]), (rotation.as_matrix(), T[:3, 3]),
                     (rotation.as_quat(), T[:3, 3]), (rotation.as_rotvec(), T[:3, 3]), reference):
        converted = to_pose(encoding)
        np.testing.assert_allclose(converted.to_matrix(), T, atol=1e-12)
        assert (converted.class_name, converted.score) == ("box", 0.5)
    np.testing.assert_array_equal(pose_processors.PoseToMatrix()(reference), reference.to_matrix())
    with pytest.raises(ValueError, match=r"pose\[0\]: expected a \(3, 3\) matrix"):
        to_pose((np.zeros(5), T[:3, 3]))
    with pytest.raises(ValueError, match=r"pose: expected Pose6D, \(4, 4\), \(7,\) or \(rotation, translation\)"):
        to_pose(np.zeros(6))
    with pytest.raises(ValueError, match="pose: expected a Pose6D, got ndarray"):
        pose_processors.PoseToMatrix()(T)
