"""The embedded default input: four synthetic human-object demonstrations on the SMPL body."""

import numpy as np
import pytest

from ingest.default_input import HAND_OFFSET, REST_OFFSETS, default_clips, default_demos
from pipeline.clip import HumanClip
from pipeline.geometry import Chair, Primitive
from pipeline.rotations import rotation_from_wxyz

SMPL22 = [
    ("pelvis", -1),
    ("left_hip", 0),
    ("right_hip", 0),
    ("spine1", 0),
    ("left_knee", 1),
    ("right_knee", 2),
    ("spine2", 3),
    ("left_ankle", 4),
    ("right_ankle", 5),
    ("spine3", 6),
    ("left_foot", 7),
    ("right_foot", 8),
    ("neck", 9),
    ("left_collar", 9),
    ("right_collar", 9),
    ("head", 12),
    ("left_shoulder", 13),
    ("right_shoulder", 14),
    ("left_elbow", 16),
    ("right_elbow", 17),
    ("left_wrist", 18),
    ("right_wrist", 19),
]
ANKLES, FEET, WRISTS = (7, 8), (10, 11), (20, 21)
TASKS = ["PickUp", "SitStand", "Push", "Carry"]


@pytest.fixture(scope="module", params=[0, 5], ids=["seed0", "seed5"])
def demos(request):
    return {d.clip.task: d for d in default_demos(seed=request.param)}


def box_distance(points: np.ndarray, pose: np.ndarray, half) -> np.ndarray:
    """Exact signed distance (negative inside) from points (T,N,3) to boxes with poses (T,7)."""
    R = rotation_from_wxyz(pose[:, 3:]).as_matrix()
    local = np.einsum("tji,tnj->tni", R, points - pose[:, None, :3])  # R^T (p - c)
    q = np.abs(local) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(-1), 0.0)


def chair_part_distances(points: np.ndarray, pose: np.ndarray, chair: Chair) -> dict:
    R = rotation_from_wxyz(pose[:, 3:]).as_matrix()
    out = {}
    for name, prim, centre in chair.parts():
        part = pose.copy()
        part[:, :3] += R @ centre
        out[name] = box_distance(points, part, prim.half_extents)
    return out


def test_four_synthetic_clips_on_the_smpl_skeleton(demos):
    clips = default_clips()
    assert [c.task for c in clips] == TASKS
    for c in clips:
        assert c.synthetic is True and c.source == f"synthetic:{c.task}"
        assert c.fps == 30.0 and c.subject_height == pytest.approx(1.70)
        assert 5.0 <= c.duration <= 10.0
        assert list(zip(c.skeleton.joint_names, c.skeleton.parents)) == SMPL22
        assert c.joint_quat is not None and c.contacts is not None and c.contacts.shape == (c.frames, 22)
        assert len(c.objects) == 1 and c.objects[0].mass > 0 and c.objects[0].contact is not None
        assert c.objects[0].source == c.source
    assert len({c.objects[0].name for c in clips}) == 1  # one dataset feature spec for all four
    assert isinstance(demos["SitStand"].clip.objects[0].geometry, Chair)
    assert demos["PickUp"].clip.objects[0].geometry == Primitive("box", (0.2, 0.15, 0.15))


def test_fps_argument():
    for fps in (24.0, 50.0):
        for c, ref in zip(default_clips(fps=fps), default_clips()):
            assert c.fps == fps and abs(c.duration - ref.duration) < 0.05


def test_deterministic_for_a_seed():
    def arrays(clips):
        for c in clips:
            yield from (c.joint_pos, c.joint_quat, c.contacts, c.objects[0].pose, c.objects[0].contact)

    a, b, other = default_clips(seed=3), default_clips(seed=3), default_clips(seed=4)
    assert all(np.array_equal(x, y) for x, y in zip(arrays(a), arrays(b)))
    assert not all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(arrays(a), arrays(other)))


def test_standing_proportions(demos):
    P = demos["PickUp"].clip.joint_pos[0]  # standing still, arms hanging
    assert 0.90 <= P[0, 2] <= 0.94  # pelvis
    assert P[ANKLES, 2] == pytest.approx(0.08, abs=0.005)
    assert np.all((0.02 <= P[FEET, 2]) & (P[FEET, 2] <= 0.03)) and np.all(P[FEET, 0] > P[ANKLES, 0] + 0.1)
    assert np.all(np.abs(P[[16, 17], 2] - 1.40) < 0.03)  # shoulders
    assert np.all((0.78 <= P[WRISTS, 2]) & (P[WRISTS, 2] <= 0.87))
    assert P[15, 2] < 1.60 and P[1, 1] > 0 > P[2, 1]  # head below the crown; left = +y
    assert np.all(P[1:, 2] < P[0, 2] + 0.7)


def test_bone_lengths_constant_and_quats_match_positions(demos):
    parents = np.array([p for _, p in SMPL22[1:]])
    rest = np.linalg.norm(REST_OFFSETS[1:], axis=1)
    for d in demos.values():
        c = d.clip
        bones = c.joint_pos[:, 1:] - c.joint_pos[:, parents]
        assert np.abs(np.linalg.norm(bones, axis=-1) - rest).max() < 1e-9
        # the global orientation of a parent carries the child's rest offset onto the bone
        R = rotation_from_wxyz(c.joint_quat[:, parents].reshape(-1, 4)).as_matrix().reshape(c.frames, 21, 3, 3)
        assert np.abs(np.einsum("tjab,jb->tja", R, REST_OFFSETS[1:]) - bones).max() < 1e-9


def test_stance_feet_planted_and_swing_clears_the_floor(demos):
    for d in demos.values():
        c, st = d.clip, d.foot_stance
        P = c.joint_pos
        assert P[:, :, 2].min() >= 0.0  # no joint (feet included) below the floor
        assert st.any(0).all() and (~st).any(0).all(), c.task  # both feet step
        for side in (0, 1):
            joints = [ANKLES[side], FEET[side]]
            both = st[1:, side] & st[:-1, side]
            speed = np.linalg.norm(np.diff(P[:, joints, :2], axis=0), axis=-1).max(-1) * c.fps
            assert speed[both].max() < 0.02, c.task
            assert np.abs(P[st[:, side], FEET[side], 2] - P[0, FEET[side], 2]).max() < 0.002
            lift = P[~st[:, side], FEET[side], 2].max() - P[0, FEET[side], 2]
            assert 0.03 <= lift <= 0.10, (c.task, lift)


def test_walking_pace(demos):
    c, d = demos["PickUp"].clip, demos["PickUp"]
    approach = next(p for p in d.phases if p.name == "approach")
    i0, i1 = int(approach.start * c.fps), int(approach.end * c.fps)
    v = np.linalg.norm(np.diff(c.joint_pos[i0:i1, 0, :2], axis=0), axis=1) * c.fps
    assert 0.9 <= v.max() <= 1.4
    lifts = np.flatnonzero(d.foot_stance[:-1, 0] & ~d.foot_stance[1:, 0])  # left lift-offs
    assert 0.9 <= c.fps / np.diff(lifts).mean() <= 1.2  # stride frequency, Hz
    bob = c.joint_pos[i0 + 30 : i1 - 15, 0, 2]
    assert 0.02 <= bob.max() - bob.min() <= 0.07


@pytest.mark.parametrize("task", ["PickUp", "Push", "Carry"])
def test_box_contacts_distances_and_floor(demos, task):
    c = demos[task].clip
    o = c.objects[0]
    half = o.geometry.half_extents
    dist = box_distance(c.joint_pos, o.pose, half)
    touch = o.contact
    assert touch.any() and np.array_equal(c.contacts[:, 20], touch) and np.array_equal(c.contacts[:, 21], touch)
    assert c.contacts[:, [j for j in range(22) if j not in WRISTS]].sum() == 0
    # hands at the surface (HAND_OFFSET outside it) whenever the flags are on
    assert np.abs(dist[touch][:, WRISTS] - HAND_OFFSET).max() < 0.005 and dist[touch][:, WRISTS].max() <= 0.05
    # no joint inside the box (or closer than 2 cm) at any frame
    assert dist.min() >= 0.02, (task, dist.min())
    # never below the floor; resting on it, level, whenever not held
    assert o.pose[:, 2].min() >= half[2] - 1e-12
    free = ~touch
    assert np.all(o.pose[free, 2] == half[2]) and np.all(o.pose[free, 4:6] == 0.0)
    # rigid with the hands while held: the wrists do not move in the box frame
    R = rotation_from_wxyz(o.pose[:, 3:]).as_matrix()
    local = np.einsum("tji,tnj->tni", R, c.joint_pos[:, WRISTS] - o.pose[:, None, :3])[touch]
    assert np.abs(local - local[0]).max() < 1e-9
    # the box moves only while touched
    moved = np.linalg.norm(np.diff(o.pose[:, :3], axis=0), axis=1) > 1e-12
    assert not np.any(moved & ~touch[1:] & ~touch[:-1])


def test_pickup_lifts_and_holds(demos):
    d = demos["PickUp"]
    o, fps = d.clip.objects[0], d.clip.fps
    hold = next(p for p in d.phases if p.name == "hold")
    assert hold.end - hold.start >= 3.0
    i0, i1 = int(np.ceil(hold.start * fps)), int(hold.end * fps)
    assert np.all(o.pose[i0:i1, 2] - o.geometry.half_extents[2] > 0.3) and o.contact[i0:i1].all()
    squat = next(p for p in d.phases if p.name == "squat_reach")
    assert 0.8 <= squat.end - squat.start <= 1.2
    assert d.clip.joint_pos[:, 0, 2].min() < 0.6  # a real squat


def test_push_and_carry_move_the_box(demos):
    push = demos["Push"].clip.objects[0].pose
    assert 0.9 <= push[-1, 0] - push[0, 0] <= 1.1 and np.all(push[:, 1:3] == push[0, 1:3])
    carry = demos["Carry"].clip.objects[0].pose
    assert np.linalg.norm(carry[-1, :2] - carry[0, :2]) >= 1.5
    assert carry[-1, 2] == carry[0, 2] == 0.15


def test_sitstand_pelvis_on_the_seat(demos):
    c = demos["SitStand"].clip
    o = c.objects[0]
    chair = o.geometry
    assert np.all(o.pose == o.pose[0])  # the chair does not move
    seated = o.contact
    assert seated.sum() / c.fps >= 1.0
    assert np.array_equal(c.contacts[:, 0], seated) and np.array_equal(c.contacts[:, 20], np.zeros(c.frames, bool))
    R = rotation_from_wxyz(o.pose[:1, 3:]).as_matrix()[0]
    local = (c.joint_pos[seated, 0] - o.pose[0, :3]) @ R  # pelvis in the chair frame
    assert np.all(np.abs(local[:, 0]) < chair.seat_depth / 2) and np.all(np.abs(local[:, 1]) < chair.seat_width / 2)
    above = local[:, 2] - chair.seat_height
    assert np.all((0.08 <= above) & (above <= 0.20))
    assert c.joint_pos[~seated, 0, 2].max() > 0.85  # stands before and after
    for name, d in chair_part_distances(c.joint_pos, o.pose, chair).items():
        assert d.min() >= 0.02, name
    # the walker turned round to sit: facing -x (the chair's front) while seated
    fwd = c.joint_pos[seated, 10, 0] - c.joint_pos[seated, 7, 0]
    assert np.all(fwd < -0.1)


def test_phases_cover_each_clip(demos):
    for d in demos.values():
        c, ph = d.clip, d.phases
        assert ph[0].start == 0.0 and ph[-1].end == pytest.approx(c.duration, abs=0.5 / c.fps)
        assert all(p.start < p.end for p in ph) and all(a.start <= b.start for a, b in zip(ph, ph[1:]))
        assert all(b.start <= a.end + 1e-9 for a, b in zip(ph, ph[1:]))  # no gaps
    names = {t: {p.name for p in d.phases} for t, d in demos.items()}
    assert {"approach", "squat_reach", "grasp", "lift", "hold"} <= names["PickUp"]
    assert {"approach", "turn", "sit_down", "seated", "stand_up"} <= names["SitStand"]
    assert {"approach", "reach", "push", "release", "step_back"} <= names["Push"]
    assert {"approach", "lift", "carry", "put_down", "release"} <= names["Carry"]


def test_clips_validate_and_resample():
    for c in default_clips():
        again = HumanClip(
            c.skeleton,
            c.joint_pos,
            c.fps,
            c.source,
            c.subject_height,
            c.joint_quat,
            c.contacts,
            c.objects,
            c.task,
            c.synthetic,
        )
        assert again.frames == c.frames
        r = c.resampled(50.0)
        assert r.synthetic and r.fps == 50.0 and abs(r.duration - c.duration) < 0.03
