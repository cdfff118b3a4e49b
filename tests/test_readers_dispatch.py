"""read_clips / read_robot_clip: dispatch by suffix and npz keys, folders, skipped files."""

import shutil
import struct
import zipfile

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared

from pipeline.readers import npz_kind, read_clips, read_robot_clip, read_robot_clips
from pipeline.readers.amass import read_amass
from pipeline.readers.keypoints import read_keypoints_npz
from pipeline.readers.peers import read_beyondmimic_npz
from pipeline.robot import G1_JOINT_NAMES

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Head
  {
    OFFSET 0 0.7 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 0.2 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.02
0 0.9 0 0 0 0 0 0 0
0.1 0.9 0 0 0 0 0 0 0
"""


def _keypoints(path, T=3):
    np.savez(path, joint_pos=np.ones((T, 2, 3)), joint_names=["a", "b"], fps=10)
    return path


def _robot(path, T=3):
    q = np.zeros((T, 36))
    q[:, 3] = 1
    np.savez(path, fps=[50], joint_pos=q, joint_names=np.array(G1_JOINT_NAMES))
    return path


def test_folder_reads_sorted_clips_and_skips_the_rest(tmp_path):
    (tmp_path / "b_walk.bvh").write_text(BVH)
    _keypoints(tmp_path / "a_keys.npz")
    sub = tmp_path / "more"
    sub.mkdir()
    _keypoints(sub / "c_keys.npz")
    deeper = sub / "deeper"
    deeper.mkdir()
    _keypoints(deeper / "ignored.npz")  # two levels down: not searched
    _robot(tmp_path / "peer_g1.npz")  # a robot motion is not a human clip
    (tmp_path / "box.obj").write_text("v 0 0 0\n")
    (tmp_path / "height_dict.pkl").write_bytes(b"\x80\x04}\x94.")
    np.savez(tmp_path / "other.npz", something=np.zeros(3))
    clips = read_clips(tmp_path)
    assert [c.source.split("/")[-1] for c in clips] == ["a_keys.npz", "b_walk.bvh", "c_keys.npz"]
    assert clips[1].fps == 50 and clips[1].skeleton.joint_names == ("Hips", "Head")


def test_single_files_and_errors(tmp_path):
    k = _keypoints(tmp_path / "k.npz")
    assert read_clips(k)[0].frames == 3
    r = _robot(tmp_path / "g1.npz")
    expect_input_error(lambda: read_clips(r), tmp_path, file=r, field="joint_pos", match="read_robot_clip")
    u = tmp_path / "clip.fbx"
    u.write_text("x")
    expect_input_error(lambda: read_clips(u), tmp_path, file=u, field="suffix", match=r"unknown clip format '\.fbx'")
    missing = tmp_path / "nope.bvh"
    expect_input_error(lambda: read_clips(missing), tmp_path, file=missing, field="input", match="does not exist")
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no clips here")
    expect_input_error(lambda: read_clips(empty), tmp_path, file=empty, field="input", match="no readable human clips")


def test_bad_clip_in_a_folder_is_an_error(tmp_path):
    (tmp_path / "a.bvh").write_text(BVH)
    (tmp_path / "b.bvh").write_text(BVH.replace("Frames: 2", "Frames: 3"))
    bad = tmp_path / "b.bvh"
    expect_input_error(lambda: read_clips(tmp_path), tmp_path, file=bad, field="MOTION", frame=2)


def test_npz_kinds_and_robot_dispatch(tmp_path):
    assert npz_kind(_keypoints(tmp_path / "k.npz")) == "keypoints"
    assert npz_kind(_robot(tmp_path / "r.npz")) == "robot"
    np.savez(tmp_path / "a.npz", poses=np.zeros((2, 156)), trans=np.zeros((2, 3)))
    assert npz_kind(tmp_path / "a.npz") == "amass"
    assert read_robot_clip(tmp_path / "r.npz").frames == 3
    k = tmp_path / "k.npz"
    expect_input_error(lambda: read_robot_clip(k), tmp_path, file=k, field="joint_pos", match="not a G1 motion")
    b = tmp_path / "walk.bvh"
    b.write_text(BVH)
    expect_input_error(lambda: read_robot_clip(b), tmp_path, file=b, field="suffix", match=".npz, .pkl or .csv")


def _npy(header: bytes, data: bytes) -> bytes:
    """A ``.npy`` member by hand: magic, version 1.0, header length, header padded to 128 bytes, data."""
    header = header.ljust(117) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + data


def _damaged(tmp_path, how):
    """A ``.npz`` that numpy cannot read: empty, one ``.npy`` array, truncated, a garbled ``.npy`` header, a member
    shorter than its header says, or damaged deflated data."""
    p = tmp_path / f"{how}.npz"
    if how == "empty":
        p.write_bytes(b"")
    elif how == "npy":  # one array saved with np.save, named .npz
        with open(p, "wb") as f:
            np.save(f, np.zeros((3, 2, 3)))
    elif how == "truncated":
        _keypoints(p, T=50)
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    elif how in ("header", "short"):  # a well-formed zip (right CRCs) whose joint_pos.npy numpy cannot parse
        header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (3, 2, 3), }" if how == "short" else b"((((("
        with zipfile.ZipFile(p, "w") as z:
            z.writestr("joint_pos.npy", _npy(header, bytes(8)))  # 8 of the 144 data bytes
            z.writestr("fps.npy", _npy(b"{'descr': '<f8', 'fortran_order': False, 'shape': (), }", bytes(8)))
    else:  # deflated: the compressed joint_pos data zeroed
        np.savez_compressed(p, joint_pos=np.random.default_rng(0).random((50, 2, 3)), joint_names=["a", "b"], fps=10)
        raw = bytearray(p.read_bytes())
        start = raw.index(b"joint_pos.npy") + len("joint_pos.npy") + 20
        raw[start : start + 40] = bytes(40)
        p.write_bytes(bytes(raw))
    return p


@pytest.mark.parametrize("how", ["empty", "npy", "truncated", "header", "short", "deflated"])
def test_unreadable_npz_is_a_one_line_error(tmp_path, how):
    """``make retarget INPUT=x.npz`` (read_clips) and every npz reader: an empty, truncated or corrupt file is a
    one-line InputError naming it, never numpy's EOFError / BadZipFile traceback."""
    p = _damaged(tmp_path, how)
    match = {"empty": "is empty", "npy": "not an npz archive"}.get(how, "not a readable npz")
    for call in (
        lambda: read_clips(p),
        lambda: read_clips(tmp_path),  # inside a folder too: a damaged clip is an error, not skipped
        lambda: npz_kind(p),
        lambda: read_robot_clip(p),
        lambda: read_robot_clips(tmp_path),
        lambda: read_keypoints_npz(p, fps=30),
        lambda: read_amass(p, body_model=tmp_path),
        lambda: read_beyondmimic_npz(p),
    ):
        expect_input_error(call, tmp_path, file=p, field="file", match=match)


@needs_shared
def test_shared_folders(tmp_path):
    (clip,) = read_clips(SHARED_MOCAP / "omomo")  # the mesh and height_dict.pkl beside it are skipped
    assert clip.frames == 196 and clip.objects[0].name == "largebox"
    assert [c.frames for c in read_clips(SHARED_MOCAP / "bvh")] == [10, 1064]  # lafan1_... sorts before pymo_...
    e = expect_input_error(
        lambda: read_clips(SHARED_MOCAP / "amass"),
        SHARED_MOCAP / "amass",
        file=SHARED_MOCAP / "amass" / "amass_sample.npz",
        field="body_model",
    )
    assert "--body-model" in str(e)
    with pytest.raises(Exception, match="no readable human clips"):
        read_clips(SHARED_MOCAP / "omniretarget")  # only a robot motion there
    shutil.copy(SHARED_MOCAP / "omomo" / "sub3_largebox_003.pt", tmp_path / "sub3_largebox_003.pt")
    expect_input_error(lambda: read_clips(tmp_path), tmp_path, file=tmp_path / "sub3_largebox_003.pt", field="mesh")
    (clip,) = read_clips(tmp_path, mesh=SHARED_MOCAP / "omomo" / "largebox.obj")
    assert clip.objects[0].geometry.path.endswith("largebox.obj")


def test_csv_dispatch_by_content(tmp_path):
    """A ``.csv`` of 36 numbers a row without a header is a Unitree G1 motion (read_robot_clip, skipped by the human
    readers inside a folder, refused alone); one with a header row stays a keypoints clip; ``fmt=`` names the format
    where the content would not (a robot CSV with a header)."""
    from pipeline.readers import csv_kind

    rows = np.zeros((3, 36))
    rows[:, 6] = 1.0  # quaternion xyzw = identity
    robot = tmp_path / "g1.csv"
    np.savetxt(robot, rows, delimiter=",")
    keys = tmp_path / "keys.csv"
    keys.write_text("time,a_x,a_y,a_z\n0,0,0,1\n0.1,0,0,1\n")
    assert (csv_kind(robot), csv_kind(keys)) == ("robot", "keypoints")
    clip = read_robot_clip(robot)
    assert clip.fps == 30 and clip.frames == 3 and read_robot_clip(robot, fps=50).fps == 50
    np.testing.assert_allclose(clip.qpos[:, 3:7], [[1, 0, 0, 0]] * 3)
    assert [c.source.split("/")[-1] for c in read_clips(tmp_path)] == ["keys.csv"]
    expect_input_error(lambda: read_clips(robot), tmp_path, file=robot, field="columns", match="read_robot_clip")
    assert [c.frames for c in read_robot_clips(tmp_path)] == [3]
    expect_input_error(lambda: read_robot_clip(keys), tmp_path, file=keys, field="columns", match="Unitree G1 CSV")
    named = tmp_path / "named.txt"
    named.write_text(",".join(f"c{k}" for k in range(36)) + "\n" + robot.read_text())
    assert read_robot_clip(named, fmt="unitree-csv").frames == 3
    expect_input_error(lambda: read_robot_clip(named, fmt="bvh"), tmp_path, file=named, field="format")
