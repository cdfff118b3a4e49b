"""Mapping files, skeleton matching and rotation offsets on the real skeletons.

The real files (OMOMO, PyMO walk, LAFAN1) live in ``../shared/mocap`` and are skipped cleanly
when absent; the synthetic default clips always run.
"""

from __future__ import annotations

import dataclasses
import json
from functools import cache

import mujoco
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared
from scipy.spatial.transform import Rotation

from ingest.default_input import default_clips
from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError
from pipeline.robot import g1_xml_path
from pipeline.rotations import rotation_from_wxyz, wxyz_from_rotation
from retarget.frames import body_axes, rest_positions
from retarget.mapping import (
    CORE_BODIES,
    G1_ROLES,
    MAPPINGS_DIR,
    g1_rest,
    human_points,
    load_mapping,
    map_human,
    mapping_files,
    read_spec,
)
from retarget.scaling import compute_scale, human_to_targets

OMOMO = SHARED_MOCAP / "omomo" / "sub3_largebox_003.pt"
PYMO = SHARED_MOCAP / "bvh" / "pymo_walk_120hz.bvh"
LAFAN = SHARED_MOCAP / "bvh" / "lafan1_dance1_subject2_10frames.bvh"


@cache
def real_clip(name: str) -> HumanClip:
    from pipeline.readers import read_clip

    return read_clip({"omomo": OMOMO, "pymo": PYMO, "lafan1": LAFAN}[name])


def clip_named(name: str) -> HumanClip:
    return default_clips()[0] if name == "synthetic" else real_clip(name)


CLIPS = [
    pytest.param("synthetic", id="synthetic"),
    pytest.param("omomo", id="omomo", marks=needs_shared),
    pytest.param("pymo", id="pymo", marks=needs_shared),
    pytest.param("lafan1", id="lafan1", marks=needs_shared),
]
EXPECTED = {"synthetic": "smpl", "omomo": "smpl", "pymo": "bvh_generic", "lafan1": "lafan1"}


def rot(q: np.ndarray) -> np.ndarray:
    return rotation_from_wxyz(q).as_matrix().reshape(q.shape[:-1] + (3, 3))


def tilt_deg(R: np.ndarray) -> np.ndarray:
    """Angle between a rotation's z axis and the world's up."""
    return np.degrees(np.arccos(np.clip(R[..., 2, 2], -1.0, 1.0)))


def angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    return np.degrees(Rotation.from_matrix((np.swapaxes(Ra, -1, -2) @ Rb).reshape(-1, 3, 3)).magnitude())


# --- files -----------------------------------------------------------------------------------------


def test_shipped_files_are_valid_and_name_real_g1_bodies():
    model = mujoco.MjModel.from_xml_path(str(g1_xml_path()))
    bodies = {model.body(i).name for i in range(model.nbody)}
    assert set(G1_ROLES) <= bodies
    rest = g1_rest()
    assert all(a in rest.pos for role in G1_ROLES.values() for a in role.robot_aim)
    names = [p.stem for p in mapping_files()]
    assert {"smpl", "lafan1", "bvh_generic", "mixamo"} <= set(names)
    assert names.index("lafan1") < names.index("bvh_generic")  # the more specific file first
    for path in mapping_files():
        spec = read_spec(path)
        assert set(CORE_BODIES) <= set(spec["links"]) <= set(G1_ROLES)
        for e in spec["links"].values():
            assert e["pos_weight"] >= 0 and e["rot_weight"] >= 0


@pytest.mark.parametrize("name", CLIPS)
def test_each_skeleton_gets_its_mapping(name):
    clip = clip_named(name)
    m = load_mapping(clip.skeleton, source=clip.source)
    assert m.name == EXPECTED[name]
    assert set(m.body_names) == set(read_spec(MAPPINGS_DIR / f"{m.name}.json")["links"])
    assert all(link.joint in clip.skeleton.joint_names and link.aim in clip.skeleton.joint_names for link in m.links)


@needs_shared
def test_candidates_pick_what_the_skeleton_has():
    hands = {n: load_mapping(clip_named(n).skeleton).link("left_wrist_yaw_link") for n in ("omomo", "pymo", "lafan1")}
    assert (hands["omomo"].aim, hands["omomo"].aim_sign) == ("left_middle1", 1.0)  # SMPL-H fingers
    assert (hands["pymo"].aim, hands["pymo"].aim_sign) == ("LeftHand_End", 1.0)
    assert (hands["lafan1"].aim, hands["lafan1"].aim_sign) == ("LeftForeArm", -1.0)  # along the forearm
    assert load_mapping(clip_named("synthetic").skeleton).link("left_wrist_yaw_link").aim == "left_elbow"


def test_unknown_skeleton_lists_its_joints_and_the_files_tried():
    skel = Skeleton(("root", "thingA", "thingB"), (-1, 0, 1))
    with pytest.raises(InputError) as info:
        load_mapping(skel, source="weird.bvh")
    e, msg = info.value, str(info.value)
    assert e.field == "skeleton" and msg.startswith("weird.bvh: skeleton: ") and "\n" not in msg
    assert "root, thingA, thingB" in msg
    for path in mapping_files():
        assert path.name in msg
    assert "missing pelvis" in msg and "missing Hips" in msg


def test_explicit_mapping_by_name_path_and_mismatch(tmp_path):
    skel = clip_named("synthetic").skeleton
    assert load_mapping(skel, "smpl").name == "smpl"
    assert load_mapping(skel, str(MAPPINGS_DIR / "smpl.json")).name == "smpl"
    with pytest.raises(InputError, match=r"skeleton: .*tried lafan1\.json \(missing Hips"):
        load_mapping(skel, "lafan1", source="x")
    with pytest.raises(InputError) as info:
        load_mapping(skel, "no_such_mapping", source="x")
    assert info.value.field == "mapping" and "smpl" in str(info.value)
    spec = json.loads((MAPPINGS_DIR / "smpl.json").read_text())
    spec["links"]["pelvis"]["pos_weight"] = 3.0
    (tmp_path / "mine.json").write_text(json.dumps(spec))
    assert load_mapping(skel, str(tmp_path / "mine.json")).link("pelvis").pos_weight == 3.0


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda s: s["links"].pop("left_knee_link"), "links"),
        (lambda s: s["links"]["pelvis"].update(rot_weight=-1), "links.pelvis.rot_weight"),
        (lambda s: s["links"].update(nose_link=s["links"]["pelvis"]), "links.nose_link"),
        (lambda s: s["links"]["pelvis"].update(aim=[]), "links.pelvis.aim"),
        (lambda s: s.pop("required"), "required"),
        (lambda s: s["links"].pop("left_shoulder_roll_link"), "links"),
    ],
)
def test_malformed_mapping_file_names_file_and_field(tmp_path, edit, field):
    spec = json.loads((MAPPINGS_DIR / "smpl.json").read_text())
    edit(spec)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(spec))
    with pytest.raises(InputError) as info:
        read_spec(path)
    assert info.value.field == field and str(info.value).startswith(f"{path}: ")


# --- rotation offsets ------------------------------------------------------------------------------


def upright_rest_clip(clip: HumanClip, yaw_deg: float) -> HumanClip:
    """The skeleton's rest pose (all global rotations equal), stood upright on the floor facing
    ``yaw_deg``, as a 2-frame clip."""
    m = load_mapping(clip.skeleton)
    R = rot(clip.joint_quat)
    rest = rest_positions(clip.joint_pos, R, clip.skeleton)
    L, U, F = body_axes(human_points(rest[None], clip.skeleton, m), m)
    Q = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix() @ np.stack([F[0], L[0], U[0]])
    pos = np.repeat((rest @ Q.T)[None], 2, axis=0)
    pos[..., 2] -= pos[0, :, 2].min()
    quat = np.repeat(wxyz_from_rotation(Rotation.from_matrix(np.repeat(Q[None], len(rest), 0)))[None], 2, axis=0)
    return HumanClip(
        clip.skeleton, pos, 30.0, clip.source + "#rest", subject_height=clip.subject_height, joint_quat=quat
    )


@pytest.mark.parametrize("name", [p for p in CLIPS if p.values[0] != "lafan1"])
def test_rest_pose_targets_are_the_g1_zero_pose(name):
    """In the (upright) rest pose every trunk/leg target is the G1's q = 0 rotation, up to the
    rest pose's heading; legs differ only by the angle between the human's and the G1's bones."""
    clip = upright_rest_clip(clip_named(name), yaw_deg=-141.0)
    mh = map_human(clip, load_mapping(clip.skeleton))
    assert compute_scale(mh).reference.label == "rest pose"
    tg = human_to_targets(mh)
    g = g1_rest()
    R = {b: rot(tg.quat[0, k]) for k, b in enumerate(tg.body_names)}
    heading = R["pelvis"] @ g.rot["pelvis"].T
    assert np.degrees(Rotation.from_matrix(heading).as_rotvec())[2] == pytest.approx(-141.0, abs=1e-6)
    for b in ("pelvis", "torso_link"):
        assert angle_deg(heading @ g.rot[b], R[b]) < 1e-4
    for s in ("left", "right"):
        for b in (f"{s}_hip_pitch_link", f"{s}_knee_link"):
            assert angle_deg(heading @ g.rot[b], R[b]) < 15.0
        foot = R[f"{s}_ankle_roll_link"]
        assert tilt_deg(foot) < 1e-3  # level, only toe-out differs


@pytest.mark.parametrize("name", CLIPS)
def test_segment_directions_are_carried_over_exactly(name):
    """For every frame the G1 segment axis (body -> its child at q = 0, in the body frame), turned
    by the target rotation, points along the human segment: offsets are computed, not guessed."""
    clip = clip_named(name)
    mh = map_human(clip, load_mapping(clip.skeleton))
    tg, P, g = human_to_targets(mh), mh.points, g1_rest()
    for s in ("left", "right"):
        for body, child in (
            ("hip_pitch_link", "knee_link"),
            ("knee_link", "ankle_roll_link"),
            ("shoulder_roll_link", "elbow_link"),
            ("elbow_link", "wrist_yaw_link"),
        ):
            b, c = f"{s}_{body}", f"{s}_{child}"
            axis = g.rot[b].T @ (g.pos[c] - g.pos[b])
            mapped = rot(tg.quat[:, tg.body_names.index(b)]) @ (axis / np.linalg.norm(axis))
            human = (P[c] - P[b]) / np.linalg.norm(P[c] - P[b], axis=-1, keepdims=True)
            assert np.degrees(np.arccos(np.clip(np.sum(mapped * human, -1), -1, 1))).max() < 0.01, b


@needs_shared
def test_lafan1_calibrates_on_its_most_upright_frame():
    clip = clip_named("lafan1")
    mh = map_human(clip, load_mapping(clip.skeleton))
    info = compute_scale(mh)
    assert info.reference.label.startswith("frame ")  # its zero-rotation pose lies along +x
    t = int(info.reference.label.split()[1])
    tg = human_to_targets(mh)
    for b in ("pelvis", "torso_link", "left_ankle_roll_link", "right_ankle_roll_link"):
        R = rot(tg.quat[t, tg.body_names.index(b)])
        assert tilt_deg(R) < 0.5  # upright trunk, level feet


@pytest.mark.parametrize("name", [p for p in CLIPS if p.values[0] in ("synthetic", "pymo")])
def test_positions_only_clip_gets_comparable_orientations(name):
    clip = clip_named(name)
    m = load_mapping(clip.skeleton)
    with_quat = human_to_targets(map_human(clip, m))
    without = human_to_targets(map_human(dataclasses.replace(clip, joint_quat=None), m))
    for b in ("pelvis", "left_ankle_roll_link", "right_ankle_roll_link"):
        k = with_quat.body_names.index(b)
        assert np.median(angle_deg(rot(with_quat.quat[:, k]), rot(without.quat[:, k]))) < 8.0
    arms = [k for k, b in enumerate(without.body_names) if G1_ROLES[b].kind in ("upper_arm", "forearm", "hand")]
    assert (without.rot_weight[arms] == 0).all() and (
        with_quat.rot_weight[arms] == np.array([m.links[k].rot_weight for k in arms])
    ).all()


@needs_shared
def test_mixamo_names_map_like_lafan1():
    """The same LAFAN1 motion under Mixamo names ('mixamorig:' prefix, ToeBase) picks mixamo.json
    and gives the same targets: the files differ in names only."""
    clip = clip_named("lafan1")
    rename = {n: "mixamorig:" + n.replace("Toe", "ToeBase") for n in clip.skeleton.joint_names}
    skel = Skeleton(tuple(rename[n] for n in clip.skeleton.joint_names), clip.skeleton.parents)
    mixamo = dataclasses.replace(clip, skeleton=skel)
    m = load_mapping(skel)
    assert m.name == "mixamo"
    a, b = human_to_targets(map_human(clip, load_mapping(clip.skeleton))), human_to_targets(map_human(mixamo, m))
    assert a.body_names == b.body_names and np.allclose(a.pos, b.pos) and np.allclose(a.quat, b.quat)
