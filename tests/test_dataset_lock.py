"""One writer per dataset (pipeline.stage.lock): real processes racing for one ``datasets/<NAME>/``."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.errors import InputError
from pipeline.stage.lock import LOCK_NAME, dataset_lock, process_start

HOLD = """
import sys, time
from pipeline.stage.lock import dataset_lock
with dataset_lock(sys.argv[1], command="holder"):
    print("held", flush=True)
    time.sleep(120)
"""


def _env(root: Path) -> dict:
    return {**os.environ, "LESSMIMIC_DATASETS": str(root), "HF_HUB_OFFLINE": "1"}


def _cli(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "lessmimic.cli", *args], env=_env(root), capture_output=True, text=True, timeout=300
    )


def _holder(folder: Path) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def _wait_for(path: Path, proc: subprocess.Popen, seconds: float = 120) -> None:
    t0 = time.monotonic()
    while not (path.is_file() and path.stat().st_size):
        assert proc.poll() is None, "the first writer ended before taking its lock"
        assert time.monotonic() - t0 < seconds
        time.sleep(0.05)


def test_two_retargets_on_one_name_the_second_stops_naming_the_first(tmp_path):
    """Issue 55, case 1: ``retarget --input A --name x &`` then ``--input B --name x``."""
    first = subprocess.Popen(
        [sys.executable, "-m", "lessmimic.cli", "retarget", "--input", "synthetic:0:PickUp", "--name", "x"],
        env=_env(tmp_path),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(tmp_path / "x" / LOCK_NAME, first)
    second = _cli(tmp_path, "retarget", "--input", "synthetic:1:PickUp", "--name", "x")
    assert second.returncode == 2
    line = second.stderr.strip()
    assert "\n" not in line and line.startswith(f"error: {tmp_path / 'x'}: lock: held by pid {first.pid} ("), line
    assert "retarget --input synthetic:0:PickUp" in line
    assert first.wait(timeout=300) == 0, first.stderr
    for stage in ("human", "retargeted"):  # the first run's input only
        report = json.loads((tmp_path / "x" / stage / "report.json").read_text())
        assert report["input"] == "synthetic:0:PickUp"
    assert not (tmp_path / "x" / LOCK_NAME).exists()  # released


def test_a_killed_writers_lock_is_taken_over_with_a_line(tmp_path):
    folder = tmp_path / "x"
    holder = _holder(folder)
    held = _cli(tmp_path, "features", "--name", "x")
    assert held.returncode == 2 and f"lock: held by pid {holder.pid} (holder, since " in held.stderr
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert (folder / LOCK_NAME).is_file()  # what a kill -9 leaves
    after = _cli(tmp_path, "features", "--name", "x")
    lines = after.stderr.strip().splitlines()
    assert lines[0].startswith(f"{folder}: lock: took over the stale lock of pid {holder.pid} (holder, since ")
    assert lines[0].endswith("): no longer running")
    assert after.returncode == 2 and lines[-1].startswith("error: ") and "no physicalized dataset" in lines[-1]
    assert not (folder / LOCK_NAME).exists()


def test_a_lock_naming_a_running_process_is_held_even_without_flock(tmp_path):
    """A lock file whose flock is free (a file system without flock) but whose writer runs is held: pid + start."""
    folder = tmp_path / "x"
    folder.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        while process_start(sleeper.pid) is None:
            time.sleep(0.01)
        me = {"pid": sleeper.pid, "start": process_start(sleeper.pid), "since": time.time(), "command": "elsewhere"}
        (folder / LOCK_NAME).write_text(json.dumps(me))
        with pytest.raises(InputError, match=f"lock: held by pid {sleeper.pid} \\(elsewhere"):
            with dataset_lock(folder):
                pass
        me["start"] += 1  # the same pid, another process (a reused pid): stale
        (folder / LOCK_NAME).write_text(json.dumps(me))
        with dataset_lock(folder):
            assert json.loads((folder / LOCK_NAME).read_text())["pid"] == os.getpid()
    finally:
        sleeper.kill()
        sleeper.wait()


def test_the_lock_is_reentrant_and_leaves_nothing(tmp_path):
    folder = tmp_path / "root" / "x"
    with dataset_lock(folder):
        with dataset_lock(folder):
            assert (folder / LOCK_NAME).is_file()
        assert (folder / LOCK_NAME).is_file()
    assert not (tmp_path / "root").exists()  # the folders the lock made, empty again, are gone
    with pytest.raises(RuntimeError):
        with dataset_lock(folder):
            raise RuntimeError
    assert not (tmp_path / "root").exists()


def _shard(root: Path) -> Path:
    from pipeline.clip import RobotClip
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import write_dataset
    from pipeline.robot import actuator_profile, default_qpos

    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    return write_dataset(root, "lessmimic/shard", 50, features, episodes)


def test_merge_holds_the_writer_lock_of_its_output(tmp_path):
    """Issue 55, part 1: ``merge --out datasets/<NAME>/...`` is a writer of NAME like every other; outside the datasets
    root it holds the lock of the folder it writes into."""
    shard = _shard(tmp_path / "shards" / "a")
    holder = _holder(tmp_path / "x")
    try:
        out = tmp_path / "x" / "merged"
        held = _cli(tmp_path, "merge", str(shard), "--out", str(out), "--repo-id", "lessmimic/merged")
        assert held.returncode == 2 and held.stderr.strip().startswith(
            f"error: {tmp_path / 'x'}: lock: held by pid {holder.pid} (holder, since "
        ), held.stderr
        assert "\n" not in held.stderr.strip() and not out.exists()
    finally:
        holder.kill()
        holder.wait()
    assert _cli(tmp_path, "merge", str(shard), "--out", str(out), "--repo-id", "lessmimic/merged").returncode == 0
    assert (out / "meta" / "info.json").is_file() and not (tmp_path / "x" / LOCK_NAME).exists()
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    holder = _holder(outside)
    try:
        held = _cli(tmp_path, "merge", str(shard), "--out", str(outside / "m"), "--repo-id", "lessmimic/merged")
        assert held.returncode == 2 and f"error: {outside}: lock: held by pid {holder.pid}" in held.stderr
    finally:
        holder.kill()
        holder.wait()
