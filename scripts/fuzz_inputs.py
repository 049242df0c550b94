"""Seeded fuzzing of ``paz6d`` with bad inputs: mutated JSON, CSV, flags and paths through the real command
line (``paz6d.cli.main`` in this process), judged for tracebacks, hangs and silent or destructive results.

Usage::

    python scripts/fuzz_inputs.py                      # 600 cases, seed 0
    python scripts/fuzz_inputs.py --cases 2000 --seed 7 --report fuzz.json

Each case spoils one input of a small world of valid inputs (``tests/bad_input_cases.py``: a generated
two-image BOP data set, a results CSV, COCO and VOC files, run directories) and runs one command on it:

* ``json``: a BOP JSON file (camera, models_info, scene_gt, scene_camera, scene_gt_info, targets) or a
  COCO file with one value deleted, replaced (wrong type, NaN, huge, negative, empty, deeply nested) or
  duplicated, evaluated with ``paz6d evaluate bop|coco`` or read by ``paz6d estimate``;
* ``bytes``: one of those files truncated, emptied, with bytes flipped or made non-UTF-8;
* ``csv``: the BOP results CSV with fields dropped, added, replaced or swapped, rows duplicated, NUL
  bytes, broken quotes or huge fields;
* ``flag``: one flag of ``generate``, ``evaluate bop|coco|voc`` or ``estimate`` set to a hostile value
  (negative, zero, NaN, inf, 1e308, text, empty, ``../..``, a device, a folder, a file);
* ``path``: an output path that is a folder, a symbolic link, a FIFO, a device, under a file, one of
  the command's inputs, or an output folder holding a symbolic link;
* ``run``: an AAE or KeypointNet run directory with one file's JSON values or bytes mutated, given to
  ``paz6d estimate``;
* ``detector``: an SSD run directory whose ``detector.json`` has one value mutated (priors, class names,
  variances, image scale, architecture), given to ``paz6d detect``;
* ``trainer``: an AAE run as a killed training leaves it with one of the files a resume reads
  (``checkpoint.json``, ``log.csv``, the checkpoint's ``optimizer.npz``) mutated in its JSON values or
  bytes, resumed with ``paz6d train aae``;
* ``output``: an output of ``detect``, ``estimate``, any ``train <method>`` or ``benchmark lmo`` aimed at
  one of the call's inputs (a data set's file or folder, an image, a run directory's file, another
  method's run, a symbolic link): refused before anything is written;
* ``sample``: a VOC, COCO, Open Images or YCB-Video fixture (``tests/data/datasets``) with one value
  mutated (boxes, sizes, ids, file names, image-set ids), read through the loader's ``SampleSequence``
  in this process: either refused with a ``ValueError`` naming the file, or every sample is sound
  (finite, non-inverted boxes on the image, its image inside the data set).

A case passes when the exit code is 0 or 2, no traceback is printed, it ends within ``--timeout``
seconds, nothing outside its output is touched, an error (exit 2) is one ``paz6d ...: error:`` or
argparse line naming a file or flag, and a success (exit 0) is sound: BOP recalls, COCO stats and VOC
mAP within [0, 1] (a recall above 1 is a silent wrong result). Exit status 1 when any case fails.
"""

from __future__ import annotations

import argparse
import collections
import copy
import json
import os
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))

import bad_input_cases as cases  # noqa: E402  (the world and the runner of the test table)

HOSTILE_VALUES = [None, "", "abc", -1, 0, 1, -1e308, 1e308, 1.5, True, [], {}, [1, 2], {"a": 1}, "NaN", 10**30,
                  "0", -0.0, [[[[[]]]]], "../../etc", "\x00", "é" * 3, float("nan"), float("inf")]
HOSTILE_FLAG_VALUES = ["-1", "0", "nan", "inf", "-inf", "1e308", "-1e308", "abc", "", "../..", "/dev/null",
                       "1.5", "99999999999999999999", "{world}/results.csv", "{world}/bop", "{case}/missing",
                       "\x01", "--", "0x10", " 1", "1e-320"]
#: Output flags get no existing world file (replacing a regular file the user names is allowed, and
#: would spoil the world for later cases) and no folder they could legitimately write into.
OUTPUT_FLAGS = ("--out", "--errors", "--plots", "--targets-out", "--ground-truth", "--detections-out")
HOSTILE_OUTPUT_VALUES = ["-1", "0", "abc", "", "../..", "/dev/null", "{world}/bop", "{case}/missing/x.json",
                         "\x01", " 1", "{world}/results.csv/x"]
BOP_JSON = ["camera.json", "models/models_info.json", "test/000000/scene_gt.json", "test/000000/scene_camera.json",
            "test/000000/scene_gt_info.json", "test_targets_bop19.json"]
HEADER = "scene_id,im_id,obj_id,score,R,t,time"
RECALL_KEYS = ("AR_VSD", "AR_MSSD", "AR_MSPD", "AR", "ADD(-S)_recall")


# ------------------------------------------------------------------------------------------------ mutations

def _paths(value, prefix=()):
    """Every (path, value) in a JSON tree, the root first."""
    yield prefix, value
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, prefix + (key,))
    elif isinstance(value, list):
        for index, item in enumerate(value[:4]):
            yield from _paths(item, prefix + (index,))


def mutate_json(data, rng: random.Random):
    """``data`` with one value deleted, replaced or duplicated (a deep copy), and what was done."""
    data = copy.deepcopy(data)
    paths = [path for path, _ in _paths(data) if path]
    if not paths:
        return rng.choice(HOSTILE_VALUES), "root replaced"
    path = rng.choice(paths)
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    operation = rng.choice(["delete", "replace", "replace", "replace", "duplicate", "nest"])
    if operation == "delete":
        del parent[key]
    elif operation == "replace":
        parent[key] = rng.choice(HOSTILE_VALUES)
    elif operation == "duplicate" and isinstance(parent, list):
        parent.append(copy.deepcopy(parent[key]))
    else:
        parent[key] = [parent[key]]
    return data, f"{operation} {'/'.join(map(str, path))}"


def mutate_bytes(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    operation = rng.choice(["truncate", "empty", "flip", "not-utf8", "nul"])
    if operation == "truncate":
        cut = rng.randrange(max(1, len(data)))
        return data[:cut], f"truncated at {cut}"
    if operation == "empty":
        return b"", "emptied"
    position = rng.randrange(max(1, len(data)))
    if operation == "flip":
        return data[:position] + bytes([rng.randrange(256)]) + data[position + 1:], f"byte {position} flipped"
    if operation == "nul":
        return data[:position] + b"\x00" + data[position:], f"NUL at {position}"
    return data[:position] + b"\xff\xfe" + data[position:], f"non-UTF-8 at {position}"


def mutate_csv(text: str, rng: random.Random) -> tuple[str, str]:
    lines = text.splitlines()
    index = rng.randrange(len(lines))
    fields = lines[index].split(",")
    operation = rng.choice(["drop", "add", "replace", "replace", "swap", "duplicate-row", "nul", "quote", "huge",
                            "header"])
    if operation == "drop" and len(fields) > 1:
        del fields[rng.randrange(len(fields))]
    elif operation == "add":
        fields.insert(rng.randrange(len(fields) + 1), rng.choice(["1", "x", "", "nan"]))
    elif operation == "replace":
        fields[rng.randrange(len(fields))] = str(rng.choice(HOSTILE_VALUES + ["1 2 3", "1e999", "-5", "nan nan"]))
    elif operation == "swap" and len(fields) > 1:
        a, b = rng.sample(range(len(fields)), 2)
        fields[a], fields[b] = fields[b], fields[a]
    elif operation == "duplicate-row":
        lines.append(lines[index])
    elif operation == "nul":
        fields[0] += "\x00"
    elif operation == "quote":
        fields[-1] = '"' + fields[-1]
    elif operation == "huge":
        fields[rng.randrange(len(fields))] = "7" * rng.choice([5000, 200_000])
    else:
        lines[0] = rng.choice(["", HEADER.upper(), HEADER.replace(",", ";"), HEADER + ",extra"])
        return "\n".join(lines) + "\n", "header changed"
    lines[index] = ",".join(fields)
    return "\n".join(lines) + "\n", f"{operation} in line {index + 1}"


# ------------------------------------------------------------------------------------------------ cases

def _write_mutated_bop(world: cases.World, folder: Path, relative: str, mutation) -> None:
    root = cases.copy_bop(world, folder)
    cases.put(root / relative, mutation)


def json_case(world: cases.World, rng: random.Random, number: int):
    relative = rng.choice(BOP_JSON + ["coco_gt.json", "coco_results.json"])
    if relative.startswith("coco"):
        data, what = mutate_json(json.loads((world.root / relative).read_text()), rng)
        flag = "--gt" if relative == "coco_gt.json" else "--results"
        argv = cases.replace_flag(cases.EVALUATE_COCO, flag, "{case}/" + relative)
        return cases.Case(f"fuzz-{number}-json-{relative}-{what}", argv, cases.case_file(relative, _dumps(data)))
    data, what = mutate_json(json.loads((world.bop / relative).read_text()), rng)
    argv = rng.choice([cases.EVALUATE_BOP, cases.replace_flag(cases.ESTIMATE, "--dataset", "{case}/bop")])
    return cases.Case(f"fuzz-{number}-json-{relative}-{what}", argv,
                      lambda w, folder: _write_mutated_bop(w, folder, relative, _dumps(data)))


def _dumps(data) -> str:
    if isinstance(data, list) and data == [[[[[]]]]]:
        return cases.deep_json()
    return json.dumps(data)  # NaN/inf written as NaN/Infinity, as Python's json reads them


def bytes_case(world: cases.World, rng: random.Random, number: int):
    relative = rng.choice(BOP_JSON)
    data, what = mutate_bytes((world.bop / relative).read_bytes(), rng)
    return cases.Case(f"fuzz-{number}-bytes-{relative}-{what}", cases.EVALUATE_BOP,
                      lambda w, folder: _write_mutated_bop(w, folder, relative, data))


def csv_case(world: cases.World, rng: random.Random, number: int):
    text, what = mutate_csv(world.results.read_text(), rng)
    argv = cases.replace_flag(cases.EVALUATE_WORLD_BOP, "--results", "{case}/results.csv")
    if rng.random() < 0.3:
        argv += ("--skip-invalid",)
        what += " (--skip-invalid)"
    return cases.Case(f"fuzz-{number}-csv-{what}", argv, cases.case_file("results.csv", text.encode("utf-8",
                                                                                                    "surrogatepass")))


FLAGS = {
    cases.GENERATE: ["--num-images", "--width", "--height", "--seed", "--split", "--mesh-scale", "--intrinsics",
                     "--objects-per-image", "--distance", "--inplane-degrees", "--elevation-degrees", "--distractors",
                     "--occluder-probability", "--light-count", "--color-jitter", "--blur-probability",
                     "--noise-std", "--depth-scale", "--images-per-scene", "--crop-size", "--meshes", "--symmetries",
                     "--backgrounds", "--out", "--workers"],
    cases.EVALUATE_WORLD_BOP: ["--dataset", "--split", "--results", "--targets", "--metrics", "--out", "--errors",
                               "--plots", "--visib-gt-min", "--vsd-delta", "--workers"],
    cases.EVALUATE_COCO: ["--gt", "--results", "--out", "--plots", "--iou-type"],
    cases.EVALUATE_VOC: ["--annotations", "--detections", "--iou", "--out", "--plots", "--class-names"],
    cases.ESTIMATE: ["--run", "--dataset", "--split", "--object-id", "--out", "--min-visible", "--targets-out"],
}
ARITY = {"--intrinsics": 4, "--objects-per-image": 2, "--distance": 2, "--elevation-degrees": 2, "--light-count": 2}


def flag_case(world: cases.World, rng: random.Random, number: int):
    base = rng.choice(list(FLAGS))
    flag = rng.choice(FLAGS[base])
    pool = HOSTILE_OUTPUT_VALUES if flag in OUTPUT_FLAGS else HOSTILE_FLAG_VALUES
    values = [rng.choice(pool) for _ in range(ARITY.get(flag, 1))]
    if flag == "--workers" and base is cases.GENERATE:
        values = [rng.choice(["0", "-1", "abc", "nan"])]  # valid worker counts only cost time here
    argv = cases.replace_flag(base, flag, *values)
    return cases.Case(f"fuzz-{number}-flag-{argv[0]}-{flag}={'|'.join(values)!r}", argv)


def _output_setups():
    def folder(world, case):
        (case / "out").mkdir(parents=True, exist_ok=True)
        (case / "out" / "scores.json").mkdir()

    def symlink(world, case):
        (case / "out").mkdir(parents=True, exist_ok=True)
        os.symlink(world.results, case / "out" / "scores.json")

    def fifo(world, case):
        (case / "out").mkdir(parents=True, exist_ok=True)
        os.mkfifo(case / "out" / "scores.json")

    def under_file(world, case):
        (case / "out").write_text("a file")

    def dangling(world, case):
        (case / "out").mkdir(parents=True, exist_ok=True)
        os.symlink(case / "nowhere", case / "out" / "scores.json")

    return {"folder": folder, "symlink": symlink, "fifo": fifo, "under-file": under_file, "dangling": dangling}


OUTPUT_SETUPS = _output_setups()


def path_case(world: cases.World, rng: random.Random, number: int):
    name = rng.choice(sorted(OUTPUT_SETUPS) + ["generate-link", "device", "input"])
    if name == "input":  # an output path that is also an input: refused before anything is written
        base, flag, value = rng.choice([(cases.EVALUATE_WORLD_BOP, "--out", "{world}/results.csv"),
                                        (cases.EVALUATE_WORLD_BOP, "--errors", "{world}/results.csv"),
                                        (cases.EVALUATE_COCO, "--out", "{world}/coco_gt.json"),
                                        (cases.EVALUATE_COCO, "--out", "{world}/coco_results.json")])
        return cases.Case(f"fuzz-{number}-path-{flag}-is-an-input", cases.replace_flag(base, flag, value))
    if name == "generate-link":
        def setup(w, case):
            (case / "out" / "test").mkdir(parents=True)
            (case / "elsewhere").mkdir()
            os.symlink(case / "elsewhere", case / "out" / "test" / rng.choice(["000000", "rgb", "x"]))
        return cases.Case(f"fuzz-{number}-path-generate-link", cases.GENERATE, setup)
    base = rng.choice([cases.EVALUATE_WORLD_BOP, cases.EVALUATE_COCO, cases.EVALUATE_VOC])
    flag = rng.choice(["--out"] + (["--errors"] if base is cases.EVALUATE_WORLD_BOP else []))
    if name == "device":
        return cases.Case(f"fuzz-{number}-path-{flag}-device", cases.replace_flag(base, flag, "/dev/full"))
    return cases.Case(f"fuzz-{number}-path-{flag}-{name}", cases.replace_flag(base, flag, "{out}/scores.json"),
                      OUTPUT_SETUPS[name])


RUN_FILES = {"aae": ["config.json", "codebook.npz", "object.npz"], "keypointnet": ["config.json", "keypoints.json",
                                                                                 "object.json"]}


def run_case(world: cases.World, rng: random.Random, number: int):
    """A run directory with one file mutated (JSON values or bytes), given to ``paz6d estimate``."""
    method = rng.choice(sorted(RUN_FILES))
    name = rng.choice(RUN_FILES[method])
    source = getattr(world, f"{method}_run")
    if name.endswith(".json") and rng.random() < 0.7:
        data, what = mutate_json(json.loads((source / name).read_text()), rng)
        content = _dumps(data).encode()
    else:
        content, what = mutate_bytes((source / name).read_bytes(), rng)

    def setup(w, folder):
        shutil.copytree(source, folder / "run")
        cases.put(folder / "run" / name, content)

    argv = cases.replace_flag(cases.ESTIMATE, "--run", "{case}/run")
    if method == "keypointnet":
        argv = cases.replace_flag(argv, "--method", "keypoints")
    return cases.Case(f"fuzz-{number}-run-{method}-{name}-{what}", argv, setup)


def detector_case(world: cases.World, rng: random.Random, number: int):
    """An SSD run directory whose ``detector.json`` has one value mutated, given to ``paz6d detect``."""
    detector, what = mutate_json(cases.SSD_DETECTOR, rng)
    valid = cases._ssd_run(lambda data: None)

    def setup(w, folder):
        valid(w, folder)
        (folder / "ssd" / "detector.json").write_text(_dumps(detector))

    return cases.Case(f"fuzz-{number}-detector-{what}", cases.DETECT, setup)


TRAINER_FILES = ("checkpoint.json", "log.csv", f"{cases.CHECKPOINT}/optimizer.npz")  # what a resume reads


def trainer_case(world: cases.World, rng: random.Random, number: int):
    """A killed AAE training's checkpoint pointer, log or optimizer file with its JSON values or its
    bytes mutated (by a generator seeded now, so the case is the same each run), then resumed."""
    relative = rng.choice(TRAINER_FILES)
    as_json = relative.endswith(".json") and rng.random() < 0.7
    state = random.Random(rng.getrandbits(32))
    killed = cases._resumed_aae_run("checkpoint.json", lambda pointer: pointer)  # as the killed run left it

    def setup(w, folder):
        killed(w, folder)
        path = folder / "run" / relative
        if as_json:
            path.write_text(_dumps(mutate_json(json.loads(path.read_text()), state)[0]))
        else:
            path.write_bytes(mutate_bytes(path.read_bytes(), state)[0])

    argv = cases.replace_flag(cases.TRAIN_AAE, "--out", "{case}/run")
    what = "json" if as_json else "bytes"
    return cases.Case(f"fuzz-{number}-trainer-{relative.rsplit('/', 1)[-1]}-{what}", argv, setup)


def output_case(world: cases.World, rng: random.Random, number: int):
    """An output flag aimed at one of the call's own inputs, or an output folder of another kind."""
    ssd_run = {f"ssd/{name}": content for name, content in cases.FOREIGN_RUNS["ssd"].items()}
    image = {"images/a.png": cases.FOREIGN_RUNS["ssd"]["model.keras"]}
    scene = "bop/test/000000/"
    choice = rng.choice(["detect", "detect-bop", "estimate", "train", "benchmark"])
    if choice in ("detect", "detect-bop"):
        base = cases.DETECT if choice == "detect" else cases.DETECT_BOP
        targets = ["{case}/ssd/model.keras", "{case}/ssd/detector.json"] + (
            ["{case}/images/a.png"] if choice == "detect" else
            ["{case}/" + scene + name for name in ("scene_gt.json", "scene_camera.json", "scene_gt_info.json",
                                                    "rgb/000000.png", "depth/000000.png")] + ["{case}/bop/camera.json"])
        flag = "--out" if choice == "detect" else rng.choice(["--out", "--ground-truth"])
        argv = cases.replace_flag(base, flag, rng.choice(targets))
        setup = cases.files_setup({**ssd_run, **(image if choice == "detect" else {})},
                                  copy_dataset=choice == "detect-bop")
    elif choice == "estimate":
        targets = ["{world}/" + scene + name for name in ("scene_gt.json", "scene_camera.json", "scene_gt_info.json",
                                                           "rgb/000000.png")]
        targets += ["{world}/runs/aae/" + name for name in ("config.json", "codebook.npz", "object.npz", "model.keras")]
        targets += ["{world}/bop/models/models_info.json", "{world}/bop/test_targets_bop19.json"]
        argv = cases.replace_flag(cases.ESTIMATE, rng.choice(["--out", "--targets-out"]), rng.choice(targets))
        setup = None
    else:
        method = rng.choice(sorted(cases.TRAINERS)) if choice == "train" else "benchmark lmo"
        base = cases.TRAINERS[method] if choice == "train" else cases.BENCHMARK_LMO + ("--lmo", "{world}/bop")
        others = [name for name in ("aae", "keypointnet") if name != method]
        targets = ["{world}/bop", "{world}/bop/test", "{world}/bop/test/000000", "{case}/link", "{case}/foreign"]
        targets += ["{world}/runs/" + name for name in others]
        owner = rng.choice([name for name in cases.FOREIGN_RUNS if name != method])
        setup = cases.files_setup({f"foreign/{name}": content for name, content in cases.FOREIGN_RUNS[owner].items()})
        target = rng.choice(targets)
        if target == "{case}/link":
            setup = cases._symlink(rng.choice(["{world}/runs", "{world}/bop", "{case}"]), "link")
        argv = cases.replace_flag(base, "--out", target)
    target = argv[argv.index("--out") + 1] if "--out" in argv else ""
    return cases.Case(f"fuzz-{number}-output-{' '.join(argv[:2])}-{target}", argv, setup)


#: The fixtures of the ``sample`` kind: ``(fixture folder, file to mutate, reader of every sample)``.
SAMPLE_FIXTURES = {
    "voc": ("voc", "VOC2007/Annotations/000001.xml", lambda root: __import__(
        "paz6d.datasets.voc", fromlist=["load"]).load(root / "VOC2007", "train")),
    "voc-image-set": ("voc", "VOC2007/ImageSets/Main/train.txt", lambda root: __import__(
        "paz6d.datasets.voc", fromlist=["load"]).load(root / "VOC2007", "train")),
    "coco": ("coco", "annotations/instances_tiny2017.json", lambda root: __import__(
        "paz6d.datasets.coco", fromlist=["load"]).load(root, "tiny2017", masks=False)),
    "openimages": ("openimages", "validation-annotations-bbox.csv", lambda root: __import__(
        "paz6d.datasets.openimages", fromlist=["load"]).load(root, "validation")),
    "ycb-video": ("ycb_video", "data/0048/000001-box.txt", lambda root: __import__(
        "paz6d.datasets.ycb_video", fromlist=["load"]).load(root, "train", masks=False)),
}
SAMPLE_VALUES = ["-1", "0", "1e9", "-1e6", "1e308", "-1e308", "nan", "inf", "abc", "", "../../../outside",
                 "/etc/passwd", "9" * 30, "1.5", "100000", "-5", "\x00", "0x10"]


def _mutate_text_number(text: str, rng: random.Random) -> tuple[str, str]:
    """One number or word of ``text`` (an XML, CSV or text file) replaced by a hostile value."""
    import re

    tokens = [match for match in re.finditer(r"[^\s<>,/]+", text) if not match.group().startswith(("?", "!"))]
    match = rng.choice(tokens)
    value = rng.choice(SAMPLE_VALUES)
    return text[:match.start()] + value + text[match.end():], f"{match.group()[:12]}->{value[:12]}"


def _sound_samples(samples, root: Path) -> str | None:
    """Why the samples a loader returned are unsound (``None``: sound)."""
    import numpy as np

    from paz6d.backend.image import image_size_from_header

    for sample in samples:
        boxes = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 4)
        if not np.all(np.isfinite(boxes)) or np.any(boxes[:, 2:] < boxes[:, :2]):
            return f"{sample.source}: box {boxes.tolist()} not finite or inverted"
        image = Path(sample.image)
        if root.resolve() not in image.resolve().parents:
            return f"{sample.source}: image {image} outside the data set"
        if image.is_file() and len(boxes):
            width, height = image_size_from_header(image)
            if np.any(boxes[:, 2] < 0) or np.any(boxes[:, 3] < 0) or np.any(boxes[:, 0] > width) \
                    or np.any(boxes[:, 1] > height):
                return f"{sample.source}: box {boxes.tolist()} off the {width} x {height} image"
    return None


def sample_case(world: cases.World, rng: random.Random, number: int):
    """A data-set fixture with one value mutated, read through its loader (a Python API case)."""
    name = rng.choice(sorted(SAMPLE_FIXTURES))
    fixture, relative, read = SAMPLE_FIXTURES[name]
    source = cases.POSE_DATA / fixture / relative
    if relative.endswith(".json"):
        data, what = mutate_json(json.loads(source.read_text()), rng)
        content = _dumps(data).encode()
    else:
        text, what = _mutate_text_number(source.read_text(), rng)
        content = text.encode("utf-8", "surrogatepass")
    return ApiCase(f"fuzz-{number}-sample-{name}-{what}", fixture, relative, content, read)


class ApiCase:
    """A fixture copy with one file replaced by ``content``, read by ``read(root)`` in this process."""

    def __init__(self, name, fixture, relative, content, read):
        self.name, self.fixture, self.relative, self.content, self.read = name, fixture, relative, content, read

    def judge(self, world: cases.World, timeout: float) -> tuple[str, str]:
        import traceback

        folder = world.root / cases.CASES_FOLDER / self.name.replace("/", "_")
        shutil.rmtree(folder, ignore_errors=True)
        root = folder / self.fixture
        shutil.copytree(cases.POSE_DATA / self.fixture, root)
        (root / self.relative).write_bytes(self.content)
        outside = folder.parent / "outside.jpg"
        outside.write_bytes((cases.POSE_DATA / "voc" / "VOC2007" / "JPEGImages" / "000001.jpg").read_bytes())
        started = time.perf_counter()
        try:
            with cases.time_limit(timeout):
                samples = list(self.read(root))
        except cases.CaseTimeout:
            return "hang", f"beyond {timeout:g} s"
        except ValueError as error:
            message = str(error)
            if len(message) > 1100 or not any(mark in message for mark in (str(root), "split", "root")):
                return "unclear", f"message names no file: {message[:300]!r}"
            return "ok", "rejected"
        except Exception:  # noqa: BLE001 - reported as the traceback it is
            return "traceback", traceback.format_exc()[-1500:]
        if time.perf_counter() - started > timeout:
            return "hang", f"took {time.perf_counter() - started:.1f} s"
        wrong = _sound_samples(samples, root)
        return ("silent", wrong) if wrong else ("ok", "accepted")


KINDS = {"json": json_case, "bytes": bytes_case, "csv": csv_case, "flag": flag_case, "path": path_case,
         "run": run_case, "detector": detector_case, "trainer": trainer_case, "output": output_case,
         "sample": sample_case}
WEIGHTS = {"json": 0.2, "bytes": 0.05, "csv": 0.14, "flag": 0.12, "path": 0.05, "run": 0.07, "detector": 0.07,
           "trainer": 0.07, "output": 0.1, "sample": 0.13}


# ------------------------------------------------------------------------------------------------ judging

def _sound_success(case: cases.Case, folder: Path) -> str | None:
    """Why an exit-0 result is wrong (``None``: it is sound)."""
    scores = folder / "out" / "scores.json"
    if case.argv[:2] == ("evaluate", "bop") and scores.is_file():
        summary = json.loads(scores.read_text())
        for key in RECALL_KEYS:
            value = summary.get(key)
            if value is not None and not 0.0 <= value <= 1.0:
                return f"{key} = {value} outside [0, 1]"
    coco = folder / "out" / "coco.json"
    if case.argv[:2] == ("evaluate", "coco") and coco.is_file():
        stats = json.loads(coco.read_text())["stats"]
        if any(not (value == -1 or 0.0 <= value <= 1.0) for value in stats):
            return f"COCO stats {stats} outside [0, 1] (or -1)"
    voc = folder / "out" / "voc.json"
    if case.argv[:2] == ("evaluate", "voc") and voc.is_file():
        value = json.loads(voc.read_text())["mAP"]
        if value is not None and not 0.0 <= value <= 1.0:
            return f"VOC mAP {value} outside [0, 1]"
    return None


def _output_paths(case: cases.Case, world: cases.World, folder: Path) -> list[Path]:
    """The paths the case's output flags name (relative ones from the case's folder, where it runs),
    except the world's input files."""
    found = [folder / "out"]
    for index, part in enumerate(case.argv[:-1]):
        if part in OUTPUT_FLAGS:
            value = case.argv[index + 1].format(world=world.root, case=folder, out=folder / "out")
            path = Path(os.path.normpath(folder / value))
            if not (path.is_file() and world.root / cases.CASES_FOLDER not in path.parents):
                found.append(path)  # a file of the world is an input: changing it counts as touching it
    return found


def judge(world: cases.World, case: cases.Case, timeout: float, strict: bool = False) -> tuple[str, str]:
    """``(kind, detail)``: ``ok``, ``traceback``, ``hang``, ``wrong-code``, ``unclear``, ``silent`` or ``touched``
    (``strict``: the output flags name inputs, so only the case's own ``out`` folder may change)."""
    verdict = cases.run_case(world, cases.Case(case.name, case.argv, case.setup, (), 2, timeout))
    outcome, folder = verdict.outcome, world.root / cases.CASES_FOLDER / case.name
    if verdict.kind in ("traceback", "hang"):
        return verdict.kind, "; ".join(verdict.problems)[-1500:]
    outputs = [folder / "out"] if strict else _output_paths(case, world, folder)
    touched = [path for path in verdict.touched  # an output, inside one, or a folder made to hold one
               if not any(world.root / path == output or output in (world.root / path).parents
                          or (world.root / path) in output.parents for output in outputs)]
    if touched:
        return "touched", f"changed outside the outputs: {touched[:5]}"
    if outcome.code == 0:
        wrong = _sound_success(case, folder)
        return ("silent", wrong) if wrong else ("ok", "accepted")
    if outcome.code != 2:
        return "wrong-code", f"exit {outcome.code}: {outcome.stderr[-300:]!r}"
    lines = [line for line in outcome.stderr.splitlines() if "error:" in line]
    message = lines[-1] if lines else ""
    if not message.startswith("paz6d ") and not message.startswith("usage:"):
        return "unclear", f"no 'paz6d ...: error:' line: {outcome.stderr[-300:]!r}"
    given = [part.format(world=world.root, case=folder, out=folder / "out") for part in case.argv
             if not part.startswith("--")]
    marks = ["--", "/", ".json", ".csv", "argument"] + [str(Path(part)) for part in given if part.strip()]
    if len(message) > 1100 or not any(mark in message for mark in marks):
        return "unclear", f"message names no file or flag: {message[:300]!r}"
    return "ok", "rejected"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=600, help="number of generated cases (default 600)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the mutations (default 0)")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds a case may take (a hang beyond)")
    parser.add_argument("--world", type=Path, help="folder for the world and the cases (default: a temporary one)")
    parser.add_argument("--report", type=Path, help="write every case's verdict to this JSON file")
    parser.add_argument("--kinds", nargs="+", choices=sorted(KINDS), default=None,
                        help="draw only these kinds of case (default: all, weighted)")
    args = parser.parse_args(argv)

    from paz6d.backend.tensorflow_guard import import_tensorflow

    import_tensorflow()  # before any GL context (see tests/conftest.py)
    with tempfile.TemporaryDirectory(prefix="paz6d-fuzz-") as temporary:
        root = args.world or Path(temporary)
        world = cases.build_world(root / "world")
        rng = random.Random(args.seed)
        drawn = {kind: weight for kind, weight in WEIGHTS.items() if args.kinds is None or kind in args.kinds}
        kinds = rng.choices(list(drawn), weights=list(drawn.values()), k=args.cases)
        counts, by_kind, failures, report = collections.Counter(), collections.Counter(), [], []
        started = time.perf_counter()
        for number, kind in enumerate(kinds):
            case = KINDS[kind](world, rng, number)
            name = case.name[:120].replace("/", "_").replace("\x00", "NUL")
            if isinstance(case, ApiCase):
                case.name = name
                verdict, detail = case.judge(world, args.timeout)
            else:
                case = cases.Case(name, case.argv, case.setup)
                verdict, detail = judge(world, case, args.timeout, strict=kind == "output")
            counts[verdict] += 1
            by_kind[(kind, detail if verdict == "ok" else verdict)] += 1
            report.append({"case": case.name, "kind": kind, "verdict": verdict, "detail": detail})
            if verdict != "ok":
                failures.append((case.name, verdict, detail))
                print(f"FAIL {case.name} [{verdict}] {detail[:400]}", flush=True)
        seconds = time.perf_counter() - started
    print(f"\n{args.cases} cases (seed {args.seed}) in {seconds:.0f} s: " +
          ", ".join(f"{name} {count}" for name, count in sorted(counts.items())))
    for (kind, outcome), count in sorted(by_kind.items()):
        print(f"  {kind:6s} {outcome:10s} {count}")
    if args.report is not None:
        args.report.write_text(json.dumps({"seed": args.seed, "cases": args.cases, "counts": dict(counts),
                                           "seconds": round(seconds, 1), "verdicts": report}, indent=1))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
