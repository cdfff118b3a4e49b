"""Clean starts: a retargeted clip that begins mid-stride gets a synthetic prefix, a standing settle in double
support at its first frame's footholds and a blend into the clip, so that tracking starts from rest.

Why: a rollout starts from the reference's first frame (:func:`physicalize.rollout.initial_state`). By a reading of
the 20 shared real takes, 8 start with a foot in swing and 11 with the pelvis moving at >= 0.1 m/s; traced on
``interact/sub8_largebox_000`` (starting on one foot), the pelvis lagged its reference by 10 cm at 0.5 s and 13 cm
by first contact, and the clip failed from there. The synthetic clips start standing still and get no prefix.

The prefix (:func:`clean_start`), :data:`SETTLE_S` + :data:`BLEND_S` = 1.5 s at most:

* **stance** (:func:`standing_pose`): the first frame's pose re-solved by differential IK (mink) with both soles
  flat on the floor, each foot at its first-frame position and heading (a foot in swing put down where it is), the
  pelvis over the feet's midpoint at the first frame's height and heading, the rest of the body at the first
  frame's joints; then placed on the floor (:func:`physicalize.reference.place_on_floor`);
* **settle**: that pose held for :data:`SETTLE_S`;
* **blend** over :data:`BLEND_S` into frame 0: root position and joints by a cubic Hermite curve from the stance at
  rest to frame 0 at its own velocity (``p(s) = h00(s) p_stance + h01(s) p_0 + h11(s) B v_0``, ``B`` the blend's
  length in seconds, ``v_0`` the clip's velocity at frame 0: no velocity jump where the clip begins), the root
  orientation slerped by the smoothstep ``h01(s)``.

The objects hold their first-frame pose and every contact label is off over the prefix; the clip's own frames follow
unchanged. The prefix is part of the tracked reference and of the episode, held to the same validation bars, and
marked: ``provenance["start_prefix_frames"]`` (the frames before the clip's first).
"""

from __future__ import annotations

from dataclasses import replace

import mink
import numpy as np

from physicalize.reference import build_reference, place_on_floor
from pipeline.clip import START_PREFIX_KEY, RobotClip
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import FOOT_BODIES, g1_model, sole_corners
from pipeline.rotations import slerp_wxyz, yaw_of, yaw_quat
from pipeline.terms.layout import CONTROL_FPS

SETTLE_S = 0.5  # s: the stance held still
BLEND_S = 1.0  # s: from the stance into the clip's first frame
SWING_S = 0.3  # s: a foot in swing at frame 0 leaves the floor this long before the clip begins
SWING_M = 0.03  # a sole corner higher than this above the floor: that foot is in swing (physicalize.reference)
MOVING_MPS = 0.1  # a pelvis faster than this at frame 0: the clip starts moving
IK_STEPS = 60


def starts_clean(clip: RobotClip) -> bool:
    """Whether the clip starts standing still: both soles on the floor (every corner within :data:`SWING_M`) and the
    pelvis slower than :data:`MOVING_MPS` horizontally (the median over its first ten frames: a retargeted clip's
    first frames are solved on their own and their differences can jump). On the 20 shared takes, a prefix for
    these (a foot in swing or the pelvis moving) left 2 valid and 1 falling before contact; for a foot in swing
    alone, 1 valid and 2 falling before contact."""
    speed = np.linalg.norm(qvel_from_qpos(clip.qpos[:11], clip.fps)[:10, :2], axis=1) if clip.frames > 1 else [0.0]
    return not _swing_feet(clip.qpos[0]) and float(np.median(speed)) < MOVING_MPS


def _swing_feet(q: np.ndarray) -> list[int]:
    """The feet (0 left, 1 right) of pose ``q`` with a sole corner above :data:`SWING_M`."""
    corners = build_reference(g1_model(), q[None], float(CONTROL_FPS)).corners[0]  # (2, 4, 3) sole corners
    return [k for k in range(2) if corners[k, :, 2].max() > SWING_M]


def _yaw_quat(quat: np.ndarray) -> np.ndarray:
    """The heading part (rotation about z) of a wxyz quaternion."""
    return yaw_quat(float(yaw_of(quat)))


def standing_pose(q0: np.ndarray) -> np.ndarray:
    """(36,) the pose ``q0`` re-solved to stand in double support (module docstring), on the floor."""
    model = g1_model()
    configuration = mink.Configuration(model, q0.copy())
    d = configuration.data
    feet = []
    for body in FOOT_BODIES:
        b = model.body(body).id
        target = np.concatenate([_yaw_quat(d.xquat[b]), d.xpos[b]])
        target[6] = -sole_corners(model, body)[:, 2].min()  # the sole flat on the floor
        task = mink.FrameTask(body, "body", position_cost=1000.0, orientation_cost=100.0)
        task.set_target(mink.SE3(target))
        feet.append(task)
    pelvis = mink.FrameTask("pelvis", "body", position_cost=[10.0, 10.0, 1.0], orientation_cost=10.0)
    mid = np.mean([t.transform_target_to_world.translation() for t in feet], axis=0)
    pelvis.set_target(mink.SE3(np.concatenate([_yaw_quat(q0[3:7]), [mid[0], mid[1], q0[2]]])))
    posture = mink.PostureTask(model, cost=0.1)
    posture.set_target(q0)
    limits = [mink.ConfigurationLimit(model)]
    for _ in range(IK_STEPS):
        dq = mink.solve_ik(configuration, [*feet, pelvis, posture], 1.0, "daqp", damping=1e-3, limits=limits)
        configuration.integrate_inplace(dq, 1.0)
    return place_on_floor(model, configuration.q[None])[0]


def _hermite(p0: np.ndarray, p1: np.ndarray, v1: np.ndarray, s: np.ndarray, length_s: float) -> np.ndarray:
    """(n, k): the cubic from ``p0`` at rest to ``p1`` at velocity ``v1`` (k,) at phases ``s`` (n,) in [0, 1], each
    coordinate's end tangent ``length_s v1`` clipped into ``[0, 3 (p1 - p0)]``: the curve then never overshoots
    either end (a cubic from rest is monotone iff its end tangent lies there; traced on a take that starts in a
    squat, joints at 3 rad/s, the unclipped tangent swung the legs 0.4 rad back before the clip and the robot
    fell), matching the clip's velocity wherever that keeps it monotone."""
    span = 3 * (p1 - p0)
    tangent = np.clip(length_s * v1, np.minimum(span, 0), np.maximum(span, 0))
    s = s[:, None]
    h01 = 3 * s**2 - 2 * s**3
    h11 = s**3 - s**2
    return (1 - h01) * p0 + h01 * p1 + h11 * tangent


def clean_start(clip: RobotClip) -> RobotClip:
    """``clip`` with the prefix of the module docstring when it does not :func:`starts_clean`, else ``clip``."""
    if clip.frames < 2 or starts_clean(clip):
        return clip
    fps, q0 = clip.fps, clip.qpos[0]
    stand = standing_pose(q0)
    settle, blend = round(SETTLE_S * fps), round(BLEND_S * fps)
    s = np.arange(1, blend + 1) / (blend + 1)
    v0 = np.median(qvel_from_qpos(clip.qpos[:6], fps)[:5], axis=0)
    v_pos = np.concatenate([v0[:3], v0[6:]])  # root linear velocity (world) and joint velocities
    p_stand, p0 = np.concatenate([stand[:3], stand[7:]]), np.concatenate([q0[:3], q0[7:]])
    moving = _hermite(p_stand, p0, v_pos, s, BLEND_S)
    # a foot in swing at frame 0 stays down until the blend's last SWING_S: a short single support, as in a gait
    late = np.clip((s * BLEND_S - (BLEND_S - SWING_S)) / SWING_S, 0.0, 1.0)
    for k in _swing_feet(clip.qpos[0]):
        cols = 3 + np.arange(6 * k, 6 * k + 6)  # the leg's six joints after the root position
        moving[:, cols] = _hermite(p_stand[cols], p0[cols], v_pos[cols], late, SWING_S)
    h01 = 3 * s**2 - 2 * s**3
    quat = slerp_wxyz(np.array([0.0, 1.0]), np.stack([stand[3:7], q0[3:7]]), h01)
    prefix = np.concatenate([np.repeat(stand[None], settle, 0), np.column_stack([moving[:, :3], quat, moving[:, 3:]])])
    n = len(prefix)
    objects = tuple(
        replace(
            o,
            pose=np.concatenate([np.repeat(o.pose[:1], n, 0), o.pose]),
            contact=None if o.contact is None else np.concatenate([np.zeros(n, bool), o.contact]),
        )
        for o in clip.objects
    )
    contacts = (
        None if clip.contacts is None else np.concatenate([np.zeros((n, clip.contacts.shape[1]), bool), clip.contacts])
    )
    return replace(
        clip,
        qpos=np.concatenate([prefix, clip.qpos]),
        objects=objects,
        contacts=contacts,
        provenance={**clip.provenance, START_PREFIX_KEY: n},
    )


def prefix_frames(clip: RobotClip) -> int:
    """The frames of a clip's synthetic start prefix (0: none)."""
    return int(clip.provenance.get(START_PREFIX_KEY, 0))
