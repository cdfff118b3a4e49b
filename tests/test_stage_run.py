"""The stage recipe (pipeline.stage.run): up to date, resume after kill -9 at any point, the same datasets on
every executor (local processes, a local Ray instance)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from pipeline.errors import InputError
from pipeline.stage.executor import map_ordered
from pipeline.stage.run import StageRun, digest


def _square(x: int) -> int:
    return x * x


def _square_once(item: tuple[Path, int]) -> int:
    """x^2, leaving a file per call so a test can count the calls."""
    folder, x = item
    (folder / f"call-{x}-{time.monotonic_ns()}").touch()
    return x * x


def test_map_keeps_the_order_on_every_executor():
    items = list(range(7))
    assert map_ordered(_square, items) == [x * x for x in items]
    assert map_ordered(_square, items, jobs=2) == [x * x for x in items]
    with pytest.raises(InputError, match="--executor: unknown executor"):
        map_ordered(_square, items, executor="slurm")


def test_begin_refuses_another_runs_dataset_and_resumes_its_own(tmp_path):
    out = tmp_path / "name" / "retargeted"
    out.mkdir(parents=True)  # a dataset some other run finished
    with pytest.raises(InputError, match="already exists; pass --overwrite"):
        StageRun(out, "fp-a").begin(overwrite=False)
    assert not (tmp_path / "name" / ".work").exists()  # refused before any work
    run = StageRun(out, "fp-a")
    run.begin(overwrite=True)
    assert run.replaces and run.finished() is None
    # killed now: the same run again owns `out` (it may replace what it wrote), another run does not
    again = StageRun(out, "fp-a")
    again.begin(overwrite=False)
    assert again.replaces
    with pytest.raises(InputError, match="already exists"):
        StageRun(out, "fp-b").begin(overwrite=False)


def test_map_resumes_from_the_clips_an_interrupted_run_finished(tmp_path):
    calls = tmp_path / "calls"
    calls.mkdir()
    out = tmp_path / "name" / "features"

    def key(k, item):
        return digest(k, item[1])

    run = StageRun(out, "fp")
    run.begin(overwrite=False)
    assert run.map(_square_once, [(calls, 2), (calls, 3)], key=key) == [4, 9]
    resumed = StageRun(out, "fp")  # the same run, started again after a kill
    resumed.begin(overwrite=False)
    assert resumed.map(_square_once, [(calls, 2), (calls, 3), (calls, 4)], key=key) == [4, 9, 16]
    assert len(list(calls.iterdir())) == 3  # 2 and 3 came from the cache
    other = StageRun(out, "fp-other")  # other input or options: a fresh cache
    other.begin(overwrite=False)
    assert other.map(_square_once, [(calls, 2)], key=key) == [4] and len(list(calls.iterdir())) == 4


def test_finish_writes_the_done_mark_last_and_drops_the_work(tmp_path):
    out = tmp_path / "name" / "physicalized"
    run = StageRun(out, "fp")
    run.begin(overwrite=False)
    out.mkdir()  # the dataset this run wrote
    report = run.finish({"clips": []}, dataset_written=True)
    assert report["fingerprint"] == "fp" and not run.work.exists()
    assert json.loads((out / "report.json").read_text()) == report
    assert StageRun(out, "fp").finished() == report and StageRun(out, "fp2").finished() is None
    out.rename(tmp_path / "moved")  # the dataset gone: not up to date any more
    assert StageRun(out, "fp").finished() is None
    empty = StageRun(tmp_path / "name" / "features", "fp")  # a run that wrote no dataset is finished too
    empty.begin(overwrite=False)
    assert empty.finish({}, dataset_written=False)["dataset_written"] is False and empty.finished() is not None


# --- the default chain, end to end ------------------------------------------------------------------------------

STAGES = ("human", "retargeted", "physicalized", "features")
COMMANDS = (["retarget"], ["physicalize"], ["features"])
# Timings differ between any two runs; so do the fingerprints downstream of a report that holds them
# (pipeline.stage.state.dataset_fingerprint hashes the previous stage's report).
TIMING = ("realtime", "seconds", "cpu", "per_s", "wall", "fingerprint")


def _chain(root: Path, *extra: str, stop_after: str | None = None) -> None:
    """``make retarget physicalize features`` (each stage's command in turn; up to ``stop_after``)."""
    env = {**os.environ, "LESSMIMIC_DATASETS": str(root), "HF_HUB_OFFLINE": "1"}
    for cmd in COMMANDS:
        done = subprocess.run(
            [sys.executable, "-m", "lessmimic", *cmd, *extra], env=env, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr[-2000:]
        if cmd[0] == stop_after:
            return


def _untimed(o):
    if isinstance(o, dict):
        return {k: _untimed(v) for k, v in o.items() if not any(t in k for t in TIMING)}
    return [_untimed(v) for v in o] if isinstance(o, list) else o


def _datasets(root: Path) -> dict:
    """Every stage's frames, per-episode metadata and report, without the timing figures."""
    out = {}
    for stage in STAGES:
        d = root / "default" / stage
        out[stage] = {
            "data": pd.concat([pd.read_parquet(p) for p in sorted((d / "data").rglob("*.parquet"))]),
            "episodes": [_untimed(json.loads(line)) for line in (d / "meta/lessmimic_episodes.jsonl").open()],
            "info": json.loads((d / "meta/info.json").read_text()),
            "report": _untimed(json.loads((d / "report.json").read_text())),
        }
    return out


def _assert_same(a: dict, b: dict) -> None:
    for stage in STAGES:
        pd.testing.assert_frame_equal(a[stage]["data"], b[stage]["data"], check_exact=True)
        for k in ("episodes", "info", "report"):
            assert a[stage][k] == b[stage][k], (stage, k)


def _kill_when(cmd: list[str], root: Path, ready) -> None:
    """Start ``lessmimic <cmd>`` and SIGKILL it as soon as ``ready()`` holds (polled every 5 ms)."""
    env = {**os.environ, "LESSMIMIC_DATASETS": str(root), "HF_HUB_OFFLINE": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "lessmimic", *cmd], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 600
    while not ready() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert proc.poll() is None, f"{cmd} finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()


@pytest.mark.slow
def test_kill_9_anywhere_in_the_chain_then_the_same_command_gives_identical_datasets(tmp_path):
    """The chain killed at five points in the order ``make retarget physicalize features`` reaches them (mid-way
    through a stage's clips; between a stage's dataset commit and its report) and started again each time: the
    datasets of an uninterrupted run."""
    clean = tmp_path / "clean"
    _chain(clean)
    root = tmp_path / "killed"
    name = root / "default"

    def clips_done(stage: str, n: int):
        return lambda: len(list((name / ".work" / stage / "clips").glob("*.pkl"))) >= n

    def committed(stage: str):  # the dataset renamed into place
        return lambda: (name / stage / "meta" / "info.json").is_file()

    for command, stage, kills in (
        ("retarget", "retargeted", (clips_done("retargeted", 1), committed("retargeted"))),
        ("physicalize", "physicalized", (clips_done("physicalized", 2), committed("physicalized"))),
        ("features", "features", (committed("features"),)),
    ):
        for ready in kills:
            _kill_when([command], root, ready)
            assert not (name / "logs" / stage / "report.json").is_file(), f"{command} finished before the kill"
        assert (name / ".work" / stage / "run.json").is_file()
        if command != "features":
            _chain(root, stop_after=command)
    _chain(root)  # the same command again: what is finished is up to date, the rest resumes
    _assert_same(_datasets(root), _datasets(clean))
    assert not any((name / ".work").glob("*/run.json"))


@pytest.mark.slow
def test_a_local_ray_cluster_gives_the_datasets_of_two_worker_processes(tmp_path):
    pytest.importorskip("ray")
    _chain(tmp_path / "jobs", "-j", "2")
    _chain(tmp_path / "ray", "-j", "2", "--executor", "ray")
    _assert_same(_datasets(tmp_path / "ray"), _datasets(tmp_path / "jobs"))
