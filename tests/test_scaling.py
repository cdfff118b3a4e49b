"""Scale factors, scaled targets (pelvis height, feet on the floor, any start yaw), objects and the
bad-input cases, on the synthetic default clips and (when ``../shared/mocap`` exists) OMOMO,
the PyMO walk and LAFAN1."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from mocap_paths import needs_shared
from scipy.spatial.transform import Rotation
from test_mapping import CLIPS, clip_named

from ingest.default_input import default_clips, default_demos
from ingest.synthetic.skeleton import FOREARM, SHANK, THIGH, UPPER_ARM
from pipeline.clip import HumanClip, ObjectTrack
from pipeline.errors import InputError
from pipeline.robot import g1_xml_path
from pipeline.rotations import rotation_from_wxyz, wxyz_from_rotation
from retarget.frames import standing_frame
from retarget.mapping import g1_rest, load_mapping, map_human
from retarget.objects import map_objects, object_bottom
from retarget.scaling import compute_scale, human_to_targets

SYNTH = {c.task: c for c in default_clips()}


def targets_for(clip: HumanClip, **kw):
    m = load_mapping(clip.skeleton, source=clip.source)
    mh = map_human(clip, m)
    return m, compute_scale(mh, **kw), human_to_targets(mh, **kw)


def mapped_synth(task: str):
    return map_human(SYNTH[task], load_mapping(SYNTH[task].skeleton))


def test_g1_lengths_are_measured_from_the_model():
    model = mujoco.MjModel.from_xml_path(str(g1_xml_path()))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    x = {model.body(i).name: data.xpos[i].copy() for i in range(model.nbody)}
    info = compute_scale(mapped_synth("PickUp"))
    d = lambda a, b: np.linalg.norm(x[f"left_{a}"] - x[f"left_{b}"])  # noqa: E731
    assert info.robot["thigh"] == pytest.approx(d("hip_pitch_link", "knee_link"))
    assert info.robot["shank"] == pytest.approx(d("knee_link", "ankle_roll_link"))
    assert info.robot["forearm"] == pytest.approx(d("elbow_link", "wrist_yaw_link"))
    shoulders = (x["left_shoulder_roll_link"] + x["right_shoulder_roll_link"]) / 2
    assert info.robot["trunk"] == pytest.approx(np.linalg.norm(shoulders - x["pelvis"]))
    rest = g1_rest()
    assert rest.pos["pelvis"][2] == pytest.approx(x["pelvis"][2] - rest.sole)  # standing on its soles
    assert 1.2 < rest.height < 1.4 and 0.0 <= rest.sole < 0.01


def test_scale_factors_on_the_synthetic_skeleton():
    """The synthetic SMPL skeleton's bones are known exactly, so the factors are too."""
    info = compute_scale(mapped_synth("PickUp"))
    assert info.human["thigh"] == pytest.approx(THIGH) and info.human["shank"] == pytest.approx(SHANK)
    assert info.human["upper_arm"] == pytest.approx(UPPER_ARM) and info.human["forearm"] == pytest.approx(FOREARM)
    assert info.leg == pytest.approx(info.robot["leg"] / (THIGH + SHANK))
    assert info.arm == pytest.approx(info.robot["arm"] / (UPPER_ARM + FOREARM))
    assert (info.subject_height, info.height_source) == (1.70, "clip")
    s = info.summary()
    assert (
        s["scale_leg"] == info.leg
        and s["reference"] == "rest pose"
        and s["height_ratio"] == pytest.approx(g1_rest().height / 1.70)
    )


#: (leg, trunk, arm) factors measured on each clip (see the module doc of retarget.scaling).
FACTORS = {
    "synthetic": (0.863, 0.621, 0.647),
    "omomo": (0.760, 0.665, 0.629),
    "pymo": (0.803, 0.592, 0.756),
    "lafan1": (0.767, 0.557, 0.634),
}


@pytest.mark.parametrize("name", CLIPS)
def test_factors_and_standing_pelvis_height(name):
    clip = clip_named(name)
    m, info, tg = targets_for(clip)
    assert (info.leg, info.trunk, info.arm) == pytest.approx(FACTORS[name], abs=2e-3)
    assert tg.scale == info.leg and tg.fps == clip.fps and tg.body_names == m.body_names
    t = standing_frame(map_human(clip, m).points, m)
    pelvis = tg.pos[t, tg.body_names.index("pelvis"), 2]
    assert pelvis == pytest.approx(g1_rest().pos["pelvis"][2], abs=0.05)


@pytest.mark.parametrize("name", CLIPS)
def test_planted_feet_are_at_the_g1_ankle_height(name):
    clip = clip_named(name)
    _, _, tg = targets_for(clip)
    g = g1_rest()
    assert tg.foot_contact is not None and tg.foot_contact.any(axis=0).all()
    for i, side in enumerate(("left", "right")):
        body = f"{side}_ankle_roll_link"
        z = tg.pos[tg.foot_contact[:, i], tg.body_names.index(body), 2]
        ankle = g.pos[body][2]  # 3.5 cm: the ankle axis above the sole
        assert np.median(z) == pytest.approx(ankle, abs=0.02)  # PyMO: +1.5 cm, its heels rise while "planted"
        assert z.min() > ankle - 0.015
        R = rotation_from_wxyz(tg.quat[tg.foot_contact[:, i], tg.body_names.index(body)]).as_matrix()
        assert np.median(np.degrees(np.arccos(np.clip(R[:, 2, 2], -1, 1)))) < 8.0  # planted feet level


def test_synthetic_planted_feet_are_exactly_on_the_floor():
    """The generator's own stance flags (flat, planted feet) give exactly the G1's ankle height."""
    for demo in default_demos():
        _, _, tg = targets_for(demo.clip)
        for i, side in enumerate(("left", "right")):
            body = f"{side}_ankle_roll_link"
            z = tg.pos[demo.foot_stance[:, i], tg.body_names.index(body), 2]
            assert np.abs(z - g1_rest().pos[body][2]).max() < 1e-9, demo.clip.task


def turned(clip: HumanClip, yaw_deg: float, shift=(3.0, -2.0)) -> HumanClip:
    """``clip`` rotated about z by ``yaw_deg`` and moved by ``shift`` (objects too)."""
    Rz = Rotation.from_euler("z", yaw_deg, degrees=True)
    t = np.array([*shift, 0.0])
    quat = wxyz_from_rotation(Rz * rotation_from_wxyz(clip.joint_quat.reshape(-1, 4))).reshape(clip.joint_quat.shape)

    def pose(p):
        q = wxyz_from_rotation(Rz * rotation_from_wxyz(p[:, 3:]))
        return np.concatenate([Rz.apply(p[:, :3]) + t, q], axis=1)

    objects = tuple(dataclasses.replace(o, pose=pose(o.pose)) for o in clip.objects)
    pos = Rz.apply(clip.joint_pos.reshape(-1, 3)).reshape(clip.joint_pos.shape) + t
    return dataclasses.replace(clip, joint_pos=pos, joint_quat=quat, objects=objects)


@pytest.mark.parametrize("yaw", [180.0, -117.0])
def test_any_start_yaw_and_place_give_the_same_motion(yaw):
    """Targets and objects are equivariant: turning and moving the human turns and moves them."""
    clip = SYNTH["Carry"]
    m, info, tg = targets_for(clip)
    clip2 = turned(clip, yaw)
    _, info2, tg2 = targets_for(clip2)
    Rz = Rotation.from_euler("z", yaw, degrees=True)
    t = np.array([3.0, -2.0, 0.0])
    assert np.abs(Rz.apply(tg.pos.reshape(-1, 3)).reshape(tg.pos.shape) + t - tg2.pos).max() < 1e-9
    turned_q = (Rz * rotation_from_wxyz(tg.quat.reshape(-1, 4))).as_matrix()
    assert np.abs(turned_q - rotation_from_wxyz(tg2.quat.reshape(-1, 4)).as_matrix()).max() < 1e-9
    assert (tg.foot_contact == tg2.foot_contact).all()
    m2 = map_human(clip2, m)
    o, o2 = map_objects(map_human(clip, m), info, tg)[0], map_objects(m2, info2, tg2)[0]
    assert np.abs(Rz.apply(o.pose[:, :3]) + t - o2.pose[:, :3]).max() < 1e-9


# --- objects ---------------------------------------------------------------------------------------


def mapped(clip: HumanClip):
    m, info, tg = targets_for(clip)
    return tg, map_objects(map_human(clip, m), info, tg)


@pytest.mark.parametrize("task", ["PickUp", "SitStand", "Push", "Carry"])
def test_objects_keep_size_and_orientation_and_stay_on_the_floor(task):
    clip = SYNTH[task]
    _, objs = mapped(clip)
    (o,), (h,) = objs, clip.objects
    assert o.geometry == h.geometry and o.name == h.name and o.mass == h.mass
    assert np.array_equal(o.pose[:, 3:], h.pose[:, 3:]) and np.array_equal(o.contact, h.contact)
    bottom, human_bottom = object_bottom(o.geometry, o.pose), object_bottom(h.geometry, h.pose)
    assert bottom.min() > -1e-9 and bottom[0] == pytest.approx(human_bottom[0])  # starts resting
    assert bottom[-1] == pytest.approx(human_bottom[-1], abs=1e-3) or human_bottom[-1] > 0.01  # ends resting
    still = np.linalg.norm(np.diff(h.pose[:, :3], axis=0), axis=1) < 1e-9
    assert np.abs(np.diff(o.pose[:, :3], axis=0))[still].max(initial=0.0) < 1e-3  # a still object stays still


def test_pushed_box_slides_on_the_floor_and_chair_never_moves():
    _, (box,) = mapped(SYNTH["Push"])
    assert np.abs(box.pose[:, 2] - SYNTH["Push"].objects[0].pose[:, 2]).max() < 1e-9
    assert np.ptp(box.pose[:, 0]) > 0.5  # it was pushed (1 m for the human, scaled for the G1)
    _, (chair,) = mapped(SYNTH["SitStand"])
    assert np.ptp(chair.pose[:, :3], axis=0).max() == 0.0


@pytest.mark.parametrize("task", ["PickUp", "Carry"])
def test_carried_box_moves_with_the_g1_hands(task):
    clip = SYNTH[task]
    tg, (o,) = mapped(clip)
    h = clip.objects[0]
    lifted = h.contact & (object_bottom(h.geometry, h.pose) > 0.02)
    hands = tg.pos[:, [tg.body_names.index(f"{s}_wrist_yaw_link") for s in ("left", "right")]].mean(axis=1)
    names = clip.skeleton.joint_names
    human_hands = clip.joint_pos[:, [names.index("left_wrist"), names.index("right_wrist")]].mean(axis=1)
    rel, human_rel = o.pose[lifted, :3] - hands[lifted], h.pose[lifted, :3] - human_hands[lifted]
    assert np.abs(rel[:, :2] - human_rel[:, :2]).max() < 0.005  # horizontally as the human held it
    assert np.ptp(rel[:, 2]) < 0.005  # vertically rigid with the G1's hands


@needs_shared
def test_omomo_box_follows_the_scaled_interaction():
    clip = clip_named("omomo")
    tg, (o,) = mapped(clip)
    h = clip.objects[0]
    bottom = object_bottom(o.geometry, o.pose)
    assert bottom.min() >= min(0.0, object_bottom(h.geometry, h.pose).min()) - 1e-9
    assert abs(bottom[-1] - object_bottom(h.geometry, h.pose)[-1]) < 1e-3  # put down on the floor again
    lifted = h.contact & (object_bottom(h.geometry, h.pose) > 0.02)
    hands = tg.pos[:, [tg.body_names.index(f"{s}_wrist_yaw_link") for s in ("left", "right")]].mean(axis=1)
    names = clip.skeleton.joint_names
    human_hands = clip.joint_pos[:, [names.index("left_wrist"), names.index("right_wrist")]].mean(axis=1)
    gap = (o.pose[lifted, :2] - hands[lifted, :2]) - (h.pose[lifted, :2] - human_hands[lifted, :2])
    assert np.median(np.linalg.norm(gap, axis=1)) < 0.02
    travel, human_travel = (
        np.linalg.norm(o.pose[-1, :2] - o.pose[0, :2]),
        np.linalg.norm(h.pose[-1, :2] - h.pose[0, :2]),
    )
    leg = compute_scale(map_human(clip, load_mapping(clip.skeleton))).leg
    assert travel == pytest.approx(leg * human_travel, rel=0.15)


# --- bad input -------------------------------------------------------------------------------------


def test_height_out_of_range_needs_an_override():
    clip = dataclasses.replace(SYNTH["PickUp"], subject_height=2.5)
    m = load_mapping(clip.skeleton)
    with pytest.raises(InputError) as info:
        human_to_targets(map_human(clip, m))
    assert (
        info.value.field == "subject_height" and "2.500 m" in str(info.value) and "pass --height M" in str(info.value)
    )
    tg = human_to_targets(map_human(clip, m), height_override=2.5)
    assert compute_scale(map_human(clip, m), height_override=2.5).height_source == "override"
    assert tg.frames == clip.frames
    short = dataclasses.replace(SYNTH["PickUp"], subject_height=0.8)
    with pytest.raises(InputError, match="subject_height: 0.800 m"):
        compute_scale(map_human(short, m))
    with pytest.raises(InputError) as info:
        compute_scale(map_human(clip, m), height_override=-1.0)
    assert info.value.field == "--height"  # the command line's flag (lessmimic retarget --height)
    estimated = compute_scale(map_human(dataclasses.replace(SYNTH["PickUp"], subject_height=None), m))
    assert estimated.height_source == "estimate" and 1.5 < estimated.subject_height < 1.9


def test_clip_shorter_than_two_frames():
    clip = SYNTH["PickUp"]
    one = HumanClip(
        clip.skeleton, clip.joint_pos[:1], clip.fps, "one.bvh", subject_height=1.7, joint_quat=clip.joint_quat[:1]
    )
    with pytest.raises(InputError) as info:
        human_to_targets(map_human(one, load_mapping(one.skeleton)))
    assert str(info.value).startswith("one.bvh: joint_pos: ") and "at least 2" in str(info.value)


def test_object_track_without_geometry():
    clip = SYNTH["PickUp"]
    bad = ObjectTrack("box", None, clip.objects[0].pose, source="scan.pt")
    clip = dataclasses.replace(clip, objects=(bad,))
    m = load_mapping(clip.skeleton)
    with pytest.raises(InputError) as info:
        human_to_targets(map_human(clip, m))
    assert info.value.field == "object box geometry" and str(info.value).startswith("scan.pt: ")
    with pytest.raises(InputError):
        map_objects(map_human(clip, m), compute_scale(map_human(dataclasses.replace(clip, objects=()), m)))


def test_no_objects_maps_to_none():
    clip = dataclasses.replace(SYNTH["PickUp"], objects=())
    m = load_mapping(clip.skeleton)
    mh = map_human(clip, m)
    assert map_objects(mh, compute_scale(mh)) == ()
