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

from ingest.default_input import default_clips
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


def _bvh(folder: Path, xs, rs=None, name="take.bvh", sideways=False) -> Path:
    """A two-joint BVH at 30 Hz; ``sideways``: its rest pose lies flat and it has no head or ankle, so its units
    cannot be guessed."""
    rs = rs if rs is not None else [10] * len(xs)
    rows = "".join(ROW.format(x=x, r=r) + "\n" for x, r in zip(xs, rs))
    path = folder / name
    header = HEADER.replace("OFFSET 0 50 0", "OFFSET 50 0 0") if sideways else HEADER
    path.write_text(header + f"Frames: {len(xs)}\nFrame Time: 0.0333333\n" + rows)
    return path


def _keypoints_csv(folder: Path, *, drop=(), lurch_cm=0.0, name="take.csv") -> Path:
    """The default PickUp's first 40 frames of joints as a keypoints CSV in centimetres with no time column (no rate,
    and metres assumed: the file says neither); ``lurch_cm``: every joint moved that far along x from frame 20 on."""
    clip = next(c for c in default_clips() if c.task == "PickUp")
    names = [n for n in clip.skeleton.joint_names if n not in drop]
    pos = clip.joint_pos[:40, [clip.skeleton.joint_names.index(n) for n in names]] * 100.0
    pos[20:, :, 0] += lurch_cm
    rows = [",".join(f"{n}_{a}" for n in names for a in "xyz")] + [",".join(f"{v:.4f}" for v in p.ravel()) for p in pos]
    path = folder / name
    path.write_text("\n".join(rows) + "\n")
    return path


def _c3d_blank_labels(folder: Path) -> Path:
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("", "")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, 2, 30))
    data[2] = 1000.0
    c["data"]["points"] = data
    path = folder / "blank.c3d"
    c.write(str(path))
    return path


def _triangle(folder: Path) -> Path:
    path = folder / "triangle.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return path


def _no_objects(folder: Path) -> None:
    """datasets/bare/physicalized/: a physicalized dataset of one clip with no object track."""
    from pipeline.clip import RobotClip
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import write_dataset
    from pipeline.robot import actuator_profile, default_qpos

    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    write_dataset(folder.parent / "datasets" / "bare" / "physicalized", "lessmimic/bare", 50, features, episodes)


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


def _standing_qpos() -> np.ndarray:
    """A standing G1's qpos (36,), each joint a little off its default, so that every column differs."""
    from pipeline.robot import actuator_profile, default_qpos

    return default_qpos(actuator_profile("mjlab")) + np.r_[np.zeros(7), 0.01 * np.arange(1, 30)]


def _nameless_npz(folder: Path, order=None) -> Path:
    """:func:`_standing_qpos` as a BeyondMimic ``.npz`` with ``joint_pos [T, 36]`` and no joint names nor bodies: its
    order cannot be told. ``order``: its joint columns in these names' order (default mjlab's)."""
    from pipeline.robot import G1_JOINT_NAMES
    from retarget.clip import FPS

    qpos = _standing_qpos()
    cols = [7 + G1_JOINT_NAMES.index(n) for n in order or G1_JOINT_NAMES]
    path = folder / "nameless.npz"
    np.savez(path, fps=[FPS], joint_pos=np.tile(np.r_[qpos[:7], qpos[cols]], (10, 1)))
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
    (
        "--object-mesh a folder",
        lambda d: ["retarget", "--input", str(_bvh(d, [0, 1])), "--object-mesh", str(d)],
        2,
        "inputs: mesh: is a folder; give the object's mesh file",
    ),
    (
        "a one-triangle mesh",
        lambda d: ["retarget", "--input", str(_bvh(d, [0, 1])), "--object-mesh", str(_triangle(d))],
        2,
        "triangle.obj: mesh: has 3 vertices: too few to enclose a volume",
    ),
    ("--fps 0", lambda d: ["retarget", "--input", str(_bvh(d, [0, 1])), "--fps", "0"], 2, "--fps: must be a positive"),
    ("--units on the synthetic input", lambda d: ["retarget", "--units", "cm"], 2, "--units: applies to mocap files"),
    (
        "a CSV with no rate",
        lambda d: ["retarget", "--input", str(_keypoints_csv(d))],
        2,
        "take.csv: fps: no time column; pass --fps N$",
    ),
    (
        "a BVH whose units cannot be guessed",
        lambda d: ["retarget", "--input", str(_bvh(d, [0, 1], sideways=True))],
        2,
        "take.bvh: units: cannot guess units .*; pass --units m \\(or cm, mm, inch\\)$",
    ),
    (
        "a dataset with no object tracks",
        lambda d: _no_objects(d) or ["features", "--name", "bare"],
        2,
        "bare/physicalized: objects: the dataset has no object tracks",
    ),
    ("verify a missing folder", lambda d: ["verify", "/nonexistent/x"], 2, "is not a dataset folder"),
    (
        "a nameless npz whose order cannot be told",
        lambda d: ["import", "--input", str(_nameless_npz(d))],
        2,
        "nameless.npz: joint_names: missing, and .* cannot be told: pass --joint-names mjlab or isaaclab, or the",
    ),
    (
        "--joint-names not the 29 joints",
        lambda d: ["import", "--input", str(_nameless_npz(d)), "--joint-names", "a,b"],
        2,
        "a,b: --joint-names: 2 names; not G1 joints: a, b; missing: .* \\(and 25 more\\): expected mjlab or isaaclab",
    ),
    (
        "--joint-names with no npz to apply to",
        lambda d: ["inspect", str(_bvh(d, [0, 1])), "--out", str(d / "x.mcap"), "--joint-names", "mjlab"],
        2,
        "take.bvh: --joint-names: applies to a G1 motion \\(--robot\\)",
    ),
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


@pytest.mark.skipif(not Path("/sys").is_dir(), reason="needs /sys (sysfs: no file can be made in it)")
def test_an_output_where_nothing_can_be_written_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    """Issue 55, case 6: a read-only or /sys output folder was a traceback (then a line naming no file)."""
    monkeypatch.chdir(tmp_path)
    bvh = _bvh(tmp_path, [0, 1])
    before = _tree(tmp_path)
    assert main(["inspect", str(bvh), "--out", "/sys/lessmimic-x.mcap"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("error: /sys/lessmimic-x.mcap: "), err
    assert _tree(tmp_path) == before and not Path("/sys/lessmimic-x.mcap").exists()


@pytest.mark.skipif(not Path("/sys").is_dir(), reason="needs /sys (sysfs: no file can be made in it)")
def test_an_export_where_nothing_can_be_written_names_the_out_given(tmp_path, monkeypatch, capsys):
    """Issue 55, case 6: export-motion's unwritable --out named its staging folder beside it
    ('error: /sys/.x.staging-3781-f949296c: Operation not permitted'), a path the user never gave."""
    import errno

    from motion_export import stage
    from pipeline.clip import RobotClip
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import write_dataset
    from pipeline.robot import actuator_profile, default_qpos

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    monkeypatch.chdir(tmp_path)
    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    write_dataset(tmp_path / "datasets/x/retargeted", "lessmimic/x-retargeted", 50, features, episodes)
    export = ["export-motion", "--name", "x", "--stage", "retargeted", "--format", "gmr", "--out"]
    before = _tree(tmp_path)
    for out, why in (
        ("/sys/lessmimic-x", "cannot be written: "),  # sysfs: no folder can be made in it
        ("/proc/lessmimic-x", "cannot be written: "),
        ("/sys/lessmimic-x/y", "its folder /sys/lessmimic-x does not exist \\(make it first\\)"),
        (str(tmp_path / "no" / "x"), re.escape(f"its folder {tmp_path / 'no'} does not exist (make it first)")),
    ):
        assert main([*export, out]) == 2
        err = capsys.readouterr().err.strip()
        assert re.fullmatch(f"error: {re.escape(out)}: out: {why}[^\\n]*", err), err
        assert "staging" not in err and not Path(out).exists() and not (tmp_path / "no").exists()

    def full_disk(ep, folder, stem):  # a failure in the middle names the file as the --out given holds it
        (folder / f"{stem}.pkl").write_bytes(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(folder / f"{stem}.pkl"))

    monkeypatch.setitem(stage.FORMATS, "gmr", full_disk)
    out = tmp_path / "out"
    assert main([*export, str(out)]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress bar
    assert last == f"error: {out}/0000_hand-made_stand.pkl: out: cannot be written: No space left on device", last
    assert _tree(tmp_path) == before


def test_the_flag_the_order_error_names_exists_and_fixes_it(tmp_path, monkeypatch, capsys):
    """Issue 55, case 8: a nameless .npz whose order its kinematics cannot tell asked for ``joint_names=``, which no
    command has; the flag it names now exists in every command that reads G1 motions, and fixes the case end to
    end: the columns, given in Isaac Lab's order, land on mjlab's joints."""
    from lessmimic.cli import build_parser
    from motion_export.episodes import select_episodes
    from pipeline.isaaclab_order import ISAACLAB_JOINT_NAMES

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    npz = _nameless_npz(tmp_path, order=ISAACLAB_JOINT_NAMES)
    assert main(["import", "--input", str(npz), "--name", "n"]) == 2
    flag = re.search(r"pass (--[\w-]+) ", capsys.readouterr().err).group(1)
    parser = build_parser()
    for argv in (["import"], ["inspect", "f", "--out", "o", "--robot"], ["evaluate-retarget", "f"]):
        assert getattr(parser.parse_args([*argv, flag, "isaaclab"]), flag[2:].replace("-", "_")) == "isaaclab"
    names = tmp_path / "names.txt"
    names.write_text("\n".join(ISAACLAB_JOINT_NAMES) + "\n")
    want = _standing_qpos()
    for name, value in (("named", "isaaclab"), ("listed", ",".join(ISAACLAB_JOINT_NAMES)), ("file", str(names))):
        assert main(["import", "--input", str(npz), "--name", name, flag, value]) == 0, capsys.readouterr().err
        (ep,) = select_episodes(name, "retargeted").episodes
        np.testing.assert_allclose(ep.clip.qpos, np.tile(want, (ep.clip.frames, 1)), atol=1e-6)
        assert ep.clip.provenance["joint_order"].startswith("no joint names: the names given (--joint-names)")
    assert main(["import", "--input", str(npz), "--name", "wrong", flag, "mjlab"]) == 0  # told, not checked
    assert not np.allclose(select_episodes("wrong", "retargeted").episodes[0].clip.qpos[0], want, atol=1e-3)


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


def _as_at_a_terminal() -> None:
    """The child's SIGINT as a terminal gives it (default and unblocked): a test worker may hold it ignored or
    blocked, which a child inherits (measured: the command ran to the end, exit 0, in 2 of 2 full `make test` runs
    after other test files, never alone)."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_is_one_line(tmp_path):
    env = {**os.environ, "LESSMIMIC_DATASETS": str(tmp_path), "HF_HUB_OFFLINE": "1"}
    held = (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, set()))
    proc = subprocess.Popen([sys.executable, "-m", "lessmimic.cli", "retarget", "--name", "x"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_as_at_a_terminal)  # fmt: skip
    while not (tmp_path / "x" / ".work" / "retargeted" / "run.json").is_file():  # at work on the clips
        assert proc.poll() is None
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 130, f"the worker's SIGINT handler and blocked signals: {held}"
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


# Issue 55, case 4: a clip that fails only in the retargeting (after it was read) leaves nothing either: exit 1, its
# one error line and "retargeted nothing", no human/, no logs, no .work, no lock.
PER_CLIP = [
    ("a 1-frame BVH", lambda d: ["--input", str(_bvh(d, [0]))], "take.bvh: frames: a clip needs at least 2 frames"),
    ("blank C3D labels", lambda d: ["--input", str(_c3d_blank_labels(d))], "blank.c3d: skeleton: no joint mapping"),
    (
        "a keypoints CSV with no head",
        lambda d: ["--input", str(_keypoints_csv(d, drop=("head",))), "--fps", "30", "--units", "cm"],
        "take.csv: skeleton: no joint mapping fits this skeleton",
    ),
]


@pytest.mark.parametrize("case, argv, error", PER_CLIP, ids=[c[0] for c in PER_CLIP])
def test_a_clip_failing_in_the_retargeting_leaves_nothing(case, argv, error, tmp_path, monkeypatch, capsys):
    root, inputs = tmp_path / "datasets", tmp_path / "inputs"
    root.mkdir()
    inputs.mkdir()
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(root))
    monkeypatch.chdir(tmp_path)
    args = ["retarget", *argv(inputs)]
    before = _tree(tmp_path)
    assert main(args) == 1
    captured = capsys.readouterr()
    lines = [ln for ln in captured.out.splitlines() if ln.startswith(("error: ", "retargeted "))]
    assert len(lines) == 2 and re.search(error, lines[0]), lines
    assert lines[1] == "retargeted nothing: every clip failed (1); datasets/default/ is left as it was"
    assert "error" not in captured.err
    assert _tree(tmp_path) == before


def test_the_stages_check_before_they_claim_their_output(tmp_path, monkeypatch):
    """Issue 55, case 4: without the command line's undo, the stage itself refuses a dataset with no object tracks
    (features) and a mesh that is a folder or one triangle (import) before it writes its resume record."""
    from features.stage import run_stage as features
    from pipeline.errors import InputError

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    _no_objects(tmp_path / "inputs")
    before = _tree(tmp_path)
    with pytest.raises(InputError, match="objects: the dataset has no object tracks"):
        features("bare")
    assert _tree(tmp_path) == before  # no .work/features/run.json, no logs/features/
    if not SHARED_MOCAP.is_dir():
        return
    from retarget.imported import run_stage as import_stage

    npz = SHARED_MOCAP / "omniretarget" / "sub3_largebox_003_mj_w_obj.npz"
    for mesh, error in ((tmp_path, "mesh: is a folder"), (_triangle(tmp_path), "has 3 vertices")):
        before = _tree(tmp_path)
        with pytest.raises(InputError, match=error):
            import_stage(str(npz), "x", object_mesh=str(mesh))
        assert _tree(tmp_path) == before
