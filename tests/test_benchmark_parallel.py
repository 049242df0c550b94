"""`paz6d.benchmark.parallel`: tasks in spawned processes, at most N at once, failures named; and
`import_tensorflow(threads=)`, which gives each side-by-side training its share of the cores."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from paz6d.benchmark.parallel import run_in_processes, threads_per_job


def record_run(folder: str, name: str) -> None:
    """A task: while it runs, ``folder/running/<name>`` exists; it logs its pid and how many tasks ran with it."""
    running = Path(folder) / "running"
    (running / name).touch()
    time.sleep(0.3)
    alongside = len(list(running.iterdir()))
    (running / name).unlink()
    (Path(folder) / f"{name}.done").write_text(f"{os.getpid()} {alongside}")


def fail(folder: str, name: str) -> None:
    raise ValueError(f"{name} fails on purpose")


def test_every_task_runs_once_in_its_own_process_and_never_more_than_jobs_at_once(tmp_path):
    (tmp_path / "running").mkdir()
    names = [f"task{i}" for i in range(3)]
    run_in_processes([(name, record_run, (str(tmp_path), name)) for name in names], jobs=2)
    logs = {name: (tmp_path / f"{name}.done").read_text().split() for name in names}
    pids = {int(pid) for pid, _ in logs.values()}
    assert len(pids) == 3 and os.getpid() not in pids
    assert max(int(alongside) for _, alongside in logs.values()) <= 2
    assert not list((tmp_path / "running").iterdir())


def test_a_failing_task_is_named_and_later_tasks_do_not_start(tmp_path):
    (tmp_path / "running").mkdir()
    with pytest.raises(RuntimeError, match="broken task: its process failed"):
        run_in_processes([("broken task", fail, (str(tmp_path), "x")),
                          ("later", record_run, (str(tmp_path), "later"))], jobs=1)
    assert not (tmp_path / "later.done").exists()
    with pytest.raises(ValueError, match="jobs: expected at least 1"):
        run_in_processes([], jobs=0)


def test_a_benchmark_stage_runs_in_a_spawned_process_and_leaves_its_marker(tmp_path):
    from paz6d.benchmark.lmo import Benchmark, BenchmarkSettings, _run_side_by_side, stage_done, stages

    (tmp_path / "lmo" / "models").mkdir(parents=True)
    (tmp_path / "lmo" / "models" / "obj_000001.ply").write_text("ply\n")
    (tmp_path / "lmo" / "test").mkdir()
    settings = BenchmarkSettings(images=2, backgrounds=2, detector_steps=1, aae_steps=1, aae_in_plane=1,
                                 keypointnet_steps=1, keypointnet_views=1, detector_input_size=128)
    job = Benchmark(out=tmp_path / "bench", lmo=tmp_path / "lmo", settings=settings, progress=False, jobs=2)
    _run_side_by_side(job, ["backgrounds"])
    name, _, outputs = stages(job)[0]
    assert name == "backgrounds" and stage_done(job, name, outputs)
    assert len(list((job.out / "backgrounds").iterdir())) == 2
    assert json.loads(job.marker(name).read_text())["seconds"] > 0
    with pytest.raises(RuntimeError, match="synthetic: its process failed"):  # the meshes are not meshes
        _run_side_by_side(job, ["synthetic"])


def test_cores_are_shared_out_between_jobs():
    assert threads_per_job(1, cores=2) == 2
    assert threads_per_job(2, cores=2) == 1
    assert threads_per_job(4, cores=2) == 1  # never 0
    assert threads_per_job(3, cores=16) == 5


def test_import_tensorflow_limits_its_thread_pools_and_refuses_once_they_run():
    script = """
from paz6d.backend.tensorflow_guard import import_tensorflow
tf = import_tensorflow(threads=1)
print(tf.config.threading.get_intra_op_parallelism_threads(), tf.config.threading.get_inter_op_parallelism_threads())
tf.constant(1.0) + 1.0
import_tensorflow(threads=1)  # the same limit again: fine
try:
    import_tensorflow(threads=2)
except RuntimeError as error:
    print("refused:", error)
"""
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[0] == "1 1"
    assert lines[1].startswith("refused: threads: TensorFlow already runs")
