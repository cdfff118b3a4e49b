"""Peers' G1 outputs: the OmniRetarget (BeyondMimic-format) npz, GMR pickles and HDMI motion folders."""

import json
import pickle

import mujoco
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared

from pipeline.geometry import MeshGeometry
from pipeline.readers import read_robot_clips
from pipeline.readers.peers import read_beyondmimic_npz, read_gmr_pkl, read_hdmi_motion, read_unitree_csv
from pipeline.robot import G1_JOINT_NAMES, actuator_profile, g1_model
from pipeline.rotations import xyzw_to_wxyz

OMNI = SHARED_MOCAP / "omniretarget" / "sub3_largebox_003_mj_w_obj.npz"
BOX_MESH = SHARED_MOCAP / "omomo" / "largebox.obj"


@pytest.fixture(scope="module")
def omni():
    if not OMNI.is_file():
        pytest.skip(f"{OMNI} not found")
    with np.load(OMNI) as d:
        return {k: d[k] for k in d.files}


@needs_shared
def test_omniretarget_npz(omni):
    assert [str(n) for n in omni["joint_names"]] == list(G1_JOINT_NAMES)  # the file already uses mjlab's order
    r = read_beyondmimic_npz(OMNI, object_geometry=MeshGeometry(str(BOX_MESH)))
    assert r.frames == 325 and r.fps == 50.0 and r.method == "peer:beyondmimic_npz"
    np.testing.assert_allclose(r.qpos[:, 7:], omni["joint_pos"][:, 7:])
    pelvis = list(omni["body_names"]).index("pelvis")
    np.testing.assert_allclose(r.qpos[:, 3:7], omni["body_quat_w"][:, pelvis], atol=1e-6)  # root quaternion is wxyz
    (obj,) = r.objects
    assert obj.name == "largebox" and obj.geometry.scale == (1.0, 1.0, 1.0)
    np.testing.assert_allclose(obj.pose[:, 3:], omni["object_quat_w"], atol=1e-6)


@needs_shared
def test_object_quaternion_is_wxyz_and_xy_scaled(omni):
    """Against the human clip (xyzw in the .pt): the peer's quaternion equals it in wxyz order."""
    from pipeline.readers.omomo import read_omomo

    human = read_omomo(SHARED_MOCAP / "omomo" / "sub3_largebox_003.pt").objects[0].resampled(30, 50)
    n = 325
    dots = np.abs(np.sum(human.pose[:n, 3:] * omni["object_quat_w"], axis=1))
    assert np.median(dots) > 0.999
    ratio = omni["object_pos_w"][:, :2] / human.pose[:n, :2]
    assert np.median(ratio) == pytest.approx(0.68, abs=0.005)
    assert omni["object_pos_w"][0, 2] == pytest.approx(human.pose[0, 2], abs=1e-3)  # resting height unscaled


@needs_shared
def test_reorder_by_name_and_object_scale(tmp_path, omni):
    perm = np.random.default_rng(0).permutation(29)
    d = dict(omni)
    d["joint_pos"] = np.concatenate([omni["joint_pos"][:, :7], omni["joint_pos"][:, 7:][:, perm]], axis=1)
    d["joint_names"] = omni["joint_names"][perm]
    p = tmp_path / "shuffled.npz"
    np.savez(p, **d)
    with pytest.warns(UserWarning, match="left out"):
        r = read_beyondmimic_npz(p)
    np.testing.assert_allclose(r.qpos, read_beyondmimic_npz(OMNI, object_geometry=MeshGeometry(str(BOX_MESH))).qpos)
    assert r.objects == () and r.provenance["object_left_out"] == "largebox"
    scaled = read_beyondmimic_npz(p, object_geometry=MeshGeometry(str(BOX_MESH)), object_scale=0.68)
    assert scaled.objects[0].geometry.scale == pytest.approx((0.68, 0.68, 0.68))
    d["joint_names"] = np.array([n if n != "waist_roll_joint" else "torso_joint" for n in d["joint_names"]])
    q = tmp_path / "renamed.npz"
    np.savez(q, **d)
    expect_input_error(
        lambda: read_beyondmimic_npz(q),
        tmp_path,
        file=q,
        field="joint_names",
        match="missing G1 joints: waist_roll_joint",
    )


def test_joints_only_npz_takes_root_from_bodies(tmp_path):
    T = 3
    body_pos, body_quat = np.zeros((T, 2, 3)), np.tile([1.0, 0, 0, 0], (T, 2, 1))
    body_pos[:, 1] = [0.1, 0.2, 0.8]
    p = tmp_path / "bm.npz"
    np.savez(
        p,
        fps=[50],
        joint_pos=np.zeros((T, 29)),
        joint_names=np.array(G1_JOINT_NAMES),
        body_pos_w=body_pos,
        body_quat_w=body_quat,
        body_names=np.array(["world", "pelvis"]),
    )
    r = read_beyondmimic_npz(p)
    np.testing.assert_allclose(r.qpos[:, :7], [[0.1, 0.2, 0.8, 1, 0, 0, 0]] * T)
    q = tmp_path / "nonames.npz"
    np.savez(q, fps=[50], joint_pos=np.zeros((T, 36)))
    expect_input_error(
        lambda: read_beyondmimic_npz(q), tmp_path, file=q, field="joint_names", match="pass --joint-names mjlab"
    )
    np.savez(q, fps=[50], joint_pos=np.tile(np.r_[0, 0, 0.8, 1, 0, 0, 0, 0.01 * np.arange(29)], (T, 1)))
    given = read_beyondmimic_npz(q, joint_names=G1_JOINT_NAMES[::-1])  # the names given read its columns
    np.testing.assert_allclose(given.qpos[0, 7:], 0.01 * np.arange(29)[::-1])
    backwards = list(G1_JOINT_NAMES)[::-1]  # names given for a file naming its own in another order: refused
    expect_input_error(lambda: read_beyondmimic_npz(p, joint_names=backwards), tmp_path, file=p, field="joint_names",
                       match="names its joints, in another order than the names given")  # fmt: skip
    assert read_beyondmimic_npz(p, joint_names=G1_JOINT_NAMES).provenance["joint_order"].startswith("reordered")
    s = tmp_path / "wide.npz"
    np.savez(s, fps=[50], joint_pos=np.zeros((T, 30)), joint_names=np.array(G1_JOINT_NAMES))
    expect_input_error(lambda: read_beyondmimic_npz(s), tmp_path, file=s, field="joint_pos", match=r"\(3, 30\)")


def _gmr(T=5, **over):
    root_rot = np.tile([0.0, 0.0, np.sin(0.3), np.cos(0.3)], (T, 1))  # xyzw, yaw 0.6 rad
    d = dict(
        fps=30,
        root_pos=np.tile([0.0, 0.0, 0.79], (T, 1)),
        root_rot=root_rot,
        dof_pos=np.linspace(0, 1, T * 29).reshape(T, 29),
        local_body_pos=None,
        link_body_list=["pelvis", "torso_link"],
    )
    d.update(over)
    return d


def _pkl(tmp_path, obj, name="motion.pkl"):
    p = tmp_path / name
    p.write_bytes(pickle.dumps(obj))
    return p


def test_gmr_pkl_roundtrip(tmp_path):
    d = _gmr()
    r = read_gmr_pkl(_pkl(tmp_path, d))
    assert r.frames == 5 and r.fps == 30 and r.method == "peer:gmr_pkl"
    np.testing.assert_allclose(r.qpos[:, 3:7], xyzw_to_wxyz(d["root_rot"]))
    np.testing.assert_allclose(r.qpos[0, 3:7], [np.cos(0.3), 0, 0, np.sin(0.3)])
    np.testing.assert_allclose(r.qpos[:, 7:], d["dof_pos"])
    assert r.provenance["link_body_list"] == ["pelvis", "torso_link"]


class _Evil:
    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_bad_gmr_files(tmp_path):
    p = _pkl(tmp_path, _gmr(dof_pos=np.zeros((5, 23))), "narrow.pkl")
    expect_input_error(
        lambda: read_gmr_pkl(p), tmp_path, file=p, field="dof_pos", match=r"shape \(5, 23\) does not match \(T, 29\)"
    )
    root = np.zeros((5, 3))
    root[4, 2] = np.inf
    q = _pkl(tmp_path, _gmr(root_pos=root), "inf.pkl")
    expect_input_error(lambda: read_gmr_pkl(q), tmp_path, file=q, field="root_pos", frame=4, match="NaN or infinite")
    s = _pkl(tmp_path, _gmr(root_rot=np.zeros((4, 4))), "short.pkl")
    expect_input_error(lambda: read_gmr_pkl(s), tmp_path, file=s, field="root_rot", match="has 4 frames, expected 5")
    target = tmp_path / "pwned.txt"
    e = _pkl(tmp_path, {"fps": 30, "x": _Evil(str(target))}, "evil.pkl")
    expect_input_error(lambda: read_gmr_pkl(e), tmp_path, file=e, field="file", match=r"refusing to load io\.open")
    assert not target.exists()


HDMI_WRISTS = [j for j in G1_JOINT_NAMES if "wrist_pitch" in j or "wrist_yaw" in j]  # HDMI's G1 has 25 joints


def _hdmi_walk(folder, first="root", T=4, placeholder=7.5):
    """An HDMI LAFAN1-walk-like folder: ``joint_names`` = ``first`` + the 25 joints, ``joint_pos`` [T, 26] whose first
    column is ``placeholder`` (not a joint), bodies by forward kinematics of a known qpos (no object). Returns it."""
    rng = np.random.default_rng(0)
    joints = [j for j in G1_JOINT_NAMES if j not in HDMI_WRISTS]
    qpos = np.zeros((T, 36))
    qpos[:, :3] = [0.3, -0.2, 0.78] + 0.01 * np.arange(T)[:, None]
    yaw = 0.1 * np.arange(T)
    qpos[:, 3], qpos[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    qpos[:, 7:] = actuator_profile("mjlab").default_joint_pos + 0.05 * rng.standard_normal((T, 29))
    for j in HDMI_WRISTS:  # HDMI has no such joints: the reader holds them at the default pose
        qpos[:, 7 + G1_JOINT_NAMES.index(j)] = actuator_profile("mjlab").default_joint_pos[G1_JOINT_NAMES.index(j)]
    m, d = g1_model(), mujoco.MjData(g1_model())
    bodies = [m.body(i).name for i in range(1, m.nbody)]
    pos, quat = np.zeros((T, len(bodies), 3)), np.zeros((T, len(bodies), 4))
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        pos[t], quat[t] = d.xpos[1:], d.xquat[1:]
    jp = np.concatenate([np.full((T, 1), placeholder), qpos[:, 7:][:, [G1_JOINT_NAMES.index(j) for j in joints]]], 1)
    folder.mkdir(parents=True)
    np.savez(folder / "motion.npz", joint_pos=jp, body_pos_w=pos, body_quat_w=quat)
    (folder / "meta.json").write_text(json.dumps({"fps": 30, "joint_names": [first, *joints], "body_names": bodies}))
    return qpos


def test_hdmi_root_placeholder_column_is_dropped(tmp_path):
    """HDMI's LAFAN1 walks name the free joint ``root`` in joint_names, with a joint_pos column: it is dropped, the
    25 joints land in mjlab order, the wrists are held, and the root is the pelvis body."""
    folder = tmp_path / "walk1_subject1"
    qpos = _hdmi_walk(folder)
    (clip,) = read_robot_clips(folder)  # what `make import INPUT=walk1_subject1` reads
    assert clip.qpos.shape == (4, 36) and clip.fps == 30 and clip.objects == ()
    assert clip.provenance["held_joints"] == HDMI_WRISTS
    np.testing.assert_allclose(clip.qpos[:, 7:], qpos[:, 7:], atol=1e-12)  # the 25 joints, and the held wrists
    pelvis = [g1_model().body(i).name for i in range(1, g1_model().nbody)].index("pelvis")
    np.testing.assert_allclose(clip.qpos[:, :3], qpos[:, :3], atol=1e-9)  # the pelvis body, not the 7.5 column
    np.testing.assert_allclose(np.abs((clip.qpos[:, 3:7] * qpos[:, 3:7]).sum(1)), 1, atol=1e-9)
    with np.load(folder / "motion.npz") as d:
        np.testing.assert_allclose(clip.qpos[:, :7], np.concatenate([d["body_pos_w"], d["body_quat_w"]], 2)[:, pelvis])
    assert np.array_equal(read_hdmi_motion(folder).qpos, clip.qpos)


@pytest.mark.parametrize("name", ["Root", "root_joint", "pelvis"])
def test_hdmi_other_unknown_joint_names_stay_errors(tmp_path, name):
    folder = tmp_path / "walk"
    _hdmi_walk(folder, first=name)
    expect_input_error(
        lambda: read_robot_clips(folder), tmp_path, file=folder, field="joint_names", match=f"not G1 joints: {name}$"
    )


def test_hdmi_unreadable_motion_npz_is_one_line(tmp_path):
    folder = tmp_path / "walk"
    _hdmi_walk(folder)
    npz = folder / "motion.npz"
    npz.write_bytes(npz.read_bytes()[:200])  # truncated mid-download
    expect_input_error(lambda: read_robot_clips(folder), tmp_path, file=npz, field="file", match="not a readable npz")
    npz.write_bytes(b"")
    expect_input_error(lambda: read_robot_clips(folder), tmp_path, file=npz, field="file", match="empty")
    bm = tmp_path / "bm.npz"
    bm.write_bytes(b"")
    expect_input_error(lambda: read_beyondmimic_npz(bm), tmp_path, file=bm, field="file", match="empty")


def _unitree_rows(T=4):
    """Unitree CSV rows (root xyz, quaternion xyzw, 29 joints) and the qpos they stand for."""
    rng = np.random.default_rng(1)
    qpos = np.zeros((T, 36))
    qpos[:, :3] = [0.1, 0.2, 0.78]
    yaw = 0.2 * np.arange(T)
    qpos[:, 3], qpos[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    qpos[:, 7:] = 0.1 * rng.standard_normal((T, 29))
    rows = np.concatenate([qpos[:, :3], qpos[:, [4, 5, 6, 3]], qpos[:, 7:]], axis=1)
    return rows, qpos


def test_unitree_csv(tmp_path):
    """Unitree's G1 CSV: 36 numbers a row, quaternion xyzw, 30 Hz unless told; a header row of names is skipped; a
    short row or a word is one line naming its row."""
    rows, qpos = _unitree_rows()
    p = tmp_path / "walk.csv"
    np.savetxt(p, rows, delimiter=",", fmt="%.17g")
    r = read_unitree_csv(p)
    assert r.fps == 30 and r.frames == 4 and r.method == "peer:unitree_csv"
    np.testing.assert_allclose(r.qpos, qpos, atol=1e-12)
    assert read_unitree_csv(p, fps=50).fps == 50
    h = tmp_path / "header.csv"
    h.write_text(",".join(f"c{k}" for k in range(36)) + "\n" + p.read_text())
    np.testing.assert_allclose(read_unitree_csv(h).qpos, r.qpos)
    lines = p.read_text().splitlines()
    s = tmp_path / "short.csv"
    s.write_text("\n".join([*lines[:2], lines[2].rsplit(",", 1)[0], lines[3]]) + "\n")
    expect_input_error(lambda: read_unitree_csv(s), tmp_path, file=s, field="row 3", frame=2, match="35 columns")
    w = tmp_path / "word.csv"
    w.write_text("\n".join([lines[0], lines[1].replace(",", ",x", 1)]) + "\n")
    expect_input_error(lambda: read_unitree_csv(w), tmp_path, file=w, field="row 2", frame=1, match="not a number")
