"""Speed of `paz6d generate` against a bare pyrender loop rendering the same meshes and poses.

For each image size it measures, in one process and run:

* bare loop: one ``pyrender.OffscreenRenderer``, the same meshes and poses, colour + depth only,
  nothing written (the floor any generator built on pyrender pays);
* generator, 1 worker, steady state: the ``generate`` code path (sampling, randomization,
  rendering, masks, BOP + COCO annotation, PNG writing) after start-up;
* generator end to end with 1 and 2 worker processes: with start-up ("e2e") and once all
  workers run ("run", from the shard files' finishing times), for the 2-worker speed-up;
* the same running rate of 1 worker confined to one CPU (``sched_setaffinity``): 2 workers on 2
  cores against 1 worker on 1 core is the scaling per core, which the plain 2w/1w ratio hides on a
  2-core machine because one worker already overlaps encoding and writing on the second core.

Usage: ``.venv/bin/python benchmarks/generate.py [--images-small 200] [--images-large 120]``.
Needs the LM-O meshes in ``../shared/data`` (or pass ``--mesh``).
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from data_gen.config import GenerationConfig  # noqa: E402
from data_gen.generator import generate, render_indices  # noqa: E402
from data_gen.producer import ImageProducer, image_generator  # noqa: E402
from paz6d.datasets.bop.units import MM_PER_M  # noqa: E402
from paz6d.synthesis.scene import sample_scene  # noqa: E402
from renderers import select_platform  # noqa: E402
from renderers.conventions import FLIP_YZ  # noqa: E402

DEFAULT_MESHES = [REPO.parent / "shared" / "data" / "bop_lmo" / "models" / f"obj_{i:06d}.ply" for i in (1, 5)]


def bare_loop(config: GenerationConfig, producer: ImageProducer, count: int) -> tuple[float, object]:
    """Views/s of a plain pyrender loop: same meshes, poses and intrinsics; colour + depth.

    Also returns the pyrender renderer: pyrender's ``delete`` terminates the process-wide EGL
    display, so the caller deletes it only after every other renderer is closed.
    """
    import pyrender

    K = np.asarray(config.K)
    flip = FLIP_YZ  # the OpenCV -> OpenGL camera axes
    scene = pyrender.Scene(ambient_light=[0.3, 0.3, 0.3])
    scene.add(pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], znear=0.01, zfar=10.0))
    scene.add(pyrender.DirectionalLight(intensity=3.0))
    nodes = [scene.add(pyrender.Mesh.from_trimesh(mesh), pose=np.eye(4)) for mesh in producer.assets.meshes]
    renderer = pyrender.OffscreenRenderer(config.width, config.height)
    scenes = [sample_scene(image_generator(config.seed, index), producer.assets, config) for index in range(count)]
    renderer.render(scene)  # warm-up: uploads meshes, compiles shaders
    started = time.perf_counter()
    for sampled in scenes:
        for node in nodes:
            node.mesh.is_visible = False
        for mesh_index, pose in zip(sampled.object_indices, sampled.T_model2cam):
            nodes[mesh_index].mesh.is_visible = True
            scene.set_pose(nodes[mesh_index], flip @ pose)
        renderer.render(scene)
    return count / (time.perf_counter() - started), renderer


def generator_steady(config: GenerationConfig, producer: ImageProducer, count: int) -> float:
    """Views/s of the generator's own loop (render + annotate + write) after start-up."""
    config.out.mkdir(parents=True, exist_ok=True)
    render_indices(producer, [count], config.out, lambda _: None)  # warm-up image
    started = time.perf_counter()
    render_indices(producer, range(count), config.out, lambda _: None)
    return count / (time.perf_counter() - started)


def end_to_end(config: GenerationConfig, workers: int) -> tuple[float, float]:
    """``(views/s including start-up, views/s once every worker runs)``; the second comes from
    the finishing times of the images' shard files, skipping each worker's first two images."""
    summary = generate(config, workers=workers, show_progress=False)
    shards = config.out / ".paz6d-generate" / "shards"
    finished = sorted(path.stat().st_mtime for path in shards.rglob("*.json"))
    skip = 2 * workers
    span = finished[-1] - finished[skip - 1] if len(finished) > skip + 1 else 0.0
    running = (len(finished) - skip) / span if span > 0 else float("nan")  # too few images to tell
    return summary.images_rendered / summary.seconds, running


def _pinned_end_to_end(config: GenerationConfig, workers: int, cores: int, results) -> None:
    os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[:cores]))  # inherited by spawned workers
    results.put(end_to_end(config, workers)[1])


def pinned_running_rate(config: GenerationConfig, workers: int, cores: int) -> float:
    """Running views/s (as :func:`end_to_end`) of ``workers`` workers confined to ``cores`` CPUs."""
    context = multiprocessing.get_context("spawn")
    results = context.Queue()
    process = context.Process(target=_pinned_end_to_end, args=(config, workers, cores, results))
    process.start()
    rate = results.get()
    process.join()
    return rate


def measure(meshes: list[Path], width: int, height: int, count: int, antialias: str, rgb_format: str,
            workdir: Path) -> dict:
    config = GenerationConfig(meshes=tuple(meshes), out=workdir / "steady", num_images=count, width=width,
                              height=height, mesh_scale=1.0 / MM_PER_M, objects_per_image=(1, 1), distractors=0,
                              occluder_probability=0.0, antialias=antialias, rgb_format=rgb_format)
    producer = ImageProducer(config)
    steady = generator_steady(config, producer, count)
    bare, bare_renderer = bare_loop(config, producer, count)
    producer.close()
    bare_renderer.delete()
    one, one_running = end_to_end(dataclasses.replace(config, out=workdir / "one"), 1)
    two, two_running = end_to_end(dataclasses.replace(config, out=workdir / "two"), 2)
    one_core = pinned_running_rate(dataclasses.replace(config, out=workdir / "one_core"), 1, 1)
    return {"bare": bare, "steady": steady, "one": one, "two": two, "one_running": one_running,
            "two_running": two_running, "one_core": one_core}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", action="append", type=Path, help="BOP mesh in mm (default: LM-O obj 1 and 5)")
    parser.add_argument("--images-small", type=int, default=200, help="images at 128x128")
    parser.add_argument("--images-large", type=int, default=120, help="images at 640x480")
    parser.add_argument("--platform", choices=("egl", "osmesa"))
    parser.add_argument("--rgb-format", choices=("png", "jpg"), default=GenerationConfig.rgb_format)
    parser.add_argument("--sizes", nargs="+", default=["640x480", "128x128"], help="image sizes WxH")
    args = parser.parse_args()
    meshes = args.mesh or DEFAULT_MESHES
    missing = [path for path in meshes if not path.is_file()]
    if missing:
        print(f"benchmark: mesh not found: {missing[0]} (pass --mesh)", file=sys.stderr)
        return 2
    platform = select_platform(args.platform)
    print(f"platform {platform}; one annotated object per image, no distractors; RGB as {args.rgb_format}; views/s")
    print(f"{'size':>8} {'antialias':>9} {'bare loop':>10} {'gen 1w':>8} {'ratio':>6} "
          f"{'e2e 1w':>7} {'e2e 2w':>7} {'2w/1w':>6} {'run 1w':>7} {'run 2w':>7} {'2w/1w':>6} "
          f"{'1w@1core':>8} {'2w/(1w@1core)':>13}")
    for size in args.sizes:
        width, height = (int(value) for value in size.split("x"))
        count = args.images_large if width * height > 128 * 128 else args.images_small
        for antialias in ("edges", "msaa", "none"):  # the generator's default first
            workdir = Path(tempfile.mkdtemp(prefix="paz6d-bench-"))
            try:
                result = measure(meshes, width, height, count, antialias, args.rgb_format, workdir)
            finally:
                shutil.rmtree(workdir, ignore_errors=True)
            print(f"{width}x{height:<4} {antialias:>9} {result['bare']:10.1f} {result['steady']:8.1f} "
                  f"{result['steady'] / result['bare']:6.2f} {result['one']:7.1f} {result['two']:7.1f} "
                  f"{result['two'] / result['one']:6.2f} {result['one_running']:7.1f} {result['two_running']:7.1f} "
                  f"{result['two_running'] / result['one_running']:6.2f} {result['one_core']:8.1f} "
                  f"{result['two_running'] / result['one_core']:13.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
