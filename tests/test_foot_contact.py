"""Human foot-ground contact detection: joint lookup by name, the generator's own stance flags
on the synthetic clips, a real BVH walk, floor independence and the flicker filter."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from ingest.synthetic import default_demos
from pipeline.foot_contact import FootContacts, detect_foot_contacts, find_foot_joints, keep_runs


@pytest.fixture(scope="module")
def demos():
    return default_demos()


@pytest.mark.parametrize(
    "names, expected",
    [
        (
            ("pelvis", "left_ankle", "right_ankle", "left_foot", "right_foot"),
            {"left": ("left_ankle", "left_foot"), "right": ("right_ankle", "right_foot")},
        ),  # SMPL: foot = toe joint
        (
            ("Hips", "LeftFoot", "LeftToe", "RightFoot", "RightToe"),
            {"left": ("LeftFoot", "LeftToe"), "right": ("RightFoot", "RightToe")},
        ),  # LAFAN: foot = ankle
        (
            ("Hips", "LeftFoot", "LeftToeBase", "LeftToeBase_End", "RightFoot", "RightToeBase"),
            {"left": ("LeftFoot", "LeftToeBase"), "right": ("RightFoot", "RightToeBase")},
        ),
        (
            ("root", "L_Ankle", "L_Toe", "R_Ankle", "R_Toe"),
            {"left": ("L_Ankle", "L_Toe"), "right": ("R_Ankle", "R_Toe")},
        ),
        (("hip", "LAnkle", "RAnkle"), {"left": ("LAnkle",), "right": ("RAnkle",)}),
    ],
)
def test_foot_joints_by_name(names, expected):
    assert find_foot_joints(names) == expected


def test_no_foot_joint_lists_the_joints_seen():
    with pytest.raises(ValueError, match=r"no right foot joint.*Hips, LeftFoot, Head"):
        find_foot_joints(("Hips", "LeftFoot", "Head"))


def test_synthetic_clips_agree_with_the_generator(demos):
    for d in demos:
        fc = detect_foot_contacts(d.clip)
        assert isinstance(fc, FootContacts) and fc.left.dtype == bool and fc.left.shape == (d.clip.frames,)
        agree = (fc.both == d.foot_stance).mean(axis=0)
        assert (agree >= 0.9).all(), (d.clip.task, agree)
        assert fc.floor_height == pytest.approx(0.025, abs=0.005)  # SMPL toe joints 2.5 cm over the sole


def test_same_contacts_at_another_fps():
    for d in default_demos(fps=120.0)[:2]:
        assert ((detect_foot_contacts(d.clip).both == d.foot_stance).mean(axis=0) >= 0.9).all()


def test_floor_is_estimated_not_assumed(demos):
    clip = demos[3].clip
    base = detect_foot_contacts(clip)
    shifted = detect_foot_contacts(replace(clip, joint_pos=clip.joint_pos + [0.3, -1.0, 0.5]))
    assert shifted.floor_height == pytest.approx(base.floor_height + 0.5)
    assert np.array_equal(shifted.left, base.left) and np.array_equal(shifted.right, base.right)


def test_flicker_filter():
    f = np.array([0, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 0, 0], bool)
    assert keep_runs(f, 2, False).astype(int).tolist() == [0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1, 0, 0]
    assert keep_runs(f, 2, True).astype(int).tolist() == [0, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0]
    edge = np.array([0, 1, 1, 1], bool)  # a gap at the clip start is not a gap between contacts
    assert keep_runs(edge, 3, False).tolist() == edge.tolist()


@needs_shared
def test_bvh_walk_alternates_feet():
    from pipeline.readers import read_clips

    clip = read_clips(SHARED_MOCAP / "bvh" / "pymo_walk_120hz.bvh")[0]
    fc = detect_foot_contacts(clip)
    assert fc.foot_joints == {"left": ("LeftFoot", "LeftToeBase"), "right": ("RightFoot", "RightToeBase")}
    assert 0.2 < fc.left.mean() < 0.6 and 0.2 < fc.right.mean() < 0.6
    # each foot plants in turn: the sequence of touch-downs alternates left, right, left, ...
    downs = sorted((t, s) for s, f in enumerate((fc.left, fc.right)) for t in np.flatnonzero(f[1:] & ~f[:-1]) + 1)
    sides = [s for _, s in downs]
    assert len(sides) >= 8
    assert all(a != b for a, b in zip(sides, sides[1:])), sides
