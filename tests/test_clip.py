"""The clip schema: validation with precise errors, resampling with slerp."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.clip import HumanClip, ObjectTrack, RobotClip, Skeleton
from pipeline.errors import InputError
from pipeline.geometry import Chair, MeshGeometry, ObjectPhysics, Primitive, geometry_from_dict, geometry_to_dict
from pipeline.rotations import wxyz_from_rotation

SKEL = Skeleton(("pelvis", "spine", "head"), (-1, 0, 1))
BOX = Primitive("box", (0.2, 0.2, 0.2))


def _human(T=10, **kw):
    pos = np.zeros((T, 3, 3))
    pos[:, :, 2] = [0.9, 1.2, 1.6]
    pos[:, :, 0] = np.linspace(0, 1, T)[:, None]
    return HumanClip(SKEL, kw.pop("joint_pos", pos), kw.pop("fps", 30.0), "walk.bvh", **kw)


def _robot_qpos(T=10):
    q = np.zeros((T, 36))
    q[:, 2], q[:, 3] = 0.79, 1.0
    return q


def test_valid_clip_properties():
    c = _human(31, subject_height=1.7)
    assert c.frames == 31 and c.duration == pytest.approx(1.0)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(fps=0.0), r"walk\.bvh: fps: must be a positive"),
        (dict(fps=float("nan")), r"walk\.bvh: fps"),
        (dict(joint_pos=np.zeros((0, 3, 3))), r"walk\.bvh: joint_pos: has zero frames"),
        (dict(joint_pos=np.zeros((5, 2, 3))), r"walk\.bvh: joint_pos: shape \(5, 2, 3\) does not match \(T, 3, 3\)"),
        (dict(subject_height=12.0), r"walk\.bvh: subject_height"),
    ],
)
def test_human_clip_rejects(kw, match):
    with pytest.raises(InputError, match=match):
        _human(**kw)


def test_nan_frame_is_named():
    pos = np.zeros((8, 3, 3))
    pos[5, 1, 2] = np.inf
    with pytest.raises(InputError, match=r"^walk\.bvh: frame 5: joint_pos: is NaN or infinite$"):
        _human(joint_pos=pos)


def test_zero_norm_quaternion_frame_is_named():
    q = np.tile([1.0, 0, 0, 0], (10, 3, 1))
    q[7, 2] = 0
    with pytest.raises(InputError, match=r"frame 7: joint_quat: quaternion has zero norm"):
        _human(joint_quat=q)
    pose = np.tile([0, 0, 0, 1.0, 0, 0, 0], (10, 1))
    pose[3, 3:] = 0
    with pytest.raises(InputError, match=r"frame 3: object box quaternion: quaternion has zero norm"):
        ObjectTrack("box", BOX, pose, source="clip.pt")


def test_object_frame_count_must_match():
    track = ObjectTrack("box", BOX, np.tile([0, 0, 0, 1.0, 0, 0, 0], (4, 1)))
    with pytest.raises(InputError, match="object box pose: has 4 frames, joint_pos has 10"):
        _human(objects=(track,))


def test_object_physics_defaults_and_validation():
    pose = np.tile([0, 0, 0, 1.0, 0, 0, 0], (4, 1))
    assert ObjectTrack("box", BOX, pose).physics() == ObjectPhysics()
    assert ObjectTrack("box", BOX, pose, mass=20.0, friction=0.15).physics() == ObjectPhysics(mass=20.0, friction=0.15)
    got = ObjectTrack("box", BOX, pose, friction=0.7, floor_friction=0.3).physics()
    assert (got.friction, got.floor_friction) == (0.7, 0.3)
    with pytest.raises(InputError, match="object box floor_friction: must be a positive number, got 0"):
        ObjectTrack("box", BOX, pose, floor_friction=0)
    with pytest.raises(InputError, match=r"clip\.pt: object box friction: must be a positive number, got -0\.1"):
        ObjectTrack("box", BOX, pose, source="clip.pt", friction=-0.1)
    with pytest.raises(InputError, match="object box mass: must be a positive number, got nan"):
        ObjectTrack("box", BOX, pose, mass=float("nan"))


def test_robot_clip_validation():
    RobotClip(_robot_qpos(), 50, "x.npz")
    with pytest.raises(InputError, match=r"x\.npz: qpos: shape \(10, 35\)"):
        RobotClip(np.zeros((10, 35)), 50, "x.npz")
    with pytest.raises(InputError, match=r"contacts: shape \(10, 1\) does not match \(10, 2\)"):
        RobotClip(_robot_qpos(), 50, "x.npz", contact_links=("a", "b"), contacts=np.zeros((10, 1)))


def test_resample_positions_linear_and_rotations_slerp():
    T = 11
    yaw = np.linspace(0, np.pi / 2, T)
    quat = np.repeat(wxyz_from_rotation(Rotation.from_euler("z", yaw[:, None]))[:, None], 3, axis=1)
    contacts = np.zeros((T, 3), bool)
    contacts[5:, 2] = True
    c = _human(T, fps=10.0, joint_quat=quat, contacts=contacts)
    r = c.resampled(30.0)
    assert r.frames == 31 and r.fps == 30.0
    np.testing.assert_allclose(r.joint_pos[:, 0, 0], np.linspace(0, 1, 31), atol=1e-12)
    got_yaw = Rotation.from_quat(r.joint_quat[:, 0][:, [1, 2, 3, 0]]).as_euler("zyx")[:, 0]
    np.testing.assert_allclose(got_yaw, np.linspace(0, np.pi / 2, 31), atol=1e-9)
    assert r.contacts[:14, 2].sum() == 0 and r.contacts[16:, 2].all()


def test_robot_resample_keeps_objects_in_step():
    q = _robot_qpos(26)
    q[:, 0] = np.linspace(0, 1, 26)
    pose = np.tile([0, 0, 0.2, 1.0, 0, 0, 0], (26, 1))
    pose[:, 0] = np.linspace(0, 2, 26)
    clip = RobotClip(q, 50, "x", objects=(ObjectTrack("box", BOX, pose),))
    r = clip.resampled(30)
    assert r.frames == 16 and r.objects[0].frames == 16
    np.testing.assert_allclose(r.objects[0].pose[:, 0], 2 * r.qpos[:, 0], atol=1e-12)


def test_geometry_round_trip_and_checks():
    for g in (
        BOX.scaled(1.6),
        Chair(seat_height=0.4),
        MeshGeometry("a.obj", (1, 1, 2), "decomposition"),
        Primitive("capsule", (0.1, 0.3)),
    ):
        assert geometry_from_dict(geometry_to_dict(g)) == g
    np.testing.assert_allclose(BOX.scaled(0.4).half_extents, [0.08, 0.08, 0.08])
    with pytest.raises(ValueError, match="box size must be 3 positive numbers"):
        Primitive("box", (0.1, 0.1))
    with pytest.raises(ValueError, match="scale must be three positive"):
        Primitive("sphere", (0.1,), scale=(1, -1, 1))
    with pytest.raises(ValueError, match="primitive kind"):
        Primitive("torus", (0.1,))


def test_skeleton_checks():
    with pytest.raises(ValueError, match="parents must precede children"):
        Skeleton(("a", "b"), (1, -1))
    with pytest.raises(ValueError, match="not unique"):
        Skeleton(("a", "a"), (-1, 0))


def test_half_extents_of_every_primitive():
    assert Primitive("sphere", (0.1,), (1.0, 2.0, 3.0)).half_extents.tolist() == pytest.approx([0.1, 0.2, 0.3])
    assert Primitive("capsule", (0.1, 0.2)).half_extents.tolist() == pytest.approx([0.1, 0.1, 0.3])
    assert Primitive("cylinder", (0.1, 0.2)).half_extents.tolist() == pytest.approx([0.1, 0.1, 0.2])
