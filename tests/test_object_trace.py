"""The object trace every physicalized clip with objects carries (physicalize/object_trace.py): a G1 standing in real
MuJoCo beside a box whose reference track moves away (and turns) while nothing pushes it."""

import numpy as np
from standing import standing_qpos

from physicalize.clip import physicalize_clip
from physicalize.object_trace import OBJECT_DRIFT_M, hand_columns
from pipeline.clip import ObjectTrack, RobotClip
from pipeline.geometry import Primitive
from pipeline.rotations import yaw_of


def _stand_beside_a_box(turn_deg: float, frames: int = 100) -> RobotClip:
    """The G1 standing; a box 0.8 m ahead whose track slides 0.3 m further away over frames 40-70 while turning by
    ``turn_deg``; no hand is labelled on it."""
    stand = standing_qpos(frames)
    s = np.clip((np.arange(frames) - 40) / 30, 0.0, 1.0)
    yaw = np.radians(turn_deg) * s
    box = np.zeros((frames, 7))
    box[:, 0], box[:, 2] = 0.8 + 0.3 * s, 0.15
    box[:, 3], box[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    track = ObjectTrack("box", Primitive("box", (0.15, 0.15, 0.15)), box, None, 1.0, "hand-made")
    return RobotClip(stand, 50, "hand-made:stand", objects=(track,), task="stand")


def test_a_box_its_track_leaves_behind_is_traced_as_left_behind_with_no_hand_on_it():
    clip = _stand_beside_a_box(0.0)
    _, roll, figures, _ = physicalize_clip(clip, search=None)
    assert not figures["valid"]  # the box never moves: its track leaves it 0.3 m behind
    assert figures["object_drift_object"] == "box" and figures["object_drift_cause"] == "left behind"
    assert 40 / 50 < figures["object_drift_s"] < 70 / 50
    assert -0.12 < figures["object_drift_along_m"] <= -OBJECT_DRIFT_M + 0.01
    assert abs(figures["object_drift_lateral_m"]) < 0.01 and abs(figures["object_drift_yaw_deg"]) < 1.0
    assert figures["object_drift_hands_planned"] == 0 and figures["object_drift_hands_touching"] == 0


def test_a_box_its_track_turns_away_from_is_traced_as_turned():
    clip = _stand_beside_a_box(60.0)
    _, roll, figures, _ = physicalize_clip(clip, search=None)
    onset = round(figures["object_drift_s"] * 50)
    assert figures["object_drift_cause"] == "turned"
    expected = -np.degrees(yaw_of(clip.objects[0].pose[onset, 3:]))  # the box stayed square; its track turned
    assert abs(figures["object_drift_yaw_deg"] - expected) < 2.0 and expected < -10.0


def test_a_box_that_stays_on_its_track_has_no_drift_and_the_hand_columns_are_the_wrists():
    clip = _stand_beside_a_box(0.0, frames=40)  # the track starts moving only at frame 40: never
    _, _, figures, _ = physicalize_clip(clip, search=None)
    assert figures["valid"] and figures["object_drift_s"] is None and "object_drift_cause" not in figures
    links = ("pelvis", "left_wrist_yaw_link", "right_knee_link", "right_wrist_yaw_link", "left_elbow_link")
    assert hand_columns(links) == ([1], [3])


def test_an_invalid_rollouts_reason_names_the_physics_before_the_plans_split():
    """Where pressing hands cannot give the needed force at all (physicalize.feasibility), the reason says so; where
    only the plan's share per hand leaves a cone, it says that the hands together could give it."""
    from physicalize.clip import _hold_cause

    outside = np.zeros(100, bool)
    outside[60:] = True
    physics = {"reference_hold_infeasible_from_s": 1.5, "reference_hold_infeasible_frac": 0.25}
    assert _hold_cause(physics, outside, 50) == (
        "; pressing hands cannot give the force the held object needs on 25% of the held frames from t=1.50 s"
    )
    split = {"reference_hold_infeasible_from_s": None, "reference_hold_infeasible_frac": 0.0}
    assert _hold_cause(split, outside, 50).endswith("from t=1.20 s (the hands together could give it)")
    assert _hold_cause(split, np.zeros(100, bool), 50) == ""
