"""Two-handed squeezes kept on the faces the human squeezes.

The scaled pose decides where on the object a hand lands (:mod:`retarget.contact` only closes the gap), and a G1
scaled from a human holding a box between its palms can end with a hand on the box's top (measured on a held-out
OMOMO lift: the human's wrists at ``n_l . n_r = -1.00``, the G1's at 0.07). Where the human squeezes an object
(:func:`pipeline.take.human_hold`'s opposition <= :data:`SQUEEZE`) and the retargeted G1 does not
(:func:`g1_opposition` over the same frames > :data:`SQUEEZE`), :func:`anchored_targets` moves the G1's wrist
targets onto the human's wrists as they sit in the object's frame, carried to the robot's object pose,

``p_G1(t) = c_r(t) + R_r(t) R_h(t)^T (p_h(t) - c_h(t))``   (``c``, ``R``: the object's pose, human ``h`` / robot ``r``),

blended in and out over :data:`RAMP` frames around the held frames, and the clip is solved again: the object keeps
its real size in both worlds, so the same faces are the same points. Where the G1 cannot reach them, the IK's
residual shows it and physicalize's ``out of reach`` class says so with its distance."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.ndimage import distance_transform_edt

from pipeline.clip import HumanClip, ObjectTrack
from pipeline.distance.field import ObjectField
from pipeline.robot import HAND_BODIES
from pipeline.rotations import from_pose_frame, to_pose_frame
from pipeline.take import mean_opposition, wrist_normals
from pipeline.terms.link_motion import link_motion
from retarget.targets import IKTargets

SQUEEZE = -0.5  # n_l . n_r at or below this: the hands hold the object between them
RAMP = 10  # frames over which the anchored wrist targets blend in and out
WRISTS = ("left_wrist", "right_wrist")  # the human's joints the G1's wrist targets are anchored on


def g1_opposition(
    field: ObjectField, qpos: np.ndarray, objects: tuple[ObjectTrack, ...], frames: np.ndarray, source: str
) -> float:
    """Mean ``n_l . n_r`` of the G1's hands (``qpos`` (T, 36)) on ``frames`` against the robot's object 0, whose
    distance field is ``field`` (the human's object's: the robot's is the same geometry, placed anew)."""
    links = link_motion(qpos[frames], np.zeros((len(frames), 35)), HAND_BODIES, source).pos
    return mean_opposition(wrist_normals(field, links, objects[0].pose[frames]))


def anchored_targets(
    human: HumanClip,
    targets: IKTargets,
    objects: tuple[ObjectTrack, ...],
    frames: np.ndarray,
    carry: Callable[[np.ndarray], np.ndarray] | None = None,
) -> IKTargets:
    """``targets`` with the G1's wrist targets on the human's wrists carried from the human's object pose to the
    robot's (module docstring), weight 1 on ``frames`` falling to 0 over :data:`RAMP` frames around them. ``carry``
    maps (N, 3) points of the human's object frame onto the robot's object when that is a variant of it
    (:meth:`retarget.augment.VariantMap.carry`); None: the same object."""
    held = np.zeros(targets.frames, bool)
    held[frames[frames < targets.frames]] = True
    weight = np.clip(1.0 - distance_transform_edt(~held) / (RAMP + 1), 0.0, 1.0)
    h_pose, r_pose = human.objects[0].pose, objects[0].pose
    t = np.flatnonzero(weight > 0)
    pos = targets.pos.copy()
    for side, wrist in zip(("left", "right"), WRISTS):
        k = targets.body_names.index(f"{side}_wrist_yaw_link")
        p_h = human.joint_pos[t, human.skeleton.index(wrist)]
        local = to_pose_frame(h_pose[t], p_h)
        if carry is not None:
            local = carry(local)
        carried = from_pose_frame(r_pose[t], local)
        pos[t, k] = (1 - weight[t, None]) * pos[t, k] + weight[t, None] * carried
    return replace(targets, pos=pos)
