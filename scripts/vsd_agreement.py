"""paz6d's VSD against bop_toolkit's ``pose_error.vsd``, side by side, on a generated data set with depth.

1. ``paz6d generate`` makes a ``test`` split of LM-O meshes (objects, distractors, occluders) with
   depth PNGs (BOP's 0.1 mm depth scale); some test depth images get rectangular holes (missing
   sensor depth, which bop19 visibility counts as visible).
2. Estimates: every annotated instance gets ``--estimates-per-instance`` perturbed poses, from
   sub-millimetre to far off (rotation up to 60 degrees, translation up to 60 mm).
3. paz6d: each estimate and its ground truth are rendered as the BOP protocol does
   (``renderers.Renderer``, ``antialias="none"``, the ``models/`` meshes) and scored with
   ``evaluation.pose_errors.vsd_error`` (BOP's delta = 15 mm, tau = 0.05 ... 0.5 x diameter).
4. bop_toolkit: in its own virtualenv (``--toolkit-python``; created with ``numpy<2`` and scipy
   when missing) a child process imports ``bop_toolkit_lib.pose_error`` from a bop_toolkit checkout
   (``--toolkit``; e.g. ``git clone https://github.com/thodan/bop_toolkit``; nothing of it is part of
   paz6d) and calls ``vsd(R_est, t_est, R_gt, t_gt, depth_test, K, delta, taus, True, diameter,
   renderer, obj_id, "step")`` with a renderer that hands it the same two depth images. So the
   comparison covers everything VSD does after rendering (distance images, visibility masks, costs);
   the renderer's depth is checked against exact pixel-centre depth in ``tests/test_renderer.py``.

Prints and writes (``<work>/vsd_agreement.json``) the largest difference, how many VSD values are
bit-identical, and how many correct/incorrect decisions (VSD < theta for each tau and theta, as in
the BOP score) differ. Exit status 1 when a value differs by more than ``--tolerance``.

Run: ``.venv/bin/python scripts/vsd_agreement.py --toolkit /path/to/bop_toolkit --work /tmp/vsd
[--toolkit-python /path/to/venv/bin/python] [--images 60] [--estimates-per-instance 3]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap
import venv
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from data_gen.config import GenerationConfig  # noqa: E402
from data_gen.generator import generate  # noqa: E402
from evaluation import pose_errors  # noqa: E402
from evaluation.bop import BOP_FRACTIONS  # noqa: E402
from evaluation.bop_data import load_evaluation_data  # noqa: E402
from paz6d.datasets.bop.scene import nearest_rotation  # noqa: E402
from paz6d.datasets.bop import MM_PER_M, Target, write_targets  # noqa: E402

SHARED_MODELS = ROOT.parent / "shared" / "data" / "bop_lmo" / "models"
DELTA_MM = 15.0
TAUS = np.asarray(BOP_FRACTIONS, dtype=np.float64)
THRESHOLDS = np.asarray(BOP_FRACTIONS, dtype=np.float64)

# Runs inside the toolkit's environment: reads one .npz per image, prints one JSON line of VSDs.
TOOLKIT_CHILD = textwrap.dedent('''
    import json, sys
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    from bop_toolkit_lib import pose_error

    class GivenDepth:
        """A stand-in for the toolkit's renderer: returns the depth rendered for that pose."""
        def __init__(self, depths):
            self.depths = depths
        def render_object(self, obj_id, R, t, fx, fy, cx, cy):
            return {"depth": self.depths.pop(0)}

    results = {}
    for path in sys.argv[3:]:
        data = np.load(path)
        for index in range(len(data["estimate_ids"])):
            renderer = GivenDepth([data["depth_est"][index], data["depth_gt"][index]])
            values = pose_error.vsd(data["R_est"][index], data["t_est"][index][:, None], data["R_gt"][index],
                                    data["t_gt"][index][:, None], data["depth_test"], data["K"], float(sys.argv[2]),
                                    list(data["taus"]), True, float(data["diameters"][index]), renderer,
                                    int(data["obj_ids"][index]), "step")
            results[int(data["estimate_ids"][index])] = [float(value) for value in values]
    print(json.dumps(results))
''')


def toolkit_python(path: Path | None, work: Path) -> Path:
    """The toolkit environment's Python: ``path``, or a virtualenv made in ``work`` with numpy<2 and scipy
    (what ``bop_toolkit_lib.pose_error`` imports; the toolkit pins numpy<2)."""
    if path is not None:
        return path
    environment = work / "toolkit-venv"
    python = environment / "bin" / "python"
    if not python.exists():
        venv.create(environment, with_pip=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", "numpy<2", "scipy"], check=True)
    return python


def make_dataset(work: Path, images: int, seed: int) -> Path:
    """A generated ``test`` split with depth (resumes an existing one) and its targets file."""
    dataset = work / "dataset"
    meshes = tuple(SHARED_MODELS / f"obj_{obj_id:06d}.ply" for obj_id in (1, 5, 6, 8, 9, 12))
    config = GenerationConfig(meshes=meshes, out=dataset, num_images=images, seed=seed, split="test",
                              mesh_scale=1.0 / MM_PER_M, objects_per_image=(3, 5), occluder_probability=0.6)
    generate(config, show_progress=False)
    targets = []
    for scene in sorted(p for p in (dataset / "test").iterdir() if p.is_dir()):
        for im_id, instances in json.loads((scene / "scene_gt.json").read_text()).items():
            for obj_id in sorted({instance["obj_id"] for instance in instances}):
                count = sum(instance["obj_id"] == obj_id for instance in instances)
                targets.append(Target(int(scene.name), int(im_id), obj_id, count))
    if not targets:
        raise ValueError(f"{dataset}: the generated data set has no annotated instance")
    write_targets(dataset / "test_targets_bop19.json", targets)
    return dataset


def perturbed(T_gt: np.ndarray, generator: np.random.Generator) -> np.ndarray:
    """``T_gt`` (mm) moved by a random rotation and translation, from tiny to large."""
    angle = np.deg2rad(generator.choice([0.2, 2.0, 8.0, 20.0, 60.0]) * generator.random())
    axis = generator.normal(size=3)
    axis /= np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rotation = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    T = T_gt.copy()
    T[:3, :3] = rotation @ nearest_rotation(T_gt[:3, :3])
    T[:3, 3] += generator.normal(size=3) * generator.choice([0.3, 3.0, 10.0, 30.0, 60.0])
    return T


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--toolkit", type=Path, required=True, help="bop_toolkit checkout (has bop_toolkit_lib/)")
    parser.add_argument("--toolkit-python", type=Path, help="Python of an environment for the toolkit "
                                                            "(default: make one in --work)")
    parser.add_argument("--work", type=Path, required=True, help="work folder (data set, depth files, report)")
    parser.add_argument("--images", type=int, default=60, help="generated test images")
    parser.add_argument("--estimates-per-instance", type=int, default=3, help="perturbed estimates per instance")
    parser.add_argument("--seed", type=int, default=0, help="seed of the data set and the perturbations")
    parser.add_argument("--tolerance", type=float, default=1e-9, help="largest allowed |VSD difference|")
    args = parser.parse_args(argv)
    if not (args.toolkit / "bop_toolkit_lib" / "pose_error.py").is_file():
        parser.error(f"--toolkit: {args.toolkit} has no bop_toolkit_lib/pose_error.py")
    from renderers import Renderer

    args.work.mkdir(parents=True, exist_ok=True)
    python = toolkit_python(args.toolkit_python, args.work)
    dataset = make_dataset(args.work, args.images, args.seed)
    data = load_evaluation_data(dataset, "test")
    generator = np.random.default_rng(args.seed)
    depth_folder = args.work / "depth"
    depth_folder.mkdir(exist_ok=True)
    ours: dict[int, np.ndarray] = {}
    files = []
    estimate_id = 0
    with Renderer(data.width, data.height, antialias="none") as renderer:
        def render_mm(obj_id: int, T_mm: np.ndarray, K: np.ndarray) -> np.ndarray:
            T = T_mm.copy()
            T[:3, :3] = nearest_rotation(T[:3, :3])
            T[:3, 3] /= MM_PER_M
            depth = renderer.render(K, [(data.render_mesh(obj_id), T)], rgb=False, masks=False).depth
            return depth.astype(np.float64) * MM_PER_M

        for number, ((scene_id, im_id), image) in enumerate(sorted(data.images.items())):
            depth_test = data.read_depth(scene_id, im_id)
            if number % 3 == 0:  # missing sensor depth
                for _ in range(3):
                    row, col = generator.integers(0, data.height - 30), generator.integers(0, data.width - 40)
                    depth_test[row:row + 30, col:col + 40] = 0.0
            record = {name: [] for name in ("estimate_ids", "obj_ids", "diameters", "R_est", "t_est", "R_gt", "t_gt",
                                            "depth_est", "depth_gt")}
            for obj_id, T_gt in zip(image.obj_ids, image.T_model2cam):
                depth_gt = render_mm(int(obj_id), T_gt, image.K)
                for _ in range(args.estimates_per_instance):
                    T_est = perturbed(T_gt, generator)
                    depth_est = render_mm(int(obj_id), T_est, image.K)
                    diameter = data.diameters[int(obj_id)]
                    ours[estimate_id] = pose_errors.vsd_error(depth_test, depth_est, depth_gt, image.K, DELTA_MM,
                                                              TAUS, diameter)
                    for name, value in (("estimate_ids", estimate_id), ("obj_ids", obj_id), ("diameters", diameter),
                                        ("R_est", T_est[:3, :3]), ("t_est", T_est[:3, 3]), ("R_gt", T_gt[:3, :3]),
                                        ("t_gt", T_gt[:3, 3]), ("depth_est", depth_est), ("depth_gt", depth_gt)):
                        record[name].append(value)
                    estimate_id += 1
            path = depth_folder / f"{scene_id:06d}_{im_id:06d}.npz"
            np.savez_compressed(path, depth_test=depth_test, K=image.K, taus=TAUS,
                                **{name: np.asarray(values) for name, values in record.items()})
            files.append(str(path))
    child = subprocess.run([str(python), "-c", TOOLKIT_CHILD, str(args.toolkit.resolve()), str(DELTA_MM), *files],
                           capture_output=True, text=True, check=True)
    theirs = {int(key): np.asarray(value) for key, value in json.loads(child.stdout.splitlines()[-1]).items()}
    ids = sorted(ours)
    assert sorted(theirs) == ids, "the toolkit scored a different set of estimates"
    a, b = np.stack([ours[i] for i in ids]), np.stack([theirs[i] for i in ids])
    difference = np.abs(a - b)
    decisions_a = a[:, :, None] < THRESHOLDS[None, None, :]
    decisions_b = b[:, :, None] < THRESHOLDS[None, None, :]
    report = {"estimates": len(ids), "images": len(files), "values": int(a.size),
              "identical_values": int(np.sum(a == b)), "max_abs_difference": float(difference.max()),
              "differing_decisions": int(np.sum(decisions_a != decisions_b)), "decisions": int(decisions_a.size),
              "vsd_quantiles_tau_0.2": [float(q) for q in np.quantile(a[:, 3], [0, 0.25, 0.5, 0.75, 1])],
              "share_of_vsd_strictly_between_0_and_1": float(np.mean((a > 0) & (a < 1))),
              "delta_mm": DELTA_MM, "taus": TAUS.tolist(), "toolkit": str(args.toolkit.resolve())}
    (args.work / "vsd_agreement.json").write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))
    return 0 if report["max_abs_difference"] <= args.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
