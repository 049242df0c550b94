"""Bad inputs for every ``paz6d`` command, as data: a tiny world of valid inputs, a table of cases that
spoil one thing each, and a runner that checks what ``paz6d`` did with them.

Used by ``tests/test_bad_inputs.py`` (the table) and ``scripts/fuzz_inputs.py`` (seeded mutations of
the same world). A case passes when ``paz6d.cli.main(argv)`` (in-process)

* returns the expected exit code (2 for bad input; argparse's own errors also exit 2),
* prints a message naming the file or flag (``expect``: substrings of stderr),
* prints no traceback and raises nothing but ``SystemExit``,
* finishes within its time limit (a hang is a failure), and
* touches no file outside the case's own output folder (the world is snapshotted before and after;
  each case runs in its own folder, so relative paths land there).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import stat
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from paz6d import cli

TRACEBACK = "Traceback (most recent call last)"
#: Every case's folder lives under ``<world>/cases/<name>``; its outputs under ``.../out``.
CASES_FOLDER = "cases"


# ------------------------------------------------------------------------------------------------ the world

@dataclass(frozen=True)
class World:
    """Valid inputs of every command, built once (see :func:`build_world`).

    Attributes:
        root: the folder.
        mesh: ``obj_000001.ply``, a 5 x 4 x 3 cm box (metres).
        bop: a generated BOP data set (split ``test``, 2 images 64 x 48, depth, masks, targets).
        results: a BOP results CSV with the ground-truth poses (mm).
        coco_gt, coco_results: COCO ground truth (of ``bop``) and detections.
        voc_annotations, voc_detections: a VOC text-annotation folder and per-image detections.
        aae_run, keypointnet_run: run directories (valid files, untrained stand-in models).
        fer_csv: a FER-2013 style CSV with 14 faces.
    """

    root: Path
    mesh: Path
    bop: Path
    results: Path
    coco_gt: Path
    coco_results: Path
    voc_annotations: Path
    voc_detections: Path
    aae_run: Path
    keypointnet_run: Path
    fer_csv: Path


def _write_results(world_bop: Path, path: Path) -> None:
    gt = json.loads((world_bop / "test" / "000000" / "scene_gt.json").read_text())
    lines = ["scene_id,im_id,obj_id,score,R,t,time"]
    for im_id, instances in gt.items():
        for instance in instances:
            R = " ".join(repr(v) for v in instance["cam_R_m2c"])
            t = " ".join(repr(v) for v in instance["cam_t_m2c"])
            lines.append(f"0,{im_id},{instance['obj_id']},0.9,{R},{t},-1")
    path.write_text("\n".join(lines) + "\n")


def _write_runs(root: Path) -> tuple[Path, Path]:
    from paz6d.aae import run_dir as aae_run
    from paz6d.aae.codebook import Codebook
    from paz6d.aae.run_dir import AAERunDir
    from paz6d.keypointnet import run_dir as keypointnet_run
    from paz6d.keypointnet.run_dir import KeypointNetRunDir

    hull = np.array([[x, y, z] for x in (-0.025, 0.025) for y in (-0.02, 0.02) for z in (-0.015, 0.015)])
    aae = root / "runs" / "aae"
    AAERunDir.write_config(aae, {"crop_size": 16, "padding": 1.2, "latent_size": 8}, root / "obj_000001.ply", 1.0, 0,
                           None)
    aae_run.write_object(aae, hull, hull * 0.9, 0.07, hull)
    Codebook(np.eye(2, 8), np.stack([np.eye(3)] * 2), np.array([[0.0, 0, 10, 10]] * 2),
             np.diag([100.0, 100.0, 1.0]), 0.5).save(aae_run.codebook_path(aae))
    AAERunDir.model_path(aae).write_bytes(b"not a keras model")
    keypoints = root / "runs" / "keypointnet"
    KeypointNetRunDir.write_config(keypoints, {"input_size": 32, "margin": 1.25, "downsample": 2, "mode": "supervised"})
    keypointnet_run.write_keypoints(keypoints, hull, np.ones(8, bool), "farthest-point")
    keypointnet_run.write_object(keypoints, 0.07, hull)
    KeypointNetRunDir.model_path(keypoints).write_bytes(b"not a keras model")
    return aae, keypoints


def build_world(root: Path) -> World:
    """Writes the valid inputs under ``root`` (about 2 s: two 64 x 48 images are rendered)."""
    import trimesh

    from data_gen.config import GenerationConfig
    from data_gen.generator import generate

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    mesh = root / "obj_000001.ply"
    trimesh.creation.box((0.05, 0.04, 0.03)).export(mesh)
    bop = root / "bop"
    generate(GenerationConfig(meshes=(mesh,), out=bop, num_images=2, width=64, height=48, split="test", seed=3,
                              objects_per_image=(2, 2)), show_progress=False)
    results = root / "results.csv"
    _write_results(bop, results)
    coco_gt = root / "coco_gt.json"
    shutil.copy(bop / "test" / "000000" / "scene_gt_coco.json", coco_gt)
    annotations = json.loads(coco_gt.read_text())["annotations"]
    coco_results = root / "coco_results.json"
    coco_results.write_text(json.dumps([{"image_id": a["image_id"], "category_id": a["category_id"],
                                         "bbox": a["bbox"], "score": 0.8} for a in annotations]))
    voc_annotations, voc_detections = root / "voc" / "annotations", root / "voc" / "detections"
    voc_annotations.mkdir(parents=True)
    voc_detections.mkdir(parents=True)
    for name in ("a", "b"):
        (voc_annotations / f"{name}.txt").write_text("box 10 10 30 30\n")
        (voc_detections / f"{name}.txt").write_text("box 0.9 11 10 30 29\n")
    aae_run, keypointnet_run = _write_runs(root)
    fer_csv = root / "fer.csv"
    rng = np.random.default_rng(0)
    rows = [f"{index % 7},{' '.join(str(v) for v in rng.integers(0, 256, 48 * 48))},Training" for index in range(14)]
    fer_csv.write_text("emotion,pixels,Usage\n" + "\n".join(rows) + "\n")
    return World(root, mesh, bop, results, coco_gt, coco_results, voc_annotations, voc_detections, aae_run,
                 keypointnet_run, fer_csv)


# ------------------------------------------------------------------------------------------------ snapshots

def snapshot(root: Path, skip: Path | None = None) -> dict[str, tuple]:
    """``{relative path: (kind, size, mtime_ns, mode)}`` of everything under ``root`` (links not
    followed), leaving out ``skip`` and what is inside it."""
    found = {}
    for folder, folders, files in os.walk(root):
        here = Path(folder)
        if skip is not None and (here == skip or skip in here.parents):
            folders[:] = []
            continue
        for name in folders + files:
            path = here / name
            if skip is not None and path == skip:
                continue
            info = os.lstat(path)
            kind = stat.S_IFMT(info.st_mode)
            found[str(path.relative_to(root))] = (kind, info.st_size if stat.S_ISREG(info.st_mode) else 0,
                                                  info.st_mtime_ns if not stat.S_ISDIR(info.st_mode) else 0,
                                                  stat.S_IMODE(info.st_mode))
    return found


def world_snapshot(world: World, case_folder: Path) -> dict[str, tuple]:
    """:func:`snapshot` of the world's inputs (other cases' folders left out, for speed) and of the
    case's folder except its output folder."""
    found = snapshot(world.root, skip=world.root / CASES_FOLDER)
    found.update({f"{CASES_FOLDER}/{case_folder.name}/{path}": value
                  for path, value in snapshot(case_folder, skip=case_folder / "out").items()})
    return found


def changes(before: dict, after: dict) -> list[str]:
    """Paths created, removed or modified between two snapshots."""
    return sorted(path for path in set(before) | set(after) if before.get(path) != after.get(path))


# ------------------------------------------------------------------------------------------------ running

@dataclass
class Outcome:
    """What one run of ``paz6d`` did."""

    code: int | None
    stdout: str
    stderr: str
    exception: str | None  # formatted traceback of an exception main() let through
    seconds: float


class CaseTimeout(BaseException):
    """Raised by the alarm in a case that runs past its time limit (not an ``Exception``, so no
    ``except Exception`` in paz6d swallows it)."""


def _alarm(signum, frame):
    raise CaseTimeout()


@contextlib.contextmanager
def time_limit(seconds: float):
    """Interrupts the block after ``seconds`` with :class:`CaseTimeout` (main thread only; elsewhere
    the limit is checked afterwards)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run_cli(argv: list[str], timeout: float = 60.0) -> Outcome:
    """``paz6d.cli.main(argv)`` in this process, with stdout/stderr captured; a run longer than
    ``timeout`` seconds is interrupted (``code`` None, ``exception`` "timeout")."""
    out, err = io.StringIO(), io.StringIO()
    code, exception = None, None
    started = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            with time_limit(timeout):
                code = cli.main(argv)
        except CaseTimeout:
            exception = "timeout"
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        except BaseException:  # noqa: BLE001 - a case reports it instead of stopping the run
            exception = traceback.format_exc()
    return Outcome(code, out.getvalue(), err.getvalue(), exception, time.perf_counter() - started)


@dataclass(frozen=True)
class Case:
    """One bad input.

    Attributes:
        name: unique, also the case's folder name.
        argv: the command line; ``{world}``, ``{case}`` and ``{out}`` are replaced by the world's
            folder, the case's folder and its output folder (``{case}/out``, absent at the start).
        setup: writes the case's spoiled inputs into its folder: ``setup(world, case_folder)``.
        expect: substrings the error output must contain (file, field, flag).
        code: expected exit code.
    """

    name: str
    argv: tuple[str, ...]
    setup: Callable[[World, Path], Any] | None = None
    expect: tuple[str, ...] = ()
    code: int = 2
    timeout: float = 20.0


@dataclass
class Verdict:
    """A case's outcome and what was wrong with it (``problems`` empty: passed)."""

    case: Case
    outcome: Outcome
    problems: list[str] = field(default_factory=list)
    kind: str = "ok"  # ok | traceback | hang | wrong-code | silent | unclear | touched
    touched: list[str] = field(default_factory=list)  # paths changed outside the output folder


def run_case(world: World, case: Case) -> Verdict:
    """Sets the case up, runs it and judges it (see the module docstring)."""
    folder = world.root / CASES_FOLDER / case.name
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    out = folder / "out"
    if case.setup is not None:
        case.setup(world, folder)
    argv = [part.format(world=world.root, case=folder, out=out) for part in case.argv]
    before = world_snapshot(world, folder)
    previous = os.getcwd()
    os.chdir(folder)  # relative paths in a case ("", "../..", "abc") land in its own folder
    try:
        outcome = run_cli(argv, case.timeout)
    finally:
        os.chdir(previous)
    after = world_snapshot(world, folder)
    verdict = Verdict(case, outcome)
    text = outcome.stderr
    if outcome.exception == "timeout" or outcome.seconds > case.timeout:
        verdict.kind = "hang"
        verdict.problems.append(f"took {outcome.seconds:.1f} s (limit {case.timeout:g} s)")
    elif outcome.exception is not None or TRACEBACK in text:
        verdict.kind = "traceback"
        verdict.problems.append("traceback: " + (outcome.exception or text)[-2000:])
    elif outcome.code != case.code:
        verdict.kind = "silent" if outcome.code == 0 else "wrong-code"
        verdict.problems.append(f"exit code {outcome.code}, expected {case.code}; stderr: {text[-500:]!r}")
    else:
        missing = [part.format(world=world.root, case=folder, out=out) for part in case.expect]
        missing = [part for part in missing if part not in text + outcome.stdout]
        if missing:
            verdict.kind = "unclear"
            verdict.problems.append(f"message lacks {missing}: {text[-600:]!r}")
        if case.code == 2 and len(text) > 4000:
            verdict.kind = "unclear"
            verdict.problems.append(f"message of {len(text)} characters")
    verdict.touched = changes(before, after)
    if verdict.touched:
        verdict.kind = "touched" if verdict.kind == "ok" else verdict.kind
        verdict.problems.append(f"touched outside --out: {verdict.touched[:5]}")
    return verdict


# ------------------------------------------------------------------------------------------------ spoilers

def copy_bop(world: World, folder: Path) -> Path:
    """A private copy of the world's data set (``<case>/bop``)."""
    target = folder / "bop"
    shutil.copytree(world.bop, target, symlinks=True)
    return target


def put(path: Path, content) -> None:
    """Writes ``content`` at ``path``: bytes/str as is, ``None`` deletes, ``"<dir>"`` makes a folder,
    anything else as JSON."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
    if content is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, str) and content == "<dir>":
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, str):
        path.write_text(content)
    else:
        path.write_text(json.dumps(content))


def bop_file(relative: str, content) -> Callable[[World, Path], None]:
    """Setup: the data set copy with ``relative`` replaced by ``content`` (see :func:`put`); a
    callable ``content`` maps the file's JSON to the new content."""

    def setup(world: World, folder: Path) -> None:
        root = copy_bop(world, folder)
        value = content(json.loads((root / relative).read_text())) if callable(content) else content
        put(root / relative, value)

    return setup


def case_file(name: str, content) -> Callable[[World, Path], None]:
    """Setup: ``<case>/<name>`` holds ``content`` (see :func:`put`)."""

    def setup(world: World, folder: Path) -> None:
        put(folder / name, content)

    return setup


def deep_json(depth: int = 100_000) -> str:
    return "[" * depth + "]" * depth


HUGE_NUMBER = "9" * 5_000_000
NOT_UTF8 = b"\xff\xfe\x00bad \xc3\x28 bytes\n"


# ------------------------------------------------------------------------------------------------ the table

GENERATE = ("generate", "--meshes", "{world}/obj_000001.ply", "--out", "{out}", "--num-images", "1", "--width", "64",
            "--height", "48", "--no-progress")
EVALUATE_BOP = ("evaluate", "bop", "--dataset", "{case}/bop", "--results", "{world}/results.csv",
                "--out", "{out}/scores.json", "--metrics", "mssd,mspd,add", "--no-progress")
EVALUATE_WORLD_BOP = ("evaluate", "bop", "--dataset", "{world}/bop", "--results", "{world}/results.csv",
                      "--out", "{out}/scores.json", "--metrics", "mssd,mspd,add", "--no-progress")
EVALUATE_COCO = ("evaluate", "coco", "--gt", "{world}/coco_gt.json", "--results", "{world}/coco_results.json",
                 "--out", "{out}/coco.json")
EVALUATE_VOC = ("evaluate", "voc", "--annotations", "{world}/voc/annotations", "--detections",
                "{world}/voc/detections", "--out", "{out}/voc.json")
ESTIMATE = ("estimate", "--run", "{world}/runs/aae", "--dataset", "{world}/bop", "--split", "test", "--object-id", "1",
            "--out", "{out}/results.csv")
TRAIN_AAE = ("train", "aae", "--out", "{out}", "--mesh", "{world}/obj_000001.ply", "--no-progress")
TRAIN_AAE_DATASET = ("train", "aae", "--out", "{out}", "--dataset", "{case}/bop", "--split", "test", "--no-progress")
TRAIN_KEYPOINTNET = ("train", "keypointnet", "--out", "{out}", "--mesh", "{world}/obj_000001.ply", "--no-progress")
TRAIN_EMOTION = ("train", "emotion", "--data", "{world}/fer.csv", "--out", "{out}", "--no-progress")
TRAIN_SSD = ("train", "ssd", "--dataset", "{case}/data", "--out", "{out}", "--no-progress")
DEMO = ("demo", "--out", "{out}")
BENCHMARK_LMO = ("benchmark", "lmo", "--out", "{out}", "--quick", "--no-progress")


def replace_flag(argv: tuple[str, ...], flag: str, *values: str) -> tuple[str, ...]:
    """``argv`` with ``flag``'s value(s) replaced (appended when absent; no values: removed)."""
    parts = list(argv)
    if flag in parts:
        start = parts.index(flag)
        stop = start + 1
        while stop < len(parts) and not parts[stop].startswith("--"):
            stop += 1
        del parts[start:stop]
    if values:
        parts += [flag, *values]
    return tuple(parts)


def _flag_cases(prefix: str, base: tuple[str, ...], table: dict[str, list[tuple[tuple[str, ...], str]]],
                setup=None) -> list[Case]:
    """One case per ``(values, expected text)`` of each flag."""
    found = []
    for flag, rows in table.items():
        for index, (values, expect) in enumerate(rows):
            found.append(Case(f"{prefix}{flag.strip('-')}-{index}", replace_flag(base, flag, *values), setup,
                              (expect,) if expect else (flag,)))
    return found


def generate_cases() -> list[Case]:
    flags = {
        "--num-images": [(("0",), ""), (("-3",), ""), (("abc",), ""), (("1.5",), "")],
        "--width": [(("0",), ""), (("-64",), ""), (("100000000",), ""), (("x",), "")],
        "--height": [(("0",), ""), (("1000000000",), ""), ((HUGE_NUMBER,), "characters left out")],
        "--seed": [(("-1",), ""), (("1e3",), "")],
        "--split": [(("../..",), ""), (("a/b",), ""), ((".hidden",), ""), (("",), ""), (("..",), ""),
                    (("a\\b",), ""), (("a\x00b",), "")],
        "--mesh-scale": [(("0",), ""), (("-1",), ""), (("nan",), ""), (("inf",), ""), (("1e300",), "scale")],
        "--intrinsics": [(("nan", "1", "1", "1"), ""), (("0", "100", "32", "24"), ""), (("1", "2"), ""),
                         (("inf", "100", "32", "24"), "")],
        "--objects-per-image": [(("3", "1"), ""), (("0", "1"), ""), (("1", "100000"), "")],
        "--distance": [(("0", "1"), ""), (("2", "1"), ""), (("nan", "1"), ""), (("-1", "1"), ""),
                       (("0.001", "0.002"), "--distance"), (("1", "1e300"), "")],
        "--inplane-degrees": [(("200",), ""), (("nan",), ""), (("-1",), "")],
        "--elevation-degrees": [(("-100", "0"), ""), (("10", "-10"), ""), (("nan", "0"), "")],
        "--distractors": [(("-1",), ""), (("1000000",), "")],
        "--occluder-probability": [(("2",), ""), (("nan",), ""), (("-0.5",), "")],
        "--neutral-distractors": [(("2",), "share in [0, 1]"), (("nan",), "share in [0, 1]")],
        "--object-colored-distractors": [(("2",), "share in [0, 1]"), (("nan",), "share in [0, 1]")],
        "--light-count": [(("-1", "2"), ""), (("2", "1"), ""), (("0", "100000"), "")],
        "--color-jitter": [(("1",), ""), (("nan",), ""), (("-0.1",), "")],
        "--blur-probability": [(("-0.1",), ""), (("inf",), "")],
        "--noise-std": [(("-1",), ""), (("inf",), ""), (("nan",), "")],
        "--depth-scale": [(("0",), ""), (("nan",), ""), (("-0.1",), ""), (("1e-9",), "depth")],
        "--images-per-scene": [(("0",), ""), (("-1",), "")],
        "--crop-size": [(("-1",), ""), (("100000",), "")],
        "--workers": [(("0",), ""), (("-1",), "")],
        "--rotation": [(("bogus",), "")],
        "--rgb-format": [(("gif",), "")],
        "--antialias": [(("always",), "")],
        "--backend": [(("cloud",), "")],
    }
    found = _flag_cases("generate-", GENERATE, flags)
    mesh = "{case}/obj_000002.ply"
    mesh_cases = {
        "missing": (None, "obj_000002.ply"),
        "empty": (b"", "obj_000002.ply"),
        "garbage": (b"ply\nformat binary_little_endian 1.0\nelement vertex 99\nend_header\n\x00\x01", "obj_000002.ply"),
        "text": ("hello\n", "obj_000002.ply"),
        "folder": ("<dir>", "obj_000002.ply"),
        "not-utf8": (NOT_UTF8, "obj_000002.ply"),
        "no-faces": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "end_header\n0 0 0\n1 0 0\n0 1 0\n", "obj_000002.ply"),
        "flat": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                 "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n",
                 "obj_000002.ply"),
        "nan-vertex": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                       "element face 1\nproperty list uchar int vertex_indices\nend_header\nnan 0 0\n1 0 0\n0 1 0\n"
                       "3 0 1 2\n", "obj_000002.ply"),
        "bad-face-index": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                           "0 0 0\n0.05 0 0\n0 0.05 0\n3 0 1 99\n", "obj_000002.ply"),
    }
    found.append(Case("generate-out-symlink-inside", GENERATE,
                      lambda world, folder: (folder.joinpath("out", ".paz6d-generate").mkdir(parents=True),
                                             folder.joinpath("elsewhere").mkdir(),
                                             os.symlink(folder / "elsewhere", folder / "out" / "train")),
                      ("symbolic link",)))
    found.append(Case("generate-out-foreign-folder", replace_flag(GENERATE, "--out", "{world}/voc"), None,
                      ("not the output of paz6d generate",)))
    for name, (content, expect) in mesh_cases.items():
        found.append(Case(f"generate-mesh-{name}", replace_flag(GENERATE, "--meshes", mesh),
                          case_file("obj_000002.ply", content), (expect,)))
    symmetries = {
        "missing": (None, "symmetries"),
        "folder": ("<dir>", "symmetries"),
        "invalid-json": ("{", "sym.json"),
        "list": ([1, 2], "sym.json"),
        "unknown-object": ({"7": {}}, "sym.json"),
        "bad-key": ({"one": {}}, "sym.json"),
        "unknown-field": ({"1": {"colour": 3}}, "sym.json"),
        "not-a-list": ({"1": {"symmetries_discrete": 5}}, "symmetries_discrete"),
        "short-matrix": ({"1": {"symmetries_discrete": [[1, 0, 0, 0]]}}, "symmetries_discrete"),
        "text-matrix": ({"1": {"symmetries_discrete": [["a"] * 16]}}, "symmetries_discrete"),
        "not-rotation": ({"1": {"symmetries_discrete": [[2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]]}},
                         "symmetries_discrete"),
        "nan-matrix": ('{"1": {"symmetries_discrete": [[NaN, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]]}}',
                       "symmetries_discrete"),
        "continuous-no-axis": ({"1": {"symmetries_continuous": [{"offset": [0, 0, 0]}]}}, "symmetries_continuous"),
        "continuous-zero-axis": ({"1": {"symmetries_continuous": [{"axis": [0, 0, 0], "offset": [0, 0, 0]}]}},
                                 "symmetries_continuous"),
        "continuous-string": ({"1": {"symmetries_continuous": "z"}}, "symmetries_continuous"),
        "fields-not-object": ({"1": [1, 2]}, "sym.json"),
        "deep": (deep_json(), "sym.json"),
        "not-utf8": (NOT_UTF8, "sym.json"),
        "huge-number": ('{"1": {"symmetries_discrete": [[' + HUGE_NUMBER + ']]}}', "sym.json"),
    }
    for name, (content, expect) in symmetries.items():
        found.append(Case(f"generate-symmetries-{name}", GENERATE + ("--symmetries", "{case}/sym.json"),
                          case_file("sym.json", content), (expect,)))
    backgrounds = {
        "missing": (None, "backgrounds"),
        "a-file": ("text", "backgrounds"),
        "empty": ("<dir>", "backgrounds"),
    }
    for name, (content, expect) in backgrounds.items():
        found.append(Case(f"generate-backgrounds-{name}", GENERATE + ("--backgrounds", "{case}/bg"),
                          case_file("bg", content), (expect,)))
    found.append(Case("generate-backgrounds-corrupt-png", GENERATE + ("--backgrounds", "{case}/bg"),
                      case_file("bg/a.png", b"\x89PNG\r\n\x1a\nbroken"), ("a.png",)))
    out_cases = {
        "is-a-file": (case_file("out", "x"), "{out}"),
        "under-a-file": (case_file("out", "x"), "{out}"),
        "dev-null": (None, "/dev/null"),
        "state-garbage": (case_file("out/.paz6d-generate/config.json", "{not json"), "config.json"),
        "state-list": (case_file("out/.paz6d-generate/config.json", "[]"), "config.json"),
        "state-not-utf8": (case_file("out/.paz6d-generate/config.json", NOT_UTF8), "config.json"),
        "state-folder": (case_file("out/.paz6d-generate/config.json", "<dir>"), "config.json"),
        "state-other-settings": (case_file("out/.paz6d-generate/config.json", {"seed": 5}), "differ"),
    }
    for name, (setup, expect) in out_cases.items():
        argv = GENERATE
        if name == "under-a-file":
            argv = replace_flag(GENERATE, "--out", "{case}/out/inner")
        elif name == "dev-null":
            argv = replace_flag(GENERATE, "--out", "/dev/null")
        found.append(Case(f"generate-out-{name}", argv, setup, (expect,)))
    return found


def evaluate_bop_cases() -> list[Case]:
    found = []
    scene = "test/000000/"
    R_bad = [2, 0, 0, 0, 1, 0, 0, 0, 1]
    files = {
        "camera-missing": ("camera.json", None, "camera.json"),
        "camera-invalid": ("camera.json", "{", "camera.json"),
        "camera-list": ("camera.json", [], "camera.json"),
        "camera-width-text": ("camera.json", lambda d: {**d, "width": "abc"}, "width"),
        "camera-width-negative": ("camera.json", lambda d: {**d, "width": -640}, "width"),
        "camera-fx-null": ("camera.json", lambda d: {**d, "fx": None}, "fx"),
        "camera-no-height": ("camera.json", lambda d: {k: v for k, v in d.items() if k != "height"}, "height"),
        "camera-deep": ("camera.json", deep_json(), "camera.json"),
        "camera-not-utf8": ("camera.json", NOT_UTF8, "camera.json"),
        "camera-huge-number": ("camera.json", '{"width": ' + HUGE_NUMBER + "}", "camera.json"),
        "camera-folder": ("camera.json", "<dir>", "camera.json"),
        "models-info-missing": ("models/models_info.json", None, "models_info.json"),
        "models-info-invalid": ("models/models_info.json", "[", "models_info.json"),
        "models-info-list": ("models/models_info.json", [1], "models_info.json"),
        "models-info-bad-key": ("models/models_info.json", lambda d: {"x": v for v in d.values()}, "models_info.json"),
        "diameter-text": ("models/models_info.json", lambda d: {k: {**v, "diameter": "big"} for k, v in d.items()},
                          "diameter"),
        "diameter-negative": ("models/models_info.json", lambda d: {k: {**v, "diameter": -3} for k, v in d.items()},
                              "diameter"),
        "diameter-zero": ("models/models_info.json", lambda d: {k: {**v, "diameter": 0} for k, v in d.items()},
                          "diameter"),
        "diameter-missing": ("models/models_info.json", lambda d: {k: {} for k in d}, "diameter"),
        "symmetry-malformed": ("models/models_info.json",
                               lambda d: {k: {**v, "symmetries_discrete": [[1, 2]]} for k, v in d.items()},
                               "symmetries_discrete"),
        "symmetry-not-list": ("models/models_info.json",
                              lambda d: {k: {**v, "symmetries_continuous": 3} for k, v in d.items()},
                              "symmetries_continuous"),
        "symmetry-zero-axis": ("models/models_info.json",
                               lambda d: {k: {**v, "symmetries_continuous": [{"axis": [0, 0, 0], "offset": [0, 0, 0]}]}
                                          for k, v in d.items()}, "axis"),
        "models-info-entry-list": ("models/models_info.json", lambda d: {k: [] for k in d}, "models_info.json"),
        "scene-gt-missing": (scene + "scene_gt.json", None, "scene_gt.json"),
        "scene-gt-invalid": (scene + "scene_gt.json", "{]", "scene_gt.json"),
        "scene-gt-entries-dict": (scene + "scene_gt.json", lambda d: {k: {} for k in d}, "scene_gt.json"),
        "scene-gt-entry-list": (scene + "scene_gt.json", lambda d: {k: [[1]] for k in d}, "scene_gt.json"),
        "scene-gt-no-R": (scene + "scene_gt.json",
                          lambda d: {k: [{kk: vv for kk, vv in e.items() if kk != "cam_R_m2c"} for e in v]
                                     for k, v in d.items()}, "cam_R_m2c"),
        "scene-gt-R-not-rotation": (scene + "scene_gt.json",
                                    lambda d: {k: [{**e, "cam_R_m2c": R_bad} for e in v] for k, v in d.items()},
                                    "cam_R_m2c"),
        "scene-gt-R-text": (scene + "scene_gt.json",
                            lambda d: {k: [{**e, "cam_R_m2c": "identity"} for e in v] for k, v in d.items()},
                            "cam_R_m2c"),
        "scene-gt-t-short": (scene + "scene_gt.json",
                             lambda d: {k: [{**e, "cam_t_m2c": [1, 2]} for e in v] for k, v in d.items()}, "cam_t_m2c"),
        "scene-gt-obj-text": (scene + "scene_gt.json",
                              lambda d: {k: [{**e, "obj_id": "one"} for e in v] for k, v in d.items()}, "obj_id"),
        "scene-gt-obj-float": (scene + "scene_gt.json",
                               lambda d: {k: [{**e, "obj_id": 1.5} for e in v] for k, v in d.items()}, "obj_id"),
        "scene-gt-obj-null": (scene + "scene_gt.json",
                              lambda d: {k: [{**e, "obj_id": None} for e in v] for k, v in d.items()}, "obj_id"),
        "scene-gt-deep": (scene + "scene_gt.json", deep_json(), "scene_gt.json"),
        "scene-gt-not-utf8": (scene + "scene_gt.json", NOT_UTF8, "scene_gt.json"),
        "scene-gt-folder": (scene + "scene_gt.json", "<dir>", "scene_gt.json"),
        "scene-gt-negative-key": (scene + "scene_gt.json", lambda d: {"-1": v for v in d.values()}, "scene_gt.json"),
        "scene-camera-missing": (scene + "scene_camera.json", None, "scene_camera.json"),
        "scene-camera-K-short": (scene + "scene_camera.json", lambda d: {k: {**v, "cam_K": [1, 2, 3]}
                                                                         for k, v in d.items()}, "cam_K"),
        "scene-camera-depth-scale": (scene + "scene_camera.json", lambda d: {k: {**v, "depth_scale": -1}
                                                                             for k, v in d.items()}, "depth_scale"),
        "scene-camera-depth-scale-text": (scene + "scene_camera.json",
                                          lambda d: {k: {**v, "depth_scale": "x"} for k, v in d.items()},
                                          "depth_scale"),
        "scene-camera-entry-list": (scene + "scene_camera.json", lambda d: {k: [] for k in d}, "scene_camera.json"),
        "scene-camera-K-zero-focal": (scene + "scene_camera.json", lambda d: {k: {**v, "cam_K": [0] * 9}
                                                                              for k, v in d.items()}, "cam_K"),
        "scene-camera-one-image": (scene + "scene_camera.json", lambda d: dict(list(d.items())[:1]),
                                   "scene_camera.json"),
        "gt-info-missing": (scene + "scene_gt_info.json", None, "scene_gt_info.json"),
        "gt-info-short": (scene + "scene_gt_info.json", lambda d: {k: v[:1] for k, v in d.items()},
                          "scene_gt_info.json"),
        "gt-info-visib-text": (scene + "scene_gt_info.json",
                               lambda d: {k: [{**e, "visib_fract": "most"} for e in v] for k, v in d.items()},
                               "visib_fract"),
        "gt-info-visib-large": (scene + "scene_gt_info.json",
                                lambda d: {k: [{**e, "visib_fract": 7} for e in v] for k, v in d.items()},
                                "visib_fract"),
        "gt-info-entries-dict": (scene + "scene_gt_info.json", lambda d: {k: {"a": 1} for k in d},
                                 "scene_gt_info.json"),
        "gt-info-entry-number": (scene + "scene_gt_info.json", lambda d: {k: [1, 2] for k in d},
                                 "scene_gt_info.json"),
        "targets-missing": ("test_targets_bop19.json", None, "test_targets_bop19.json"),
        "targets-object": ("test_targets_bop19.json", {}, "test_targets_bop19.json"),
        "targets-duplicated": ("test_targets_bop19.json", lambda d: d + d[:1], "repeats"),
        "targets-negative": ("test_targets_bop19.json", lambda d: [{**d[0], "im_id": -1}] + d[1:], "im_id"),
        "targets-zero-count": ("test_targets_bop19.json", lambda d: [{**d[0], "inst_count": 0}] + d[1:], "inst_count"),
        "targets-float": ("test_targets_bop19.json", lambda d: [{**d[0], "obj_id": 1.0}] + d[1:], "obj_id"),
        "targets-unknown-object": ("test_targets_bop19.json", lambda d: [{**d[0], "obj_id": 9}] + d[1:], "object 9"),
        "targets-unknown-image": ("test_targets_bop19.json", lambda d: [{**d[0], "im_id": 77}] + d[1:], "image 77"),
        "targets-unknown-scene": ("test_targets_bop19.json", lambda d: [{**d[0], "scene_id": 5}] + d[1:], "000005"),
        "targets-empty": ("test_targets_bop19.json", [], "test_targets_bop19.json"),
        "targets-entry-text": ("test_targets_bop19.json", ["a"], "test_targets_bop19.json"),
        "targets-count-too-high": ("test_targets_bop19.json", lambda d: [{**d[0], "inst_count": 50}] + d[1:],
                                   "inst_count"),
        "targets-huge-id": ("test_targets_bop19.json", '[{"scene_id": ' + HUGE_NUMBER + "}]",
                            "test_targets_bop19.json"),
        "model-ply-garbage": ("models/obj_000001.ply", b"ply\ngarbage", "obj_000001.ply"),
        "model-ply-missing": ("models/obj_000001.ply", None, "obj_000001.ply"),
        "split-folder-missing": ("test", None, "test"),
        "scene-folder-file": ("test/000000", "x", "000000"),
    }
    for name, (relative, content, expect) in files.items():
        found.append(Case(f"evaluate-bop-{name}", EVALUATE_BOP, bop_file(relative, content), (expect,)))
    header = "scene_id,im_id,obj_id,score,R,t,time\n"
    identity, t = "1 0 0 0 1 0 0 0 1", "0 0 500"
    rows = {
        "missing": (None, "res.csv"),
        "folder": ("<dir>", "res.csv"),
        "empty": ("", "res.csv"),
        "wrong-header": ("a,b,c\n", "header"),
        "not-utf8": (NOT_UTF8, "res.csv"),
        "not-utf8-row": (header.encode() + NOT_UTF8, "res.csv"),
        "nul-byte": (header + "0,0,1,1,\x00,0,0\n", "res.csv"),
        "few-fields": (header + "0,0,1\n", "res.csv:2"),
        "many-fields": (header + f"0,0,1,1,{identity},{t},-1,9\n", "res.csv:2"),
        "text-id": (header + f"zero,0,1,1,{identity},{t},-1\n", "scene_id"),
        "negative-id": (header + f"0,-1,1,1,{identity},{t},-1\n", "im_id"),
        "float-id": (header + f"0,0,1.0,1,{identity},{t},-1\n", "obj_id"),
        "nan-score": (header + f"0,0,1,nan,{identity},{t},-1\n", "score"),
        "inf-t": (header + f"0,0,1,1,{identity},0 0 inf,-1\n", "'t'"),
        "short-R": (header + f"0,0,1,1,1 0 0,{t},-1\n", "'R'"),
        "scaled-R": (header + f"0,0,1,1,2 0 0 0 2 0 0 0 2,{t},-1\n", "'R'"),
        "reflection-R": (header + f"0,0,1,1,-1 0 0 0 1 0 0 0 1,{t},-1\n", "'R'"),
        "text-R": (header + f"0,0,1,1,a b c d e f g h i,{t},-1\n", "'R'"),
        "unknown-object": (header + f"0,0,9,1,{identity},{t},-1\n", "object id 9"),
        "unknown-image": (header + f"0,99,1,1,{identity},{t},-1\n", "image 99"),
        "unknown-scene": (header + f"4,0,1,1,{identity},{t},-1\n", "scene 4"),
        "huge-number": (header + f"0,0,1,{HUGE_NUMBER},{identity},{t},-1\n", "res.csv"),
        "huge-id": (header + f"0,{HUGE_NUMBER},1,1,{identity},{t},-1\n", "res.csv"),
        "unterminated-quote": (header + '0,0,1,1,"1 0 0 0 1 0 0 0 1\n', "res.csv"),
        "binary": (bytes(range(256)) * 10, "res.csv"),
        "nan-time": (header + f"0,0,1,1,{identity},{t},nan\n", "time"),
        "header-spaces-only": ("   \n", "header"),
        "huge-field": (header + "0,0,1,1," + "1 " * 200_000 + f",{t},-1\n", "res.csv"),
    }
    base = replace_flag(EVALUATE_WORLD_BOP, "--results", "{case}/res.csv")
    for name, (content, expect) in rows.items():
        found.append(Case(f"evaluate-bop-results-{name}", base, case_file("res.csv", content), (expect,)))
    found.append(Case("evaluate-bop-results-header-only", base, case_file("res.csv", header),
                      ("no estimates",), code=0))
    found.append(Case("evaluate-bop-results-all-skipped", base + ("--skip-invalid",),
                      case_file("res.csv", header + f"0,0,9,1,{identity},{t},-1\n"), ("no estimates",), code=0))
    flags = {
        "--split": [(("../..",), ""), (("..",), ""), (("test/../..",), ""), (("/etc",), ""), (("nope",), "nope"),
                    (("",), "")],
        "--metrics": [(("vsd,bogus",), ""), ((",",), "")],
        "--visib-gt-min": [(("2",), ""), (("nan",), ""), (("-0.5",), "")],
        "--vsd-delta": [(("nan",), ""), (("-1",), ""), (("0",), ""), (("inf",), "")],
        "--workers": [(("0",), ""), (("-2",), ""), (("x",), "")],
        "--dataset": [(("{case}/none",), "none"), (("{world}/results.csv",), "results.csv")],
        "--targets": [(("{case}/none.json",), "none.json"), (("{world}/bop",), "bop")],
        "--out": [(("{world}/bop",), "bop"), (("/dev/null",), "/dev/null"),
                  (("{world}/results.csv/x.json",), "results.csv")],
        "--errors": [(("{world}/bop",), "bop")],
        "--plots": [(("{world}/results.csv",), "results.csv")],
    }
    found += _flag_cases("evaluate-bop-flag-", EVALUATE_WORLD_BOP, flags)
    found.append(Case("evaluate-bop-out-is-results", replace_flag(EVALUATE_WORLD_BOP, "--out", "{world}/results.csv"),
                      None, ("is also --results",)))
    found.append(Case("evaluate-bop-errors-is-out", EVALUATE_WORLD_BOP + ("--errors", "{out}/scores.json"), None,
                      ("--errors", "is also --out")))
    found.append(Case("evaluate-bop-out-is-targets",
                      replace_flag(EVALUATE_WORLD_BOP, "--out", "{case}/t.json") + ("--targets", "{case}/t.json"),
                      lambda world, folder: shutil.copy(world.bop / "test_targets_bop19.json", folder / "t.json"),
                      ("is also --targets",)))
    found.append(Case("evaluate-bop-out-symlink", replace_flag(EVALUATE_WORLD_BOP, "--out", "{case}/link.json"),
                      lambda world, folder: os.symlink(world.results, folder / "link.json"), ("link.json",)))
    found.append(Case("evaluate-bop-out-fifo", replace_flag(EVALUATE_WORLD_BOP, "--out", "{case}/fifo"),
                      lambda world, folder: os.mkfifo(folder / "fifo"), ("fifo",)))
    found.append(Case("evaluate-bop-vsd-depth-garbage", replace_flag(EVALUATE_BOP, "--metrics", "vsd"),
                      bop_file("test/000000/depth/000000.png", b"garbage"), ("000000.png",)))
    found.append(Case("evaluate-bop-vsd-depth-wrong-size", replace_flag(EVALUATE_BOP, "--metrics", "vsd"),
                      bop_file("test/000000/depth/000000.png",
                               bytes(__import__("cv2").imencode(".png", np.zeros((5, 7), np.uint16))[1])),
                      ("000000.png",)))
    found.append(Case("evaluate-bop-vsd-without-depth", replace_flag(EVALUATE_BOP, "--metrics", "vsd"),
                      bop_file("test/000000/depth", None), ("depth",)))
    return found


def evaluate_coco_cases() -> list[Case]:
    annotations = lambda world: json.loads(world.coco_gt.read_text())  # noqa: E731
    found = []
    gt_cases = {
        "missing": (None, "gt.json"),
        "invalid": ("{", "gt.json"),
        "list": ([], "gt.json"),
        "deep": (deep_json(), "gt.json"),
        "not-utf8": (NOT_UTF8, "gt.json"),
        "folder": ("<dir>", "gt.json"),
        "images-not-list": ({"images": 3, "annotations": [], "categories": []}, "images"),
        "image-no-id": ({"images": [{}], "annotations": [], "categories": []}, "images"),
        "bbox-short": (lambda d: {**d, "annotations": [{**a, "bbox": [1, 2]} for a in d["annotations"]]}, "gt.json"),
        "bbox-text": (lambda d: {**d, "annotations": [{**a, "bbox": "box"} for a in d["annotations"]]}, "gt.json"),
        "annotation-no-image": (lambda d: {**d, "annotations": [{**a, "image_id": 999} for a in d["annotations"]]},
                                "gt.json"),
        "category-text-id": (lambda d: {**d, "categories": [{"id": "a", "name": "x"}]}, "categories"),
        "huge-number": ('{"images": [{"id": ' + HUGE_NUMBER + '}], "annotations": [], "categories": []}', "gt.json"),
    }
    for name, (content, expect) in gt_cases.items():
        def setup(world, folder, content=content):
            put(folder / "gt.json", content(annotations(world)) if callable(content) else content)
        # pycocotools drops annotations of unknown images and ignores unknown categories: same numbers here
        code = 0 if name == "annotation-no-image" else 2
        found.append(Case(f"evaluate-coco-gt-{name}", replace_flag(EVALUATE_COCO, "--gt", "{case}/gt.json"), setup,
                          (expect,) if code else (), code=code))
    result_cases = {
        "missing": (None, "res.json"),
        "object": ({}, "res.json"),
        "entry-text": (["x"], "res.json"),
        "bbox-short": ([{"image_id": 0, "category_id": 1, "bbox": [1], "score": 1}], "res.json"),
        "score-nan": ('[{"image_id": 0, "category_id": 1, "bbox": [1, 2, 3, 4], "score": NaN}]', "res.json"),
        "score-text": ([{"image_id": 0, "category_id": 1, "bbox": [1, 2, 3, 4], "score": "high"}], "res.json"),
        "unknown-image": ([{"image_id": 77, "category_id": 1, "bbox": [1, 2, 3, 4], "score": 1}], "res.json"),
        "unknown-category": ([{"image_id": 0, "category_id": 42, "bbox": [1, 2, 3, 4], "score": 1}], "res.json"),
        "deep": (deep_json(), "res.json"),
        "not-utf8": (NOT_UTF8, "res.json"),
        "huge-box": ([{"image_id": 0, "category_id": 1, "bbox": [1e308, 1e308, 1e308, 1e308], "score": 1}],
                     "res.json"),
        "segm-without-segmentation": ([{"image_id": 0, "category_id": 1, "bbox": [1, 2, 3, 4], "score": 1}],
                                      "segmentation"),
    }
    for name, (content, expect) in result_cases.items():
        argv = replace_flag(EVALUATE_COCO, "--results", "{case}/res.json")
        if name == "segm-without-segmentation":
            argv += ("--iou-type", "segm")
        code = 0 if name == "unknown-category" else 2
        found.append(Case(f"evaluate-coco-results-{name}", argv, case_file("res.json", content),
                          (expect,) if code else (), code=code))
    found += _flag_cases("evaluate-coco-flag-", EVALUATE_COCO, {
        "--out": [(("{world}/bop",), "bop"), (("/dev/null",), "/dev/null")],
        "--plots": [(("{world}/results.csv",), "results.csv")],
        "--iou-type": [(("mask",), "")],
    })
    found.append(Case("evaluate-coco-out-is-gt", replace_flag(EVALUATE_COCO, "--out", "{world}/coco_gt.json"), None,
                      ("is also --gt",)))
    found.append(Case("evaluate-coco-out-under-file",
                      replace_flag(EVALUATE_COCO, "--out", "{world}/results.csv/x.json"), None, ("results.csv",)))
    found.append(Case("evaluate-coco-out-fifo", replace_flag(EVALUATE_COCO, "--out", "{case}/fifo"),
                      lambda world, folder: os.mkfifo(folder / "fifo"), ("fifo",)))
    return found + evaluate_coco_silent_cases()


def evaluate_coco_silent_cases() -> list[Case]:
    """COCO ground truth and results that pycocotools would score without a word (negative sizes,
    overflowing boxes, duplicate or boolean ids, duplicate category names): refused naming the entry."""

    def first_annotation(**fields):
        return lambda d: {**d, "annotations": [{**d["annotations"][0], **fields}, *d["annotations"][1:]]}

    def extra_category(**fields):
        return lambda d: {**d, "categories": d["categories"] + [{**d["categories"][0], **fields}]}

    gt = {
        "bbox-negative-width": (first_annotation(bbox=[1, 2, -5, 4]), "annotations[0].bbox"),
        "bbox-overflow": (first_annotation(bbox=[1e308, 2, 1e308, 4]), "annotations[0].bbox"),
        "image-id-boolean": (first_annotation(image_id=True), "annotations[0].image_id"),
        "category-id-duplicate": (extra_category(name="other"), ".id"),
        "category-name-duplicate": (extra_category(id=999), ".name"),
        "image-id-duplicate": (lambda d: {**d, "images": d["images"] + [d["images"][0]]}, ".id"),
    }
    found = []
    for name, (content, expect) in gt.items():
        def setup(world, folder, content=content):
            put(folder / "gt.json", content(json.loads(world.coco_gt.read_text())))
        found.append(Case(f"evaluate-coco-gt-{name}", replace_flag(EVALUATE_COCO, "--gt", "{case}/gt.json"), setup,
                          ("gt.json", expect)))
    results = {"bbox-negative-height": [1, 2, 5, -4], "bbox-overflow": [1, -1e308, 5, -1e308]}
    for name, box in results.items():
        def setup(world, folder, box=box):
            entries = json.loads(world.coco_results.read_text())
            put(folder / "res.json", [{**entries[0], "bbox": box}, *entries[1:]])
        found.append(Case(f"evaluate-coco-results-{name}", replace_flag(EVALUATE_COCO, "--results", "{case}/res.json"),
                          setup, ("res.json", "entry [0].bbox")))
    return found


def evaluate_voc_cases() -> list[Case]:
    found = []
    cases = {
        "annotations-missing": ("--annotations", "{case}/none", None, "none"),
        "annotations-file": ("--annotations", "{world}/results.csv", None, "results.csv"),
        "annotation-bad-line": ("--annotations", "{case}/ann", ("ann/a.txt", "box ten 10 30 30\n"), "a.txt"),
        "annotation-short-line": ("--annotations", "{case}/ann", ("ann/a.txt", "box 10\n"), "a.txt"),
        "annotation-bad-xml": ("--annotations", "{case}/ann", ("ann/a.xml", "<annotation><object>"), "a.xml"),
        "annotation-xml-no-box": ("--annotations", "{case}/ann",
                                  ("ann/a.xml", "<annotation><object><name>x</name></object></annotation>"), "a.xml"),
        "annotation-not-utf8": ("--annotations", "{case}/ann", ("ann/a.txt", NOT_UTF8), "a.txt"),
        "annotation-nan-box": ("--annotations", "{case}/ann", ("ann/a.txt", "box nan 10 30 30\n"), "a.txt"),
        "annotation-xml-deep": ("--annotations", "{case}/ann", ("ann/a.xml", "<a>" * 100_000 + "</a>" * 100_000),
                                "a.xml"),  # well-formed, but its root is <a>, not a VOC <annotation>
        "detections-missing": ("--detections", "{case}/none", None, "none"),
        "detection-bad-score": ("--detections", "{case}/det", ("det/a.txt", "box high 1 2 3 4\n"), "a.txt"),
        "detection-short": ("--detections", "{case}/det", ("det/a.txt", "box 0.5 1 2\n"), "a.txt"),
        "detection-nan-score": ("--detections", "{case}/det", ("det/a.txt", "box nan 1 2 3 4\n"), "a.txt"),
        "detection-not-utf8": ("--detections", "{case}/det", ("det/a.txt", NOT_UTF8), "a.txt"),
        "detection-unknown-image": ("--detections", "{case}/det", ("det/zzz.txt", "box 0.5 1 2 3 4\n"), "zzz"),
        "class-names-missing": ("--class-names", "{case}/names.txt", None, "names.txt"),
        "class-names-not-utf8": ("--class-names", "{case}/names.txt", ("names.txt", NOT_UTF8), "names.txt"),
    }
    for name, (flag, value, file, expect) in cases.items():
        setup = None if file is None else case_file(*file)
        found.append(Case(f"evaluate-voc-{name}", replace_flag(EVALUATE_VOC, flag, value), setup, (expect,)))
    found += _flag_cases("evaluate-voc-flag-", EVALUATE_VOC, {
        "--iou": [(("0",), ""), (("2",), ""), (("nan",), "")],
        "--out": [(("{world}/voc",), "voc")],
        "--plots": [(("{world}/results.csv",), "results.csv")],
    })
    found.append(Case("evaluate-voc-out-symlink", replace_flag(EVALUATE_VOC, "--out", "{case}/link.json"),
                      lambda world, folder: os.symlink(world.results, folder / "link.json"), ("link.json",)))
    return found


def estimate_cases() -> list[Case]:
    found = _flag_cases("estimate-", ESTIMATE, {
        "--run": [(("{case}/none",), "none"), (("{world}/results.csv",), "results.csv"), (("{world}/bop",), "bop")],
        "--dataset": [(("{case}/none",), "none"), (("{world}/results.csv",), "results.csv")],
        "--split": [(("../..",), ""), (("nope",), "nope"), (("",), "")],
        "--object-id": [(("7",), "7"), (("-1",), ""), (("0",), "")],
        "--min-visible": [(("2",), ""), (("nan",), ""), (("-1",), "")],
        "--out": [(("{world}/bop",), "bop"), (("/dev/null",), "/dev/null")],
        "--method": [(("keypoints",), "")],
        "--score-threshold": [(("2",), ""), (("nan",), "")],
        "--keypoint-crops": [(("0",), "--keypoint-crops"), (("14",), "--keypoint-crops")],
        "--detector": [(("{case}/none",), "none"), (("{world}/runs/aae",), "aae run directory")],
        "--detections-out": [(("{out}/d.json",), "only with --detector")],
        "--vote-iou": [(("0.5",), "--vote-iou: only with --detector")],
        "--elevation-degrees": [(("50", "10"), "--elevation-degrees"), (("nan", "90"), "--elevation-degrees"),
                                (("-100", "90"), "--elevation-degrees"), (("x", "9"), "")],
        "--inplane-degrees": [(("200",), "--inplane-degrees"), (("-1",), "--inplane-degrees"), (("nan",), "")],
    })
    found.append(Case("estimate-viewpoints-without-aae", replace_flag(replace_flag(
        ESTIMATE, "--run", "{world}/runs/keypointnet"), "--elevation-degrees", "0", "90"), None,
        ("only AAE runs answer from a codebook",)))
    found += _flag_cases("estimate-run-id-", ESTIMATE, {
        "--run": [(("0={world}/runs/aae",), "expected a BOP object id"),
                  (("2={world}/runs/aae",), "trained on object 1, not 2")],
    })
    run_files = {
        "config-garbage": ("config.json", "{", "config.json"),
        "config-list": ("config.json", [], "config.json"),
        "config-missing-keys": ("config.json", {"config": {}}, "config.json"),
        "codebook-truncated": ("codebook.npz", b"PK\x03\x04trunc", "codebook.npz"),
        "codebook-empty": ("codebook.npz", b"", "codebook.npz"),
        "object-truncated": ("object.npz", b"PK\x03\x04", "object.npz"),
        "object-missing": ("object.npz", None, "object.npz"),
        "model-garbage": ("model.keras", b"garbage", "model.keras"),
        "model-folder": ("model.keras", "<dir>", "model.keras"),
        "object-mismatch": ("config.json", lambda d: {**d, "mesh": "/data/models/obj_000005.ply"}, "5"),
        "mesh-number": ("config.json", lambda d: {**d, "mesh": 1.5}, "'mesh'"),
    }
    for name, (relative, content, expect) in run_files.items():
        def setup(world, folder, relative=relative, content=content):
            run = folder / "run"
            shutil.copytree(world.aae_run, run)
            value = content(json.loads((run / relative).read_text())) if callable(content) else content
            put(run / relative, value)
        found.append(Case(f"estimate-run-{name}", replace_flag(ESTIMATE, "--run", "{case}/run"), setup, (expect,)))
    found.append(Case("estimate-keypointnet-keypoints-garbage",
                      replace_flag(replace_flag(ESTIMATE, "--run", "{case}/run"), "--method", "keypoints"),
                      lambda world, folder: (shutil.copytree(world.keypointnet_run, folder / "run"),
                                             put(folder / "run" / "keypoints.json", "{"))[-1], ("keypoints.json",)))
    found.append(Case("estimate-dataset-no-scene-gt", replace_flag(ESTIMATE, "--dataset", "{case}/bop"),
                      bop_file("test/000000/scene_gt.json", None), ("scene_gt.json",)))
    found.append(Case("estimate-targets-out-is-out", ESTIMATE + ("--targets-out", "{out}/results.csv"), None,
                      ("--targets-out", "is also --out")))
    found.append(Case("estimate-dataset-rgb-garbage", replace_flag(ESTIMATE, "--dataset", "{case}/bop"),
                      bop_file("test/000000/rgb/000000.png", b"\x89PNG\r\n\x1a\nbroken"), ("000000.png",)))
    found.append(Case("estimate-dataset-rgb-folder", replace_flag(ESTIMATE, "--dataset", "{case}/bop"),
                      bop_file("test/000000/rgb/000000.png", "<dir>"), ("model.keras",)))  # no image: skipped
    found.append(Case("estimate-dataset-bad-bbox", replace_flag(ESTIMATE, "--dataset", "{case}/bop"),
                      bop_file("test/000000/scene_gt_info.json",
                               lambda d: {k: [{**e, "bbox_obj": [0, 0, -5, "x"]} for e in v] for k, v in d.items()}),
                      ("bbox_obj",)))
    found += [
        Case("estimate-neither-dataset-nor-images", replace_flag(ESTIMATE, "--dataset"), None,
             ("--dataset or --images",)),
        Case("estimate-camera-without-images", ESTIMATE + ("--camera", "{world}/bop/camera.json"), None,
             ("--camera: only with --images",)),
    ]
    return found


#: ``paz6d estimate --images``: the world's RGB folder and camera, a stand-in detector (:func:`detector_stand_in`).
ESTIMATE_IMAGES = ("estimate", "--images", "{world}/bop/test/000000/rgb", "--camera", "{world}/bop/camera.json",
                   "--detector", "{case}/ssd", "--run", "1={world}/runs/aae", "--out", "{out}/results.csv",
                   "--no-progress")


def detector_stand_in(*more: Callable[[World, Path], None]) -> Callable[[World, Path], None]:
    """Setup: ``<case>/ssd``, an SSD run directory of class ``obj_000001`` with valid files (an untrained
    stand-in model), then each of ``more``."""

    def setup(world: World, folder: Path) -> None:
        from paz6d.ssd.run_dir import SSDRunDir, write_detector

        write_detector(folder / "ssd", "light", ["obj_000001"], SSD_DETECTOR["priors"])
        SSDRunDir.model_path(folder / "ssd").write_bytes(b"not a keras model")
        for step in more:
            step(world, folder)

    return setup


def estimate_images_cases() -> list[Case]:
    """``paz6d estimate --images``: the flags it needs and refuses, the camera file and the image folder, all
    refused before a model loads."""
    found = _flag_cases("estimate-images-", ESTIMATE_IMAGES, {
        "--detector": [((), "--images: needs --detector")],
        "--camera": [((), "--camera: --images needs"), (("{case}/none.json",), "none.json"),
                     (("{world}/results.csv",), "results.csv")],
        "--images": [(("{case}/none",), "none"), (("{world}/results.csv",), "not a folder")],
        "--dataset": [(("{world}/bop",), "--images: not with --dataset")],
        "--targets-out": [(("{out}/targets.json",), "--targets-out: not with --images")],
        "--split": [(("test",), "--split: not with --images")],
        "--box": [(("visib",), "--box: only without --detector")],
        "--min-visible": [(("0.5",), "--min-visible: only without --detector")],
    }, detector_stand_in())
    found += [
        Case("estimate-images-depth", ESTIMATE_IMAGES + ("--depth",), detector_stand_in(),
             ("--depth: not with --images",)),
        Case("estimate-images-camera-size-mismatch", replace_flag(ESTIMATE_IMAGES, "--camera", "{case}/camera.json"),
             detector_stand_in(_camera_file(lambda d: {**d, "width": 640, "height": 480})),
             ("000000.png", "expected 640x480")),
        Case("estimate-images-camera-garbage", replace_flag(ESTIMATE_IMAGES, "--camera", "{case}/camera.json"),
             detector_stand_in(case_file("camera.json", "{")), ("camera.json",)),
        Case("estimate-images-camera-no-fx", replace_flag(ESTIMATE_IMAGES, "--camera", "{case}/camera.json"),
             detector_stand_in(_camera_file(lambda d: {k: v for k, v in d.items() if k != "fx"})),
             ("camera.json", "'fx'")),
        Case("estimate-images-folder-empty", replace_flag(ESTIMATE_IMAGES, "--images", "{case}/frames"),
             detector_stand_in(case_file("frames", "<dir>")), ("frames", "no image file")),
        Case("estimate-images-image-garbage", replace_flag(ESTIMATE_IMAGES, "--images", "{case}/frames"),
             detector_stand_in(case_file("frames/000000.png", b"\x89PNG\r\n\x1a\nbroken")), ("000000.png",)),
        Case("estimate-images-out-is-an-image",
             replace_flag(ESTIMATE_IMAGES, "--out", "{world}/bop/test/000000/rgb/000000.png"), detector_stand_in(),
             ("--out", "000000.png", "a file of --images")),
    ]
    return found


#: The YCB-Video and FAT fixtures (``tests/data/datasets``, see ``make_pose_fixtures.py``).
POSE_DATA = Path(__file__).parent / "data" / "datasets"
TRAIN_AAE_YCB = ("train", "aae", "--out", "{out}", "--dataset", "{case}/ycb_video", "--object-class", "003_cracker_box",
                 "--no-progress")
TRAIN_KEYPOINTNET_YCB = ("train", "keypointnet", "--out", "{out}", "--dataset", "{case}/ycb_video", "--object-id", "2",
                         "--no-progress")
TRAIN_KEYPOINTNET_FAT = ("train", "keypointnet", "--out", "{out}", "--dataset", "{case}/fat", "--object-class",
                         "003_cracker_box", "--dataset-mesh",
                         "{case}/fat/ycb_models/003_cracker_box/google_16k/textured.obj", "--no-progress")


def pose_copy(name: str, relative: str | None = None, content=None) -> Callable[[World, Path], None]:
    """Setup: a copy of the ``name`` fixture (``ycb_video``, ``fat``) with ``relative`` replaced by
    ``content`` (see :func:`put`; a callable maps the file's JSON)."""

    def setup(world: World, folder: Path) -> None:
        shutil.copytree(POSE_DATA / name, folder / name)
        if relative is not None:
            path = folder / name / relative
            put(path, content(json.loads(path.read_text())) if callable(content) else content)

    return setup


def pose_dataset_cases() -> list[Case]:
    """``paz6d train aae|keypointnet --dataset`` on YCB-Video / FAT data with one spoiled file or flag."""

    def drop_quaternion(frame):
        frame["objects"][0].pop("quaternion_xyzw")
        return frame

    return [
        Case("train-keypointnet-ycb-video-meta-garbage", TRAIN_KEYPOINTNET_YCB,
             pose_copy("ycb_video", "data/0048/000001-meta.mat", b"garbage"), ("000001-meta.mat",)),
        Case("train-keypointnet-ycb-video-box-unknown-class", TRAIN_KEYPOINTNET_YCB,
             pose_copy("ycb_video", "data/0048/000002-box.txt", "999_x 1 2 3 4\n"), ("000002-box.txt", "999_x")),
        Case("train-aae-ycb-video-no-class", replace_flag(TRAIN_AAE_YCB, "--object-class", "999_x"),
             pose_copy("ycb_video"), ("--object-class", "999_x")),
        Case("train-aae-ycb-video-no-image-set", TRAIN_AAE_YCB + ("--split", "test"), pose_copy("ycb_video"),
             ("--split", "test.txt")),
        Case("train-keypointnet-fat-no-quaternion", TRAIN_KEYPOINTNET_FAT,
             pose_copy("fat", "mixed/kitchen_0/000000.left.json", drop_quaternion),
             ("000000.left.json", "objects[0]", "quaternion_xyzw")),
        Case("train-keypointnet-fat-without-mesh", replace_flag(TRAIN_KEYPOINTNET_FAT, "--dataset-mesh"),
             pose_copy("fat"), ("--dataset-mesh",)),
        Case("train-keypointnet-fat-split-outside", TRAIN_KEYPOINTNET_FAT + ("--split", "../.."), pose_copy("fat"),
             ("--split",)),
    ]


def train_cases() -> list[Case]:
    found = _flag_cases("train-aae-", TRAIN_AAE, {
        "--mesh": [(("{case}/none.ply",), "none.ply"), (("{world}/bop",), "bop")],
        "--steps": [(("0",), ""), (("-5",), "")],
        "--workers": [(("-1",), "")],
        "--mesh-scale": [(("nan",), ""), (("0",), "")],
        "--pair-fraction": [(("2",), ""), (("nan",), ""), (("-0.5",), "")],
        "--crop-box": [(("whole",), "whole")],
        "--precision": [(("half",), "half")],
        "--encoder-backbone": [(("resnet50",), "resnet50")],
        "--seed": [(("-1",), "")],
        "--config": [(("huge",), "")],
        "--out": [(("{world}/results.csv",), "results.csv"), (("/dev/null",), "/dev/null")],
    })
    found += _flag_cases("train-aae-dataset-", TRAIN_AAE_DATASET, {
        "--split": [(("nope",), "nope"), (("../..",), ""), (("",), "")],
        "--object-id": [(("9",), "9"), (("0",), "")],
    }, setup=lambda world, folder: copy_bop(world, folder))
    for name, base in (("aae", TRAIN_AAE), ("keypointnet", TRAIN_KEYPOINTNET)):
        found.append(Case(f"train-{name}-mesh-garbage", replace_flag(base, "--mesh", "{case}/bad.ply"),
                          case_file("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 2\nend_header\n1 2\n"),
                          ("bad.ply",)))
        other = "keypointnet" if name == "aae" else "aae"
        found.append(Case(f"train-{name}-out-foreign-run", replace_flag(base, "--out", "{case}/run"),
                          lambda world, folder, other=other:
                          shutil.copytree(getattr(world, f"{other}_run"), folder / "run"),
                          ("--out", "output folder of " + other)))
    found.append(Case("train-aae-dataset-no-scene-gt", TRAIN_AAE_DATASET,
                      bop_file("test/000000/scene_gt.json", None), ("scene_gt.json",)))
    found.append(Case("train-aae-dataset-no-models", TRAIN_AAE_DATASET, bop_file("models", None), ("models",)))
    found.append(Case("train-aae-dataset-scene-gt-garbage", TRAIN_AAE_DATASET,
                      bop_file("test/000000/scene_gt.json", "{"), ("scene_gt.json",)))
    found += pose_dataset_cases()
    found += _flag_cases("train-keypointnet-", TRAIN_KEYPOINTNET, {
        "--mesh": [(("{case}/none.ply",), "none.ply")],
        "--workers": [(("-1",), "")],
        "--steps": [(("0",), "")],
        "--mesh-scale": [(("inf",), "")],
        "--seed": [(("-1",), "")],
        "--out": [(("{world}/results.csv",), "results.csv")],
    })
    orientation = TRAIN_KEYPOINTNET + ("--orientation-network",)
    bop_mesh = replace_flag(orientation, "--mesh", "{case}/bop/models/obj_000001.ply")
    quarter_turn = [0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    found += [Case("train-keypointnet-orientation-not-a-bop-model", orientation, None, ("models_info.json",)),
              Case("train-keypointnet-orientation-no-symmetry", bop_mesh, copy_bop,
                   ("models_info.json", "exactly one discrete symmetry")),
              Case("train-keypointnet-orientation-quarter-turn", bop_mesh,
                   bop_file("models/models_info.json",
                            lambda d: {k: {**v, "symmetries_discrete": [quarter_turn]} for k, v in d.items()}),
                   ("models_info.json", "half-turn"))]
    found += _flag_cases("train-emotion-", TRAIN_EMOTION, {
        "--learning-rate": [(("nan",), ""), (("-1",), ""), (("inf",), ""), (("0",), "")],
        "--epochs": [(("0",), "")],
        "--batch-size": [(("0",), ""), (("-8",), "")],
        "--val-fraction": [(("2",), ""), (("0",), ""), (("nan",), "")],
        "--input-size": [(("0",), ""), (("100000",), "")],
        "--checkpoint-every": [(("0",), "")],
        "--validate-every": [(("-1",), "")],
        "--data": [(("{case}/none.csv",), "none.csv")],
        "--seed": [(("-1",), "")],
        "--out": [(("{world}/results.csv",), "results.csv")],
    })
    fer = {
        "empty": ("", "fer.csv"),
        "header-only": ("emotion,pixels,Usage\n", "fer.csv"),
        "wrong-header": ("a,b\n1,2\n", "fer.csv"),
        "short-pixels": ("emotion,pixels,Usage\n0,1 2 3,Training\n", "fer.csv"),
        "text-pixels": ("emotion,pixels,Usage\n0," + "x " * 2304 + ",Training\n", "fer.csv"),
        "bad-label": ("emotion,pixels,Usage\n9," + "1 " * 2304 + ",Training\n", "fer.csv"),
        "not-utf8": (NOT_UTF8, "fer.csv"),
        "huge-field": ("emotion,pixels,Usage\n0," + "1" * 300_000 + ",Training\n", "fer.csv"),
        "folder-empty": ("<dir>", "fer.csv"),
    }
    for name, (content, expect) in fer.items():
        found.append(Case(f"train-emotion-data-{name}", replace_flag(TRAIN_EMOTION, "--data", "{case}/fer.csv"),
                          case_file("fer.csv", content), (expect,)))
    found += dataset_format_cases()
    found += _flag_cases("train-ssd-", TRAIN_SSD, {  # refused before the data set is read
        "--input-size": [(("100",), ""), (("0",), ""), (("-64",), "")],
        "--steps": [(("0",), "")],
        "--backbone": [(("resnet50",), ""), (("",), "")],
    })
    found.append(Case("train-ssd-backbone-full-config", (*TRAIN_SSD, "--config", "full", "--backbone",
                                                         "efficientnet-lite0"), None, ("backbone", "light network")))
    found.append(Case("train-keypointnet-backbone-full-config", (*TRAIN_KEYPOINTNET, "--config", "full", "--backbone",
                                                                  "efficientnet-lite0"), None,
                      ("backbone", "strides 2 to 8")))
    found.append(Case("train-ssd-top-down-full-config", (*TRAIN_SSD, "--config", "full", "--top-down"), None,
                      ("--top-down", "light network")))
    found.append(Case("train-ssd-input-size-full-config", (*TRAIN_SSD, "--config", "full", "--input-size", "512"),
                      None, ("light network",)))
    found += _flag_cases("demo-", DEMO, {
        "--out": [(("{world}/results.csv",), "results.csv"), (("/dev/null",), "/dev/null")],
        "--test-images": [(("0",), ""), (("-2",), "")],
        "--steps": [(("0",), "")],
        "--workers": [(("-1",), "")],
        "--scene-crops": [(("1.5",), ""), (("-0.1",), "")],
    })
    found.append(Case("demo-train-images-0-with-scene-crops", (*DEMO, "--scene-crops", "0.25", "--train-images", "0"),
                      None, ("--train-images",)))
    found += _flag_cases("benchmark-lmo-", BENCHMARK_LMO, {  # every case fails before any stage runs
        "--lmo": [(("{case}/none",), "none")],
        "--method": [(("pvnet",), "")],
        "--aae-crop-box": [(("whole",), "whole")],
        "--detector-backbone": [(("resnet50",), "resnet50")],
        "--detector-input-size": [(("416",), "416"), (("0",), "0"), (("65536",), "65536")],
        "--neutral-distractors": [(("1.5",), "1.5"), (("nan",), "nan")],
        "--aae-encoder-backbone": [(("resnet50",), "resnet50")],
        "--out": [(("{world}/results.csv",), "results.csv")],
    })
    return found


def dataset_format_cases() -> list[Case]:
    """Malformed VOC, COCO and Open Images folders for ``paz6d train ssd`` and FERPlus votes for
    ``paz6d train emotion``: the message names the file (and the field)."""
    box = "<bndbox><xmin>1</xmin><ymin>1</ymin><xmax>{}</xmax><ymax>4</ymax></bndbox>"
    coco_file = {"images": [{"id": 1, "file_name": "a.jpg", "width": 8, "height": 6}],
                 "categories": [{"id": 1, "name": "thing"}],
                 "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 2, "x"]}]}
    header = ("ImageID,Source,LabelName,Confidence,XMin,XMax,YMin,YMax,IsOccluded,IsTruncated,IsGroupOf,IsDepiction,"
              "IsInside")
    ssd = {
        "no-format": ({"data/readme.txt": "nothing here"}, ("cannot tell the format",)),
        "voc-bad-xml": ({"data/a.xml": "<annotation><object>"}, ("a.xml", "malformed XML")),
        "voc-bad-number": ({"data/a.xml": f"<annotation><object><name>dog</name>{box.format('x')}</object>"
                                          "</annotation>"},
                           ("a.xml", "<xmax>")),
        "voc-unknown-class": ({"data/a.xml": f"<annotation><object><name>dragon</name>{box.format(4)}</object>"
                                             "</annotation>"},
                              ("a.xml", "dragon")),
        "coco-bad-bbox": ({"data/annotations/instances_train2017.json": coco_file},
                          ("instances_train2017.json", "'bbox'")),
        "openimages-unknown-label": ({"data/train-annotations-bbox.csv": f"{header}\nab,x,/m/0zz,1,0,1,0,1,0,0,0,0,0\n",
                                      "data/class-descriptions-boxable.csv": "/m/01yrx,Cat\n"},
                                     ("train-annotations-bbox.csv", "LabelName")),
    }
    found = []
    for name, (files, expect) in ssd.items():
        def setup(world: World, folder: Path, files=files) -> None:
            for relative, content in files.items():
                put(folder / relative, content)

        found.append(Case(f"train-ssd-{name}", TRAIN_SSD, setup, expect))
    votes_header = "Usage,Image name,neutral,happiness,surprise,sadness,anger,disgust,fear,contempt,unknown,NF\n"
    ferplus = {
        "bad-vote": (votes_header + "Training,a.png,1,2,x,0,0,0,0,0,0,0\n", ("votes.csv", "surprise")),
        "row-count": (votes_header + "Training,a.png,10,0,0,0,0,0,0,0,0,0\n", ("votes.csv", "vote rows")),
        "not-csv": (NOT_UTF8, ("votes.csv",)),
    }
    for name, (content, expect) in ferplus.items():
        found.append(Case(f"train-emotion-ferplus-{name}", TRAIN_EMOTION + ("--ferplus", "{case}/votes.csv"),
                          case_file("votes.csv", content), expect))
    return found


DETECT = ("detect", "--run-dir", "{case}/ssd", "--images", "{case}/images", "--out", "{out}/detections.json",
          "--no-progress")
DETECT_BOP = replace_flag(replace_flag(DETECT, "--images"), "--dataset", "{case}/bop")
TRAIN_STN = ("train", "stn", "--out", "{out}", "--no-progress")
TRAIN_HRNET = ("train", "hrnet", "--out", "{out}", "--mesh", "{world}/obj_000001.ply", "--no-progress")
TRAIN_PROBABILISTIC = ("train", "probabilistic-keypoints", "--out", "{out}", "--mesh", "{world}/obj_000001.ply",
                       "--no-progress")
TRAIN_SEGMENTATION = ("train", "segmentation", "--dataset", "{world}/bop", "--out", "{out}", "--no-progress")
#: One valid command line of every ``paz6d train <method>`` (its ``--out`` is ``{out}``).
TRAINERS = {"ssd": replace_flag(TRAIN_SSD, "--dataset", "{world}/bop"), "stn": TRAIN_STN, "aae": TRAIN_AAE,
            "keypointnet": TRAIN_KEYPOINTNET, "emotion": TRAIN_EMOTION, "hrnet": TRAIN_HRNET,
            "probabilistic-keypoints": TRAIN_PROBABILISTIC, "segmentation": TRAIN_SEGMENTATION}
#: Files that make a folder another command's output: ``{name: {relative path: content}}`` (see :func:`put`).
FOREIGN_RUNS = {
    "emotion": {"classes.json": ["angry", "happy"], "model.keras": b"a trained model", "metrics.json": {}},
    "ssd": {"detector.json": {"architecture": "light"}, "model.keras": b"a trained model"},
    "benchmark lmo": {".paz6d-run.json": {"method": "benchmark lmo"}, "stages/detector.json": {}},
}


def files_setup(files: dict[str, Any], copy_dataset: bool = False) -> Callable[[World, Path], None]:
    """Setup: ``<case>/<relative>`` holds each content of ``files`` (see :func:`put`), after a copy of
    the world's data set with ``copy_dataset``."""

    def setup(world: World, folder: Path) -> None:
        if copy_dataset:
            copy_bop(world, folder)
        for relative, content in files.items():
            put(folder / relative, content)

    return setup


def _symlink(target: str, name: str) -> Callable[[World, Path], None]:
    """Setup: ``<case>/<name>`` is a symbolic link to ``target`` (``{world}`` and ``{case}`` filled in)."""

    def setup(world: World, folder: Path) -> None:
        (folder / name).symlink_to(target.format(world=world.root, case=folder))

    return setup


def output_rule_cases() -> list[Case]:
    """The one output rule: no command writes over a file it reads (a data set's, a run directory's,
    an image), over another output of the call, into a data set or another method's run folder, or
    through a symbolic link; all refused before any work (the runner checks that nothing changed)."""
    images = {"images/a.png": (np.ones((8, 8, 3), np.uint8) * 255).tobytes(), **{
        f"ssd/{name}": content for name, content in FOREIGN_RUNS["ssd"].items()}}
    detect_files = files_setup(images)
    detect_bop = files_setup({f"ssd/{name}": content for name, content in FOREIGN_RUNS["ssd"].items()},
                             copy_dataset=True)
    scene_gt = "{case}/bop/test/000000/scene_gt.json"
    found = [
        Case("detect-out-is-an-input-image", replace_flag(DETECT, "--out", "{case}/images/a.png"), detect_files,
             ("--out", "a.png", "a file of --images")),
        Case("detect-out-is-the-model", replace_flag(DETECT, "--out", "{case}/ssd/model.keras"), detect_files,
             ("--out", "model.keras", "a file of --run-dir")),
        Case("detect-ground-truth-is-scene-gt", DETECT_BOP + ("--ground-truth", scene_gt), detect_bop,
             ("--ground-truth", "scene_gt.json", "a file of --dataset")),
        Case("detect-out-is-scene-gt", replace_flag(DETECT_BOP, "--out", scene_gt), detect_bop,
             ("--out", "a file of --dataset")),
        Case("detect-ground-truth-is-out", DETECT_BOP + ("--ground-truth", "{out}/detections.json"), detect_bop,
             ("--ground-truth", "is also --out")),
        Case("detect-out-symlink", replace_flag(DETECT, "--out", "{case}/link.json"),
             lambda world, folder: (detect_files(world, folder), _symlink("{world}/results.csv", "link.json")(
                 world, folder)), ("--out", "symbolic link")),
        Case("estimate-out-is-scene-gt", replace_flag(ESTIMATE, "--out", "{world}/bop/test/000000/scene_gt.json"),
             None, ("--out", "a file of --dataset")),
        Case("estimate-out-is-scene-camera",
             replace_flag(ESTIMATE, "--out", "{world}/bop/test/000000/scene_camera.json"), None,
             ("--out", "scene_camera.json", "a file of --dataset")),
        Case("estimate-targets-out-is-run-config", ESTIMATE + ("--targets-out", "{world}/runs/aae/config.json"), None,
             ("--targets-out", "a file of --run 1")),
        Case("estimate-detections-out-is-scene-gt",
             ESTIMATE + ("--detector", "{case}/ssd", "--detections-out", "{world}/bop/test/000000/scene_gt.json"),
             detect_files, ("--detections-out", "a file of --dataset")),
        Case("estimate-out-is-detector-model", replace_flag(ESTIMATE + ("--detector", "{case}/ssd"), "--out",
                                                            "{case}/ssd/model.keras"),
             detect_files, ("--out", "a file of --detector")),
    ]
    for method, base in TRAINERS.items():
        other = "ssd" if method == "emotion" else "emotion"
        found.append(Case(f"train-{method}-out-{other}-run", replace_flag(base, "--out", "{case}/run"),
                          files_setup({f"run/{name}": content for name, content in FOREIGN_RUNS[other].items()}),
                          ("--out", f"output folder of {other}, not {method}")))
        found.append(Case(f"train-{method}-out-benchmark", replace_flag(base, "--out", "{case}/run"),
                          files_setup({f"run/{name}": content
                                       for name, content in FOREIGN_RUNS["benchmark lmo"].items()}),
                          ("--out", "output folder of benchmark lmo")))
        found.append(Case(f"train-{method}-out-symlink", replace_flag(base, "--out", "{case}/link"),
                          _symlink("{world}/runs/aae", "link"), ("--out", "symbolic link")))
        found.append(Case(f"train-{method}-out-dataset", replace_flag(base, "--out", "{world}/bop"), None,
                          ("--out", "BOP data set")))
        found.append(Case(f"train-{method}-out-dataset-scene", replace_flag(base, "--out", "{world}/bop/test/000000"),
                          None, ("--out", "BOP data set")))
    found += [
        Case("train-ssd-out-is-dataset", (*TRAIN_SSD[:3], "{case}/bop", "--out", "{case}/bop", "--no-progress"),
             copy_bop, ("--out", "BOP data set")),
        Case("train-emotion-out-is-data", replace_flag(TRAIN_EMOTION, "--out", "{world}/fer.csv"), None,
             ("--out", "fer.csv")),
        Case("benchmark-lmo-out-is-lmo", BENCHMARK_LMO + ("--lmo", "{case}/bop", "--out", "{case}/bop"), copy_bop,
             ("--out", "BOP data set")),
        Case("benchmark-lmo-out-ssd-run", replace_flag(BENCHMARK_LMO, "--out", "{case}/run"),
             files_setup({f"run/{name}": content for name, content in FOREIGN_RUNS["ssd"].items()}),
             ("--out", "output folder of ssd, not benchmark lmo")),
        Case("benchmark-lmo-out-symlink", replace_flag(BENCHMARK_LMO, "--out", "{case}/link"),
             _symlink("{world}/runs", "link"), ("--out", "symbolic link")),
    ]
    return found


RUN = ("run", "--input", "{world}/bop/test/000000/rgb", "--faces", "haar", "--camera", "{world}/bop/camera.json",
       "--out", "{out}", "--no-progress")
RUN_DETECTOR = ("run", "--input", "{world}/bop/test/000000/rgb", "--detector", "{world}/runs/aae", "--run",
                "1={world}/runs/aae", "--camera", "{world}/bop/camera.json", "--out", "{out}", "--no-progress")


def _camera_file(change) -> Callable[[World, Path], None]:
    """Setup: ``<case>/camera.json``, the world's camera changed by ``change`` (its dict -> new content)."""

    def setup(world: World, folder: Path) -> None:
        put(folder / "camera.json", change(json.loads((world.bop / "camera.json").read_text())))

    return setup


def run_cases() -> list[Case]:
    """``paz6d run``: the frame source, the camera file, the pipeline flags and the output folder."""
    found = _flag_cases("run-", RUN, {
        "--input": [(("{case}/none.mp4",), "none.mp4"), (("97",), "device 97"),
                    (("{world}/results.csv",), "results.csv")],
        "--camera": [(("{case}/none.json",), "none.json"), (("{world}/results.csv",), "results.csv")],
        "--out": [(("{world}/bop/test/000000/rgb",), "--out"), (("{world}/bop",), "BOP"),
                  (("{world}/results.csv",), "results.csv")],
        "--fps": [(("0",), ""), (("nan",), ""), (("x",), "")],
        "--max-frames": [(("0",), ""), (("-2",), "")],
        "--score-threshold": [(("2",), ""), (("nan",), "")],
        "--faces": [(("smile",), ""), ((), "--detector or --faces")],
        "--run": [(("1={world}/runs/aae",), "--run: pose models need --detector")],
        "--smooth": [(("0",), ""), (("nan",), ""), (("1.5",), ""), (("0.5",), "--smooth: smooths poses")],
        "--bop-scene-id": [(("2",), "without --run"), (("x",), "")],
    })
    found += _flag_cases("run-detector-", RUN_DETECTOR, {
        "--detector": [(("{case}/none",), "none"), (("{world}/runs/aae",), "aae run directory, not a detector")],
        "--run": [(("1={case}/none",), "none"), (("x={world}/runs/aae",), "OBJ_ID=RUN_DIR"),
                  (("0={world}/runs/aae",), "positive BOP object id")],
        "--camera": [((), "--camera: --run needs")],
        "--bop-scene-id": [(("-1",), "--bop-scene-id")],
    })
    found += [
        Case("run-video-corrupt", replace_flag(RUN, "--input", "{case}/clip.mp4"),
             case_file("clip.mp4", b"\x00\x00\x00\x18ftypmp42" + b"garbage" * 64), ("clip.mp4", "cannot open")),
        Case("run-video-empty", replace_flag(RUN, "--input", "{case}/clip.avi"), case_file("clip.avi", b""),
             ("clip.avi",)),
        Case("run-folder-empty", replace_flag(RUN, "--input", "{case}/frames"), case_file("frames", "<dir>"),
             ("frames", "no image file")),
        Case("run-folder-image-garbage", replace_flag(RUN, "--input", "{case}/frames"),
             case_file("frames/000000.png", b"\x89PNG\r\n\x1a\nbroken"), ("000000.png",)),
        Case("run-camera-size-mismatch", replace_flag(RUN, "--camera", "{case}/camera.json"),
             _camera_file(lambda d: {**d, "width": 640, "height": 480}), ("expected 640x480",)),
        Case("run-camera-no-fx", replace_flag(RUN, "--camera", "{case}/camera.json"),
             _camera_file(lambda d: {k: v for k, v in d.items() if k != "fx"}), ("camera.json", "'fx'")),
        Case("run-camera-dist-short", replace_flag(RUN, "--camera", "{case}/camera.json"),
             _camera_file(lambda d: {**d, "dist": [0.1, 0.2]}), ("camera.json", "'dist'")),
        Case("run-camera-dist-text", replace_flag(RUN, "--camera", "{case}/camera.json"),
             _camera_file(lambda d: {**d, "dist": ["a", 0, 0, 0, 0]}), ("camera.json", "'dist'")),
        Case("run-camera-garbage", replace_flag(RUN, "--camera", "{case}/camera.json"), case_file("camera.json", "{"),
             ("camera.json",)),
        Case("run-camera-list", replace_flag(RUN, "--camera", "{case}/camera.json"), case_file("camera.json", []),
             ("camera.json",)),
        Case("run-head-pose-without-camera", replace_flag(replace_flag(RUN, "--faces", "head-pose"), "--camera"),
             None, ("--camera: --faces head-pose needs",)),
    ]
    return found

def fixture_text(name: str, relative: str, old: str, new: str) -> Callable[[World, Path], None]:
    """Setup: a copy of the ``name`` fixture (``tests/data/datasets``) with ``old`` replaced by ``new``
    in the text of ``relative``."""

    def setup(world: World, folder: Path) -> None:
        shutil.copytree(POSE_DATA / name, folder / name)
        path = folder / name / relative
        text = path.read_text()
        if old not in text:
            raise AssertionError(f"{path} lacks {old!r}")
        path.write_text(text.replace(old, new))

    return setup


def _with_outside_file(setup: Callable[[World, Path], None]) -> Callable[[World, Path], None]:
    """``setup``, plus ``<case>/outside.jpg`` and ``<case>/outside.xml``: files outside the data set
    that a path escaping it would reach."""

    def wrapped(world: World, folder: Path) -> None:
        setup(world, folder)
        shutil.copy(POSE_DATA / "voc" / "VOC2007" / "JPEGImages" / "000001.jpg", folder / "outside.jpg")
        shutil.copy(POSE_DATA / "voc" / "VOC2007" / "Annotations" / "000001.xml", folder / "outside.xml")

    return wrapped


TRAIN_SSD_VOC = replace_flag(TRAIN_SSD, "--dataset", "{case}/voc/VOC2007") + ("--split", "train")
TRAIN_SSD_COCO = replace_flag(TRAIN_SSD, "--dataset", "{case}/coco")
TRAIN_SSD_OPENIMAGES = replace_flag(TRAIN_SSD, "--dataset", "{case}/openimages")
COCO_FILE = "annotations/instances_tiny2017.json"


def coco_edit(change: Callable[[dict], Any]) -> Callable[[World, Path], None]:
    """Setup: the COCO fixture with its instances file changed in place by ``change(data)``."""

    def edit(data: dict) -> dict:
        change(data)
        return data

    return pose_copy("coco", COCO_FILE, edit)


def dataset_path_cases() -> list[Case]:
    """The path rule: a path read from a data set or run directory that leads outside it is refused,
    naming the file and the field (the files it would reach exist, so nothing else stops it)."""
    return [
        Case("train-ssd-voc-filename-parent", TRAIN_SSD_VOC, _with_outside_file(fixture_text(
            "voc", "VOC2007/Annotations/000001.xml", "<filename>000001.jpg", "<filename>../../../outside.jpg")),
             ("000001.xml", "<filename>", "expected a relative path inside")),
        Case("train-ssd-voc-filename-absolute", TRAIN_SSD_VOC, fixture_text(
            "voc", "VOC2007/Annotations/000001.xml", "<filename>000001.jpg", "<filename>/etc/passwd"),
             ("000001.xml", "<filename>", "/etc/passwd")),
        Case("train-ssd-voc-image-set-id-parent", TRAIN_SSD_VOC, _with_outside_file(fixture_text(
            "voc", "VOC2007/ImageSets/Main/train.txt", "000003", "../../../../outside")),
             ("train.txt", "image id #2", "expected a relative path inside")),
        Case("train-ssd-coco-file-name-parent", TRAIN_SSD_COCO, _with_outside_file(coco_edit(
            lambda data: data["images"][0].update(file_name="../../outside.jpg"))),
             ("instances_tiny2017.json", "images[0]", "'file_name'", "expected a relative path inside")),
        Case("train-ssd-coco-file-name-absolute", TRAIN_SSD_COCO, coco_edit(
            lambda data: data["images"][1].update(file_name="/etc/passwd")),
             ("instances_tiny2017.json", "images[1]", "'file_name'")),
        Case("train-ssd-coco-file-name-integer", TRAIN_SSD_COCO, coco_edit(
            lambda data: data["images"][1].update(file_name=7)), ("images[1]", "'file_name'")),
        Case("train-ssd-openimages-image-id-parent", TRAIN_SSD_OPENIMAGES, _with_outside_file(fixture_text(
            "openimages", "validation-annotations-bbox.csv", "0a1b2c3d4e5f6071,", "../../outside,")),
             ("validation-annotations-bbox.csv", "ImageID", "expected a relative path inside")),
        Case("train-emotion-checkpoint-path-outside",
             TRAIN_EMOTION + ("--val-fraction", "0.3", "--epochs", "1"),
             files_setup({"out/checkpoint.json": {"step": 1, "path": "../outside"},
                          "outside/model.weights.h5": b"not this run's"}),
             ("checkpoint.json", '"path"', "expected a relative path inside")),
    ]


def _voc_box(xmin: str, ymin: str, xmax: str, ymax: str) -> Callable[[World, Path], None]:
    """Setup: the VOC fixture whose first box (a dog in a 40 x 30 image) is ``xmin ymin xmax ymax``."""
    return fixture_text("voc", "VOC2007/Annotations/000001.xml",
                        "<xmin>5</xmin>\n\t\t\t<ymin>4</ymin>\n\t\t\t<xmax>30</xmax>\n\t\t\t<ymax>25</ymax>",
                        f"<xmin>{xmin}</xmin><ymin>{ymin}</ymin><xmax>{xmax}</xmax><ymax>{ymax}</ymax>")


def _coco_box(box: list) -> Callable[[World, Path], None]:
    return coco_edit(lambda data: data["annotations"][0].update(bbox=box))


def _one_pixel_image(world: World, folder: Path) -> None:
    """The COCO fixture whose 20 x 16 PNG is replaced by a 1 x 1 image (its record says so too)."""
    from paz6d.backend.image import save_image

    coco_edit(lambda data: data["images"][1].update(width=1, height=1))(world, folder)
    save_image(folder / "coco" / "tiny2017" / "000003.png", np.zeros((1, 1, 3), np.uint8))


TRAIN_SSD_BOP = replace_flag(TRAIN_SSD, "--dataset", "{case}/bop") + ("--split", "test")
GENERATED_COCO = "test/000000/scene_gt_coco.json"


def annotation_cases() -> list[Case]:
    """Boxes and sizes that cannot be, checked against the image's real size where every loader's
    samples pass (:func:`paz6d.datasets.sample.check_sample`): refused naming the file, record and field."""
    voc, coco = ("000001.xml",), ("instances_tiny2017.json", "image id 7")
    return [
        Case("train-ssd-voc-box-1e9", TRAIN_SSD_VOC, _voc_box("5", "4", "1e9", "25"), voc + ("box 0 (dog)", "outside")),
        Case("train-ssd-voc-box-minus-1e6", TRAIN_SSD_VOC, _voc_box("-1e6", "4", "30", "25"),
             voc + ("box 0 (dog)", "outside")),
        Case("train-ssd-voc-box-off-image", TRAIN_SSD_VOC, _voc_box("100", "4", "120", "25"),
             voc + ("entirely outside the 40 x 30 px image",)),
        Case("train-ssd-voc-box-1e308", TRAIN_SSD_VOC, _voc_box("5", "4", "1e308", "25"), voc + ("outside",)),
        Case("train-ssd-voc-box-inverted", TRAIN_SSD_VOC, _voc_box("30", "4", "5", "25"), voc + ("<bndbox>",)),
        Case("train-ssd-voc-box-nan", TRAIN_SSD_VOC, _voc_box("nan", "4", "30", "25"), voc + ("<xmin>",)),
        Case("train-ssd-voc-size-negative", TRAIN_SSD_VOC,
             fixture_text("voc", "VOC2007/Annotations/000001.xml", "<width>40</width>", "<width>-5</width>"),
             voc + ("field image size", "-5")),
        Case("train-ssd-voc-size-not-the-image", TRAIN_SSD_VOC,
             fixture_text("voc", "VOC2007/Annotations/000001.xml", "<width>40</width>", "<width>400</width>"),
             voc + ("says 400 x 30 px", "is 40 x 30 px")),
        Case("train-ssd-voc-image-set-duplicate-id", TRAIN_SSD_VOC,
             fixture_text("voc", "VOC2007/ImageSets/Main/train.txt", "000003", "000001"),
             ("train.txt", "000001", "twice")),
        Case("train-ssd-coco-width-10x", TRAIN_SSD_COCO, coco_edit(lambda data: data["images"][0].update(width=320)),
             coco + ("says 320 x 24 px", "is 32 x 24 px")),
        Case("train-ssd-coco-box-overflow", TRAIN_SSD_COCO, _coco_box([1e308, 0, 1e308, 5]),
             coco + ("box 0", "not finite")),
        Case("train-ssd-coco-box-off-image", TRAIN_SSD_COCO, _coco_box([-50, -50, 10, 10]),
             coco + ("box 0", "entirely outside the 32 x 24 px image")),
        Case("train-ssd-coco-box-1e9", TRAIN_SSD_COCO, _coco_box([0, 0, 1e9, 5]), coco + ("box 0", "outside")),
        Case("train-ssd-coco-one-pixel-image", TRAIN_SSD_COCO, _one_pixel_image,
             ("instances_tiny2017.json", "image id 3", "1 x 1 px image")),
        Case("train-ssd-coco-duplicate-image-id", TRAIN_SSD_COCO,
             coco_edit(lambda data: data["images"][1].update(id=7)), ("images[1]", "'id'", "also the id of images[0]")),
        Case("train-ssd-coco-image-id-list", TRAIN_SSD_COCO, coco_edit(lambda data: data["images"][0].update(id=[7])),
             ("images[0]", "'id'", "expected an integer")),
        Case("train-ssd-coco-category-id-text", TRAIN_SSD_COCO,
             coco_edit(lambda data: data["categories"][0].update(id="64")), ("categories[0]", "'id'")),
        Case("train-ssd-coco-annotation-image-id-list", TRAIN_SSD_COCO,
             coco_edit(lambda data: data["annotations"][0].update(image_id=[7])), ("annotations[0]", "'image_id'")),
        Case("train-ssd-coco-area-nested", TRAIN_SSD_COCO,
             coco_edit(lambda data: data["annotations"][2].update(area=[[1], [2, 3]])), ("annotations[2]", "'area'")),
        Case("train-ssd-coco-width-negative", TRAIN_SSD_COCO,
             coco_edit(lambda data: data["images"][0].update(width=-32)), ("images[0]", "'width'/'height'")),
        Case("train-ssd-generated-coco-list", TRAIN_SSD_BOP, bop_file(GENERATED_COCO, []),
             ("scene_gt_coco.json", "expected a JSON object")),
        Case("train-ssd-generated-file-name-parent", TRAIN_SSD_BOP,
             bop_file(GENERATED_COCO, lambda d: {**d, "images": [{**d["images"][0], "file_name": "../../../x.png"},
                                                                *d["images"][1:]]}),
             ("scene_gt_coco.json", "'file_name'", "expected a relative path inside")),
        Case("train-ssd-generated-box-off-image", TRAIN_SSD_BOP,
             bop_file(GENERATED_COCO, lambda d: {**d, "annotations": [{**d["annotations"][0], "bbox": [500, 5, 4, 4]},
                                                                     *d["annotations"][1:]]}),
             ("scene_gt_coco.json", "entirely outside the 64 x 48 px image")),
        Case("train-ssd-generated-width-not-the-image", TRAIN_SSD_BOP,
             bop_file(GENERATED_COCO, lambda d: {**d, "images": [{**d["images"][0], "width": 640},
                                                                *d["images"][1:]]}),
             ("scene_gt_coco.json", "says 640 x 48 px")),
        Case("train-ssd-openimages-box-inverted", TRAIN_SSD_OPENIMAGES, fixture_text(
            "openimages", "validation-annotations-bbox.csv", "1,0.25,0.5,0.25,0.5", "1,0.5,0.25,0.25,0.5"),
             ("validation-annotations-bbox.csv", "line 2", "XMax < XMin")),
        Case("train-keypointnet-ycb-video-box-1e9", TRAIN_KEYPOINTNET_YCB,
             fixture_text("ycb_video", "data/0048/000001-box.txt", "16.55 10.86 37.01", "16.55 10.86 1e9"),
             ("000001-box.txt", "003_cracker_box", "outside")),
        Case("train-keypointnet-fat-box-off-image", TRAIN_KEYPOINTNET_FAT,
             pose_copy("fat", "mixed/kitchen_0/000000.left.json",
                       lambda frame: {**frame, "objects": [{**frame["objects"][0], "bounding_box": {
                           "top_left": [7.0, 20.0], "bottom_right": [1e9, 1e9]}}, *frame["objects"][1:]]}),
             ("000000.left.json", "outside")),
    ]


def _fer_rows(bad_row: bytes) -> bytes:
    """A FER-2013 CSV of 14 valid faces (every class twice, Training and PublicTest) and ``bad_row``."""
    pixels = " ".join(["128"] * 48 * 48)
    rows = [f"{index % 7},{pixels},{('Training', 'PublicTest')[index % 2]}" for index in range(14)]
    return ("emotion,pixels,Usage\n" + "\n".join(rows) + "\n").encode() + bad_row + b"\n"


def _big_png_header(world: World, folder: Path) -> None:
    """The COCO fixture whose 20 x 16 PNG claims 100000 x 100000 pixels in its header."""
    import struct

    pose_copy("coco")(world, folder)
    path = folder / "coco" / "tiny2017" / "000003.png"
    data = path.read_bytes()
    path.write_bytes(data[:16] + struct.pack(">II", 100_000, 100_000) + data[24:])


def late_validation_cases() -> list[Case]:
    """Inputs that used to be refused late (after minutes), with a traceback, or not at all."""
    pixels = " ".join(["128"] * 48 * 48).encode()
    fer = {
        "usage-misspelt": b"0," + pixels + b",Trainig",
        "usage-nul": b"0," + pixels + b",Train\x00ing",
        "usage-not-utf8": b"0," + pixels + b",Train\xffing",
        "pixel-20-digits": b"0," + b"9" * 20 + b" " + pixels[4:] + b",Training",
        "label-20-digits": b"9" * 20 + b"," + pixels + b",Training",
    }
    found = [Case(f"train-emotion-data-{name}", replace_flag(TRAIN_EMOTION, "--data", "{case}/fer.csv"),
                  case_file("fer.csv", _fer_rows(row)), ("fer.csv",)) for name, row in fer.items()]
    votes_header = "Usage,Image name,neutral,happiness,surprise,sadness,anger,disgust,fear,contempt,unknown,NF\n"
    found += [
        Case("train-emotion-ferplus-vote-1e30", TRAIN_EMOTION + ("--ferplus", "{case}/votes.csv"),
             case_file("votes.csv", votes_header + "".join(f"Training,a{index}.png,{10 ** 30},0,0,0,0,0,0,0,0,0\n"
                                                           for index in range(14))), ("votes.csv", "neutral")),
        Case("benchmark-lmo-no-test-split", BENCHMARK_LMO + ("--lmo", "{case}/bop"),
             lambda world, folder: (copy_bop(world, folder), shutil.rmtree(folder / "bop" / "test")),
             ("--lmo", "test")),
        Case("benchmark-lmo-aae-steps-1e18", BENCHMARK_LMO + ("--lmo", "{case}/bop", "--aae-steps", str(10 ** 18)),
             copy_bop, ("--aae-steps",)),
        Case("benchmark-lmo-seed-2-64", BENCHMARK_LMO + ("--lmo", "{case}/bop", "--seed", str(2 ** 64)), copy_bop,
             ("--seed",)),
        Case("benchmark-lmo-out-empty", replace_flag(BENCHMARK_LMO, "--out", "") + ("--lmo", "{case}/bop"),
             copy_bop, ("--out", "empty")),
        Case("train-ssd-out-empty", replace_flag(TRAIN_SSD, "--out", ""), None, ("--out", "empty")),
        Case("train-ssd-input-size-65536", TRAIN_SSD + ("--input-size", "65536"), None, ("--input-size", "2048")),
        Case("train-aae-dataset-mesh-not-an-id", TRAIN_AAE_DATASET,
             lambda world, folder: (copy_bop(world, folder),
                                    shutil.copy(world.mesh, folder / "bop" / "models" / "obj_abc.ply")),
             ("obj_abc.ply", "obj_<object id>.ply")),
        Case("train-ssd-coco-png-header-100000", TRAIN_SSD_COCO, _big_png_header,
             ("000003.png", "100000 x 100000")),
        Case("estimate-principal-point-1e9", replace_flag(ESTIMATE, "--dataset", "{case}/bop"),
             bop_file("test/000000/scene_camera.json", lambda d: {
                 key: {**entry, "cam_K": [*entry["cam_K"][:2], 1e9, *entry["cam_K"][3:]]} for key, entry in d.items()}),
             ("scene_camera.json", "cam_K", "principal point")),
    ]
    return found


#: A valid ``detector.json`` of a light SSD on 128-pixel inputs (the model beside it is garbage: the
#: description is checked before the network is loaded).
SSD_DETECTOR = {"architecture": "light", "class_names": ["a", "b"], "variances": [0.1, 0.1, 0.2, 0.2],
                "priors": {"input_size": 128, "feature_map_sizes": [16, 8, 4, 2, 1, 1],
                           "steps": [8.0, 16.0, 32.0, 64.0, 128.0, 128.0],
                           "min_sizes": [5.6, 12.0, 24.3, 43.5, 67.8, 96.0],
                           "max_sizes": [12.0, 24.3, 43.5, 67.8, 96.0, 128.0],
                           "aspect_ratios": [[2.0], [2.0, 3.0], [2.0, 3.0], [2.0, 3.0], [2.0], [2.0]]}}
#: A checkpoint of the shared Trainer, as ``train <method> --out`` finds it when resuming.
CHECKPOINT = "checkpoints/step_00000010"


def _ssd_run(change: Callable[[dict], Any]) -> Callable[[World, Path], None]:
    """Setup: ``<case>/ssd``, an SSD run directory whose ``detector.json`` is :data:`SSD_DETECTOR` after
    ``change(detector)`` (which edits it in place), and ``<case>/images`` with one image."""

    def setup(world: World, folder: Path) -> None:
        detector = json.loads(json.dumps(SSD_DETECTOR))
        change(detector)
        put(folder / "ssd" / "detector.json", json.dumps(detector))  # json.dumps writes inf as Infinity
        put(folder / "ssd" / "model.keras", b"not a keras model")
        shutil.copytree(world.bop / "test" / "000000" / "rgb", folder / "images")

    return setup


def _priors(name: str, value) -> Callable[[dict], None]:
    return lambda detector: detector["priors"].__setitem__(name, value)


def _resumed_aae_run(relative: str, content) -> Callable[[World, Path], None]:
    """Setup: ``<case>/run``, the world's AAE run with a Trainer checkpoint, ``checkpoint.json`` and
    ``log.csv`` as a killed training leaves them, then ``relative`` replaced by ``content`` (see
    :func:`put`; a callable maps the file's JSON)."""

    def setup(world: World, folder: Path) -> None:
        import h5py

        run = folder / "run"
        shutil.copytree(world.aae_run, run)
        (run / CHECKPOINT).mkdir(parents=True)
        with h5py.File(run / CHECKPOINT / "model.weights.h5", "w") as weights:
            weights.create_dataset("kernel", data=np.zeros((4, 2), np.float32))
        np.savez(run / CHECKPOINT / "optimizer.npz", **{"0": np.int64(10), "1": np.float32(0.001)})
        put(run / CHECKPOINT / "state.json", {"step": 10, "metrics": {}})
        put(run / "checkpoint.json", {"step": 10, "path": CHECKPOINT, "kept": [10]})
        put(run / "log.csv", "step,wall_seconds,data_seconds,step_seconds,loss\n5,0.1,0.01,0.02,0.5\n"
                             "10,0.2,0.01,0.02,0.4\n")
        value = content(json.loads((run / relative).read_text())) if callable(content) else content
        put(run / relative, value)

    return setup


def run_directory_cases() -> list[Case]:
    """Run directories whose settings or training files are spoilt: refused when the run directory is
    opened (``detect``, ``estimate``, ``train <method>`` resuming), naming the file and the field."""
    detector = ("detector.json",)
    found = [Case("detect-ssd-run-model-garbage", DETECT, _ssd_run(lambda detector: None), ("model.keras",))]
    found += _flag_cases("detect-", DETECT, {"--vote-iou": [(("1.5",), "--vote-iou: expected a value in [0, 1]"),
                                                            (("nan",), "--vote-iou")]}, _ssd_run(lambda detector: None))
    found += [Case(f"detect-ssd-run-{name}", DETECT, _ssd_run(change), detector + expect) for name, change, expect in (
        ("steps-0", _priors("steps", [0, 0, 0, 0, 0, 0]), ("steps",)),
        ("aspect-ratio-0", _priors("aspect_ratios", [[0.0]] * 6), ("aspect_ratios",)),
        ("feature-maps-short", _priors("feature_map_sizes", [16, 8]), ("feature_map_sizes",)),
        ("min-size-nan", _priors("min_sizes", [float("nan")] * 6), ("min_sizes",)),
        ("input-size-100", _priors("input_size", 100), ("input_size",)),
        ("priors-missing", lambda detector: detector["priors"].pop("steps"), ("priors", "steps")),
        ("class-names-duplicate", lambda detector: detector.__setitem__("class_names", ["a", "a"]),
         ("class_names", "'a'")),
        ("image-scale-1e-9", lambda detector: detector.__setitem__("image_scale", 1e-9), ("image_scale",)),
        ("image-scale-infinity", lambda detector: detector.__setitem__("image_scale", float("inf")),
         ("image_scale",)),
        ("architecture-foo", lambda detector: detector.__setitem__("architecture", "foo"), ("architecture", "foo")),
        ("variances-nan", lambda detector: detector.__setitem__("variances", [float("nan")] * 4), ("variances",)),
    )]
    aae_run = replace_flag(ESTIMATE, "--run", "{case}/run")
    for name, change, expect in (
            ("crop-size-minus-16", {"crop_size": -16}, "crop_size"),
            ("latent-size-0", {"latent_size": 0}, "latent_size"),
            ("views-text", {"views": "many"}, "views"),
            ("filters-empty", {"filters": []}, "filters"),
            ("augmentation-noise-negative", {"augmentation": {"noise": -1.0}}, "noise")):
        def setup(world, folder, change=change):
            shutil.copytree(world.aae_run, folder / "run")
            data = json.loads((folder / "run" / "config.json").read_text())
            put(folder / "run" / "config.json", {**data, "config": {**data["config"], **change}})
        found.append(Case(f"estimate-aae-config-{name}", aae_run, setup, ("config.json", expect)))
    train_aae = replace_flag(TRAIN_AAE, "--out", "{case}/run")
    found.append(Case("train-aae-resume-config-crop-size-minus-16", train_aae, _resumed_aae_run(
        "config.json", lambda data: {**data, "config": {**data["config"], "crop_size": -16}}),
        ("config.json", "crop_size")))
    for name, relative, content, expect in (
            ("pointer-garbage", "checkpoint.json", "{", ("checkpoint.json",)),
            ("pointer-no-folder", "checkpoint.json", {"step": 20, "path": "checkpoints/step_00000020"},
             ("checkpoint.json", "step_00000020")),
            ("log-garbage", "log.csv", "step,loss\nabc,1\n", ("log.csv", "line 2", "step")),
            ("log-nul", "log.csv", b"step,loss\n1\x00,1\n", ("log.csv",)),
            ("log-no-step", "log.csv", "a,b\n1,2\n", ("log.csv", "step")),
            ("weights-garbage", f"{CHECKPOINT}/model.weights.h5", b"garbage", ("model.weights.h5",)),
            ("weights-missing", f"{CHECKPOINT}/model.weights.h5", None, ("model.weights.h5",)),
            ("optimizer-garbage", f"{CHECKPOINT}/optimizer.npz", b"garbage", ("optimizer.npz",)),
            ("optimizer-missing", f"{CHECKPOINT}/optimizer.npz", None, ("optimizer.npz",))):
        found.append(Case(f"train-aae-resume-{name}", train_aae, _resumed_aae_run(relative, content), expect))
    return found


CALIBRATE = ("calibrate", "--images", "{world}/bop/test/000000/rgb", "--chessboard", "9x6", "--square-size", "0.025",
             "--out", "{out}")
EXPORT = ("export", "--run", "{world}/runs/aae", "--format", "tflite", "--out", "{out}")


def _images_of_two_sizes(world: World, folder: Path) -> None:
    from paz6d.backend.image import save_image

    save_image(folder / "shots" / "a.png", np.zeros((48, 64, 3), np.uint8))
    save_image(folder / "shots" / "b.png", np.zeros((24, 32, 3), np.uint8))


def calibrate_and_export_cases() -> list[Case]:
    """``paz6d calibrate`` (images, board flags, output folder) and ``paz6d export`` (run, format, inputs)."""
    found = _flag_cases("calibrate-", CALIBRATE, {
        "--images": [(("{case}/none",), "is not a folder"), (("{world}/results.csv",), "is not a folder"),
                     ((), "--images")],
        "--chessboard": [(("9by6",), "COLSxROWS"), (("2x6",), "at least 3"), (("",), "COLSxROWS"),
                         ((), "--chessboard --charuco")],
        "--square-size": [(("0",), ""), (("nan",), ""), (("-1",), ""), (("x",), "")],
        "--min-views": [(("2",), ""), (("x",), "")],
        "--depth-scale": [(("0",), ""), (("nan",), "")],
        "--out": [(("{world}/results.csv",), "--out")],
    })
    found += [
        Case("calibrate-no-board", CALIBRATE, None, ("found in 0 of 2 images", "--min-views")),
        Case("calibrate-folder-empty", replace_flag(CALIBRATE, "--images", "{case}/shots"), case_file("shots", "<dir>"),
             ("shots", "no image file")),
        Case("calibrate-image-garbage", replace_flag(CALIBRATE, "--images", "{case}/shots"),
             case_file("shots/a.png", b"\x89PNG\r\n\x1a\nbroken"), ("a.png",)),
        Case("calibrate-image-sizes", replace_flag(CALIBRATE, "--images", "{case}/shots"), _images_of_two_sizes,
             ("b.png", "32x24", "64x48")),
        Case("calibrate-marker-without-charuco", CALIBRATE + ("--marker-size", "0.01"), None, ("--marker-size",)),
        Case("calibrate-charuco-without-marker", replace_flag(replace_flag(CALIBRATE, "--chessboard"), "--charuco",
                                                              "7x5"), None, ("--marker-size",)),
        Case("calibrate-charuco-marker-too-big", replace_flag(replace_flag(CALIBRATE, "--chessboard"), "--charuco",
                                                              "7x5") + ("--marker-size", "0.03"), None,
             ("--marker-size", "less than --square-size")),
        Case("calibrate-charuco-dictionary", replace_flag(replace_flag(CALIBRATE, "--chessboard"), "--charuco", "7x5")
             + ("--marker-size", "0.01", "--dictionary", "DICT_X"), None, ("--dictionary", "DICT_X")),
    ]
    found += _flag_cases("export-", EXPORT, {
        "--run": [(("{case}/none",), "is not a directory"), (("{world}/bop",), "not a run directory of any method"),
                  (("{world}/runs/aae",), "model.keras")],
        "--format": [(("pdf",), ""), ((), "--format")],
        "--inputs": [(("1",), ""), (("x",), "")],
        "--out": [(("{world}/results.csv",), "--out"), (("{world}/runs/aae",), "--out")],
    })
    return found


def all_cases() -> list[Case]:
    """The table: every case, names unique."""
    found = generate_cases() + evaluate_bop_cases() + evaluate_coco_cases() + evaluate_voc_cases() + \
        estimate_cases() + estimate_images_cases() + train_cases() + output_rule_cases() + dataset_path_cases() + \
        annotation_cases() + late_validation_cases() + run_cases() + calibrate_and_export_cases() + \
        run_directory_cases()
    names = [case.name for case in found]
    duplicated = {name for name in names if names.count(name) > 1}
    if duplicated:
        raise AssertionError(f"duplicated case names: {sorted(duplicated)}")
    return found
