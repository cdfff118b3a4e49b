"""The SMPL body's 22 joints for a 1.70 m adult, and a pose solver (forward kinematics + 2-link IK).

Rest pose (all global joint rotations identity): the SMPL T-pose moved into the project's world,
z-up, metres, facing +x, left = +y, standing on the floor ``z = 0`` with the pelvis at 0.93 m.
The offsets are SMPL-like (symmetric, rounded from the SMPL neutral template and scaled to
1.70 m): hips 9 cm below and 7 cm beside the pelvis, thigh 0.377 m, shank 0.386 m, ankles 8 cm
and toe-base ("foot") joints 2.5 cm above the floor and 13 cm ahead of the ankles, shoulders at
1.395 m, upper arm 0.30 m, forearm 0.27 m (relaxed hanging wrists at about 0.84 m).

:func:`solve_pose` turns per-frame targets (pelvis position and heading, trunk pitch, ankle
targets, wrist targets) into joint rotations and then builds every joint position by forward
kinematics, ``p[j] = p[parent] + R[parent] @ OFFSETS[j]``, so bone lengths are exactly constant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.clip import Skeleton
from pipeline.readers.amass import SMPL_BODY_JOINT_NAMES, SMPL_BODY_PARENTS
from pipeline.rotations import wxyz_from_rotation

JOINT_NAMES, PARENTS = SMPL_BODY_JOINT_NAMES, SMPL_BODY_PARENTS  # an SMPL body: readers and retargeting treat it as one
SKELETON = Skeleton(JOINT_NAMES, PARENTS)
J = {name: i for i, name in enumerate(JOINT_NAMES)}
SUBJECT_HEIGHT = 1.70

# Offsets from the parent joint in the rest pose; left side listed, right side mirrored (y -> -y).
_LEFT = {
    "left_hip": (-0.005, 0.070, -0.090),
    "left_knee": (0.005, 0.034, -0.375),
    "left_ankle": (-0.030, -0.015, -0.385),
    "left_foot": (0.130, 0.025, -0.055),
    "left_collar": (-0.010, 0.070, 0.120),
    "left_shoulder": (-0.010, 0.105, 0.045),
    "left_elbow": (0.000, 0.300, 0.000),
    "left_wrist": (0.000, 0.270, 0.000),
}
_CENTRE = {
    "pelvis": (0.0, 0.0, 0.0),
    "spine1": (-0.010, 0.0, 0.110),
    "spine2": (0.005, 0.0, 0.135),
    "spine3": (0.000, 0.0, 0.055),
    "neck": (-0.015, 0.0, 0.205),
    "head": (0.045, 0.0, 0.090),
}


def _offsets() -> np.ndarray:
    off = np.zeros((len(JOINT_NAMES), 3))
    for name, v in {**_CENTRE, **_LEFT}.items():
        off[J[name]] = v
        if name.startswith("left_"):
            off[J["right_" + name[5:]]] = (v[0], -v[1], v[2])
    return off


OFFSETS = _offsets()
REST_PELVIS_Z = 0.93
ANKLE_Z = REST_PELVIS_Z + OFFSETS[[1, 4, 7], 2].sum()  # 0.08: flat-foot ankle height
FOOT_Z = ANKLE_Z + OFFSETS[J["left_foot"], 2]  # 0.025: toe-base joint height, foot flat
STANCE_HALF_WIDTH = 0.09  # ankle y in the rest pose (0.089), rounded
PELVIS_FWD = -OFFSETS[[1, 4, 7], 0].sum()  # 0.03: pelvis ahead of the ankles when standing
THIGH, SHANK = (float(np.linalg.norm(OFFSETS[J[n]])) for n in ("left_knee", "left_ankle"))
UPPER_ARM, FOREARM = (float(np.linalg.norm(OFFSETS[J[n]])) for n in ("left_elbow", "left_wrist"))
LEG_REACH = 0.995 * (THIGH + SHANK)  # most hip-ankle distance used: knees never fully locked
ARM_HANG = 0.95 * (UPPER_ARM + FOREARM)  # shoulder-wrist distance of a relaxed hanging arm
SPINE_SHARE = (0.35, 0.35, 0.30)  # how trunk flexion is spread over spine1/2/3
KNEE_OUT = 0.20  # rad: knees point this much outward of the toes
ELBOW_POLE = np.array([-0.6, 0.2, -0.7])  # heading frame, left arm: elbows back, out and down


def rot_z(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def rot_y(a) -> np.ndarray:
    """Rotation about +y; a positive angle tips +z towards +x (a forward bow)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 2], R[..., 2, 0], R[..., 2, 2], R[..., 1, 1] = c, s, -s, c, 1.0
    return R


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(a: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Orthonormal frame with columns (a, n x a, n), n made orthogonal to a."""
    a = _unit(a)
    n = _unit(n - np.sum(n * a, -1, keepdims=True) * a)
    return np.stack([a, np.cross(n, a), n], axis=-1)


def _apply(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,...j->...i", R, v)


def two_link(root, target, rest1, rest2, pole, rest_pole):
    """Analytic 2-link IK: global rotations (R1, R2) of the two bones whose rest offsets are
    ``rest1``, ``rest2``, putting the middle joint on the ``pole`` side of the root-target line.
    R1 @ rest1 and R2 @ rest2 have exactly the rest lengths; the end reaches ``target`` when
    it is within reach (otherwise it stops on the root-target line)."""
    l1, l2 = np.linalg.norm(rest1), np.linalg.norm(rest2)
    v = target - root
    d = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / d
    d = np.clip(d, abs(l1 - l2) + 1e-6, l1 + l2 - 1e-9)
    a = (l1**2 - l2**2 + d**2) / (2 * d)
    h = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    w = _unit(pole - np.sum(pole * u, -1, keepdims=True) * u)
    mid = a * u + h * w
    n = np.cross(u, w)
    u0 = _unit(rest1 + rest2)
    n0 = np.cross(u0, _unit(rest_pole - (rest_pole @ u0) * u0))
    R1 = _frame(mid, n) @ _frame(rest1, n0).T
    R2 = _frame(d * u - mid, n) @ _frame(rest2, n0).T
    return R1, R2


@dataclass
class PoseTargets:
    """Per-frame targets (T frames). Angles in radians; sides ordered (left, right)."""

    pelvis: np.ndarray  # (T,3) pelvis joint position
    yaw: np.ndarray  # (T,) heading about +z
    pelvis_pitch: np.ndarray  # (T,) forward tilt of the pelvis (hip flexion part)
    spine_pitch: np.ndarray  # (T,) extra forward flexion spread over spine1-3
    ankles: np.ndarray  # (T,2,3) ankle targets
    foot_yaw: np.ndarray  # (T,2) foot headings (feet flat)
    hand_target: np.ndarray  # (T,2,3) wrist targets (used with hand_weight)
    hand_weight: np.ndarray  # (T,2) 0 = relaxed hanging arm, 1 = wrist at hand_target
    arm_swing: np.ndarray  # (T,2) forward swing of a relaxed arm


def hip_offsets(yaw, pelvis_pitch) -> np.ndarray:
    """(T,2,3) hip joint positions relative to the pelvis."""
    R0 = rot_z(yaw) @ rot_y(pelvis_pitch)
    return np.stack([_apply(R0, OFFSETS[1]), _apply(R0, OFFSETS[2])], axis=1)


def solve_pose(p: PoseTargets) -> tuple[np.ndarray, np.ndarray]:
    """Global joint positions (T,22,3) and orientations (T,22,4, wxyz) from targets."""
    T = len(p.yaw)
    R = np.zeros((T, 22, 3, 3))
    P = np.zeros((T, 22, 3))
    Ryaw = rot_z(p.yaw)

    def place(j):
        P[:, j] = P[:, PARENTS[j]] + _apply(R[:, PARENTS[j]], OFFSETS[j])

    P[:, 0] = p.pelvis
    R[:, 0] = Ryaw @ rot_y(p.pelvis_pitch)
    trunk = p.pelvis_pitch + p.spine_pitch
    for j, share in zip((3, 6, 9), SPINE_SHARE):
        place(j)
        R[:, j] = R[:, PARENTS[j]] @ rot_y(share * p.spine_pitch)
    place(12)
    R[:, 12] = R[:, 9] @ rot_y(-0.45 * trunk)  # the neck and head keep the gaze partly level
    place(15)
    R[:, 15] = R[:, 12] @ rot_y(-0.25 * trunk)
    for side, (hip, knee, ankle, foot) in enumerate(((1, 4, 7, 10), (2, 5, 8, 11))):
        sign = 1.0 if side == 0 else -1.0
        place(hip)
        pole = _apply(rot_z(p.foot_yaw[:, side] + sign * KNEE_OUT), np.array([1.0, 0.0, 0.0]))
        R[:, hip], R[:, knee] = two_link(
            P[:, hip], p.ankles[:, side], OFFSETS[knee], OFFSETS[ankle], pole, np.array([1.0, 0, 0])
        )
        place(knee)
        place(ankle)
        R[:, ankle] = R[:, foot] = rot_z(p.foot_yaw[:, side])
        place(foot)
    for side, (collar, shoulder, elbow, wrist) in enumerate(((13, 16, 18, 20), (14, 17, 19, 21))):
        sign = 1.0 if side == 0 else -1.0
        place(collar)
        R[:, collar] = R[:, 9]
        place(shoulder)
        sw = p.arm_swing[:, side]
        hang = np.stack([ARM_HANG * np.sin(sw), np.full(T, sign * 0.06), -ARM_HANG * np.cos(sw)], -1)
        free = P[:, shoulder] + _apply(Ryaw, hang)
        w = p.hand_weight[:, side, None]
        target = (1 - w) * free + w * p.hand_target[:, side]
        pole = _apply(Ryaw, ELBOW_POLE * (1.0, sign, 1.0))
        R[:, shoulder], R[:, elbow] = two_link(
            P[:, shoulder], target, OFFSETS[elbow], OFFSETS[wrist], pole, np.array([-1.0, 0, 0])
        )
        place(elbow)
        place(wrist)
        R[:, wrist] = R[:, elbow]
    quat = wxyz_from_rotation(Rotation.from_matrix(R.reshape(-1, 3, 3))).reshape(T, 22, 4)
    return P, quat
