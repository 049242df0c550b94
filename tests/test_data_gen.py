"""`paz6d generate` end to end on tiny images: BOP/COCO files against independent readers
(pycocotools, OpenCV, the BOP reader, official LM-O model info), determinism across workers,
resume after SIGKILL, crops, sampling properties."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from pycocotools.coco import COCO

from data_gen.assets import load_assets
from data_gen.config import GenerationConfig
from data_gen.generator import generate
from data_gen.producer import image_generator
from paz6d.backend.camera import transform_and_project
from paz6d.backend.mesh import load_mesh
from paz6d.datasets.bop import BOPDataset, load_models_info
from paz6d.synthesis.scene import sample_scene

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def lmo_meshes(shared_data) -> tuple[Path, Path]:
    models = shared_data / "bop_lmo" / "models"
    return models / "obj_000001.ply", models / "obj_000005.ply"


def tiny_config(meshes, out: Path, **overrides) -> GenerationConfig:
    settings = dict(meshes=tuple(meshes), out=out, num_images=4, width=96, height=72, seed=7, mesh_scale=0.001,
                    objects_per_image=(1, 2), crop_size=32, occluder_probability=0.5, images_per_scene=3)
    settings.update(overrides)
    return GenerationConfig(**settings)


def tree_digest(root: Path) -> dict[str, str]:
    return {str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(root.rglob("*")) if path.is_file()}


@pytest.fixture(scope="module")
def generated(lmo_meshes, tmp_path_factory):
    config = tiny_config(lmo_meshes, tmp_path_factory.mktemp("generated") / "set")
    summary = generate(config, workers=1, show_progress=False)
    return config, summary


def test_summary_counts_files(generated):
    config, summary = generated
    assert summary.images_rendered == 4 and summary.images_skipped == 0
    files = [path for path in config.out.rglob("*") if path.is_file()]
    assert summary.files_written == len(files) - 1  # everything but the run's fingerprint file
    assert not [path for path in files if ".paz6d-tmp-" in path.name]


def test_poses_round_trip_through_the_bop_reader(generated):
    config, _ = generated
    assets = load_assets(config)
    samples = list(BOPDataset(config.out, split="train"))
    assert [(s.scene_id, s.im_id) for s in samples] == [(0, 0), (0, 1), (0, 2), (1, 0)]
    for index, sample in enumerate(samples):
        scene = sample_scene(image_generator(config.seed, index), assets, config)
        assert [o.obj_id for o in sample.objects] == [assets.object_ids[i] for i in scene.object_indices]
        for obj, T in zip(sample.objects, scene.T_model2cam):
            np.testing.assert_allclose(obj.T_model2cam, T, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(sample.K, np.asarray(config.K))
        assert sample.image.shape == (72, 96, 3) and sample.depth.dtype == np.float32


def test_masks_depth_and_gt_info_agree(generated, lmo_meshes):
    config, _ = generated
    meshes = {1: load_mesh(lmo_meshes[0], 0.001), 5: load_mesh(lmo_meshes[1], 0.001)}
    for sample in BOPDataset(config.out, split="train"):
        for obj in sample.objects:
            info = obj.info
            assert obj.mask.sum() == info["px_count_all"] and obj.mask_visib.sum() == info["px_count_visib"]
            assert not (obj.mask_visib & ~obj.mask).any()
            assert info["visib_fract"] == pytest.approx(info["px_count_visib"] / info["px_count_all"])
            rows, columns = np.nonzero(obj.mask)
            assert info["bbox_obj"] == [columns.min(), rows.min(), np.ptp(columns) + 1, np.ptp(rows) + 1]
            # Depth: the visible surface of this object is where the PNG depth (mm / scale) says.
            posed = meshes[obj.obj_id].copy().apply_transform(obj.T_model2cam)
            z_low, z_high = posed.vertices[:, 2].min(), posed.vertices[:, 2].max()
            visible_depth = sample.depth[obj.mask_visib]
            assert np.all(visible_depth >= z_low - 1e-3) and np.all(visible_depth <= z_high + 1e-3)
            # Projected vertices fall in the full mask, or one pixel off it at the outline of
            # these tiny objects.
            pixels = np.round(transform_and_project(meshes[obj.obj_id].vertices, obj.T_model2cam, sample.K))
            grown = cv2.dilate(obj.mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            assert grown[pixels[:, 1].astype(int), pixels[:, 0].astype(int)].all()


def test_depth_png_uses_depth_scale(generated):
    config, _ = generated
    depth_png = cv2.imread(str(config.out / "train" / "000000" / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED)
    sample = next(iter(BOPDataset(config.out, split="train")))
    assert depth_png.dtype == np.uint16
    np.testing.assert_allclose(sample.depth, depth_png * config.depth_scale / 1000.0, rtol=1e-6)
    camera = json.loads((config.out / "camera.json").read_text())
    assert camera["depth_scale"] == config.depth_scale and camera["width"] == 96


def test_coco_file_loads_in_pycocotools_and_matches_gt_info(generated):
    config, _ = generated
    folder = config.out / "train" / "000000"
    coco = COCO(str(folder / "scene_gt_coco.json"))
    gt_info = json.loads((folder / "scene_gt_info.json").read_text())
    scene_gt = json.loads((folder / "scene_gt.json").read_text())
    expected = [(int(im), inst) for im, infos in gt_info.items() for inst, info in enumerate(infos)
                if info["px_count_visib"] > 0]
    assert len(coco.getAnnIds()) == len(expected) > 0
    for annotation, (im_id, instance) in zip(coco.loadAnns(coco.getAnnIds()), expected):
        info = gt_info[str(im_id)][instance]
        assert annotation["image_id"] == im_id
        assert annotation["category_id"] == scene_gt[str(im_id)][instance]["obj_id"]
        assert annotation["bbox"] == info["bbox_visib"] and annotation["area"] == info["px_count_visib"]
        mask_file = folder / "mask_visib" / f"{im_id:06d}_{instance:06d}.png"
        np.testing.assert_array_equal(coco.annToMask(annotation).astype(bool), cv2.imread(str(mask_file), 0) > 127)
    assert sorted(coco.getCatIds()) == [1, 5]


def test_models_are_written_in_millimetres_with_official_diameters(generated, lmo_meshes, shared_data):
    config, _ = generated
    info = load_models_info(config.out / "models" / "models_info.json")
    official = load_models_info(shared_data / "bop_lmo" / "models" / "models_info.json")
    for obj_id, source in zip((1, 5), lmo_meshes):
        written = trimesh.load(config.out / "models" / f"obj_{obj_id:06d}.ply", process=False)
        original = trimesh.load(source, process=False)
        np.testing.assert_allclose(written.vertices, original.vertices, atol=1e-4)  # float32 PLY, mm
        np.testing.assert_array_equal(written.visual.vertex_colors, original.visual.vertex_colors)
        assert info[obj_id].diameter == pytest.approx(official[obj_id].diameter, abs=2e-4)  # metres
        np.testing.assert_allclose(info[obj_id].size, official[obj_id].size, atol=1e-6)


def test_crops_have_consistent_intrinsics_and_masks(generated, lmo_meshes):
    config, _ = generated
    folder = config.out / "train" / "000000"
    crops = json.loads((folder / "crops.json").read_text())
    meshes = {1: load_mesh(lmo_meshes[0], 0.001), 5: load_mesh(lmo_meshes[1], 0.001)}
    checked = 0
    for im_id, entries in crops.items():
        for entry in entries:
            name = f"{int(im_id):06d}_{entry['inst_id']:06d}.png"
            crop_mask = cv2.imread(str(folder / "crop_mask" / name), 0) > 127
            assert cv2.imread(str(folder / "crop_rgb" / name)).shape == (32, 32, 3)
            T = np.eye(4)
            T[:3, :3] = np.reshape(entry["cam_R_m2c"], (3, 3))
            T[:3, 3] = np.asarray(entry["cam_t_m2c"]) / 1000.0
            pixels = transform_and_project(meshes[entry["obj_id"]].vertices, T, np.reshape(entry["cam_K"], (3, 3)))
            # The window is 1.2x the mask's box; thin parts missing every pixel centre may stick
            # out of it by up to one full-image pixel, i.e. 32 / side crop pixels.
            slack = 1.5 * 32 / entry["window"][2]
            assert pixels.min() > -0.5 - slack and pixels.max() < 31.5 + slack
            within = np.all((pixels > -0.5) & (pixels < 31.5), axis=1)
            columns, rows = np.round(pixels[within]).astype(int).T
            assert crop_mask[rows, columns].mean() > 0.8
            checked += 1
    assert checked > 0


def test_same_seed_same_bytes_for_any_worker_count(generated, tmp_path):
    config, _ = generated
    parallel = dataclasses.replace(config, out=tmp_path / "parallel")
    generate(parallel, workers=2, show_progress=False)
    reference = tree_digest(config.out)
    assert tree_digest(parallel.out) == reference
    other_seed = dataclasses.replace(config, out=tmp_path / "other", seed=8, num_images=1)
    generate(other_seed, workers=1, show_progress=False)
    assert tree_digest(other_seed.out)["train/000000/rgb/000000.png"] != reference["train/000000/rgb/000000.png"]


def test_extending_a_finished_set_renders_only_new_images(generated, tmp_path):
    config, _ = generated
    smaller = dataclasses.replace(config, out=tmp_path / "grow", num_images=2)
    generate(smaller, show_progress=False)
    summary = generate(dataclasses.replace(smaller, num_images=4), show_progress=False)
    assert (summary.images_rendered, summary.images_skipped) == (2, 2)
    assert tree_digest(smaller.out) == tree_digest(config.out)


def resume_config(mesh: Path, out: Path) -> GenerationConfig:
    return GenerationConfig(meshes=(mesh,), out=out, num_images=30, width=128, height=96, seed=3, mesh_scale=0.001,
                            objects_per_image=(1, 1), images_per_scene=8)


GENERATE_SCRIPT = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[3])
from test_data_gen import resume_config
from data_gen.generator import generate
generate(resume_config(Path(sys.argv[1]), Path(sys.argv[2])), workers=1, show_progress=False)
"""


def test_resume_after_sigkill_completes_without_redoing_images(lmo_meshes, tmp_path):
    out = tmp_path / "killed"
    environment = dict(os.environ, PYTHONPATH=str(REPO))
    process = subprocess.Popen([sys.executable, "-c", GENERATE_SCRIPT, str(lmo_meshes[0]), str(out),
                                str(Path(__file__).parent)], env=environment, cwd=REPO)
    shards = out / ".paz6d-generate" / "shards"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(shards.rglob("*.json"))) < 2:
        time.sleep(0.01)
    process.send_signal(signal.SIGKILL)
    process.wait()
    finished = {path: path.stat().st_mtime_ns for path in shards.rglob("*.json")}
    assert 2 <= len(finished) < 30, "the run should have been killed part-way"
    for path in out.rglob("*.json"):  # whatever exists is complete, valid JSON
        json.loads(path.read_text())
    config = resume_config(lmo_meshes[0], out)
    summary = generate(config, show_progress=False)
    assert summary.images_skipped == len(finished) and summary.images_rendered == 30 - len(finished)
    assert all(path.stat().st_mtime_ns == mtime for path, mtime in finished.items())
    assert not list(out.rglob(".paz6d-tmp-*"))
    reference = dataclasses.replace(config, out=tmp_path / "uninterrupted")
    generate(reference, show_progress=False)
    assert tree_digest(out) == tree_digest(reference.out)
    assert len(BOPDataset(out, split="train")) == 30


def test_sampled_objects_stay_in_frame_and_apart(lmo_meshes, tmp_path):
    config = tiny_config(lmo_meshes, tmp_path / "unused", objects_per_image=(2, 3), width=120, height=90)
    assets = load_assets(config)
    K = np.asarray(config.K)
    for index in range(40):
        scene = sample_scene(image_generator(3, index), assets, config)
        assert 1 <= len(scene.object_indices) <= 3
        centres = []
        for mesh_index, T in zip(scene.object_indices, scene.T_model2cam):
            pixels = transform_and_project(assets.meshes[mesh_index].vertices, T, K)
            assert pixels.min(axis=0).min() >= -0.5 and pixels[:, 0].max() <= 119.5 and pixels[:, 1].max() <= 89.5
            centre = T[:3, :3] @ assets.centres[mesh_index] + T[:3, 3]
            assert assets.distance[0] - 1e-9 <= centre[2] <= assets.distance[1] + 1e-9
            centres.append((centre, assets.radii[mesh_index]))
        for i in range(len(centres)):
            for j in range(i + 1, len(centres)):
                assert np.linalg.norm(centres[i][0] - centres[j][0]) >= centres[i][1] + centres[j][1] - 1e-9


def test_occluders_and_distractors_hide_objects(lmo_meshes, tmp_path):
    config = tiny_config(lmo_meshes, tmp_path / "occluded", num_images=6, occluder_probability=1.0, distractors=3,
                         objects_per_image=(1, 1), crop_size=0)
    generate(config, show_progress=False)
    fractions = [obj.info["visib_fract"] for sample in BOPDataset(config.out, split="train")
                 for obj in sample.objects]
    assert min(fractions) < 0.95


def test_backgrounds_come_from_the_folder(lmo_meshes, tmp_path):
    backgrounds = tmp_path / "backgrounds"
    backgrounds.mkdir()
    cv2.imwrite(str(backgrounds / "green.png"), np.full((50, 80, 3), (0, 200, 0), dtype=np.uint8))
    config = tiny_config(lmo_meshes, tmp_path / "bg", num_images=1, backgrounds=backgrounds, noise_std=0.0,
                         blur_probability=0.0, distractors=0, occluder_probability=0.0, crop_size=0)
    generate(config, show_progress=False)
    sample = next(iter(BOPDataset(config.out, split="train")))
    # Away from the anti-aliased outline, every pixel without depth shows the background file.
    background = cv2.erode((sample.depth == 0).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert background.sum() > 1000
    np.testing.assert_array_equal(sample.image[background], np.broadcast_to([0, 200, 0], (background.sum(), 3)))


def test_jpg_rgb_and_symmetries_are_written(lmo_meshes, tmp_path):
    symmetries = tmp_path / "symmetries.json"
    symmetries.write_text(json.dumps({"5": {"symmetries_continuous": [{"axis": [0, 0, 1], "offset": [0, 0, 10]}]}}))
    config = tiny_config(lmo_meshes, tmp_path / "jpg", num_images=1, rgb_format="jpg", crop_size=0,
                         symmetries=symmetries)
    generate(config, show_progress=False)
    info = load_models_info(config.out / "models" / "models_info.json")
    assert info[1].symmetries_continuous == [] and len(info[5].symmetries_continuous) == 1
    axis, offset = info[5].symmetries_continuous[0]
    np.testing.assert_allclose(axis, [0, 0, 1])
    np.testing.assert_allclose(offset, [0, 0, 0.01])  # mm in the file, metres from the reader
    folder = config.out / "train" / "000000"
    assert (folder / "rgb" / "000000.jpg").is_file() and not (folder / "rgb" / "000000.png").exists()
    sample = next(iter(BOPDataset(config.out, split="train")))
    assert sample.image.shape == (72, 96, 3)
    coco = json.loads((folder / "scene_gt_coco.json").read_text())
    assert coco["images"][0]["file_name"] == "rgb/000000.jpg"
