"""Isaac Lab's (PhysX's) joint and body order of the G1, the order BeyondMimic's motion ``.npz`` holds its columns in:
kept literally here, in the shared core, because both the BeyondMimic exporter (:mod:`motion_export.isaaclab`, which
explains the order and whose tests check it against a breadth-first walk of the model) and the reader of a BeyondMimic
file (:mod:`pipeline.readers.npz_order`) need it."""

from __future__ import annotations

#: Isaac Lab (PhysX) joint order of the G1: breadth-first over the kinematic tree, left before right before waist
ISAACLAB_JOINT_NAMES: tuple[str, ...] = tuple(
    f"{n}_joint"
    for n in (
        "left_hip_pitch", "right_hip_pitch", "waist_yaw",
        "left_hip_roll", "right_hip_roll", "waist_roll",
        "left_hip_yaw", "right_hip_yaw", "waist_pitch",
        "left_knee", "right_knee", "left_shoulder_pitch", "right_shoulder_pitch",
        "left_ankle_pitch", "right_ankle_pitch", "left_shoulder_roll", "right_shoulder_roll",
        "left_ankle_roll", "right_ankle_roll", "left_shoulder_yaw", "right_shoulder_yaw",
        "left_elbow", "right_elbow",
        "left_wrist_roll", "right_wrist_roll",
        "left_wrist_pitch", "right_wrist_pitch",
        "left_wrist_yaw", "right_wrist_yaw",
    )
)  # fmt: skip

#: Isaac Lab (PhysX) body order of the G1: the pelvis (root), then each joint's child link in joint order
ISAACLAB_BODY_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip_pitch_link", "right_hip_pitch_link", "waist_yaw_link",
    "left_hip_roll_link", "right_hip_roll_link", "waist_roll_link",
    "left_hip_yaw_link", "right_hip_yaw_link", "torso_link",
    "left_knee_link", "right_knee_link", "left_shoulder_pitch_link", "right_shoulder_pitch_link",
    "left_ankle_pitch_link", "right_ankle_pitch_link", "left_shoulder_roll_link", "right_shoulder_roll_link",
    "left_ankle_roll_link", "right_ankle_roll_link", "left_shoulder_yaw_link", "right_shoulder_yaw_link",
    "left_elbow_link", "right_elbow_link",
    "left_wrist_roll_link", "right_wrist_roll_link",
    "left_wrist_pitch_link", "right_wrist_pitch_link",
    "left_wrist_yaw_link", "right_wrist_yaw_link",
)  # fmt: skip
