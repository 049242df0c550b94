"""kill -9 during every trainer, then resume: the resumed run ends with the weights of an uninterrupted one.

For each method's trainer (``paz6d train <method>`` through its Python entry point, on the small world of
``tests/bad_input_cases.py``: a mesh, a two-image BOP data set, a FER-2013 CSV) with tiny settings that
checkpoint every ``--checkpoint-every`` steps:

1. a reference run of ``--steps`` steps, uninterrupted, in its own process;
2. the same run in another process, killed with SIGKILL a random time (``--seed``) after its
   ``checkpoint.json`` first points at a checkpoint (each step is slowed by ``--step-delay`` seconds so that
   the kill lands part-way: during later steps or while the next checkpoint is written), then run again in
   a third process, which resumes from the checkpoint the pointer names;
3. the last checkpoint's ``model.weights.h5`` of both compared array by array, and both ``log.csv`` step
   columns.

TensorFlow runs with op determinism on, so two uninterrupted runs give the same bits and any difference
comes from the resume. Prints one line per method and exits 1 when a resumed run differs or was not
killed part-way.

Usage::

    python scripts/kill_resume.py                      # every trainer
    python scripts/kill_resume.py --methods ssd stn    # some
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

#: Imports TensorFlow first (with op determinism), slows every training step by argv[3] seconds, then runs the
#: method's recipe with ``out`` = argv[1] and ``world`` = argv[2].
PRELUDE = """
import inspect, sys, time
from pathlib import Path
from paz6d.backend.tensorflow_guard import import_tensorflow
import_tensorflow().config.experimental.enable_op_determinism()
import paz6d.training.trainer as trainer_module
out, world, delay, steps, every = Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), \\
    int(sys.argv[5])
original = trainer_module.Trainer.__init__
signature = inspect.signature(original)
def slowed(self, *args, **kwargs):
    bound = signature.bind(self, *args, **kwargs)
    data = bound.arguments["data"]
    if delay and callable(data):
        bound.arguments["data"] = lambda step: (time.sleep(delay), data(step))[1]
    original(*bound.args, **bound.kwargs)
trainer_module.Trainer.__init__ = slowed
"""

#: Each trainer with tiny settings: ``steps`` steps, a checkpoint every ``every``, no samples.
RECIPES = {
    "ssd": """
from paz6d.ssd.config import QUICK, SSDTraining
from paz6d.ssd.train import train_ssd
settings = QUICK.replace(input_size=128, width=0.25, learning_rate=5e-3, warmup_steps=0, expand_probability=0.0,
                         checkpoint_every=every, sample_every=0)
train_ssd(SSDTraining(dataset=world / "bop", out=out, steps=steps, batch_size=4, progress=False, settings=settings))
""",
    "segmentation": """
from paz6d.segmentation.config import QUICK, SegmentationTraining
from paz6d.segmentation.train import train_segmentation
settings = QUICK.replace(input_size=32, widths=(8, 16), batch_size=4, learning_rate=1e-2, checkpoint_every=every,
                         sample_every=0, steps=steps)
train_segmentation(SegmentationTraining(dataset=world / "bop", out=out, split="test", progress=False,
                                        settings=settings))
""",
    "stn": """
from paz6d.stn.config import QUICK, STNTraining
from paz6d.stn.train import train_stn
settings = QUICK.replace(canvas_size=16, crop_size=16, scale=(14.0, 16.0), clutter=0, filters=8, learning_rate=3e-3,
                         test_samples=16, checkpoint_every=every, sample_every=0)
train_stn(STNTraining(out=out, steps=steps, batch_size=8, progress=False, settings=settings))
""",
    "hrnet": """
from paz6d.hrnet.config import QUICK, HRNetTraining
from paz6d.hrnet.train import train_hrnet
settings = QUICK.replace(num_keypoints=5, input_size=32, stem_width=8, stem_blocks=0, widths=(8, 16),
                         stage_modules=(1,), blocks=1, precision="float32", views=16, validation_views=4,
                         test_images=4, batch_size=4, learning_rate=1e-2, checkpoint_every=every, sample_every=0)
train_hrnet(HRNetTraining(out, world / "obj_000001.ply", settings=settings, steps=steps, workers=0, progress=False))
""",
    "keypointnet": """
from paz6d.keypointnet.config import QUICK, KeypointTraining
from paz6d.keypointnet.train import train_keypointnet
settings = QUICK.replace(num_keypoints=6, input_size=32, filters=8, downsample=2, dilations=(1, 2), views=24,
                         validation_views=8, lift_views=8, pairs=4, learning_rate=3e-3, checkpoint_every=every,
                         sample_every=0)
train_keypointnet(KeypointTraining(out, world / "obj_000001.ply", mode="supervised", seed=0, workers=0, steps=steps,
                                   progress=False, settings=settings))
""",
    "probabilistic-keypoints": """
from paz6d.probabilistic_keypoints.config import QUICK, ProbabilisticTraining
from paz6d.probabilistic_keypoints.train import train_probabilistic_keypoints
settings = QUICK.replace(views=24, validation_views=8, test_images=4, lift_images=4, filters=8, input_size=32,
                         num_keypoints=6, dilations=(1, 2), pairs=2, checkpoint_every=every, sample_every=0,
                         precision="float32")
train_probabilistic_keypoints(ProbabilisticTraining(mesh=world / "obj_000001.ply", out=out, steps=steps, workers=0,
                                                    progress=False, settings=settings))
""",
    "aae": """
from dataclasses import replace
from paz6d.aae.config import QUICK
from paz6d.aae.train import train_aae
config = replace(QUICK, crop_size=16, latent_size=16, filters=(8, 16), kernel_size=3, render_size=40, views=24,
                 in_plane=6, steps=steps, batch_size=8, learning_rate=2e-3, checkpoint_every=every, sample_every=0,
                 log_every=1, precision="float32")
train_aae(world / "obj_000001.ply", out, config, workers=0, progress=False)
""",
    "emotion": """
from paz6d.faces.emotion_config import EmotionTraining
from paz6d.faces.emotion_train import train_emotion
rows = (world / "fer.csv").read_text().splitlines()  # the world's 14 faces, the last 4 held out
faces = out.parent / "fer_held_out.csv"
faces.write_text("\\n".join(rows[:-4] + [row.rsplit(",", 1)[0] + ",PublicTest" for row in rows[-4:]]) + "\\n")
train_emotion(EmotionTraining(data=faces, out=out, epochs=steps, batch_size=4, input_size=24,
                              checkpoint_every=every, validate_every=0, seed=0, progress=False))
""",
}


def _command(method: str, out: Path, world: Path, delay: float, steps: int, every: int) -> list[str]:
    return [sys.executable, "-c", PRELUDE + RECIPES[method], str(out), str(world), str(delay), str(steps), str(every)]


def _environment() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}


def _run(command: list[str], log: Path) -> None:
    with log.open("a") as handle:
        done = subprocess.run(command, stdout=handle, stderr=handle, env=_environment(), cwd=REPO)
    if done.returncode != 0:
        raise RuntimeError(f"{command[3]}: exit {done.returncode}; see {log}")


def _pointer_step(run: Path) -> int:
    try:
        return int(json.loads((run / "checkpoint.json").read_text())["step"])
    except (OSError, ValueError, KeyError):
        return 0


def _killed_part_way(command: list[str], run: Path, every: int, log: Path, timeout: float, wait: float) -> int:
    """Runs ``command`` until ``run``'s checkpoint pointer reaches ``every``, then ``wait`` seconds more (mid-way
    through later steps, or through writing the next checkpoint), kills it (SIGKILL); the step it points at then."""
    with log.open("a") as handle:
        process = subprocess.Popen(command, stdout=handle, stderr=handle, env=_environment(), cwd=REPO)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and process.poll() is None and _pointer_step(run) < every:
            time.sleep(0.01)
        time.sleep(wait)
        process.send_signal(signal.SIGKILL)
        process.wait()
    return _pointer_step(run)


def _weights(path: Path) -> dict[str, np.ndarray]:
    found = {}
    with h5py.File(path, "r") as handle:
        handle.visititems(lambda name, item: found.__setitem__(name, item[()]) if isinstance(item, h5py.Dataset)
                          else None)
    return found


def _log_steps(run: Path) -> list[int]:
    with (run / "log.csv").open() as handle:
        return [int(row["step"]) for row in csv.DictReader(handle)]


def check(method: str, world: Path, folder: Path, steps: int, every: int, delay: float, timeout: float,
          wait: float) -> dict:
    """One method: the reference, the killed and resumed run, their comparison."""
    log = folder / f"{method}.log"
    reference, resumed = folder / f"{method}_reference", folder / f"{method}_killed"
    for run in (reference, resumed):  # runs of an earlier call of the script
        shutil.rmtree(run, ignore_errors=True)
    started = time.perf_counter()
    _run(_command(method, reference, world, 0.0, steps, every), log)
    command = _command(method, resumed, world, delay, steps, every)
    killed_at = _killed_part_way(command, resumed, every, log, timeout, wait)
    _run(command, log)
    pointer = json.loads((reference / "checkpoint.json").read_text())  # emotion counts epochs: its own total
    steps, last = int(pointer["step"]), Path(pointer["path"]) / "model.weights.h5"
    if json.loads((resumed / "checkpoint.json").read_text()) != pointer:
        raise RuntimeError(f"{method}: the resumed run's checkpoint.json differs from the reference's")
    want, got = _weights(reference / last), _weights(resumed / last)
    differing = sorted(name for name in want if name not in got or not np.array_equal(want[name], got[name]))
    largest = max((float(np.max(np.abs(want[name] - got[name]))) for name in differing if name in got
                   and want[name].shape == got[name].shape), default=0.0)
    same_log = _log_steps(reference) == _log_steps(resumed)
    return {"method": method, "killed_at": killed_at, "killed_seconds_later": round(wait, 2), "steps": steps,
            "arrays": len(want), "differing": len(differing), "largest_difference": largest,
            "log_steps_equal": same_log, "seconds": round(time.perf_counter() - started, 1),
            "ok": 0 < killed_at < steps and not differing and same_log}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--methods", nargs="+", choices=sorted(RECIPES), default=sorted(RECIPES))
    parser.add_argument("--steps", type=int, default=30, help="training steps of each run (default 30)")
    parser.add_argument("--checkpoint-every", type=int, default=10, help="steps between checkpoints (default 10)")
    parser.add_argument("--step-delay", type=float, default=0.2, help="seconds added to each step of the killed run")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the first checkpoint")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of how long after the first checkpoint each run is killed: up to as long as "
                             "--checkpoint-every delayed steps take (default 0)")
    parser.add_argument("--work", type=Path, help="folder for the world and the runs (default: a temporary one)")
    args = parser.parse_args(argv)
    if not 0 < args.checkpoint_every < args.steps:
        parser.error("--checkpoint-every: expected fewer steps than --steps")

    import bad_input_cases as cases

    with tempfile.TemporaryDirectory(prefix="paz6d-kill-") as temporary:
        folder = args.work or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(folder / "world", ignore_errors=True)
        world = cases.build_world(folder / "world").root
        failures, waits = 0, random.Random(args.seed)
        for method in args.methods:
            wait = waits.uniform(0.0, args.checkpoint_every * args.step_delay)
            try:
                result = check(method, world, folder, args.steps, args.checkpoint_every, args.step_delay,
                               args.timeout, wait)
            except RuntimeError as error:
                result = {"method": method, "ok": False, "error": str(error)}
            failures += not result["ok"]
            print(json.dumps(result), flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
