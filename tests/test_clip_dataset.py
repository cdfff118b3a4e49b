"""Clips <-> datasets: qvel matches MuJoCo; clip -> dataset -> LeRobot load -> clip is lossless (float32)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.clip import HumanClip, ObjectTrack, PhysicalizedClip, RobotClip, Skeleton
from pipeline.dataset import write_dataset
from pipeline.dataset.clips import (
    clips_fps,
    episodes_to_human_clips,
    episodes_to_physicalized_clips,
    episodes_to_robot_clips,
    human_clips_to_episodes,
    physicalized_clips_to_episodes,
    robot_clips_to_episodes,
)
from pipeline.dataset.objects import objects_note
from pipeline.errors import InputError
from pipeline.geometry import Chair, Primitive
from pipeline.kinematics import qpos_difference, qvel_from_qpos
from pipeline.robot import G1_JOINT_NAMES, QPOS_NAMES, g1_model
from pipeline.rotations import wxyz_from_rotation

LeRobotDataset = pytest.importorskip("lerobot.datasets.lerobot_dataset").LeRobotDataset
F32 = dict(rtol=0, atol=2e-6)
LINKS = ("left_wrist_yaw_link", "right_wrist_yaw_link", "pelvis")


def _qpos(T, seed):
    rng = np.random.default_rng(seed)
    q = np.zeros((T, 36))
    q[:, :3] = [0.1, 0.2, 0.78] + 0.01 * np.cumsum(rng.normal(size=(T, 3)), axis=0)
    q[:, 3:7] = wxyz_from_rotation(Rotation.from_rotvec(0.3 * np.cumsum(rng.normal(size=(T, 3)), axis=0) / np.sqrt(T)))
    lo, hi = g1_model().jnt_range[[g1_model().joint(j).id for j in G1_JOINT_NAMES]].T
    q[:, 7:] = np.clip(0.2 * rng.normal(size=(T, 29)), lo, hi)  # a dataset's joints lie within their range
    return q


def _box(T, seed, contact=True):
    pose = np.tile([0.5, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], (T, 1))
    pose[:, 0] += 0.01 * np.arange(T)
    return ObjectTrack(
        "box",
        Primitive("box", (0.2, 0.15, 0.1)),
        pose,
        (np.arange(T) % 3 == 0) if contact else None,
        2.5,
        f"box{seed}.obj",
        0.3,
    )


def _chair(T):
    return ObjectTrack("chair", Chair(seat_height=0.5), np.tile([1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (T, 1)))


def _robot_clip(T, seed, contacts=True, box_contact=True, task="lift the box"):
    return RobotClip(
        _qpos(T, seed),
        50.0,
        f"take{seed}.npz",
        objects=(_box(T, seed, box_contact), _chair(T)),
        contact_links=LINKS,
        contacts=(np.random.default_rng(seed).random((T, 3)) < 0.3) if contacts else None,
        method="mink-ik",
        provenance={"source_frame_start": 7 * seed, "synthetic": seed == 2, "note": "test"},
        task=task,
    )


def _assert_robot_equal(a: RobotClip, b: RobotClip):
    np.testing.assert_allclose(a.qpos, b.qpos, **F32)
    assert (a.fps, a.source, a.method, a.provenance, a.task, a.contact_links) == (
        b.fps,
        b.source,
        b.method,
        b.provenance,
        b.task,
        b.contact_links,
    )
    assert (a.contacts is None) == (b.contacts is None) and (
        a.contacts is None or np.array_equal(a.contacts, b.contacts)
    )
    assert len(a.objects) == len(b.objects)
    for oa, ob in zip(a.objects, b.objects):
        assert (oa.name, oa.geometry, oa.mass, oa.friction, oa.source) == (
            ob.name,
            ob.geometry,
            ob.mass,
            ob.friction,
            ob.source,
        )
        np.testing.assert_allclose(oa.pose, ob.pose, **F32)
        assert (oa.contact is None) == (ob.contact is None) and (
            oa.contact is None or np.array_equal(oa.contact, ob.contact)
        )


def test_qpos_difference_matches_mujoco():
    """Against MuJoCo on a model with the G1's joint layout (a free joint, then 29 hinges)."""
    mujoco = pytest.importorskip("mujoco")
    chain = "".join('<body><joint type="hinge" axis="0 1 0"/><geom size="0.01"/>' for _ in range(29)) + "</body>" * 29
    m = mujoco.MjModel.from_xml_string(
        f'<mujoco><worldbody><body><freejoint/><geom size="0.1"/>{chain}</body></worldbody></mujoco>'
    )
    assert (m.nq, m.nv) == (36, 35)
    q = _qpos(12, 3)
    q[5, 3:7] *= -1  # the other cover of the same rotation
    for t in range(11):
        want = np.zeros(35)
        mujoco.mj_differentiatePos(m, want, 0.02, q[t], q[t + 1])
        np.testing.assert_allclose(qpos_difference(q[t], q[t + 1], 0.02), want, rtol=1e-9, atol=1e-9)


def test_qvel_constant_body_rate():
    """A body spinning at a constant body-frame rate: central differences recover it exactly."""
    w_body, fps, T = np.array([0.3, -1.2, 2.0]), 50, 20
    rot = [Rotation.from_rotvec([0.2, 0.1, -0.4])]
    for _ in range(T - 1):
        rot.append(rot[-1] * Rotation.from_rotvec(w_body / fps))  # right-multiply: body frame
    q = np.zeros((T, 36))
    q[:, 3:7] = np.stack([wxyz_from_rotation(r) for r in rot])
    q[:, 0] = 0.5 * np.arange(T) / fps
    q[:, 10] = np.sin(np.arange(T) / fps)
    v = qvel_from_qpos(q, fps)
    np.testing.assert_allclose(v[:, 3:6], np.tile(w_body, (T, 1)), atol=1e-9)
    np.testing.assert_allclose(v[:, 0], 0.5, atol=1e-12)
    np.testing.assert_allclose(v[1:-1, 10 - 1], np.cos(np.arange(1, T - 1) / fps), atol=1e-4)
    assert qvel_from_qpos(q[:1], fps).shape == (1, 35) and not qvel_from_qpos(q[:1], fps).any()
    assert qvel_from_qpos(q[:1, :7], fps).shape == (1, 6)  # a free object's one-frame track: its own width


def test_source_frame_of_a_resampled_clip():
    from dataclasses import replace

    clip = _robot_clip(10, 1)
    resampled = replace(
        clip, provenance={**clip.provenance, "source_fps": 30.0}
    )  # retargeted at 50 fps from a 30 fps take
    _, (ep,) = robot_clips_to_episodes([resampled])
    np.testing.assert_array_equal(ep.data["source_frame"], 7 + np.array([0, 1, 1, 2, 2, 3, 4, 4, 5, 5]))


def test_robot_round_trip_through_lerobot(tmp_path):
    clips = [_robot_clip(9, 1), _robot_clip(6, 2, contacts=False, box_contact=False, task=""), _robot_clip(1, 3)]
    features, episodes = robot_clips_to_episodes(clips)
    names = [f.name for f in features]
    assert names == [
        "observation.state",
        "observation.qvel",
        "contact",
        "object.pose",
        "object.contact",
        "object_2.pose",
        "source_frame",
    ]
    assert features[0].names == QPOS_NAMES
    root = write_dataset(tmp_path / "robot", "tester/robot", clips_fps(clips), features, episodes)
    ds = LeRobotDataset("tester/robot", root=root)
    i = 0
    for c, ep in zip(clips, episodes):
        for t in range(c.frames):
            item = ds[i]
            np.testing.assert_allclose(item["observation.state"].numpy(), c.qpos[t], **F32)
            np.testing.assert_array_equal(
                item["observation.qvel"].numpy(), ep.data["observation.qvel"][t].astype(np.float32)
            )
            np.testing.assert_allclose(item["object.pose"].numpy(), c.objects[0].pose[t], **F32)
            assert item["source_frame"].item() == t + c.provenance["source_frame_start"]
            assert item["task"] == (c.task or "humanoid whole-body motion")
            i += 1
    back = episodes_to_robot_clips(root)
    assert len(back) == 3
    for a, b in zip(back, clips):
        _assert_robot_equal(a, b)


def _physicalized(T, seed):
    rng = np.random.default_rng(seed)
    robot = _robot_clip(T, seed)
    return PhysicalizedClip(
        robot,
        rng.normal(size=(T, 35)),
        (rng.normal(size=(T, 6)), np.zeros((T, 6))),
        rng.normal(size=(T, 29)),
        rng.normal(size=(T, 29)),
        rng.random((T, 2)) * 300,
        _qpos(T, seed + 10),
        {"valid": seed == 1, "reason": "" if seed == 1 else "fell at t=0.10 s"},
    )


def test_physicalized_round_trip_through_lerobot(tmp_path):
    clips = [_physicalized(8, 1), _physicalized(5, 2)]
    features, episodes = physicalized_clips_to_episodes(clips)
    root = write_dataset(tmp_path / "sim", "tester/sim", 50, features, episodes)
    ds = LeRobotDataset("tester/sim", root=root)
    assert ds.num_frames == 13 and tuple(ds.features["object.vel"]["shape"]) == (6,)
    np.testing.assert_allclose(ds[8]["action"].numpy(), clips[1].action[0], **F32)
    back = episodes_to_physicalized_clips(root)
    for a, b in zip(back, clips):
        _assert_robot_equal(a.robot, b.robot)
        for k in ("qvel", "action", "torque", "foot_force", "reference_qpos"):
            np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=1e-6, atol=1e-4)
        for va, vb in zip(a.object_vel, b.object_vel):
            np.testing.assert_allclose(va, vb, **F32)
        assert a.validation == b.validation
    with pytest.raises(InputError, match="not a physicalized dataset"):
        robot_features, robot_episodes = robot_clips_to_episodes([c.robot for c in clips])
        episodes_to_physicalized_clips(
            write_dataset(tmp_path / "robot", "tester/robot", 50, robot_features, robot_episodes)
        )
    with pytest.raises(InputError, match="action.*frames"):
        PhysicalizedClip(
            clips[0].robot,
            clips[0].qvel,
            clips[0].object_vel,
            clips[0].action[:3],
            clips[0].torque,
            clips[0].foot_force,
            clips[0].reference_qpos,
        )


def test_human_round_trip_through_lerobot(tmp_path):
    skel = Skeleton(("pelvis", "spine", "head", "l_hand"), (-1, 0, 1, 1))
    rng = np.random.default_rng(0)

    def clip(T, k, contacts):
        pos = rng.normal(size=(T, 4, 3)) + [0, 0, 1]
        quat = wxyz_from_rotation(Rotation.random(T * 4, random_state=k)).reshape(T, 4, 4)
        return HumanClip(
            skel,
            pos,
            30.0,
            f"s{k}.bvh",
            subject_height=1.7,
            joint_quat=quat,
            contacts=(rng.random((T, 4)) < 0.5) if contacts else None,
            objects=(_box(T, k),),
            task="carry",
            synthetic=k == 1,
        )

    clips = [clip(5, 0, True), clip(4, 1, False)]
    features, episodes = human_clips_to_episodes(clips)
    assert features[0].names[:4] == ("pelvis.x", "pelvis.y", "pelvis.z", "spine.x")
    root = write_dataset(tmp_path / "human", "tester/human", clips_fps(clips), features, episodes)
    ds = LeRobotDataset("tester/human", root=root)
    np.testing.assert_allclose(ds[6]["observation.joint_pos"].numpy().reshape(4, 3), clips[1].joint_pos[1], **F32)
    back = episodes_to_human_clips(root)
    for a, b in zip(back, clips):
        assert (a.skeleton, a.fps, a.source, a.subject_height, a.task, a.synthetic) == (
            b.skeleton,
            b.fps,
            b.source,
            b.subject_height,
            b.task,
            b.synthetic,
        )
        np.testing.assert_allclose(a.joint_pos, b.joint_pos, **F32)
        np.testing.assert_allclose(a.joint_quat, b.joint_quat, atol=1e-6)
        assert (a.contacts is None) == (b.contacts is None) and (
            a.contacts is None or np.array_equal(a.contacts, b.contacts)
        )
        assert a.objects[0].geometry == b.objects[0].geometry
    with pytest.raises(InputError, match="was not written from a robot clip"):
        episodes_to_robot_clips(root)


def test_a_mixed_object_dataset_round_trips_through_lerobot(tmp_path):
    """A box clip and a chair clip in one dataset: the same columns (by role), each episode's object by name."""
    box = replace(_robot_clip(5, 1), objects=(_box(5, 1),))
    chair = RobotClip(_qpos(6, 2), 50.0, "chair.npz", objects=(_chair(6),), contact_links=LINKS, task="sit")
    features, episodes = robot_clips_to_episodes([box, chair])
    assert [f.name for f in features if f.name.startswith("object")] == ["object.pose", "object.contact"]
    root = tmp_path / "mixed"
    write_dataset(root, "t/mixed", 50, features, episodes)
    ds = LeRobotDataset("t/mixed", root=root)
    assert ds.num_episodes == 2
    np.testing.assert_allclose(ds[0]["object.pose"].numpy(), box.objects[0].pose[0], **F32)
    np.testing.assert_allclose(ds[5]["object.pose"].numpy(), chair.objects[0].pose[0], **F32)
    back = episodes_to_robot_clips(root)
    assert [o.name for c in back for o in c.objects] == ["box", "chair"]
    assert back[1].objects[0].geometry == chair.objects[0].geometry and back[1].objects[0].contact is None
    _assert_robot_equal(back[0], box)
    note = objects_note([box, chair])
    assert "`object`: box (box) in 1 episode(s); `object`: chair (chair) in 1 episode(s)" in note


def test_a_dataset_written_before_roles_reads_back(tmp_path):
    """Datasets written before role columns (``object.<name>.pose``, meta without ``column``) stay readable."""
    clip = _robot_clip(4, 1)
    features, episodes = robot_clips_to_episodes([clip])
    renamed = {
        "object.pose": "object.box.pose",
        "object.contact": "object.box.contact",
        "object_2.pose": "object.chair.pose",
    }
    features = [replace(f, name=renamed.get(f.name, f.name)) for f in features]
    for ep in episodes:
        ep.data = {renamed.get(k, k): v for k, v in ep.data.items()}
        for m in ep.meta["objects"]:
            del m["column"]
    write_dataset(tmp_path / "old", "t/old", 50, features, episodes)
    _assert_robot_equal(episodes_to_robot_clips(tmp_path / "old")[0], clip)


def test_inconsistent_clips_are_refused():
    a = _robot_clip(4, 1)
    b = RobotClip(_qpos(4, 2), 50.0, "other.npz", objects=(_chair(4),), contact_links=LINKS)
    with pytest.raises(InputError, match=r"other.npz: objects: 1 object\(s\) \(\['chair'\]\), take1.npz has 2"):
        robot_clips_to_episodes([a, b])
    with pytest.raises(InputError, match="other.npz: contact_links"):
        robot_clips_to_episodes(
            [a, RobotClip(_qpos(4, 2), 50.0, "other.npz", objects=a.objects, contact_links=("pelvis",))]
        )
    with pytest.raises(InputError, match="other.npz: fps: 30.0 differs"):
        robot_clips_to_episodes([a, RobotClip(_qpos(4, 2), 30.0, "other.npz")])
    with pytest.raises(InputError, match="not an integer"):
        robot_clips_to_episodes([RobotClip(_qpos(4, 2), 29.97, "ntsc.npz")])
    s1, s2 = Skeleton(("a", "b"), (-1, 0)), Skeleton(("a", "c"), (-1, 0))
    h = [HumanClip(s1, np.zeros((3, 2, 3)), 30, "h1.bvh"), HumanClip(s2, np.zeros((3, 2, 3)), 30, "h2.bvh")]
    with pytest.raises(InputError, match="h2.bvh: skeleton"):
        human_clips_to_episodes(h)
