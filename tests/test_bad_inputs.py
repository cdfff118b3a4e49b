"""The bad-input suite (issue 55): every bad input or misuse is one ``error:`` line with its exit status, and the
datasets root holds nothing new afterwards (no ``human/``, no logs, no ``.work``, no lock, no empty folder)."""

import os
import pickle
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import ezc3d
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from lessmimic.cli import main

HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {
    OFFSET 0 50 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 10 0 0
    }
  }
}
MOTION
"""
ROW = "{x} 100 20 30 20 {r} 90 40 15"


def _bvh(folder: Path, xs, rs=None, name="take.bvh") -> Path:
    rs = rs if rs is not None else [10] * len(xs)
    rows = "".join(ROW.format(x=x, r=r) + "\n" for x, r in zip(xs, rs))
    path = folder / name
    path.write_text(HEADER + f"Frames: {len(xs)}\nFrame Time: 0.0333333\n" + rows)
    return path


def _c3d_cut(folder: Path) -> Path:
    """A C3D of 300 frames cut to about a third of its bytes (its header still says 300)."""
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("a", "b")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, 2, 300))
    data[0] = np.linspace(0, 900, 300)
    data[2] = 1000.0
    c["data"]["points"] = data
    path = folder / "cut.c3d"
    c.write(str(path))
    raw = path.read_bytes()
    head = (raw[2] - 1) * 512  # the data start block (header word 2)
    path.write_bytes(raw[: head + (len(raw) - head) // 3])
    return path


def _omomo_height(folder: Path, height: float) -> Path:
    src = SHARED_MOCAP / "interact"
    take = folder / "take"
    take.mkdir()
    for f in ("sub2_largetable_001.pt", "largetable.obj"):
        shutil.copy(src / f, take / f)
    heights = pickle.loads((src / "height_dict.pkl").read_bytes())
    (take / "height_dict.pkl").write_bytes(pickle.dumps({**heights, "sub2": height}))
    return take / "sub2_largetable_001.pt"


def _fifo(folder: Path) -> Path:
    path = folder / "fifo.bvh"
    os.mkfifo(path)
    return path


# (case, the command line given the inputs folder, exit status, what the error line holds)
CASES = [
    ("height -1", lambda d: ["retarget", "--height", "-1"], 2, "-1.0: --height: must be the subject's height"),
    ("height 3 m", lambda d: ["retarget", "--height", "3"], 2, "--height: must be the subject's height"),
    (
        "hips jump 1e9 cm",
        lambda d: ["retarget", "--input", str(_bvh(d, [0, 1, 1e9, 3]))],
        2,
        "take.bvh: frame 2: Hips position: moves .* m/s since the frame before",
    ),
    (
        "rotation 1e9 degrees",
        lambda d: ["retarget", "--input", str(_bvh(d, [0, 1, 2, 3], rs=[10, 1e9, 10, 10]))],
        2,
        "take.bvh: frame 1: Hips.Xrotation: 1e\\+09 degrees is beyond \\+-720",
    ),
    ("C3D cut to a third", lambda d: ["retarget", "--input", str(_c3d_cut(d))], 2, "frames: the header promises 300"),
    ("a FIFO as input", lambda d: ["retarget", "--input", str(_fifo(d))], 2, "fifo.bvh: input: is neither a file"),
    ("features with nothing upstream", lambda d: ["features"], 2, "no physicalized dataset here"),
    (
        "inspect --out below a missing folder",
        lambda d: ["inspect", str(_bvh(d, [0, 1])), "--out", str(d / "no" / "x.mcap")],
        2,
        "--out: its folder",
    ),  # fmt: skip
    ("load offline", lambda d: ["load", "owner/repo"], 2, "owner/repo: hub: not downloaded here"),
    ("verify a missing folder", lambda d: ["verify", "/nonexistent/x"], 2, "is not a dataset folder"),
]


def _tree(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*"))


@pytest.mark.parametrize("case, argv, status, error", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_leaves_nothing(case, argv, status, error, tmp_path, monkeypatch, capsys):
    root, inputs = tmp_path / "datasets", tmp_path / "inputs"
    root.mkdir()
    inputs.mkdir()
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(root))
    monkeypatch.chdir(tmp_path)
    args = argv(inputs)
    before = _tree(tmp_path)
    assert main(args) == status
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert re.search(error, lines[0]), lines[0]
    assert _tree(tmp_path) == before  # nothing new anywhere: datasets root, inputs, working folder


@needs_shared
@pytest.mark.parametrize("height", [-5.0, 7.0])
def test_a_height_dict_height_outside_a_person_is_an_error(height, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    take = _omomo_height(tmp_path, height)
    assert main(["retarget", "--input", str(take)]) == 2
    err = capsys.readouterr().err.strip()
    pkl = take.parent / "height_dict.pkl"
    assert err == f"error: {pkl}: height_dict['sub2']: {height:g} m is not a subject height (0.5-2.5 m)"
    assert not (tmp_path / "datasets").exists()


def test_datasets_root_that_is_a_file_is_one_line(tmp_path, monkeypatch, capsys):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "file"))
    assert main(["features"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("error: ") and str(tmp_path / "file") in err


def test_a_failed_overwrite_leaves_the_previous_chain_intact(tmp_path, monkeypatch, capsys):
    """Issue 55, case 2: ``--overwrite`` with an input whose clips all fail left ``human/`` new and ``retargeted/``
    old; now the command exits 1 and ``datasets/x/`` is byte for byte what it was."""
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    assert main(["retarget", "--input", "synthetic:0:PickUp", "--name", "x"]) == 0
    name = tmp_path / "datasets" / "x"
    files = {p: p.read_bytes() for p in name.rglob("*") if p.is_file()}
    capsys.readouterr()
    one_frame = _bvh(tmp_path, [0])  # read, then refused by the retargeting: every clip fails
    assert main(["retarget", "--input", str(one_frame), "--name", "x", "--overwrite"]) == 1
    out = capsys.readouterr().out
    assert "retargeted nothing: every clip failed (1); datasets/x/ is left as it was" in out
    assert {p: p.read_bytes() for p in name.rglob("*") if p.is_file()} == files
    assert main(["retarget", "--input", "synthetic:0:PickUp", "--name", "x"]) == 0  # still up to date
    assert "is up to date" in capsys.readouterr().out


def test_ctrl_c_is_one_line(tmp_path):
    env = {**os.environ, "LESSMIMIC_DATASETS": str(tmp_path), "HF_HUB_OFFLINE": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "lessmimic.cli", "retarget", "--name", "x"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    while not (tmp_path / "x" / ".work" / "retargeted" / "run.json").is_file():  # at work on the clips
        assert proc.poll() is None
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130
    lines = [ln for ln in err.splitlines() if ln.startswith("error") or "Traceback" in ln]
    assert lines == ["error: interrupted (Ctrl-C): nothing half-written was kept; the same command resumes where it "
                     "stopped"]  # fmt: skip


def test_features_on_a_physicalized_dataset_without_its_info_names_it(tmp_path, monkeypatch, capsys):
    """Issue 55, case 3: a deleted meta/info.json made features say 'nothing to do ... none valid'."""
    from pipeline.clip import RobotClip
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import write_dataset
    from pipeline.robot import actuator_profile, default_qpos

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    root = write_dataset(tmp_path / "x" / "physicalized", "lessmimic/x-physicalized", 50, features, episodes)
    (root / "meta/info.json").unlink()
    before = _tree(tmp_path)
    assert main(["features", "--name", "x"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: {root}: meta/info.json: missing (the checksums list it): the dataset is incomplete"
    assert _tree(tmp_path) == before
