"""Processor framework (Processor, SequentialProcessor, RandomProcessor, reseed) and the thin
processors of paz6d.processors, each checked against the backend function it wraps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paz6d.abstract import Box2D, KeyedStep, Keypoints2D, Pose6D, Processor, RandomProcessor, SequentialProcessor
from paz6d.abstract import random_processors, reseed
from paz6d.backend import boxes as boxes_backend
from paz6d.backend import camera as camera_backend
from paz6d.backend import image as image_backend
from paz6d.backend.camera import Camera
from paz6d.backend.pnp import PnPError
from paz6d.backend.square_crop import crop_square, projected_box, square_window, to_full_image
from paz6d.processors import boxes as box_processors
from paz6d.processors import crops as crop_processors
from paz6d.processors import image as image_processors
from paz6d.processors import keypoints as keypoint_processors
from paz6d.processors import pose as pose_processors
from paz6d.processors.predict import Predict, predict_in_batches
from paz6d.synthesis import augment

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


def test_sequential_processor_steps_by_name():
    pipeline = SequentialProcessor([AddOne(), Scale(10, "ten"), double])
    assert pipeline.names == ["AddOne", "ten", "double"] and pipeline["ten"].factor == 10
    assert pipeline.index("double") == 2
    pipeline.insert("ten", Scale(-1, "negate"))
    pipeline.insert("ten", Scale(3, "three"), after=True)
    pipeline.insert(-1, Scale(5, "five"), after=True)
    assert pipeline.names == ["AddOne", "negate", "ten", "three", "double", "five"]
    assert pipeline(1) == -(1 + 1) * 10 * 3 * 2 * 5
    old = pipeline.replace("three", Scale(0.5, "half"))
    assert old.name == "three" and pipeline.names[3] == "half"
    assert pipeline(1) == -(1 + 1) * 10 * 0.5 * 2 * 5
    assert pipeline.remove("five").name == "five" and pipeline.names[-1] == "double"
    assert pipeline.run_steps(1, start="ten") == 1 * 10 * 0.5 * 2
    assert pipeline.run_steps(1, stop="ten") == -(1 + 1) and pipeline.run_steps(1, "ten", "double") == 5
    assert "steps=['AddOne', 'negate', 'ten', 'half', 'double']" in repr(pipeline)
    for operation in (lambda: pipeline.replace("absent", double), lambda: pipeline.insert("absent", double),
                      lambda: pipeline["absent"]):
        with pytest.raises(ValueError, match=r"name: no step named 'absent'; steps are \['AddOne'"):
            operation()
    with pytest.raises(ValueError, match="step: expected a callable"):
        pipeline.replace("ten", 3)


def test_keyed_step_reads_and_writes_named_values():
    add = KeyedStep(lambda a, b: a + b, ("a", "b"), "total", name="add")
    values = {"a": 1, "b": 2}
    assert add(values) == {"a": 1, "b": 2, "total": 3} and values == {"a": 1, "b": 2}  # a copy
    split = KeyedStep(divmod, ("a", "b"), ("quotient", "remainder"), name="split")
    assert split({"a": 7, "b": 2}) == {"a": 7, "b": 2, "quotient": 3, "remainder": 1}
    assert KeyedStep(AddOne(), "a", "a").name == "AddOne"
    with pytest.raises(ValueError, match=r"step 'add': needs \['b'\], but the values are \['a'\]"):
        add({"a": 1})
    with pytest.raises(ValueError, match=r"step 'split': expected a tuple of 2 results"):
        KeyedStep(lambda a: a, "a", ("x", "y"), name="split")({"a": 1})
    with pytest.raises(ValueError, match="expected a dict of named values"):
        add(3)


def test_keyed_step_per_sample_passes_failures_on():
    def invert(x):
        if x == 0:
            raise ZeroDivisionError("x: zero")
        return 1 / x

    pipeline = SequentialProcessor([
        KeyedStep(invert, "x", "inverse", "invert", per_sample=True, failures=(ZeroDivisionError,)),
        KeyedStep(lambda inverse, y: inverse * y, ("inverse", "y"), "product", "multiply", per_sample=True)])
    result = pipeline({"x": [2, 0, 4], "y": [1, 1, 8]})
    assert result["product"][0] == 0.5 and result["product"][2] == 2.0
    assert isinstance(result["product"][1], ZeroDivisionError) and result["inverse"][1] is result["product"][1]
    with pytest.raises(ZeroDivisionError):
        KeyedStep(invert, "x", "inverse", per_sample=True)({"x": [0]})
    with pytest.raises(ValueError, match=r"inputs \['inverse', 'y'\] have different batch sizes \[1, 2\]"):
        pipeline[1]({"inverse": [1], "y": [1, 2]})


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
    holder = KeyedStep(pose_processors.SolvePnP(), ("a", "b", "c"), "pose")
    assert random_processors(holder) == []
    inner = Jitter(seed=0)
    assert random_processors(KeyedStep(inner, "x", "y")) == [inner]
    flip = augment.RandomFlipLeftRight(seed=0)

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
    (augment.RandomBrightness(20.0, seed=5), image_backend.random_brightness, (20.0,)),
    (augment.RandomContrast(0.6, 1.4, seed=5), image_backend.random_contrast, (0.6, 1.4)),
    (augment.RandomSaturation(0.6, 1.4, seed=5), image_backend.random_saturation, (0.6, 1.4)),
    (augment.RandomHue(30.0, seed=5), image_backend.random_hue, (30.0,)),
    (augment.RandomImageNoise(8.0, seed=5), image_backend.random_image_noise, (8.0,)),
])
def test_random_photometric_processors_use_their_generator(picture, processor, backend, arguments):
    expected = backend(picture, np.random.default_rng(5), *arguments)
    np.testing.assert_array_equal(processor(picture), expected)
    processor.reseed(5)
    np.testing.assert_array_equal(processor(picture), expected)
    later = [processor(picture) for _ in range(3)]  # the generator advances between calls
    assert not all(np.array_equal(output, expected) for output in later)


def test_random_gaussian_blur_probability(picture):
    never = augment.RandomGaussianBlur(probability=0.0, seed=0)
    assert never(picture) is picture
    always = augment.RandomGaussianBlur(kernel_sizes=(5,), probability=1.0, seed=0)
    np.testing.assert_array_equal(always(picture), cv2.GaussianBlur(picture, (5, 5), 0))


def test_random_flip_left_right_mirrors_with_its_probability(picture):
    np.testing.assert_array_equal(augment.RandomFlipLeftRight(probability=1.0, seed=0)(picture), picture[:, ::-1])
    np.testing.assert_array_equal(augment.RandomFlipLeftRight(probability=0.0, seed=0)(picture), picture)


def test_blend_background_composites_over_a_background_patch(picture):
    background = np.full((50, 60, 3), 200, np.uint8)
    alpha = np.zeros((24, 32), bool)
    alpha[5:10, 5:10] = True
    blended = augment.BlendBackground([background], seed=0)(picture, alpha)
    np.testing.assert_array_equal(blended[alpha], picture[alpha])
    assert np.all(blended[~alpha] == 200)
    with pytest.raises(ValueError, match="backgrounds: expected at least one"):
        augment.BlendBackground([])


def test_box_processors_wrap_the_backend():
    boxes = np.array([[10.0, 20.0, 40.0, 40.0], [0.0, 0.0, 5.0, 30.0]])
    converted = box_processors.ConvertBoxFormat("xywh", "xyxy")(boxes)
    np.testing.assert_array_equal(converted, boxes_backend.convert(boxes, "xywh", "xyxy"))
    messages = box_processors.ToBoxes2D(["duck", "cat"])(converted, [0.9, 0.7], [0, 1])
    assert messages == [Box2D(10, 20, 50, 60, 0.9, "duck"), Box2D(0, 0, 5, 30, 0.7, "cat")]
    assert box_processors.ToBoxes2D()(boxes[:1]) == [Box2D(10, 20, 40, 40)]
    assert box_processors.ToBoxes2D(class_name="face")(converted[:1]) == [Box2D(10, 20, 50, 60, 1.0, "face")]
    assert box_processors.ToBoxes2D()(np.zeros((0, 4))) == []
    with pytest.raises(ValueError, match="class_ids: given without class_names"):
        box_processors.ToBoxes2D()(boxes, None, [0, 1])


def test_keypoint_processors_make_messages():
    points = np.array([[0.0, 0.0], [31.0, 23.0], [10.5, 4.0]])
    message = keypoint_processors.ToKeypoints2D("face")(points, [1, 1, 0.5])
    assert message == Keypoints2D(points, [1, 1, 0.5], "face")


def test_crop_processors_cut_the_square_window_and_map_back(picture):
    crop, window = crop_processors.SquareCrop(1.25, 16)(picture, Box2D(4, 3, 20, 15))
    assert window == square_window((4, 3, 20, 15), 1.25)
    np.testing.assert_array_equal(crop, crop_square(picture, window, 16))
    assert crop_processors.SquareCrop(1.25, 16)(picture, (4, 3, 20, 15))[1] == window
    points = np.array([[0.0, 0.0], [15.0, 7.5]])
    np.testing.assert_array_equal(crop_processors.CropToImage(16)(points, window), to_full_image(points, window, 16))
    with pytest.raises(ValueError, match="margin"):
        crop_processors.SquareCrop(0.0, 16)
    with pytest.raises(ValueError, match="size"):
        crop_processors.SquareCrop(1.0, 0)


def test_predict_runs_in_batches_of_arrays_or_dicts():
    calls = []

    def network(batch):
        calls.append(len(batch))
        assert batch.dtype == np.float32
        return {"sum": batch.sum(axis=1), "first": batch[:, 0]}

    inputs = np.arange(14.0).reshape(7, 2)
    outputs = Predict(network, batch_size=3)(list(inputs))
    assert calls == [3, 3, 1]
    np.testing.assert_array_equal(outputs["sum"], inputs.sum(axis=1))
    np.testing.assert_array_equal(predict_in_batches(lambda batch: 2 * batch, inputs, 4), 2 * inputs)
    with pytest.raises(ValueError, match="batch_size"):
        predict_in_batches(network, inputs, 0)


def test_pose_processors_solve_pnp_and_fit_depth_to_a_box():
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation.as_matrix(), [0.02, -0.01, 0.7]
    model = np.random.default_rng(1).uniform(-0.05, 0.05, (12, 3))
    lens = Camera(K, 640, 480, [-0.1, 0.01, 0.0, 0.0, 0.0])
    pixels = camera_backend.transform_and_project(model, T, K, lens.distortion)
    pose = pose_processors.SolvePnP(class_name="box")(model, pixels, lens)
    assert isinstance(pose, Pose6D) and pose.class_name == "box" and pose.score == 1.0
    np.testing.assert_allclose(pose.to_matrix(), T, atol=1e-8)
    outliers = pixels.copy()
    outliers[:2] += 50.0
    robust = pose_processors.SolvePnP(method="epnp", ransac=True)(model, outliers, lens, 2.0)
    assert robust.score == pytest.approx(10 / 12)
    np.testing.assert_allclose(robust.to_matrix(), T, atol=1e-6)
    with pytest.raises(ValueError, match="a 3x3 K needs the image size"):
        pose_processors.SolvePnP()(model, pixels, K)
    with pytest.raises(PnPError, match="at least 4 correspondences"):
        pose_processors.SolvePnP()(model[:3], pixels[:3], lens)
    far = Pose6D.from_rotation_matrix(T[:3, :3], T[:3, 3] * 1.1)
    fitted = pose_processors.DepthFromBox(model)(far, projected_box(model, T, K), Camera(K, 640, 480))
    np.testing.assert_allclose(fitted.translation, T[:3, 3], rtol=2e-3)
    np.testing.assert_allclose(fitted.rotation_matrix, T[:3, :3], atol=1e-12)


def test_box_variants_are_the_box_then_every_shift_and_scale():
    from paz6d.processors.crops import BoxVariants

    variants = BoxVariants(shifts=(-0.1, 0.0, 0.1), scales=(0.5, 1.0))
    boxes = variants(Box2D(10, 20, 30, 60))  # 20 x 40 px, centre (20, 40)
    assert len(variants) == len(boxes) == 18  # the unchanged box moved first, not repeated
    np.testing.assert_allclose(boxes[0], [10, 20, 30, 60])
    expected = {(round(20 + dx * 20 - s * 10, 6), round(40 + dy * 40 - s * 20, 6), round(20 + dx * 20 + s * 10, 6),
                 round(40 + dy * 40 + s * 20, 6))
                for dx in (-0.1, 0.0, 0.1) for dy in (-0.1, 0.0, 0.1) for s in (0.5, 1.0)}
    assert {tuple(np.round(box, 6)) for box in boxes} == expected
    assert len({tuple(box) for box in boxes}) == len(boxes)
    only = BoxVariants(shifts=(0.05,), scales=(1.2,))  # no unchanged variant given: the box still comes first
    assert len(only) == 2
    np.testing.assert_allclose(only((0, 0, 10, 10)), [[0, 0, 10, 10], [-0.5, -0.5, 11.5, 11.5]])
    for kwargs, message in (({"shifts": ()}, "shifts"), ({"shifts": (np.nan,)}, "shifts"),
                            ({"scales": (0.0, 1.0)}, "scales"), ({"scales": ()}, "scales")):
        with pytest.raises(ValueError, match=message):
            BoxVariants(**kwargs)

