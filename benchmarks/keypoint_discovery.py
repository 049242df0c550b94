"""KeypointNet discovery runs: train one discovery config on an object, score PnP on held-out images,
check the PnP/lifting stage alone, report CPU time.

    .venv/bin/python benchmarks/keypoint_discovery.py OUT [--config discovery] [--steps N]
        [--object demo|cylinder|symmetric] [--override key=json ...] [--views-cache DIR]

``--object symmetric`` is the half-turn symmetric demo object
(:func:`paz6d.assets.demo_object.make_symmetric_demo_mesh`), trained with the orientation network and
scored with ADD-S.
``--views-cache`` keeps the rendered training/validation/lifting views between runs of the same
object, view count and seed (proxy runs then only train and score). Writes ``OUT/proxy.json``:
the demo's report (ADD(-S) recall, rotation errors, keypoint consistency) plus

- ``cpu_seconds``: CPU time of this process and its rendering workers (user + system);
- ``oracle``: ADD(-S) recall of PnP on the exact projections of the lifted 3D keypoints into the test
  images, plus 1 and 2 px Gaussian noise (is the constellation good enough for PnP?);
- ``keypoint_spread_m``: median pairwise distance of the usable lifted keypoints (metres).
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import time
from pathlib import Path

import numpy as np


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and its finished children."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def cylinder_object(directory: Path) -> Path:
    """A plain grey-green cylinder (rotationally symmetric about z), 0.08 m tall, 0.03 m radius, as PLY (metres)."""
    import trimesh

    mesh = trimesh.creation.cylinder(radius=0.03, height=0.08, sections=48)
    mesh.visual.vertex_colors = np.tile([90, 150, 110, 255], (len(mesh.vertices), 1)).astype(np.uint8)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "cylinder.ply"
    mesh.export(path)
    return path


def oracle_recall(run_dir: Path, test, points: np.ndarray, diameter: float, camera, symmetric: bool,
                  noise_px: float, seed: int = 0) -> float:
    """ADD(-S) recall at 0.1 d of RANSAC PnP on the true projections (+ noise) of the run's usable 3D keypoints."""
    from paz6d.backend.camera import transform_and_project
    from paz6d.backend.pnp import PnPError
    from paz6d.demo.report import score_poses
    from paz6d.keypointnet.run_dir import KeypointNetRunDir
    from paz6d.processors.pose import SolvePnP

    keypoints, usable = KeypointNetRunDir.read_keypoints(run_dir)
    keypoints = keypoints[usable]
    rng = np.random.default_rng(seed)
    solve = SolvePnP(method="epnp", ransac=True)
    poses = []
    for T in test.T_model2cam:
        pixels = transform_and_project(keypoints, T, camera.K) + rng.normal(0, noise_px, (len(keypoints), 2))
        try:
            poses.append(solve(keypoints, pixels, camera, 5.0).to_matrix())
        except (PnPError, ValueError):
            poses.append(None)
    return score_poses(poses, test.T_model2cam, points, diameter, symmetric).metrics["recall_0.1d"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--config", default="discovery")
    parser.add_argument("--mode", default="discovery")
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--object", choices=("demo", "cylinder", "symmetric"), default="demo")
    parser.add_argument("--override", action="append", default=[],
                        help="setting=JSON value replacing the config's (repeatable)")
    parser.add_argument("--views-cache", type=Path, default=None)
    args = parser.parse_args()

    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()
    from paz6d.assets.demo_object import write_demo_object, write_symmetric_demo_object
    from paz6d.backend.mesh import diameter, load_mesh
    from paz6d.demo.keypoint_demo import MANY_CROPS, TEST_SEED_OFFSET, run_keypoint_demo
    from paz6d.keypointnet.config import CONFIGS, KeypointConfig, KeypointTraining
    from paz6d.keypointnet.views import ViewSampling, render_test_images

    changes = {}
    for item in args.override:
        key, _, value = item.partition("=")
        changes[key] = json.loads(value)
    settings = KeypointConfig.from_dict({**CONFIGS[args.config].to_dict(), **changes})
    symmetric = args.object in ("cylinder", "symmetric")
    orientation = args.object == "symmetric"
    if args.object == "cylinder":
        mesh_path, scale = cylinder_object(args.out / "mesh"), 1.0
    elif orientation:
        mesh_path, scale = write_symmetric_demo_object(args.out / "mesh"), 1e-3
    else:
        mesh_path, scale = write_demo_object(args.out / "mesh"), 1e-3
    run_dir = args.out / f"keypointnet_{args.mode}"
    KeypointTraining(run_dir, mesh_path, mesh_scale=scale, config=args.config, mode=args.mode, seed=args.seed,
                     steps=args.steps, settings=settings, orientation_network=orientation)  # checks the settings
    cache_names = {"train": f"{args.object}_train_{settings.views}_{args.seed}.npz",
                   "val": f"{args.object}_val_{settings.validation_views}_{args.seed}.npz",
                   "lift": f"{args.object}_lift_{settings.lift_views}_{args.seed}.npz"}
    if args.views_cache is not None:
        run_dir.mkdir(parents=True, exist_ok=True)
        for kind, name in cache_names.items():
            if (args.views_cache / name).exists() and not (run_dir / f"views_{kind}.npz").exists():
                shutil.copy(args.views_cache / name, run_dir / f"views_{kind}.npz")
    started, cpu_started = time.perf_counter(), cpu_seconds()
    report = run_keypoint_demo(args.out, mesh_path, scale, modes=(args.mode,), config=args.config, seed=args.seed,
                               steps=args.steps, symmetric=symmetric, settings=settings, progress=False,
                               orientation_network=orientation)
    report["cpu_seconds"] = round(cpu_seconds() - cpu_started, 1)
    report["wall_seconds"] = round(time.perf_counter() - started, 1)
    if args.views_cache is not None:
        args.views_cache.mkdir(parents=True, exist_ok=True)
        for kind, name in cache_names.items():
            if not (args.views_cache / name).exists() and (run_dir / f"views_{kind}.npz").exists():
                shutil.copy(run_dir / f"views_{kind}.npz", args.views_cache / name)

    mesh = load_mesh(mesh_path, scale)
    points = np.asarray(mesh.vertices)
    object_diameter = diameter(points)
    sampling = ViewSampling()
    test = render_test_images(mesh_path, report["test_images"], args.seed + TEST_SEED_OFFSET, sampling, scale,
                              progress=False)
    from paz6d.keypointnet.run_dir import KeypointNetRunDir

    keypoints, usable = KeypointNetRunDir.read_keypoints(run_dir)
    usable_points = keypoints[usable]
    distances = np.linalg.norm(usable_points[:, None] - usable_points[None], axis=-1)
    report["keypoint_spread_m"] = float(np.median(distances[np.triu_indices(len(usable_points), 1)]))
    report["oracle"] = {f"noise_{noise}px": oracle_recall(run_dir, test, points, object_diameter, sampling.camera,
                                                          symmetric, noise)
                        for noise in (0.0, 1.0, 2.0)} if usable.sum() >= 4 else None
    report["load_average"] = list(np.round(np.loadtxt("/proc/loadavg", usecols=(0, 1, 2)), 2))
    (args.out / "proxy.json").write_text(json.dumps(report, indent=2, default=str))
    mode = report["modes"][args.mode]
    print(json.dumps({**{variant: {key: mode[variant].get(key) for key in ("recall_0.1d", "rotation_error_deg")}
                         for variant in ("pnp", f"pnp_{MANY_CROPS}_crops")},
                      "training": {key: mode["training"].get(key) for key in
                                   ("reprojection_px_median", "cross_view_px_median", "usable_keypoints",
                                    "chart_accuracy")},
                      "oracle": report["oracle"], "spread_m": report["keypoint_spread_m"],
                      "cpu_s": report["cpu_seconds"], "wall_s": report["wall_seconds"]}, indent=1))


if __name__ == "__main__":
    main()
