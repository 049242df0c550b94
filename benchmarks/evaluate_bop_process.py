"""Whole-process ``paz6d evaluate bop`` (mssd, mspd, add) vs bop_toolkit's error functions, on LM-O.

Both sides score the 1,427 estimates of ``../shared/data/bop_lmo/results/results_lmo-test.csv``:

* paz6d: ``paz6d evaluate bop --dataset bop_lmo --split test --results CSV --metrics mssd,mspd,add
  --out OUT.json --no-progress [--workers W]`` as one process, start to finish (imports, reading
  every file, models, MSSD, MSPD, ADD, ADD-S, projection errors, matching, scores, JSON);
* bop_toolkit: in a child process, only its error functions, as ``eval_calc_errors.py`` calls them:
  for each estimate and its ground-truth instance ``pose_error.mssd``, ``pose_error.mspd``,
  ``pose_error.add`` and ``pose_error.adi`` on the ``models_eval`` vertices (symmetries from
  ``misc.get_symmetry_transformations(..., 0.01)``); the time of that loop alone is reported
  (imports and file reading are left out, which favours the toolkit).

The toolkit comes from a checkout given with ``--toolkit`` (e.g. ``git clone
https://github.com/thodan/bop_toolkit``; it is not a paz6d dependency) and runs under
``--toolkit-python`` (an environment with ``numpy<2`` and scipy, as the toolkit pins; default: this
Python). Best of ``--repeats`` alternating runs; wall and CPU seconds (user + system) are printed,
the CPU ones being the steadier on a shared machine. The toolkit's MSSD values are checked against
paz6d's ERRORS.csv. Run: ``.venv/bin/python benchmarks/evaluate_bop_process.py --toolkit DIR
[--toolkit-python PY] [--repeats 3] [--workers 1]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from paz6d.datasets.bop.models import load_model  # noqa: E402
from timing import run_process  # noqa: E402

LMO = ROOT.parent / "shared" / "data" / "bop_lmo"
RESULTS = "results/results_lmo-test.csv"

# Runs under the toolkit's Python: argv = toolkit folder, inputs .npz, models_info.json.
TOOLKIT_CHILD = """
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from bop_toolkit_lib import misc, pose_error

inputs = np.load(sys.argv[2])
info = {int(key): value for key, value in json.load(open(sys.argv[3])).items()}
points = {int(name[7:]): inputs[name] for name in inputs.files if name.startswith("points_")}
symmetries = {obj_id: misc.get_symmetry_transformations(info[obj_id], 0.01) for obj_id in points}
wall, cpu = time.perf_counter(), time.process_time()
mssd = []
for obj_id, R_e, t_e, R_g, t_g, K in zip(inputs["obj_ids"], inputs["R_est"], inputs["t_est"], inputs["R_gt"],
                                         inputs["t_gt"], inputs["K"]):
    pts, syms = points[int(obj_id)], symmetries[int(obj_id)]
    t_e, t_g = t_e[:, None], t_g[:, None]
    mssd.append(pose_error.mssd(R_e, t_e, R_g, t_g, pts, syms))
    pose_error.mspd(R_e, t_e, R_g, t_g, K, pts, syms)
    pose_error.add(R_e, t_e, R_g, t_g, pts)
    pose_error.adi(R_e, t_e, R_g, t_g, pts)
print(json.dumps({"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                  "mssd": [float(value) for value in mssd]}))
"""


def toolkit_inputs(data: Path, path: Path) -> list[tuple[int, int, int]]:
    """Writes the estimates, their ground truth, intrinsics and model points to ``path`` (.npz);
    returns the ``(scene, image, object)`` key of each estimate, in order."""
    scene = data / "test" / "000002"
    ground_truth = json.loads((scene / "scene_gt.json").read_text())
    cameras = json.loads((scene / "scene_camera.json").read_text())
    columns = {name: [] for name in ("obj_ids", "R_est", "t_est", "R_gt", "t_gt", "K")}
    keys = []
    with open(data / RESULTS, newline="") as file:
        for row in csv.DictReader(file):
            obj_id, im_id = int(row["obj_id"]), row["im_id"]
            (instance,) = [g for g in ground_truth[im_id] if g["obj_id"] == obj_id]
            for name, value in (("obj_ids", obj_id), ("R_est", np.array(row["R"].split(), float).reshape(3, 3)),
                                ("t_est", np.array(row["t"].split(), float)),
                                ("R_gt", np.array(instance["cam_R_m2c"], float).reshape(3, 3)),
                                ("t_gt", np.array(instance["cam_t_m2c"], float)),
                                ("K", np.array(cameras[im_id]["cam_K"], float).reshape(3, 3))):
                columns[name].append(value)
            keys.append((int(row["scene_id"]), int(im_id), obj_id))
    points = {f"points_{obj_id}": np.asarray(load_model(data / "models_eval", obj_id, units="mm").vertices, float)
              for obj_id in sorted(set(columns["obj_ids"]))}
    np.savez(path, **{name: np.asarray(values) for name, values in columns.items()}, **points)
    return keys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--toolkit", type=Path, required=True, help="bop_toolkit checkout (has bop_toolkit_lib/)")
    parser.add_argument("--toolkit-python", type=Path, default=Path(sys.executable),
                        help="Python of the toolkit's environment (default: this one)")
    parser.add_argument("--data", type=Path, default=LMO, help="the bop_lmo folder of the shared data")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each side (best time is kept)")
    parser.add_argument("--workers", type=int, default=1, help="paz6d evaluate bop --workers")
    args = parser.parse_args(argv)
    if not (args.toolkit / "bop_toolkit_lib" / "pose_error.py").is_file():
        parser.error(f"--toolkit: {args.toolkit} has no bop_toolkit_lib/pose_error.py")
    script = Path(sys.executable).with_name("paz6d")
    paz6d = [str(script)] if script.exists() else [sys.executable, "-m", "paz6d"]
    with tempfile.TemporaryDirectory(prefix="bop_process_") as temporary:
        folder = Path(temporary)
        keys = toolkit_inputs(args.data, folder / "inputs.npz")
        theirs_command = [str(args.toolkit_python), "-c", TOOLKIT_CHILD, str(args.toolkit.resolve()),
                          str(folder / "inputs.npz"), str(args.data / "models_eval" / "models_info.json")]
        ours_command = [*paz6d, "evaluate", "bop", "--dataset", str(args.data), "--split", "test", "--results",
                        str(args.data / RESULTS), "--metrics", "mssd,mspd,add", "--out", str(folder / "out.json"),
                        "--errors", str(folder / "errors.csv"), "--no-progress", "--workers", str(args.workers)]
        run_process(ours_command)  # warm-up: bytecode and numba caches, as on any run after the first
        theirs, ours = [], []
        for _ in range(args.repeats):
            theirs.append(json.loads(run_process(theirs_command)[2].splitlines()[-1]))
            ours.append(run_process(ours_command)[:2])
        with open(folder / "errors.csv", newline="") as file:
            paz6d_mssd = {(int(r["scene_id"]), int(r["im_id"]), int(r["obj_id"])): float(r["mssd"])
                          for r in csv.DictReader(file)}
    toolkit_mssd = dict(zip(keys, theirs[0]["mssd"]))
    shared = [key for key in paz6d_mssd if key in toolkit_mssd and np.isfinite(paz6d_mssd[key])]
    difference = max(abs(paz6d_mssd[key] - toolkit_mssd[key]) for key in shared)
    base_wall, base_cpu = min(t["wall"] for t in theirs), min(t["cpu"] for t in theirs)
    our_wall, our_cpu = min(o[0] for o in ours), min(o[1] for o in ours)
    print(f"load average {os.getloadavg()[0]:.2f}; {len(keys)} estimates; paz6d --workers {args.workers}; "
          f"best of {args.repeats}")
    print(f"bop_toolkit error functions (mssd, mspd, add, adi): {base_wall:7.2f} s wall / {base_cpu:7.2f} s CPU")
    print(f"paz6d evaluate bop, whole process:                  {our_wall:7.2f} s wall / {our_cpu:7.2f} s CPU")
    print(f"speed-up: {base_wall / our_wall:.2f}x wall / {base_cpu / our_cpu:.2f}x CPU; "
          f"max |MSSD difference| over {len(shared)} paired estimates: {difference:.2e} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
