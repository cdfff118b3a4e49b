"""Posture channels over time, their evaluation into a full-body pose, and clip assembly."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.synthetic.gait import GaitPlan, Keys, heading, lift_swing_feet, pelvis_height, smooth_below
from ingest.synthetic.skeleton import REST_PELVIS_Z, SKELETON, SUBJECT_HEIGHT, J, PoseTargets, solve_pose
from pipeline.clip import HumanClip, ObjectTrack

HAND_OFFSET = 0.04  # wrist joint centre outside the touched face: half a hand's thickness + palm
WALK_DIP = 0.03  # the nominal pelvis height drops this much while walking (knees softer)
ARM_SWING_GAIN = 0.5  # rad of arm swing per metre the opposite foot is ahead


@dataclass(frozen=True)
class Phase:
    """A named time interval of a clip, in seconds from its first frame."""

    name: str
    start: float
    end: float


@dataclass(frozen=True)
class SyntheticDemo:
    """A generated clip with what the generator knows about it."""

    clip: HumanClip
    phases: tuple[Phase, ...]
    foot_stance: np.ndarray  # (T,2) bool: left/right foot planted flat on the floor


class Channels:
    """Posture channels keyed in time (minimum-jerk between keys): pelvis height ``z``
    (nominal, before the legs' reach cap), pelvis shift ``dx`` along the heading, pelvis and
    spine pitch ``pp``/``sp``, and the weight ``hw`` pulling both wrists to their targets."""

    NAMES = ("z", "dx", "pp", "sp", "hw")

    def __init__(self):
        start = dict(z=REST_PELVIS_Z, dx=0.0, pp=0.0, sp=0.0, hw=0.0)
        self.ch = {n: Keys(0.0, v) for n, v in start.items()}

    def to(self, t0: float, t1: float, **values) -> Channels:
        """Hold each named channel until ``t0``, then move it to its value by ``t1``."""
        for name, v in values.items():
            k = self.ch[name]
            if t0 > k.keys[-1][0] + 1e-9:
                k.hold(t0)
            k.set(t1, v)
        return self

    def __call__(self, t):
        return {n: k(t) for n, k in self.ch.items()}


@dataclass
class Body:
    """Channels and gait evaluated on the time grid, before solving the pose."""

    t: np.ndarray
    pelvis: np.ndarray  # (T,3)
    centre: np.ndarray  # (T,2) pelvis xy without sway or posture shift: where held objects ride
    yaw: np.ndarray
    ch: dict
    ankles: np.ndarray
    foot_yaw: np.ndarray
    stance: np.ndarray

    @property
    def fwd(self) -> np.ndarray:
        return heading(self.yaw)


def _rate(t: np.ndarray) -> float:
    return 1.0 / (t[1] - t[0])


def evaluate(t: np.ndarray, gait: GaitPlan, channels: Channels) -> Body:
    ch = channels(t)
    ankles, foot_yaw, progress = gait.feet_at(t)
    xy, yaw = gait.pelvis_xy(t)
    centre, _ = gait.pelvis_xy(t, sway=False)
    xy = xy + ch["dx"][:, None] * heading(yaw)
    nominal = ch["z"] - WALK_DIP * gait.walking(t)
    z = pelvis_height(nominal, xy, yaw, ch["pp"], ankles, progress)
    pelvis = np.column_stack([xy, smooth_below(z, int(round(0.1 * _rate(t))))])
    ankles = lift_swing_feet(pelvis, yaw, ch["pp"], ankles, progress)
    return Body(t, pelvis, centre, yaw, ch, ankles, foot_yaw, gait.stance_frames(t))


def solve(body: Body, hand_target: np.ndarray):
    """Joint positions and orientations for the body, wrists pulled to ``hand_target`` by the
    ``hw`` channel; relaxed arms swing against the legs."""
    diff = np.einsum("tk,tk->t", body.ankles[:, 1, :2] - body.ankles[:, 0, :2], body.fwd)
    hw = body.ch["hw"]
    targets = PoseTargets(
        pelvis=body.pelvis,
        yaw=body.yaw,
        pelvis_pitch=body.ch["pp"],
        spine_pitch=body.ch["sp"],
        ankles=body.ankles,
        foot_yaw=body.foot_yaw,
        hand_target=hand_target,
        hand_weight=np.repeat(np.asarray(hw)[:, None], 2, axis=1),
        arm_swing=ARM_SWING_GAIN * np.column_stack([diff, -diff]),
    )
    return solve_pose(targets)


def yaw_pose(xyz: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(T,7) poses (x, y, z, qw, qx, qy, qz) turned by ``yaw`` about +z."""
    yaw = np.broadcast_to(yaw, (len(xyz),))
    zeros = np.zeros(len(xyz))
    return np.column_stack([xyz, np.cos(yaw / 2), zeros, zeros, np.sin(yaw / 2)])


def grip_points(pose: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World positions (T,2,3) of the two wrist targets ``local`` (2,3) in a yaw-only box frame."""
    yaw = 2 * np.arctan2(pose[:, 6], pose[:, 3])
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, y = local[:, 0][None], local[:, 1][None]
    return np.stack(
        [pose[:, None, 0] + c * x - s * y, pose[:, None, 1] + s * x + c * y, pose[:, None, 2] + local[:, 2][None]], -1
    )


def make_demo(
    task: str, fps: float, body: Body, hand_target, objects: list[dict], phases, contacts: dict
) -> SyntheticDemo:
    """Solve the pose and assemble the validated, synthetic-labelled clip.

    ``objects``: dicts with ``name, geometry, pose, contact, mass``; ``contacts``: joint name ->
    (T,) bool, contact of that joint with an object."""
    pos, quat = solve(body, hand_target)
    source = f"synthetic:{task}"
    flags = np.zeros(pos.shape[:2], bool)
    for name, c in contacts.items():
        flags[:, J[name]] = c
    tracks = tuple(ObjectTrack(source=source, **o) for o in objects)
    clip = HumanClip(
        SKELETON,
        pos,
        fps,
        source,
        subject_height=SUBJECT_HEIGHT,
        joint_quat=quat,
        contacts=flags,
        objects=tracks,
        task=task,
        synthetic=True,
    )
    return SyntheticDemo(clip, tuple(Phase(n, round(a, 6), round(b, 6)) for n, a, b in phases), body.stance)
