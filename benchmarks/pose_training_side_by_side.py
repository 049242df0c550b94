"""Training several pose models side by side (``paz6d benchmark lmo --jobs N``) against one after the other.

Trains the same quick AAEs (rendered views only, ``--steps`` each) twice, every AAE in its own spawned process
both times: first one at a time with TensorFlow on every core (what ``--jobs 1`` does), then ``--jobs`` at a
time with the cores shared out (``paz6d.benchmark.parallel``). Prints both wall times and their ratio.

Run: ``.venv/bin/python benchmarks/pose_training_side_by_side.py [--objects 1 5] [--steps 600] [--jobs 2]``
(meshes: ``../shared/data/bop_lmo/models``, or ``--models DIR``).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from paz6d.benchmark.lmo import DEFAULT_LMO
from paz6d.benchmark.parallel import run_in_processes, threads_per_job


def train_one(mesh: str, run_dir: str, steps: int, threads: int) -> None:
    """One quick AAE (the benchmark's settings, rendered views only), TensorFlow limited to ``threads``."""
    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow(threads=threads)
    from paz6d.aae.config import QUICK, Augmentation
    from paz6d.aae.train import train_aae

    config = replace(QUICK, steps=steps, in_plane=36, views=1000, augmentation=Augmentation())
    train_aae(mesh, run_dir, config, mesh_scale=0.001, seed=0, workers=2, progress=False)


def timed(meshes: list[Path], steps: int, jobs: int, folder: Path) -> float:
    """Wall seconds to train one AAE per mesh, ``jobs`` at a time."""
    threads = threads_per_job(jobs)
    tasks = [(mesh.stem, train_one, (str(mesh), str(folder / f"jobs{jobs}_{mesh.stem}"), steps, threads))
             for mesh in meshes]
    started = time.perf_counter()
    run_in_processes(tasks, jobs)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, default=DEFAULT_LMO / "models")
    parser.add_argument("--objects", type=int, nargs="+", default=[1, 5])
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    meshes = [args.models / f"obj_{obj_id:06d}.ply" for obj_id in args.objects]
    missing = [str(mesh) for mesh in meshes if not mesh.is_file()]
    if missing:
        raise SystemExit(f"--models: {missing} not found")
    with tempfile.TemporaryDirectory() as folder:
        one_at_a_time = timed(meshes, args.steps, 1, Path(folder))
        side_by_side = timed(meshes, args.steps, args.jobs, Path(folder))
    print(json.dumps({"objects": args.objects, "steps": args.steps, "jobs": args.jobs,
                      "threads_per_job": threads_per_job(args.jobs),
                      "one_at_a_time_s": round(one_at_a_time, 1), "side_by_side_s": round(side_by_side, 1),
                      "one_at_a_time_over_side_by_side": round(one_at_a_time / side_by_side, 3)}))


if __name__ == "__main__":
    main()
