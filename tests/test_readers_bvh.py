"""BVH reader: real LAFAN1 / PyMO files, forward kinematics against hand-computed poses, bad files."""

import time

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared

from pipeline.readers.bvh import read_bvh
from pipeline.rotations import rotation_from_wxyz

WALK = SHARED_MOCAP / "bvh" / "pymo_walk_120hz.bvh"
LAFAN = SHARED_MOCAP / "bvh" / "lafan1_dance1_subject2_10frames.bvh"

# A 3-joint chain, y-up, cm: root (6 channels, ZYX), a joint with XYZ order, a joint with a
# position channel, an End Site. Rows: root pos, root rot (Z Y X), arm rot (X Y Z), hand (Ypos, Zrot).
HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {
    OFFSET 0 50 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    JOINT Hand
    {
      OFFSET 30 0 0
      CHANNELS 2 Yposition Zrotation
      End Site
      {
        OFFSET 10 0 0
      }
    }
  }
}
MOTION
"""


def _bvh(tmp_path, rows, frames=None, frame_time="0.0333333", name="chain.bvh"):
    frames = len(rows) if frames is None else frames
    text = HEADER + f"Frames: {frames}\nFrame Time: {frame_time}\n" + "".join(r + "\n" for r in rows)
    p = tmp_path / name
    p.write_text(text)
    return p


ROW0 = "10 100 20 30 20 10 90 40 15 5 0"
ROW1 = "10 100 20 -15 90 5 0 30 90 0 45"


def _axis(axis, deg):
    """Elementary rotation matrix, written out (independent of scipy's Euler conventions)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def _expected(row):
    """Hand-computed FK of the chain in the file's frame (cm, y-up): R = R_c1 R_c2 R_c3 per joint."""
    v = [float(x) for x in row.split()]
    R_root = _axis("Z", v[3]) @ _axis("Y", v[4]) @ _axis("X", v[5])
    R_arm = R_root @ _axis("X", v[6]) @ _axis("Y", v[7]) @ _axis("Z", v[8])
    p_root = np.array(v[:3])
    p_arm = p_root + R_root @ [0, 50, 0]
    p_hand = p_arm + R_arm @ [30, v[9], 0]  # Yposition replaces the offset's y
    R_hand = R_arm @ _axis("Z", v[10])
    return np.stack([p_root, p_arm, p_hand]), [R_root, R_arm, R_hand]


def test_forward_kinematics_matches_hand_computation(tmp_path):
    c = read_bvh(_bvh(tmp_path, [ROW0, ROW1]), units="cm", up="y")
    assert c.skeleton.joint_names == ("Hips", "Arm", "Hand") and c.skeleton.parents == (
        -1,
        0,
        1,
    )  # End Site is not a joint
    A = _axis("X", 90)  # y-up -> z-up: y becomes z
    for t, row in enumerate([ROW0, ROW1]):
        pos, rots = _expected(row)
        np.testing.assert_allclose(c.joint_pos[t], pos @ A.T * 0.01, atol=1e-9)
        for j, r in enumerate(rots):
            np.testing.assert_allclose(rotation_from_wxyz(c.joint_quat[t, j]).as_matrix()[0], A @ r, atol=1e-9)


def test_channel_order_matters(tmp_path):
    """The same angles under XYZ and ZYX give different poses (intrinsic composition, listed order)."""
    row = "10 100 20 30 0 0 90 40 0 5 0"
    xyz = read_bvh(_bvh(tmp_path, [row], name="xyz.bvh"), units="cm", up="y")
    p = tmp_path / "zyx.bvh"
    p.write_text(
        HEADER.replace("CHANNELS 3 Xrotation Yrotation Zrotation", "CHANNELS 3 Zrotation Yrotation Xrotation")
        + f"Frames: 1\nFrame Time: 0.0333333\n{row}\n"
    )
    zyx = read_bvh(p, units="cm", up="y")
    assert np.abs(xyz.joint_pos[0, 2] - zyx.joint_pos[0, 2]).max() > 0.05
    np.testing.assert_allclose(xyz.joint_pos[0, :2], zyx.joint_pos[0, :2])  # the arm's own origin does not move


def test_units_and_up_options(tmp_path):
    p = _bvh(tmp_path, [ROW0])
    cm, inch = read_bvh(p, units="cm", up="y"), read_bvh(p, units="inch", up="y")
    np.testing.assert_allclose(inch.joint_pos, cm.joint_pos * 2.54)
    z = read_bvh(p, units="cm", up="z")
    np.testing.assert_allclose(z.joint_pos[0, 0], [0.1, 1.0, 0.2])  # untouched axes
    assert cm.fps == 30.0  # 0.0333333 s snaps to 30 Hz


@needs_shared
def test_pymo_walk_inches_tpose_120hz():
    read_bvh(WALK)  # warm the imports
    t0 = time.perf_counter()
    c = read_bvh(WALK)
    seconds = time.perf_counter() - t0
    assert seconds < 1.0, f"parsing the 1064-frame walk took {seconds:.2f} s"
    names = c.skeleton.joint_names
    assert c.frames == 1064 and c.fps == 120.0 and len(names) == 23
    assert 1.5 < c.subject_height < 1.9  # rest T-pose extent, inches -> m
    p = c.joint_pos
    head, hips = p[:, names.index("Head")], p[:, names.index("Hips")]
    assert np.all(head[:, 2] - hips[:, 2] > 0.4)  # upright in every frame
    feet = p[:, [names.index(n) for n in ("LeftFoot", "RightFoot", "LeftToeBase", "RightToeBase")], 2]
    lowest = feet.min(axis=1)
    assert np.all(lowest > -0.02) and np.all(lowest < 0.15), (lowest.min(), lowest.max())  # on the floor, z-up
    assert np.ptp(hips[:, :2], axis=0).max() > 2.0 and np.ptp(hips[:, 2]) < 0.2  # walks horizontally
    np.testing.assert_allclose(np.linalg.norm(c.joint_quat, axis=-1), 1.0, atol=1e-9)


@needs_shared
def test_lafan1_cm_zyx_yup():
    c = read_bvh(LAFAN)
    names = c.skeleton.joint_names
    assert c.frames == 10 and c.fps == 30.0 and len(names) == 22
    p = c.joint_pos
    assert np.all(p[:, names.index("Head"), 2] - p[:, 0, 2] > 0.5)  # y-up detected and rotated to z-up
    toes = p[:, [names.index("LeftToe"), names.index("RightToe")], 2]
    assert np.all(toes.min(axis=1) < 0.1) and np.all(toes > -0.02)
    assert 0.8 < np.median(p[:, 0, 2]) < 1.0  # hips 90 cm above the floor: cm detected
    assert 1.6 < c.subject_height < 2.0  # no upright rest pose: head-to-ankle bone path


@pytest.mark.parametrize(
    "rows, kw, field, frame, match",
    [
        ([ROW0], dict(frames=3), "MOTION", 1, r"1 motion rows but Frames: says 3 \(truncated\?\)"),
        ([ROW0, ROW1], dict(frames=1), "MOTION", 1, r"2 motion rows but Frames: says 1 \(extra rows\)"),
        ([ROW0, "10 100 20 30 0 0 90 0 0 5"], {}, "MOTION line 25", 1, r"has 10 values, the hierarchy has 11 channels"),
        ([ROW0, ROW0, "10 100 20 30 nan 0 90 0 0 5 0"], {}, "Hips.Yrotation", 2, r"NaN or infinite"),
        ([ROW0, "10 inf 20 30 0 0 90 0 0 5 0"], {}, "Hips.Yposition", 1, r"NaN or infinite"),
        ([], dict(frames=0), "Frames", None, r"zero frames"),
        ([ROW0], dict(frame_time="0"), "Frame Time", None, r"must be positive"),
        ([ROW0], dict(frame_time="-0.01"), "Frame Time", None, r"must be positive"),
        ([ROW0, "10 100 20 30 0 0 90 0 0 5 x"], {}, "MOTION line 25", 1, r"not a number"),
    ],
)
def test_bad_bvh(tmp_path, rows, kw, field, frame, match):
    p = _bvh(tmp_path, rows, **kw)
    expect_input_error(lambda: read_bvh(p, units="cm"), tmp_path, file=p, field=field, frame=frame, match=match)


def test_bad_units_and_header(tmp_path):
    p = _bvh(tmp_path, [ROW0])
    expect_input_error(
        lambda: read_bvh(p, units="furlong"), tmp_path, file=p, field="units", match="unknown units 'furlong'"
    )
    q = tmp_path / "bad_channel.bvh"
    q.write_text(
        HEADER.replace("Zrotation Yrotation Xrotation", "Zrotation Yrotation Wrotation", 1)
        + "Frames: 1\nFrame Time: 0.1\n"
        + ROW0
    )
    expect_input_error(
        lambda: read_bvh(q), tmp_path, file=q, field="HIERARCHY line 5", match="unknown channel 'Wrotation'"
    )
