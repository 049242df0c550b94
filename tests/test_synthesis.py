"""paz6d.synthesis: the render worker pool, pose sampling, lighting, backgrounds, occluders and the
random augmentation processors (determinism, ranges, order of results)."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from paz6d.abstract import SequentialProcessor
from paz6d.backend.camera import Camera, project_points
from paz6d.synthesis import augment, backgrounds, lighting, occluders, sampling, workers


# ------------------------------------------------------------------------------------ workers
def _offset_state(offset: int) -> dict:
    """Worker state of the pool tests (module level: spawn workers import it by name)."""
    return {"offset": offset, "pid": os.getpid()}


def _add_offset(state: dict, task: list[int]) -> tuple[list[int], int]:
    return [value + state["offset"] for value in task], state["pid"]


class _ClosableState:
    closed = False

    def close(self) -> None:
        _ClosableState.closed = True


def test_pool_returns_results_in_task_order_for_any_number_of_workers():
    tasks = workers.chunks(list(range(11)), 3)
    assert tasks == [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10]]

    class Bar:
        count = 0

        def update(self, amount):
            self.count += amount

    results = {}
    for processes in (0, 1, 2):
        bar = Bar()
        output = workers.run_in_workers(_offset_state, (100,), _add_offset, tasks, processes, progress=bar)
        results[processes] = [values for values, _ in output]
        assert bar.count == 11
        pids = {pid for _, pid in output}
        assert (pids == {os.getpid()}) if processes == 0 else (os.getpid() not in pids and len(pids) <= processes)
    assert results[0] == results[1] == results[2] == [[100 + value for value in task] for task in tasks]
    assert workers.run_in_workers(_offset_state, (0,), _add_offset, [], 2) == []


def test_pool_closes_an_in_process_state_and_checks_its_arguments():
    _ClosableState.closed = False
    doubled = workers.run_in_workers(_ClosableState, (), lambda state, task: task * 2, [1, 2], 0, task_size=lambda _: 1)
    assert doubled == [2, 4]
    assert _ClosableState.closed
    with pytest.raises(ValueError, match="processes: expected 0 .* got -1"):
        workers.run_in_workers(_ClosableState, (), lambda state, task: task, [1], -1)
    with pytest.raises(ValueError, match="size: expected a positive chunk size, got 0"):
        workers.chunks([1, 2], 0)


@pytest.mark.parametrize("preset", [None, "3"])
def test_workers_get_their_share_of_llvmpipe_raster_threads(monkeypatch, preset):
    """Each spawned worker gets its share of raster threads unless the user set LP_NUM_THREADS."""
    if preset is None:
        monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("LP_NUM_THREADS", preset)
    monkeypatch.setattr(workers, "_STATE", {})
    workers._start_worker(lambda: os.environ["LP_NUM_THREADS"], (), 1)
    assert workers._STATE["state"] == (preset or "1")


def test_raster_threads_share_the_cores_and_skip_a_lone_helper_thread():
    assert [workers.raster_threads(2, count) for count in (1, 2, 3)] == [2, 0, 0]
    assert [workers.raster_threads(16, count) for count in (1, 2, 4, 8, 16)] == [16, 8, 4, 2, 0]
    assert workers.raster_threads(0, 1) == 0


# ------------------------------------------------------------------------------------ sampling
def test_rotation_sampling_modes():
    generator = np.random.default_rng(0)
    rotations = np.array([sampling.random_rotation(generator) for _ in range(4000)])
    # Haar-uniform rotations have E[R] = 0; 4000 samples put each entry's mean within ~0.03.
    assert np.abs(rotations.mean(axis=0)).max() < 0.04
    for _ in range(300):
        R = sampling.random_rotation(generator, "view-sphere", (10.0, 60.0), 20.0)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        eye = -R.T @ np.array([0.0, 0.0, 1.0])  # camera direction seen from the model
        elevation = np.degrees(np.arcsin(eye[2]))
        assert 10.0 - 1e-6 <= elevation <= 60.0 + 1e-6
        up_in_image = R @ np.array([0.0, 0.0, 1.0])  # model +z should point image-up, up to in-plane angle
        angle = np.degrees(np.arctan2(up_in_image[0], -up_in_image[1]))
        assert abs(angle) <= 20.0 + 1e-6
    with pytest.raises(ValueError, match="mode: expected one of"):
        sampling.random_rotation(generator, "upright")


def test_placed_objects_are_inside_the_image_and_apart():
    K = np.array([[100.0, 0.0, 59.5], [0.0, 100.0, 44.5], [0.0, 0.0, 1.0]])
    cube = np.array([[x, y, z] for x in (-0.02, 0.03) for y in (-0.02, 0.02) for z in (-0.02, 0.02)])
    outline = sampling.hull_points(np.concatenate([cube, [[0.005, 0.0, 0.0]]]))  # the inner point is dropped
    assert len(outline) == 8
    centre, radius = cube.mean(axis=0), float(np.linalg.norm(cube - cube.mean(axis=0), axis=1).max())
    generator, placed = np.random.default_rng(1), []
    for _ in range(5):
        rotation = sampling.random_rotation(generator)
        translation = sampling.place_object(generator, rotation, centre, radius, outline, K, 120, 90, (0.3, 0.6),
                                            placed)
        if translation is None:
            continue
        assert sampling.inside_image(project_points(outline @ rotation.T + translation, K), 120, 90)
    assert len(placed) >= 2
    for i in range(len(placed)):
        for j in range(i + 1, len(placed)):
            assert np.linalg.norm(placed[i][0] - placed[j][0]) >= placed[i][1] + placed[j][1] - 1e-12


def test_random_pose_in_view_puts_the_box_centre_inside_the_border():
    camera = Camera(np.array([[150.0, 0.0, 79.5], [0.0, 150.0, 59.5], [0.0, 0.0, 1.0]]), 160, 120)
    vertices = np.random.default_rng(0).uniform(-0.05, 0.05, (50, 3)) + [0.01, 0.0, 0.0]
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    for seed in range(20):
        T = sampling.random_pose_in_view(np.random.default_rng(seed), vertices, camera, 0.2, (3.0, 5.0), 0.1)
        np.testing.assert_allclose(T, sampling.random_pose_in_view(np.random.default_rng(seed), vertices, camera,
                                                                   0.2, (3.0, 5.0), 0.1))
        centre_cam = T[:3, :3] @ centre + T[:3, 3]
        assert 0.3 - 1e-9 <= centre_cam[2] <= 0.5 + 1e-9
        u, v = project_points(centre_cam[None], camera.K)[0]
        assert 0.2 * 160 - 0.5 - 1e-6 <= u <= 0.8 * 160 - 0.5 + 1e-6
        assert 0.2 * 120 - 0.5 - 1e-6 <= v <= 0.8 * 120 - 0.5 + 1e-6


# ------------------------------------------------------------------------------------ lighting
def test_lighting_styles_are_seeded_and_in_range():
    for style in lighting.LIGHTING_STYLES:
        first = lighting.random_lighting(np.random.default_rng(4), style, (2, 4), distance=0.5)
        assert first == lighting.random_lighting(np.random.default_rng(4), style, (2, 4), distance=0.5)
        assert first != lighting.random_lighting(np.random.default_rng(5), style, (2, 4), distance=0.5)
    scene = [lighting.random_lighting(np.random.default_rng(seed), "scene", (2, 4)) for seed in range(30)]
    assert {len(light.lights) for light in scene} == {2, 3, 4}
    key_fill = lighting.random_lighting(np.random.default_rng(0), "key-fill")
    assert [light.kind for light in key_fill.lights] == ["directional", "point"]
    assert key_fill.lights[0].direction[2] > 0  # into the scene
    surround = [lighting.random_lighting(np.random.default_rng(seed), "surround") for seed in range(200)]
    assert {len(light.lights) for light in surround} == {1, 2}
    directions = np.array([light.direction for setup in surround for light in setup.lights])
    assert (directions[:, 2] < 0).mean() > 0.3 and (directions[:, 1] > 0).mean() > 0.3  # from behind, from above
    assert all(max(light.color) == 1.0 and min(light.color) >= 0.75 for setup in surround for light in setup.lights)
    tints = lighting.random_tints(np.random.default_rng(0), 50, 0.2)
    assert tints.shape == (50, 3) and tints.min() >= 0.8 and tints.max() <= 1.2
    with pytest.raises(ValueError, match="style: expected one of"):
        lighting.random_lighting(np.random.default_rng(0), "studio")


# ------------------------------------------------------------------------------------ backgrounds
@pytest.mark.parametrize("style", backgrounds.BACKGROUND_STYLES)
def test_procedural_backgrounds_are_seeded_and_varied(style):
    first = backgrounds.procedural_background(np.random.default_rng(1), 64, 48, style)
    assert first.shape == (48, 64, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, backgrounds.procedural_background(np.random.default_rng(1), 64, 48, style))
    assert not np.array_equal(first, backgrounds.procedural_background(np.random.default_rng(2), 64, 48, style))
    assert np.mean([backgrounds.procedural_background(np.random.default_rng(seed), 64, 48, style).std()
                    for seed in range(5)]) > 5


def test_unknown_background_style_is_a_clear_error():
    with pytest.raises(ValueError, match="style: expected one of"):
        backgrounds.procedural_background(np.random.default_rng(0), 8, 8, "plasma")


def test_background_files_are_cropped_to_size(tmp_path):
    cv2.imwrite(str(tmp_path / "green.png"), np.full((50, 80, 3), (0, 200, 0), dtype=np.uint8))
    crop = backgrounds.background_image(np.random.default_rng(0), [tmp_path / "green.png"], 40, 30)
    assert crop.shape == (30, 40, 3)
    np.testing.assert_array_equal(crop, np.broadcast_to([0, 200, 0], crop.shape))
    procedural = backgrounds.background_image(np.random.default_rng(0), [], 40, 30, "shapes")
    np.testing.assert_array_equal(procedural,
                                  backgrounds.procedural_background(np.random.default_rng(0), 40, 30, "shapes"))


def test_blend_background_over_procedural_clutter_or_image_crops():
    foreground = np.full((30, 40, 3), 7, np.uint8)
    alpha = np.zeros((30, 40), np.uint8)
    alpha[10:20, 10:20] = 255
    blended = augment.BlendBackground(style="noise", seed=3)(foreground, alpha)
    np.testing.assert_array_equal(blended[10:20, 10:20], 7)
    expected = backgrounds.procedural_background(np.random.default_rng(3), 40, 30, "noise")
    np.testing.assert_array_equal(blended[alpha == 0], expected[alpha == 0])
    ramp = np.repeat(np.arange(200, dtype=np.uint8)[None, :, None], 3, axis=2).repeat(100, axis=0)
    cropped = augment.BlendBackground([ramp], seed=4)(foreground, alpha)
    generator = np.random.default_rng(4)
    generator.integers(1)  # the choice among one image
    np.testing.assert_array_equal(cropped[alpha == 0], backgrounds.crop_background(generator, ramp, 40, 30)[alpha == 0])
    with pytest.raises(ValueError, match="style: expected one of"):
        augment.BlendBackground(style="plasma")


def test_background_bank_patches_come_from_the_bank():
    bank = backgrounds.BackgroundBank(16, 3, np.random.default_rng(0))
    assert len(bank.backgrounds) == 3 and bank.backgrounds[0].shape == (32, 32, 3)
    patch = bank.patch(np.random.default_rng(5))
    np.testing.assert_array_equal(patch, bank.patch(np.random.default_rng(5)))
    assert patch.shape == (16, 16, 3)
    # Every patch is a window of a bank image, possibly mirrored and transposed.
    candidates = [image for source in bank.backgrounds for image in (source, source[:, ::-1], source.transpose(1, 0, 2),
                                                                       source[:, ::-1].transpose(1, 0, 2))]
    assert any(cv2.matchTemplate(np.ascontiguousarray(image), np.ascontiguousarray(patch), cv2.TM_SQDIFF).min() == 0
               for image in candidates)
    assert not backgrounds.BackgroundBank(8, 0, np.random.default_rng(0)).patch(np.random.default_rng(0)).any()


# ------------------------------------------------------------------------------------ occluders
def test_distractor_library_and_colours():
    library = occluders.distractor_library(0.1)
    assert len(library) == 12
    assert all((mesh.visual.vertex_colors == 255).all() for mesh in library)
    assert max(np.linalg.norm(mesh.vertices, axis=1).max() for mesh in library) < 0.1
    colors = occluders.random_colors(np.random.default_rng(0), 20)
    assert colors.shape == (20, 3) and colors.min() >= 0.05 and colors.max() <= 1.0
    # a share of 0 draws nothing more: the colours (and data sets made before the option) are unchanged
    np.testing.assert_array_equal(occluders.random_colors(np.random.default_rng(0), 20, 0.0), colors)
    mixed = occluders.random_colors(np.random.default_rng(1), 2000, 0.4)
    grey = (mixed.max(axis=1) / mixed.min(axis=1) <= 1.04 / 0.96 + 1e-9) & (mixed.min(axis=1) >= 0.48)
    assert 0.37 < grey.mean() < 0.45  # the neutral share, plus the few random colours that happen to be grey
    assert mixed.max() <= 1.0 and np.all(occluders.random_colors(np.random.default_rng(2), 50, 1.0).min(axis=1) >= 0.48)


def test_palette_colours_paint_a_share_of_the_distractors():
    palettes = [np.array([[0.8, 0.2, 0.1]]), np.zeros((0, 3)), np.array([[0.9, 0.9, 0.85], [0.1, 0.4, 0.1]])]
    rows = np.concatenate([p for p in palettes if len(p)])
    exact = occluders.random_colors(np.random.default_rng(3), 200, palettes=palettes, palette_share=1.0)
    assert all(np.any(np.all(np.isclose(color, rows), axis=1)) for color in exact)  # jitter 0: palette rows
    jittered = occluders.random_colors(np.random.default_rng(3), 500, palettes=palettes, palette_share=1.0, jitter=0.2)
    ratios = np.min([np.max(np.abs(jittered / row[None] - 1), axis=1) for row in rows], axis=0)
    assert ratios.max() <= 0.2 + 1e-9 and jittered.max() <= 1.0
    # with a neutral share too, each distractor gets one kind: neutral first, then palette, then random
    mixed = occluders.random_colors(np.random.default_rng(4), 3000, 0.3, palettes, 0.5)
    from_palette = np.array([np.any(np.all(np.isclose(color, rows), axis=1)) for color in mixed])
    grey = (mixed.max(axis=1) / mixed.min(axis=1) <= 1.04 / 0.96 + 1e-9) & (mixed.min(axis=1) >= 0.48)
    assert 0.46 < from_palette.mean() < 0.54 and 0.28 < (grey & ~from_palette).mean() < 0.36
    # no palette colour (or share 0) draws nothing more than before the option existed
    plain = occluders.random_colors(np.random.default_rng(5), 20, 0.3)
    np.testing.assert_array_equal(occluders.random_colors(np.random.default_rng(5), 20, 0.3, [np.zeros((0, 3))], 0.5),
                                  plain)
    np.testing.assert_array_equal(occluders.random_colors(np.random.default_rng(5), 20, 0.3, palettes, 0.0), plain)


def test_mesh_palettes_are_the_vertex_colours(shared_data):
    import trimesh

    ape = trimesh.load(shared_data / "bop_lmo" / "models" / "obj_000001.ply")
    textured = trimesh.load(shared_data / "meshes" / "fuze.obj", force="mesh")
    palettes = occluders.mesh_palettes([ape, trimesh.creation.box(), textured])
    np.testing.assert_allclose(palettes[0], np.asarray(ape.visual.vertex_colors)[:, :3] / 255.0)
    assert palettes[1].shape == (0, 3)  # no colours: nothing to paint with
    assert palettes[2].shape == (len(textured.vertices), 3) and 0 <= palettes[2].min() and palettes[2].max() <= 1
    assert palettes[2].std(axis=0).max() > 0.05  # sampled from the texture, not one flat colour


def test_occluder_pose_lies_between_the_camera_and_the_object():
    target = np.array([0.02, -0.01, 0.5])
    for seed in range(20):
        pose = occluders.occluder_pose(np.random.default_rng(seed), target, 0.05, 0.02, 0.01)
        depth = pose[2, 3]
        assert 0.5 * 0.5 - 1e-12 <= depth <= 0.8 * 0.5 + 1e-12
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-12)
    assert occluders.occluder_pose(np.random.default_rng(0), np.array([0.0, 0.0, 0.05]), 0.01, 0.02, 0.01) is None


def test_polygon_occluders_follow_their_probability():
    crop = np.zeros((64, 64, 3), np.uint8)
    occluders.draw_polygon_occluders(crop, np.random.default_rng(0), 0.0, 2, (0.2, 0.5), 40.0)
    assert not crop.any()
    drawn = [crop.copy() for _ in range(2)]
    for image in drawn:
        occluders.draw_polygon_occluders(image, np.random.default_rng(3), 1.0, 2, (0.2, 0.5), 40.0)
    np.testing.assert_array_equal(drawn[0], drawn[1])
    assert 0 < drawn[0].any(axis=2).mean() < 0.6
    assert not drawn[0][24:40, 24:40].any() or drawn[0][24:40, 24:40].any(axis=2).mean() < 1.0  # outskirts first
    step = occluders.PolygonOccluders(1.0, 2, (0.2, 0.5), padding=64 / 40.0, seed=3)
    blank = np.zeros((64, 64, 3), np.uint8)
    np.testing.assert_array_equal(step(blank), drawn[0])
    assert not blank.any()  # the step draws on a copy
    with pytest.raises(ValueError, match="probability: expected a probability in"):
        occluders.PolygonOccluders(probability=1.5)


# ------------------------------------------------------------------------------------ augment
PICTURE = np.random.default_rng(9).integers(0, 256, (24, 32, 3), dtype=np.uint8)
RANDOM_PROCESSORS = [
    lambda: augment.RandomBrightness(20.0), lambda: augment.RandomContrast(0.6, 1.4),
    lambda: augment.RandomSaturation(0.6, 1.4), lambda: augment.RandomHue(30.0), lambda: augment.RandomImageNoise(8.0),
    lambda: augment.RandomGaussianBlur((3, 5), probability=0.7),
    lambda: augment.RandomGaussianBlur((0,), 0.7, (0.4, 1.2)),
    lambda: augment.RandomImageNoise(6.0, probability=0.8, quantized=True),
    lambda: augment.RandomContrastBrightnessNoise(),
    lambda: augment.RandomFlipLeftRight(),
    lambda: occluders.PolygonOccluders(probability=0.9, padding=1.2),
]


@pytest.mark.parametrize("make", RANDOM_PROCESSORS)
def test_every_random_processor_is_deterministic_under_reseed(make):
    processor = make()
    processor.reseed(11)
    first = [processor(PICTURE) for _ in range(6)]
    processor.reseed(11)
    np.testing.assert_equal([processor(PICTURE) for _ in range(6)], first)
    assert all(output.dtype == np.uint8 for output in first)
    assert not all(np.array_equal(output, first[0]) for output in first[1:])  # the generator advances


def test_shared_generator_draws_in_step_order():
    steps = SequentialProcessor([augment.RandomSaturation(0.7, 1.3), augment.RandomHue(8.0),
                                 augment.RandomGaussianBlur((3,), 0.5), augment.RandomImageNoise(6.0)])
    augment.share_generator(steps, np.random.default_rng(2))
    generator = np.random.default_rng(2)
    expected = augment.RandomSaturation(0.7, 1.3, seed=generator)(PICTURE)
    expected = augment.RandomHue(8.0, seed=generator)(expected)
    expected = augment.RandomGaussianBlur((3,), 0.5, seed=generator)(expected)
    expected = augment.RandomImageNoise(6.0, seed=generator)(expected)
    np.testing.assert_array_equal(steps(PICTURE), expected)


def test_gaussian_blur_with_a_sigma_range():
    blur = augment.RandomGaussianBlur((5,), probability=1.0, sigma=(0.4, 1.2), seed=0)
    sigma = np.random.default_rng(0)
    sigma.random()
    np.testing.assert_array_equal(blur(PICTURE), cv2.GaussianBlur(PICTURE, (5, 5), float(sigma.uniform(0.4, 1.2))))
    with pytest.raises(ValueError, match="kernel_sizes: expected odd positive sizes"):
        augment.RandomGaussianBlur((4,))
    with pytest.raises(ValueError, match="kernel_sizes"):
        augment.RandomGaussianBlur((0,))  # 0 (size from sigma) needs a sigma range


def test_sensor_noise_is_gaussian_seeded_rounded_and_clipped():
    from scipy import stats

    grey = np.full((200, 300, 3), 100, dtype=np.uint8)
    noisy = augment.sensor_noise(np.random.default_rng(3), grey, 4.0)
    assert noisy.dtype == np.uint8 and noisy.shape == grey.shape
    np.testing.assert_array_equal(noisy, augment.sensor_noise(np.random.default_rng(3), grey, 4.0))
    difference = noisy.astype(float) - 100
    assert abs(difference.mean()) < 0.05 and abs(difference.std() - np.hypot(4.0, 1 / np.sqrt(12))) < 0.1
    # Compare the quantized draws with the normal CDF at the rounding boundaries k + 1/2.
    levels = np.arange(-8, 8)
    empirical = np.array([(difference <= k).mean() for k in levels])
    np.testing.assert_allclose(empirical, stats.norm.cdf(levels + 0.5, scale=4.0), atol=0.01)
    extremes = augment.sensor_noise(np.random.default_rng(4), np.array([[0, 255]] * 1000, dtype=np.uint8), 20.0)
    assert extremes[:, 0].min() == 0 and extremes[:, 1].max() == 255 and extremes[:, 0].max() > 10
    assert augment.sensor_noise(np.random.default_rng(5), grey[..., 0], 2.0).shape == (200, 300)
    silent = augment.RandomImageNoise(0.0, probability=0.5, quantized=True, seed=0)
    assert silent(grey) is grey and silent.generator.random() == np.random.default_rng(0).random()  # no draw
    always = augment.RandomImageNoise(4.0, quantized=True, seed=1)
    generator = np.random.default_rng(1)
    np.testing.assert_array_equal(always(grey), augment.sensor_noise(generator, grey, generator.uniform(0.0, 4.0)))


def test_contrast_brightness_noise_without_noise_is_a_linear_map():
    jitter = augment.RandomContrastBrightnessNoise((1.5, 1.5), brightness=0.0, noise=0.0, seed=0)
    flat = np.full((4, 4, 3), 100, np.uint8)
    np.testing.assert_array_equal(jitter(flat), flat)
    ramp = np.repeat(np.arange(0, 160, 10, dtype=np.uint8)[None, :, None], 3, axis=2)
    mean = ramp.astype(np.float32).mean()
    np.testing.assert_array_equal(jitter(ramp), np.clip((ramp - mean) * 1.5 + mean, 0, 255).astype(np.uint8))
