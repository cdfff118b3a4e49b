"""Peers' G1 outputs: the OmniRetarget (BeyondMimic-format) npz and GMR pickles."""

import pickle

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared

from pipeline.geometry import MeshGeometry
from pipeline.readers.peers import read_beyondmimic_npz, read_gmr_pkl
from pipeline.robot import G1_JOINT_NAMES
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
        lambda: read_beyondmimic_npz(q), tmp_path, file=q, field="joint_names", match="pass joint_names="
    )
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
