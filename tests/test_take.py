"""Take kinds from hand-made object tracks (each kind, the thresholds' edges) and both-hand held frames, plus the
shared OMOMO slide ``sub8_largebox_000``."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from pipeline.clip import HumanClip, ObjectTrack, Skeleton
from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.take import (
    HOLD_GAP_M,
    LIFT,
    OVERHEAD,
    OVERHEAD_RISE_M,
    SLIDE,
    SLIDE_RISE_M,
    SMALL_MOVE,
    SMALL_MOVE_M,
    TakeKind,
    hand_joints,
    held_frames,
    take_kind,
)

T = 100
BOX_HALF = 0.2  # the test box's half-extent [m]


def track(rise: float, travel: float, z0: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """(T, 7) object pose: up by ``rise`` and along x by ``travel`` (smoothly, first frame at rest), yawed
    ``yaw`` [rad] by the end."""
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, T))  # 0 -> 1
    pose = np.zeros((T, 7))
    pose[:, 0] = travel * s
    pose[:, 1] = 0.3  # the start is not the origin
    pose[:, 2] = z0 + rise * s
    pose[:, 3] = np.cos(yaw * s / 2)
    pose[:, 6] = np.sin(yaw * s / 2)
    return pose


@pytest.mark.parametrize(
    "rise, travel, kind",
    [
        (0.0, 1.3, SLIDE),  # a box pushed along the floor
        (0.06, 1.1, SLIDE),  # a table dragged with one edge raised
        (0.8, 1.5, LIFT),  # lifted and carried
        (0.7, 0.1, LIFT),  # lifted in place
        (0.15, 0.6, LIFT),  # lifted a little and carried
        (1.8, 0.3, OVERHEAD),  # a table raised above the head
        (1.6, 0.0, OVERHEAD),
        (0.12, 0.16, SMALL_MOVE),  # a chair nudged
        (0.0, 0.0, SMALL_MOVE),  # untouched
    ],
)
def test_each_kind(rise, travel, kind):
    got = take_kind(track(rise, travel, z0=0.37))
    assert got.kind == kind
    assert got.rise_m == pytest.approx(rise, abs=1e-9) and got.travel_m == pytest.approx(travel, abs=1e-9)


@pytest.mark.parametrize(
    "rise, travel, kind",
    [
        (SMALL_MOVE_M, SMALL_MOVE_M, SMALL_MOVE),  # both bars inclusive
        (SMALL_MOVE_M + 1e-6, SMALL_MOVE_M, LIFT),
        (SLIDE_RISE_M, SMALL_MOVE_M + 1e-6, SLIDE),  # slide: rise inclusive, travel strictly beyond a small move
        (SLIDE_RISE_M + 1e-6, SMALL_MOVE_M + 1e-6, LIFT),
        (SLIDE_RISE_M, SMALL_MOVE_M, SMALL_MOVE),
        (OVERHEAD_RISE_M, 0.5, OVERHEAD),  # overhead inclusive
        (OVERHEAD_RISE_M - 1e-6, 0.5, LIFT),
        (OVERHEAD_RISE_M, 0.0, OVERHEAD),
    ],
)
def test_boundaries(rise, travel, kind):
    assert take_kind(track(rise, travel)).kind == kind


def test_measured_from_the_first_frame_at_the_furthest_point():
    """Rise and travel are the furthest the object gets from where it started, not where it ends."""
    out_and_back = np.sin(np.linspace(0.0, np.pi, T))  # 0 -> 1 -> 0
    pushed_back = track(0.0, 0.0)
    pushed_back[:, 0] = out_and_back  # pushed 1 m out and back to where it started
    assert take_kind(pushed_back) == TakeKind(SLIDE, 0.0, pytest.approx(1.0, abs=1e-3))
    set_down = track(0.0, 0.1)
    set_down[:, 2] = 0.9 * out_and_back  # lifted 0.9 m and set down again
    assert take_kind(set_down).kind == LIFT and take_kind(set_down).rise_m == pytest.approx(0.9, abs=1e-3)
    dipped = track(0.0, 0.1)
    dipped[:, 2] -= np.linspace(0.0, 0.5, T)  # goes down only: no rise
    assert take_kind(dipped).rise_m == 0.0


def test_orientation_is_not_motion():
    """A chair turned half round where it stands is a small move."""
    assert take_kind(track(0.0, 0.0, yaw=np.pi)).kind == SMALL_MOVE


def test_bad_track_raises():
    with pytest.raises(InputError, match="object pose"):
        take_kind(np.zeros((10, 3)))
    bad = track(0.0, 1.0)
    bad[5, 2] = np.nan
    with pytest.raises(InputError, match="frame 5"):
        take_kind(bad)


# -- held frames -------------------------------------------------------------------------------------------------

NAMES = ("pelvis", "left_wrist", "left_index1", "right_wrist", "right_index1")
SKELETON = Skeleton(NAMES, (-1, 0, 1, 0, 3))
LW, LF, RW, RF = 1, 2, 3, 4


def human(joint_pos: np.ndarray, contacts: np.ndarray | None = None) -> HumanClip:
    """A clip of the 5-joint skeleton around a still box (half-extent 0.2 m) at the origin."""
    n = len(joint_pos)
    pose = np.tile([0.0, 0.0, BOX_HALF, 1.0, 0.0, 0.0, 0.0], (n, 1))
    box = ObjectTrack("box", Primitive("box", (BOX_HALF,) * 3), pose)
    return HumanClip(SKELETON, joint_pos, 30.0, "test", contacts=contacts, objects=(box,))


def far_pose(n: int) -> np.ndarray:
    """Every joint 1 m or more from the box."""
    pos = np.zeros((n, len(NAMES), 3))
    pos[:, :, 1] = -1.5
    pos[:, :, 2] = 1.0
    return pos


def test_hand_joints_are_the_wrist_and_below():
    assert hand_joints(SKELETON, "left") == [LW, LF]
    assert hand_joints(SKELETON, "right") == [RW, RF]
    assert hand_joints(Skeleton(("pelvis", "head"), (-1, 0)), "left") == []


def test_held_by_proximity_on_opposite_sides_whether_or_not_the_object_is_up():
    """Fingers just off two opposite faces hold the box resting on the floor; the wrists alone are too far."""
    pos = far_pose(4)
    gap = HOLD_GAP_M / 2
    pos[:2, LF] = [-(BOX_HALF + gap), 0.0, BOX_HALF]
    pos[:2, RF] = [BOX_HALF + gap, 0.0, BOX_HALF]
    pos[:2, LW] = pos[:2, LF] - [0.08, 0.0, 0.0]
    pos[:2, RW] = pos[:2, RF] + [0.08, 0.0, 0.0]
    pos[1, RF, 0] = BOX_HALF + 2 * HOLD_GAP_M  # the right hand leaves at frame 1
    assert held_frames(human(pos)).tolist() == [True, False, False, False]


def test_held_by_labels_or_proximity_per_hand():
    """Each hand counts when any of its joints is labelled, or when it is near; both hands must count."""
    pos = far_pose(5)
    pos[:, LF] = [-(BOX_HALF + HOLD_GAP_M / 2), 0.0, BOX_HALF]  # the left hand is near in every frame
    contacts = np.zeros((5, len(NAMES)), bool)
    contacts[0, RW] = True  # right wrist labelled
    contacts[1, RF] = True  # right fingers labelled
    contacts[2, LW] = True  # only the (already near) left hand labelled
    contacts[3, [LW, RW]] = True  # both labelled
    assert held_frames(human(pos, contacts)).tolist() == [True, True, False, True, False]
    assert not held_frames(human(pos)).any()  # no labels: the right hand is never near


def test_no_wrists_or_no_object_no_held_frames():
    clip = human(far_pose(3), np.ones((3, len(NAMES)), bool))
    assert held_frames(clip).all()
    no_object = HumanClip(SKELETON, clip.joint_pos, 30.0, "test", contacts=clip.contacts)
    assert held_frames(no_object).tolist() == [False] * 3
    skeleton = Skeleton(("pelvis", "left_wrist"), (-1, 0))
    one_hand = HumanClip(skeleton, np.zeros((3, 2, 3)), 30.0, "test", contacts=np.ones((3, 2)), objects=clip.objects)
    assert not held_frames(one_hand).any()


@needs_shared
def test_shared_largebox_push_is_a_held_slide():
    """``sub8_largebox_000``: the box pushed along the floor is a slide, held with both hands (the old rule, the
    object 3 cm up, found no frame: its ``opp`` was blank)."""
    from pipeline.readers import read_clips

    clip = read_clips(SHARED_MOCAP / "interact" / "sub8_largebox_000.pt")[0]
    kind = take_kind(clip.objects[0].pose)
    assert kind.kind == SLIDE
    assert kind.rise_m <= SLIDE_RISE_M and kind.travel_m > 1.0
    assert held_frames(clip).mean() > 0.3
